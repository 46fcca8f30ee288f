//! The textured terrain (`tessera gen textured`): determinism, OBJ / MTL / image
//! consistency, UVs that put each tile's photo on its own tile the right way up, and a
//! build of it whose texture stage reads every image.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use tessera_gen::*;
use tessera_testkit::fnv1a;

fn opts(columns: u32, rows: u32, size: u32, format: ImageFormat) -> TexturedOptions {
    TexturedOptions {
        triangles: 4_000,
        columns,
        rows,
        image_size: size,
        image_format: format,
        seed: 7,
    }
}

/// Every file in `dir`, by name.
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect()
}

#[test]
fn same_options_write_the_same_bytes() {
    // Why: benchmarks and tests regenerate the model instead of storing gigabytes; a
    // regenerated model must be the one measured before.
    let (a, b, c) = (
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
    );
    for format in [ImageFormat::Jpeg { quality: 80 }, ImageFormat::Png] {
        let o = opts(3, 2, 96, format);
        let ra = write_textured_terrain(&a.path().join("m.obj"), &o, &NoProgress).unwrap();
        let rb = write_textured_terrain(&b.path().join("m.obj"), &o, &NoProgress).unwrap();
        let other = TexturedOptions {
            seed: 8,
            ..o.clone()
        };
        write_textured_terrain(&c.path().join("m.obj"), &other, &NoProgress).unwrap();
        let (fa, fb, fc) = (files(a.path()), files(b.path()), files(c.path()));
        assert_eq!(fa.len(), 2 + 6, "{:?}", fa.keys());
        assert_eq!(fa, fb, "{format:?}: two runs differ");
        assert_ne!(fa["m.obj"], fc["m.obj"], "the seed changes the relief");
        let img = format!("m-tile-00.{}", format.extension());
        assert_ne!(fa[&img], fc[&img], "the seed changes the photos");
        assert_eq!(ra.image_bytes, rb.image_bytes);
        for d in [&a, &b, &c] {
            for e in std::fs::read_dir(d.path()).unwrap() {
                std::fs::remove_file(e.unwrap().path()).unwrap();
            }
        }
    }
}

/// The exact OBJ, MTL and decoded texels are part of the contract (the encoders' own
/// bytes may change with the `image` crate, so the images are pinned decoded). If a
/// deliberate change alters them, update the constants.
#[test]
fn golden_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("g.obj");
    let r = write_textured_terrain(&obj, &opts(2, 1, 64, ImageFormat::Png), &NoProgress).unwrap();
    let mut texels = Vec::new();
    for p in &r.images {
        texels.extend_from_slice(image::open(p).unwrap().to_rgb8().as_raw());
    }
    let got = (
        fnv1a(&std::fs::read(&obj).unwrap()),
        fnv1a(&std::fs::read(&r.mtl).unwrap()),
        fnv1a(&texels),
    );
    assert_eq!(
        got, GOLDEN,
        "got ({:#018x}, {:#018x}, {:#018x})",
        got.0, got.1, got.2
    );
}

const GOLDEN: (u64, u64, u64) = (
    0x488f_619f_47ef_30c6,
    0x4d46_9408_75da_6e39,
    0x6820_ba15_3d98_f17a,
);

/// The OBJ as written: positions, uvs, and per material its faces' (position, uv)
/// corners.
struct Obj {
    mtllib: String,
    positions: Vec<[f64; 3]>,
    uvs: Vec<[f64; 2]>,
    faces: Vec<(String, [[usize; 2]; 3])>,
}

fn parse_obj(path: &Path) -> Obj {
    let text = std::fs::read_to_string(path).unwrap();
    let mut o = Obj {
        mtllib: String::new(),
        positions: Vec::new(),
        uvs: Vec::new(),
        faces: Vec::new(),
    };
    let mut material = String::new();
    for line in text.lines() {
        let mut w = line.split_whitespace();
        let num = |s: Option<&str>| s.unwrap().parse::<f64>().unwrap();
        match w.next() {
            Some("mtllib") => o.mtllib = w.next().unwrap().to_string(),
            Some("v") => o
                .positions
                .push([num(w.next()), num(w.next()), num(w.next())]),
            Some("vt") => o.uvs.push([num(w.next()), num(w.next())]),
            Some("usemtl") => material = w.next().unwrap().to_string(),
            Some("f") => {
                let corners: Vec<[usize; 2]> = w
                    .map(|c| {
                        let (p, t) = c.split_once('/').unwrap();
                        [p.parse().unwrap(), t.parse().unwrap()]
                    })
                    .collect();
                assert_eq!(corners.len(), 3, "{line}");
                assert!(!material.is_empty(), "a face before any usemtl");
                o.faces
                    .push((material.clone(), [corners[0], corners[1], corners[2]]));
            }
            Some("#") | None => {}
            Some(other) => panic!("unexpected statement {other:?}"),
        }
    }
    o
}

/// material -> image file, from the MTL.
fn parse_mtl(path: &Path) -> HashMap<String, String> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut out = HashMap::new();
    let mut current = None;
    for line in text.lines() {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.first() {
            Some(&"newmtl") => current = Some(w[1].to_string()),
            Some(&"map_Kd") => {
                assert_eq!(&w[1..3], ["-clamp", "on"], "{line}");
                out.insert(current.clone().unwrap(), w[3].to_string());
            }
            _ => {}
        }
    }
    out
}

#[test]
fn obj_mtl_and_images_agree() {
    // Why: the builder trusts the files' cross references; every material must have its
    // image at the stated size, every face index must exist, every UV must be in [0, 1]
    // and put the tile's photo on the tile, north up (v = 0 at the image's bottom row),
    // or the texture stage measures a model that is not the one described.
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("terrain.obj");
    let (cols, rows, size) = (3u32, 2u32, 256u32);
    let o = TexturedOptions {
        triangles: 20_000,
        ..opts(cols, rows, size, ImageFormat::Jpeg { quality: 90 })
    };
    let r = write_textured_terrain(&obj, &o, &NoProgress).unwrap();
    let k = (cols * rows) as usize;
    let n = r.cells_per_tile as usize;
    assert_eq!(n, textured_resolution(20_000, cols, rows).unwrap() as usize);
    let parsed = parse_obj(&obj);
    assert_eq!(parsed.mtllib, "terrain.mtl");
    assert_eq!(
        parsed.positions.len(),
        (cols as usize * n + 1) * (rows as usize * n + 1)
    );
    assert_eq!(parsed.positions.len() as u64, r.mesh.vertices);
    assert_eq!(parsed.uvs.len(), k * (n + 1) * (n + 1));
    assert_eq!(parsed.uvs.len() as u64, r.uvs);
    assert_eq!(parsed.faces.len(), k * 2 * n * n);
    assert_eq!(parsed.faces.len() as u64, r.mesh.triangles);
    assert_eq!(r.texels, k as u64 * u64::from(size * size));
    assert_eq!(r.decoded_bytes, 4 * r.texels);
    assert_eq!(r.obj_bytes, std::fs::metadata(&obj).unwrap().len());

    // Materials and images.
    let mtl = parse_mtl(&dir.path().join(&parsed.mtllib));
    assert_eq!(mtl.len(), k);
    let (mtl_path, image_paths) = textured_paths(&obj, &o);
    assert_eq!(
        (mtl_path, image_paths.clone()),
        (r.mtl.clone(), r.images.clone())
    );
    let mut images: HashMap<String, image::RgbImage> = HashMap::new();
    let mut on_disk = 0;
    for (i, path) in image_paths.iter().enumerate() {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        assert_eq!(mtl[&format!("tile-{i:02}")], name);
        on_disk += std::fs::metadata(path).unwrap().len();
        let img = image::open(path).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (size, size), "{name}");
        images.insert(format!("tile-{i:02}"), img);
    }
    assert_eq!(on_disk, r.image_bytes);
    let mut names: Vec<String> = files(dir.path()).into_keys().collect();
    names.sort();
    assert_eq!(names.len(), 2 + k, "{names:?}: no other (temporary) files");

    // Faces: indices in range, one tile's UVs each, mapping the tile onto [0, 1]^2.
    let t = 1.0 / f64::from(cols.max(rows));
    let (mut water, mut land, mut blue_water, mut blue_land) = (0, 0, 0, 0);
    let mut faces_per_material: HashMap<&str, usize> = HashMap::new();
    for (material, corners) in &parsed.faces {
        *faces_per_material.entry(material).or_default() += 1;
        let tile: usize = material.strip_prefix("tile-").unwrap().parse().unwrap();
        let (c, r) = ((tile % cols as usize) as f64, (tile / cols as usize) as f64);
        let uv_range = tile * (n + 1) * (n + 1) + 1..=(tile + 1) * (n + 1) * (n + 1);
        for &[p, q] in corners {
            assert!((1..=parsed.positions.len()).contains(&p));
            assert!(uv_range.contains(&q), "{material}: uv {q} of another tile");
            let [x, y, z] = parsed.positions[p - 1];
            let [u, v] = parsed.uvs[q - 1];
            assert!((0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v));
            assert!(
                (x - (c + u) * t).abs() < 1e-5,
                "u {u} at x {x} on tile {tile}"
            );
            assert!(
                (y - (r + v) * t).abs() < 1e-5,
                "v {v} at y {y} on tile {tile}"
            );
            // The photo follows the relief: deep water is blue, high land is not. The
            // texel at (u, v) is at column u * size, row (1 - v) * size.
            let px = ((u * f64::from(size)) as u32).min(size - 1);
            let py = (((1.0 - v) * f64::from(size)) as u32).min(size - 1);
            let central = |a: u32| a > size * 3 / 10 && a < size * 7 / 10;
            if (central(px) && central(py)) || (px < size / 8 && py < size / 8) {
                continue; // the tile number's plates
            }
            let [red, _, blue] = images[material.as_str()].get_pixel(px, py).0.map(u16::from);
            if z < -0.02 {
                water += 1;
                blue_water += usize::from(blue > red + 40);
            } else if z > 0.02 {
                land += 1;
                blue_land += usize::from(blue > red + 40);
            }
        }
    }
    assert_eq!(faces_per_material.len(), k);
    assert!(faces_per_material.values().all(|&f| f == 2 * n * n));
    eprintln!("water corners {water} ({blue_water} blue), land {land} ({blue_land} blue)");
    assert!(water > 100 && land > 100, "the seed gives water and land");
    assert!(blue_water * 100 >= water * 98, "{blue_water} of {water}");
    assert!(blue_land * 100 <= land, "{blue_land} of {land}");
}

#[test]
fn the_photo_is_upright() {
    // Why: a tile's number is drawn at the top-left corner of its image (row 0, the
    // tile's north edge): a reader that flips or mirrors v shows it elsewhere. Exact
    // texels (PNG): tile 0's small '0' starts at texel (2 s, 2 s), s = size / 160.
    let dir = tempfile::tempdir().unwrap();
    let r = write_textured_terrain(
        &dir.path().join("u.obj"),
        &opts(1, 1, 320, ImageFormat::Png),
        &NoProgress,
    )
    .unwrap();
    let img = image::open(&r.images[0]).unwrap().to_rgb8();
    let s = 2;
    // '0' = 01110 / 10001 / ...: the top row's columns 1..=3 are white, column 0 is not.
    for x in 1..=3 {
        assert_eq!(
            img.get_pixel(2 * s + x * s, 2 * s).0,
            [255; 3],
            "column {x}"
        );
    }
    assert_ne!(img.get_pixel(2 * s, 2 * s).0, [255; 3]);
    // Nothing white in the mirrored corners.
    for (x0, y0) in [(320 - 16 * s, 0), (0, 320 - 10 * s)] {
        for y in y0..y0 + 10 * s {
            for x in x0..x0 + 16 * s {
                assert_ne!(img.get_pixel(x, y).0, [255; 3], "({x}, {y})");
            }
        }
    }
}

#[test]
fn invalid_options_fail_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("x.obj");
    let bad = [
        TexturedOptions {
            columns: 0,
            ..opts(1, 1, 64, ImageFormat::Png)
        },
        opts(1, 1, 4, ImageFormat::Png),
        opts(1, 1, 64, ImageFormat::Jpeg { quality: 0 }),
        TexturedOptions {
            triangles: 1 << 40,
            ..opts(1, 1, 64, ImageFormat::Png)
        },
    ];
    for o in bad {
        let e = write_textured_terrain(&obj, &o, &NoProgress).unwrap_err();
        assert!(matches!(e, GenError::InvalidArgument(_)), "{e}");
    }
    assert!(files(dir.path()).is_empty());
    // A missing directory: an I/O error naming the file.
    let missing: PathBuf = dir.path().join("no/such/x.obj");
    let e = write_textured_terrain(&missing, &opts(1, 1, 64, ImageFormat::Png), &NoProgress)
        .unwrap_err();
    assert!(e.to_string().contains("no/such"), "{e}");
}

#[test]
fn the_builder_reads_every_tile_image() {
    // Why: the benchmark's figures (source images, texels, re-decodes) come from the
    // builder's texture stage; it must see exactly the K images generated, all of their
    // texels, and the leaves must keep every source texel.
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("b.obj");
    let (cols, rows, size) = (3u32, 2u32, 128u32);
    let o = TexturedOptions {
        triangles: 30_000,
        ..opts(cols, rows, size, ImageFormat::Jpeg { quality: 85 })
    };
    let g = write_textured_terrain(&obj, &o, &NoProgress).unwrap();
    let out = dir.path().join("b.tsr");
    let r = tessera_build::build(
        &obj,
        &out,
        &tessera_build::BuildOptions {
            memory_bytes: 256 << 20,
            leaf_triangles: 2000,
            node_triangles: 1000,
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    assert_eq!(r.input_triangles, g.mesh.triangles);
    let t = r.textures.expect("a textured build");
    assert_eq!(t.source_images, u64::from(cols * rows));
    assert_eq!(t.source_texels, g.texels);
    assert!(t.unreadable_images.is_empty(), "{:?}", t.unreadable_images);
    assert_eq!(t.solid_only, 0, "every face is textured");
    assert!(
        t.leaf_texels >= t.source_texels,
        "leaves {} < source {}",
        t.leaf_texels,
        t.source_texels
    );
    eprintln!("{t:?}");
}
