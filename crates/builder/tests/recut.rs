//! Re-cut textures (issue 11, fragmented atlases): a mesh whose UV atlas cuts it into
//! hundreds of small charts, as photogrammetry exports do, must still simplify. Built
//! with its atlas, the roots hold about the triangles of the same mesh without UVs, the
//! file's geometry costs about as much, and every re-cut patch's texture shows the
//! source's colours where its triangles are.

use std::fmt::Write as _;
use std::path::Path;

use tessera_build::texture::TextureOptions;
use tessera_build::{build, BuildOptions, BuildReport, NoProgress};
use tessera_format::{Model, TextureCodec, NODE_FLAG_LEAF, RECUT_IMAGE};

/// Grid cells a side, cells a chart side, atlas texels a side.
const N: usize = 96;
const CHART: usize = 3;
const ATLAS: u32 = 1024;

fn height(x: f64, y: f64) -> f64 {
    0.08 * (5.0 * x).sin() * (4.0 * y).cos()
}

/// The source's colour at model point (x, y): smooth bands, so a coarse patch's texel
/// should still show it, and a texel dragged across an atlas seam would not.
fn colour(x: f64, y: f64) -> [f64; 3] {
    [
        128.0 + 100.0 * (6.0 * x).sin(),
        128.0 + 100.0 * (5.0 * y).cos(),
        128.0 + 100.0 * (4.0 * (x + y)).sin(),
    ]
}

/// Writes the heightfield as OBJ + MTL + PNG, each CHART x CHART block of cells its own
/// chart, the charts placed in the atlas in a scrambled order with black between them
/// (as real atlases are); and `plain.obj`, the same mesh without UVs.
fn write_fragmented(dir: &Path) {
    let charts_side = N / CHART;
    let slots = charts_side; // atlas slots a side
    let slot = ATLAS as usize / slots; // texels a slot
    let island = slot - 6; // texels an island (3-texel black gap each side)
    let cell_texels = island as f64 / CHART as f64;
    let mut img = image::RgbaImage::from_pixel(ATLAS, ATLAS, image::Rgba([0, 0, 0, 255]));
    let mut obj = String::from("mtllib atlas.mtl\nusemtl atlas\n");
    let mut plain = String::new();
    let p = |i: usize, j: usize| {
        let (x, y) = (i as f64 / N as f64, j as f64 / N as f64);
        (x, y, height(x, y))
    };
    for j in 0..=N {
        for i in 0..=N {
            let (x, y, z) = p(i, j);
            writeln!(obj, "v {x} {y} {z}").unwrap();
            writeln!(plain, "v {x} {y} {z}").unwrap();
        }
    }
    let vid = |i: usize, j: usize| j * (N + 1) + i + 1;
    let mut vt = 0usize;
    for cj in 0..charts_side {
        for ci in 0..charts_side {
            // Scrambled slot (a bijection of the grid of slots).
            let k = (cj * charts_side + ci) * 37 % (slots * slots);
            let (sx, sy) = (k % slots, k / slots);
            let (ox, oy) = (sx * slot + 3, sy * slot + 3);
            // This chart's texels: the colour of the model point each maps to.
            for ty in 0..island {
                for tx in 0..island {
                    let gx = ci as f64 * CHART as f64 + (tx as f64 + 0.5) / cell_texels;
                    let gy = cj as f64 * CHART as f64 + (ty as f64 + 0.5) / cell_texels;
                    let c = colour(gx / N as f64, gy / N as f64);
                    img.put_pixel(
                        (ox + tx) as u32,
                        (oy + ty) as u32,
                        image::Rgba([c[0] as u8, c[1] as u8, c[2] as u8, 255]),
                    );
                }
            }
            // Its texture coordinates (OBJ: v up).
            let base = vt;
            for dj in 0..=CHART {
                for di in 0..=CHART {
                    let u = (ox as f64 + di as f64 * cell_texels) / ATLAS as f64;
                    let v = (oy as f64 + dj as f64 * cell_texels) / ATLAS as f64;
                    writeln!(obj, "vt {u} {}", 1.0 - v).unwrap();
                    vt += 1;
                }
            }
            let tid = |di: usize, dj: usize| base + dj * (CHART + 1) + di + 1;
            for dj in 0..CHART {
                for di in 0..CHART {
                    let (i, j) = (ci * CHART + di, cj * CHART + dj);
                    let q = [
                        (vid(i, j), tid(di, dj)),
                        (vid(i + 1, j), tid(di + 1, dj)),
                        (vid(i + 1, j + 1), tid(di + 1, dj + 1)),
                        (vid(i, j + 1), tid(di, dj + 1)),
                    ];
                    for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
                        writeln!(
                            obj,
                            "f {}/{} {}/{} {}/{}",
                            t[0].0, t[0].1, t[1].0, t[1].1, t[2].0, t[2].1
                        )
                        .unwrap();
                        writeln!(plain, "f {} {} {}", t[0].0, t[1].0, t[2].0).unwrap();
                    }
                }
            }
        }
    }
    std::fs::write(dir.join("atlas.obj"), obj).unwrap();
    std::fs::write(dir.join("plain.obj"), plain).unwrap();
    std::fs::write(dir.join("atlas.mtl"), "newmtl atlas\nmap_Kd atlas.png\n").unwrap();
    img.save(dir.join("atlas.png")).unwrap();
}

fn opts(recut: bool) -> BuildOptions {
    BuildOptions {
        leaf_triangles: 1500,
        node_triangles: 800,
        texture: TextureOptions {
            codec: TextureCodec::Png,
            recut,
            ..Default::default()
        },
        ..Default::default()
    }
}

struct Built {
    root_triangles: u64,
    geometry_bytes_per_triangle: f64,
    report: BuildReport,
}

fn build_it(input: &Path, out: &Path, recut: bool) -> Built {
    let report = build(input, out, &opts(recut), &NoProgress).unwrap();
    let model = Model::open(out).unwrap();
    let root_triangles = model
        .nodes()
        .iter()
        .filter(|n| n.level == 0)
        .map(|n| n.triangle_count as u64)
        .sum();
    let texture = report.textures.as_ref().map_or(0, |t| t.bytes);
    Built {
        root_triangles,
        geometry_bytes_per_triangle: (report.output_bytes - texture) as f64 / (2 * N * N) as f64,
        report,
    }
}

#[test]
fn a_fragmented_atlas_simplifies_and_its_recut_textures_show_the_source() {
    let dir = tempfile::tempdir().unwrap();
    write_fragmented(dir.path());
    let plain = build_it(
        &dir.path().join("plain.obj"),
        &dir.path().join("p.tsr"),
        false,
    );
    let seamed = build_it(
        &dir.path().join("atlas.obj"),
        &dir.path().join("s.tsr"),
        false,
    );
    let out = dir.path().join("r.tsr");
    let recut = build_it(&dir.path().join("atlas.obj"), &out, true);
    let t = recut.report.textures.clone().unwrap();
    eprintln!(
        "root triangles: without UVs {}, source cut {}, re-cut {}; geometry bytes a \
         triangle: {:.2}, {:.2}, {:.2}; {} of {} patches re-cut",
        plain.root_triangles,
        seamed.root_triangles,
        recut.root_triangles,
        plain.geometry_bytes_per_triangle,
        seamed.geometry_bytes_per_triangle,
        recut.geometry_bytes_per_triangle,
        t.recut,
        recut.report.nodes
    );
    // The targets: roots at most 2x, geometry at most 1.5x (measured: 1.00x and
    // 1.14x; the source cut 2.2x and 2.4x).
    assert!(
        recut.root_triangles <= 2 * plain.root_triangles,
        "{} vs {}",
        recut.root_triangles,
        plain.root_triangles
    );
    assert!(
        recut.geometry_bytes_per_triangle <= 1.5 * plain.geometry_bytes_per_triangle,
        "{} vs {}",
        recut.geometry_bytes_per_triangle,
        plain.geometry_bytes_per_triangle
    );
    // The atlas's seams are what held the source cut back: this test would not see a
    // re-cut that changed nothing.
    assert!(seamed.root_triangles > 2 * plain.root_triangles);
    assert!(seamed.geometry_bytes_per_triangle > recut.geometry_bytes_per_triangle);
    assert_eq!(
        t.recut, recut.report.nodes,
        "every patch of this atlas is re-cut"
    );
    let model = Model::open(&out).unwrap();
    let v = tessera_build::verify::verify_model(&model);
    assert!(v.is_valid(), "{:?}", v.problems);

    let (leaf_mean, worst_leaf, coarse_mean) = texel_errors(&model, true);
    let (sl, sw, sc) = texel_errors(&Model::open(dir.path().join("s.tsr")).unwrap(), false);
    eprintln!("source cut: leaves mean {sl:.2} (worst {sw:.0}), coarse mean {sc:.2}");
    eprintln!(
        "texel at a triangle centre against the source's colour: leaves mean {leaf_mean:.2} (worst \
         {worst_leaf:.0}), coarse mean {coarse_mean:.2}"
    );
    // Measured: leaves 0.80 (worst 2; the source cut 0.78, worst 1: colour
    // quantisation), coarse patches 4.6 (the source cut 2.7: its levels' texels are up
    // to half the error, a re-cut's are the error).
    assert!(
        leaf_mean < 2.0 && worst_leaf <= 8.0,
        "{leaf_mean} {worst_leaf}"
    );
    assert!(coarse_mean < 8.0, "{coarse_mean}");
}

/// Mean (and worst, at the leaves) largest channel difference between the texel under
/// each triangle's centre and the source's colour at its model point: (leaves mean, leaves worst,
/// coarse mean). `recut`: every chart must be a re-cut one.
fn texel_errors(model: &Model, recut: bool) -> (f64, f64, f64) {
    // Every re-cut vertex's texel shows the source's colour at its model point: within
    // a few levels at the leaves (resampled at the source's density), within the
    // bands' variation over a coarse patch's texel elsewhere.
    let grid = model.grid();
    let (mut leaf_err, mut leaf_n, mut coarse_err, mut coarse_n) = (0.0f64, 0u64, 0.0f64, 0u64);
    let mut worst_leaf = 0.0f64;
    for (i, n) in model.nodes().iter().enumerate() {
        let mut p = model.decode_patch(i).unwrap();
        let tex = p.texture.as_mut().unwrap();
        let (w, h) = (tex.width as usize, tex.height as usize);
        for (v, uv) in p.uvs.iter().enumerate() {
            let c = p.charts[p.chart_ids[v] as usize];
            assert!(!recut || c.image == RECUT_IMAGE);
            let m = c.map(*uv);
            assert!((0.0..=1.0).contains(&m[0]) && (0.0..=1.0).contains(&m[1]));
        }
        // Probed at triangle centres: a vertex on a chart's edge lies on the edge of
        // its source texels, next to the atlas's black.
        for t in p.indices.chunks_exact(3) {
            let m = t
                .iter()
                .map(|&v| p.charts[p.chart_ids[v as usize] as usize].map(p.uvs[v as usize]))
                .fold([0.0f64; 2], |a, m| {
                    [a[0] + m[0] as f64 / 3.0, a[1] + m[1] as f64 / 3.0]
                });
            let (x, y) = (
                ((m[0] * w as f64) as usize).min(w - 1),
                ((m[1] * h as f64) as usize).min(h - 1),
            );
            let o = 4 * (y * w + x);
            let pos = t
                .iter()
                .map(|&v| grid.position(p.positions[v as usize]))
                .fold([0.0f64; 2], |a, q| [a[0] + q[0] / 3.0, a[1] + q[1] / 3.0]);
            let want = colour(pos[0], pos[1]);
            let d = (0..3)
                .map(|k| (tex.rgba[o + k] as f64 - want[k]).abs())
                .fold(0.0, f64::max);
            if n.flags & NODE_FLAG_LEAF != 0 {
                leaf_err += d;
                leaf_n += 1;
                worst_leaf = worst_leaf.max(d);
            } else {
                coarse_err += d;
                coarse_n += 1;
            }
        }
    }
    assert!(leaf_n > 1000 && coarse_n > 500);
    (
        leaf_err / leaf_n as f64,
        worst_leaf,
        coarse_err / coarse_n as f64,
    )
}
