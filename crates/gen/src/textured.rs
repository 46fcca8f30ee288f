//! A textured terrain: the heightfield of [`crate::write_terrain`] over a grid of
//! `columns x rows` square tiles, written as Wavefront OBJ + MTL with one procedural
//! "aerial photo" (JPEG or PNG) per tile, the input the builder's texture stage needs at
//! any size (issue 11: >= 2 GB of decoded source images from a few commands).
//!
//! Layout, for `-o DIR/NAME.obj`:
//!
//! * `DIR/NAME-tile-KK.jpg` (or `.png`), `K = columns * rows` images of `image_size`
//!   squared texels, RGB. Tile `k = r * columns + c` covers `x` in `[c t, (c + 1) t]`,
//!   `y` in `[r t, (r + 1) t]` with `t = 1 / max(columns, rows)` (so the whole terrain
//!   fits the unit square, its longer side 1), image row 0 at the tile's `y = (r + 1) t`
//!   edge (north): seen from above with +y up the image reads upright. Each image shows
//!   fields, hedges, roads, forest, water, rock and snow that follow the relief (the
//!   mesh's own height function) and continue across tile borders, and its tile number
//!   in large digits in the centre and small ones in the top-left corner, so a texture
//!   on the wrong tile, flipped or rotated shows at a glance.
//! * `DIR/NAME.mtl`: material `tile-KK` per tile, `Kd 1 1 1`, `map_Kd -clamp on
//!   NAME-tile-KK.jpg` (clamped: a tile's texels end at its border).
//! * `DIR/NAME.obj`: `mtllib NAME.mtl`, the `(columns n + 1) x (rows n + 1)` positions of
//!   the vertex grid (shared by neighbouring tiles: the mesh is one connected surface),
//!   then `(n + 1)^2` texture coordinates per tile (`u = a / n`, `v = b / n` for the
//!   tile's local grid point `(a, b)`, `v = 0` at the image's bottom row as OBJ
//!   expects, so every UV is in `[0, 1]`), then per tile `usemtl tile-KK` and its `2 n^2`
//!   faces `f p/t p/t p/t`, counter-clockwise seen from +z (as the terrain's).
//!
//! Every file is written atomically ([`tessera_format::AtomicFile`]), the images first,
//! then the MTL, the OBJ last: an OBJ at the path means its library and images are all
//! there. Memory: one image's RGB texels (`3 image_size^2` bytes) and the encoder's
//! buffers; the mesh is streamed. The bytes depend only on the options (plain IEEE-754
//! arithmetic and integer hashing, as the other generators; the JPEG and PNG encoders
//! are deterministic).

use std::io::Write;
use std::path::{Path, PathBuf};

use image::ImageEncoder;
use rayon::prelude::*;
use tessera_format::{AtomicFile, AtomicFileError};
use tessera_mesh::{MeshError, Vertex};

use crate::noise::{derive_key, mix64, split, Fbm};
use crate::terrain::Height;
use crate::{stream_grid, GenError, GenReport, Progress, Ticker};

/// How the tile images are encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// Baseline JPEG of this quality (1..=100).
    Jpeg { quality: u8 },
    /// PNG (lossless, fast compression).
    Png,
}

impl ImageFormat {
    /// The file extension, without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            ImageFormat::Jpeg { .. } => "jpg",
            ImageFormat::Png => "png",
        }
    }
}

/// Options of [`write_textured_terrain`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TexturedOptions {
    /// Requested triangle count: each tile gets `n x n` grid cells of two triangles,
    /// `n = max(1, round(sqrt(triangles / (2 K))))` (see [`textured_resolution`]).
    pub triangles: u64,
    /// Tiles along x and along y (`K = columns * rows`, each at least 1).
    pub columns: u32,
    pub rows: u32,
    /// Side of every (square) tile image, texels (8..=16384).
    pub image_size: u32,
    pub image_format: ImageFormat,
    /// Seed of the relief and of the photos.
    pub seed: u64,
}

impl Default for TexturedOptions {
    fn default() -> Self {
        TexturedOptions {
            triangles: 1_000_000,
            columns: 4,
            rows: 4,
            image_size: 4096,
            image_format: ImageFormat::Jpeg { quality: 90 },
            seed: 0,
        }
    }
}

/// What [`write_textured_terrain`] wrote.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TexturedReport {
    /// The mesh: `vertices` counts the OBJ's positions (`v`), `triangles` its faces.
    pub mesh: GenReport,
    /// Texture coordinates (`vt`) in the OBJ.
    pub uvs: u64,
    /// Grid cells along each tile's side (`n`).
    pub cells_per_tile: u64,
    pub obj: PathBuf,
    pub mtl: PathBuf,
    /// The tile images, tile `k` at index `k`.
    pub images: Vec<PathBuf>,
    /// Texels of all images (`K image_size^2`).
    pub texels: u64,
    /// Bytes of all images decoded to RGBA8 (`4 texels`), as the builder holds them.
    pub decoded_bytes: u64,
    /// Bytes of all image files on disk.
    pub image_bytes: u64,
    /// Bytes of the OBJ and of the MTL.
    pub obj_bytes: u64,
    pub mtl_bytes: u64,
}

/// The most square grid of `k` tiles, `(columns, rows)` with `columns >= rows` and
/// `columns * rows == k`: `rows` is the largest divisor of `k` not above `sqrt(k)` (so a
/// prime `k` gives one row).
pub fn tile_grid(k: u32) -> (u32, u32) {
    let k = k.max(1);
    let mut rows = 1;
    let mut d = 1u32;
    while u64::from(d) * u64::from(d) <= u64::from(k) {
        if k.is_multiple_of(d) {
            rows = d;
        }
        d += 1;
    }
    (k / rows, rows)
}

/// Grid cells along a tile's side for `triangles` requested over `tiles` tiles:
/// `max(1, round(sqrt(triangles / (2 tiles))))`. Fails when the positions or the
/// texture coordinates would exceed `u32::MAX`.
pub fn textured_resolution(triangles: u64, columns: u32, rows: u32) -> Result<u64, GenError> {
    if columns == 0 || rows == 0 {
        return Err(GenError::InvalidArgument(format!(
            "a textured terrain needs at least one tile, {columns}x{rows} requested"
        )));
    }
    let k = u64::from(columns) * u64::from(rows);
    let n = ((triangles as f64 / (2.0 * k as f64)).sqrt().round() as u64).max(1);
    let positions = (u128::from(columns) * n as u128 + 1) * (u128::from(rows) * n as u128 + 1);
    let uvs = k as u128 * (n as u128 + 1) * (n as u128 + 1);
    if positions.max(uvs) > u128::from(u32::MAX) {
        return Err(GenError::InvalidArgument(format!(
            "{triangles} triangles over {k} tiles: more than {} vertices",
            u32::MAX
        )));
    }
    Ok(n)
}

/// The files [`write_textured_terrain`] writes for `obj` (`DIR/NAME.obj`): the MTL
/// `DIR/NAME.mtl` and the tile images `DIR/NAME-tile-KK.EXT`, tile `k` at index `k`.
pub fn textured_paths(obj: &Path, opts: &TexturedOptions) -> (PathBuf, Vec<PathBuf>) {
    let k = opts.columns.max(1) * opts.rows.max(1);
    let (_, names) = names(obj, k, opts.image_format);
    let dir = obj.parent().unwrap_or(Path::new(""));
    (
        obj.with_extension("mtl"),
        names.iter().map(|n| dir.join(n)).collect(),
    )
}

/// The stem of `obj` and the images' file names.
fn names(obj: &Path, k: u32, format: ImageFormat) -> (String, Vec<String>) {
    let stem = obj
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "terrain".into());
    let digits = (k.saturating_sub(1)).to_string().len().max(2);
    let names = (0..k)
        .map(|i| format!("{stem}-tile-{i:0digits$}.{}", format.extension()))
        .collect();
    (stem, names)
}

/// Write a textured terrain: `obj`, its MTL beside it and one image per tile; see the
/// module docs for the layout and contract.
///
/// Reports an `images` stage (one unit per image) then a `generate` stage (positions +
/// triangles, as [`crate::write_terrain`]) to `progress`.
pub fn write_textured_terrain(
    obj: &Path,
    opts: &TexturedOptions,
    progress: &dyn Progress,
) -> Result<TexturedReport, GenError> {
    let n = textured_resolution(opts.triangles, opts.columns, opts.rows)?;
    if !(8..=16384).contains(&opts.image_size) {
        return Err(GenError::InvalidArgument(format!(
            "the image size must be 8..=16384 texels, got {}",
            opts.image_size
        )));
    }
    if let ImageFormat::Jpeg { quality } = opts.image_format {
        if !(1..=100).contains(&quality) {
            return Err(GenError::InvalidArgument(format!(
                "the JPEG quality must be 1..=100, got {quality}"
            )));
        }
    }
    if obj.file_name().is_none() {
        return Err(GenError::InvalidArgument(format!(
            "{}: the output needs a file name (e.g. terrain.obj)",
            obj.display()
        )));
    }
    let (cols, rows) = (u64::from(opts.columns), u64::from(opts.rows));
    let k = opts.columns * opts.rows;
    let longest = cols.max(rows);
    let cells = longest * n; // grid cells along the unit length
    let height = Height::new(opts.seed, cells);
    let (stem, image_names) = names(obj, k, opts.image_format);
    let (mtl_path, image_paths) = textured_paths(obj, opts);
    let mut report = TexturedReport {
        cells_per_tile: n,
        obj: obj.to_path_buf(),
        mtl: mtl_path.clone(),
        images: image_paths.clone(),
        ..Default::default()
    };

    // 1. The images, one at a time.
    progress.stage("images", u64::from(k));
    let photo = Photo::new(opts.seed);
    let size = opts.image_size as usize;
    let mut rgb = vec![0u8; size * size * 3];
    for tile in 0..k {
        let (c, r) = (u64::from(tile) % cols, u64::from(tile) / cols);
        photo.paint(&height, tile, c, r, longest, size, &mut rgb);
        let path = &image_paths[tile as usize];
        let mut f = AtomicFile::create(path, 1 << 20).map_err(atomic_error)?;
        let (w, h) = (opts.image_size, opts.image_size);
        let encoded = match opts.image_format {
            ImageFormat::Jpeg { quality } => image::codecs::jpeg::JpegEncoder::new_with_quality(
                &mut f, quality,
            )
            .write_image(&rgb, w, h, image::ExtendedColorType::Rgb8),
            ImageFormat::Png => image::codecs::png::PngEncoder::new_with_quality(
                &mut f,
                image::codecs::png::CompressionType::Fast,
                image::codecs::png::FilterType::Adaptive,
            )
            .write_image(&rgb, w, h, image::ExtendedColorType::Rgb8),
        };
        encoded.map_err(|e| match e {
            image::ImageError::IoError(cause) => GenError::Mesh(MeshError::Io {
                path: f.tmp_path().to_path_buf(),
                cause,
            }),
            other => GenError::Encode {
                path: path.clone(),
                message: other.to_string(),
            },
        })?;
        f.commit().map_err(atomic_error)?;
        report.image_bytes += file_len(path)?;
        report.texels += u64::from(w) * u64::from(h);
        progress.advance(1);
    }
    drop(rgb);
    report.decoded_bytes = 4 * report.texels;
    progress.finish_stage();

    // 2. The material library.
    {
        let mut f = AtomicFile::create(&mtl_path, 1 << 16).map_err(atomic_error)?;
        let mut text = format!(
            "# tessera-gen textured terrain: {k} tiles ({cols}x{rows}), {} px images, seed {}\n",
            opts.image_size, opts.seed
        );
        for (tile, name) in image_names.iter().enumerate() {
            text.push_str(&format!(
                "\nnewmtl {}\nKd 1 1 1\nmap_Kd -clamp on {name}\n",
                material(tile as u32, k)
            ));
        }
        f.write_all(text.as_bytes())
            .map_err(|cause| io_error(f.tmp_path(), cause))?;
        f.commit().map_err(atomic_error)?;
        report.mtl_bytes = file_len(&mtl_path)?;
    }

    // 3. The OBJ: positions (streamed, computed in parallel blocks), UVs, faces.
    let nx = cols * n + 1;
    let ny = rows * n + 1;
    let positions = nx * ny;
    let faces = 2 * n * n * u64::from(k);
    let uvs = u64::from(k) * (n + 1) * (n + 1);
    let mut f = AtomicFile::create(obj, 8 << 20).map_err(atomic_error)?;
    let tmp = f.tmp_path().to_path_buf();
    let wr = |e: std::io::Error| io_error(&tmp, e);
    writeln!(
        f,
        "# tessera-gen textured terrain: {k} tiles ({cols}x{rows}) of {n}x{n} cells, seed {}\n\
         # {positions} positions, {uvs} uvs, {faces} triangles\nmtllib {stem}.mtl",
        opts.seed
    )
    .map_err(wr)?;
    let mut ticker = Ticker::new(progress, positions, faces);
    stream_grid(
        positions,
        nx,
        1.0 / cells as f64,
        &mut ticker,
        |x, y| Vertex {
            position: [x as f32, y as f32, height.at(x, y) as f32],
            ..Vertex::default()
        },
        |v| {
            let [x, y, z] = v.position;
            writeln!(f, "v {x} {y} {z}").map_err(|e| MeshError::Io {
                path: tmp.clone(),
                cause: e,
            })
        },
    )?;
    let inv = 1.0 / n as f64;
    for _tile in 0..k {
        for b in 0..=n {
            let v = (b as f64 * inv) as f32;
            for a in 0..=n {
                let u = (a as f64 * inv) as f32;
                writeln!(f, "vt {u} {v}").map_err(wr)?;
            }
        }
    }
    for tile in 0..k {
        let (c, r) = (u64::from(tile) % cols, u64::from(tile) / cols);
        writeln!(f, "usemtl {}", material(tile, k)).map_err(wr)?;
        // 1-based OBJ indices.
        let t0 = u64::from(tile) * (n + 1) * (n + 1) + 1;
        for b in 0..n {
            for a in 0..n {
                let p00 = (r * n + b) * nx + c * n + a + 1;
                let (p10, p01, p11) = (p00 + 1, p00 + nx, p00 + nx + 1);
                let q00 = t0 + b * (n + 1) + a;
                let (q10, q01, q11) = (q00 + 1, q00 + n + 1, q00 + n + 2);
                writeln!(f, "f {p00}/{q00} {p10}/{q10} {p11}/{q11}").map_err(wr)?;
                writeln!(f, "f {p00}/{q00} {p11}/{q11} {p01}/{q01}").map_err(wr)?;
            }
            ticker.add_triangles(2 * n);
        }
    }
    f.commit().map_err(atomic_error)?;
    ticker.finish();
    report.obj_bytes = file_len(obj)?;
    report.mesh = GenReport {
        vertices: positions,
        triangles: faces,
    };
    report.uvs = uvs;
    Ok(report)
}

/// Material name of tile `tile` of `k`.
fn material(tile: u32, k: u32) -> String {
    let digits = (k.saturating_sub(1)).to_string().len().max(2);
    format!("tile-{tile:0digits$}")
}

fn io_error(path: &Path, cause: std::io::Error) -> GenError {
    GenError::Mesh(MeshError::Io {
        path: path.to_path_buf(),
        cause,
    })
}

fn atomic_error(e: AtomicFileError) -> GenError {
    io_error(&e.path, e.source)
}

fn file_len(path: &Path) -> Result<u64, GenError> {
    std::fs::metadata(path)
        .map(|m| m.len())
        .map_err(|e| io_error(path, e))
}

/// Height samples per tile side for the photos' land cover (bilinearly interpolated:
/// the relief's octaves finer than a tile / 64 do not change the colours).
const HEIGHT_SAMPLES: usize = 64;
/// Parcels (fields) per tile side.
const PARCELS: f64 = 10.0;
/// A road runs along every `ROAD_EVERY`-th parcel border, in both directions.
const ROAD_EVERY: f64 = 3.0;
/// Half widths, in tile units.
const ROAD_HALF: f64 = 0.0022;
const LANE_HALF: f64 = 0.00025;
const HEDGE: f64 = 0.018; // of a parcel

/// The procedural aerial photo.
struct Photo {
    warp_x: Fbm,
    warp_y: Fbm,
    grain: Fbm,
    parcels: u64,
}

/// Field colours (sRGB, 0..1): wheat, young crop, pasture, ploughed soil, rapeseed,
/// orchard.
const CROPS: [[f64; 3]; 6] = [
    [0.80, 0.70, 0.42],
    [0.42, 0.58, 0.25],
    [0.55, 0.66, 0.36],
    [0.45, 0.34, 0.24],
    [0.86, 0.80, 0.25],
    [0.30, 0.45, 0.22],
];
const FOREST: [f64; 3] = [0.16, 0.30, 0.14];
const HEDGE_COLOR: [f64; 3] = [0.12, 0.24, 0.10];
const ROAD: [f64; 3] = [0.36, 0.36, 0.37];
const LANE: [f64; 3] = [0.92, 0.92, 0.88];
const SAND: [f64; 3] = [0.78, 0.72, 0.55];
const SHALLOW: [f64; 3] = [0.22, 0.45, 0.58];
const DEEP: [f64; 3] = [0.05, 0.14, 0.32];
const ROCK: [f64; 3] = [0.48, 0.43, 0.38];
const SNOW: [f64; 3] = [0.94, 0.95, 0.97];

fn mixc(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    let t = t.clamp(0.0, 1.0);
    [
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
    ]
}

/// `|fract(x + 0.5) - 0.5|`: distance to the nearest integer.
#[inline]
fn to_integer(x: f64) -> f64 {
    let (_, f) = split(x + 0.5);
    (f - 0.5).abs()
}

impl Photo {
    fn new(seed: u64) -> Photo {
        Photo {
            warp_x: Fbm::new(seed, 21, 2, 1.5),
            warp_y: Fbm::new(seed, 22, 2, 1.5),
            grain: Fbm::new(seed, 23, 5, 24.0),
            parcels: derive_key(seed, 24),
        }
    }

    /// Paint tile `tile` (column `c`, row `r` of a terrain `longest` tiles along its
    /// longer side) into `rgb` (`size x size`, row 0 north).
    #[allow(clippy::too_many_arguments)]
    fn paint(
        &self,
        height: &Height,
        tile: u32,
        c: u64,
        r: u64,
        longest: u64,
        size: usize,
        rgb: &mut [u8],
    ) {
        let t = 1.0 / longest as f64;
        // Relief samples over the tile (terrain units), row-major from the south edge.
        let g = HEIGHT_SAMPLES;
        let mut hs = vec![0.0f64; (g + 1) * (g + 1)];
        hs.par_iter_mut().enumerate().for_each(|(i, h)| {
            let (a, b) = ((i % (g + 1)) as f64, (i / (g + 1)) as f64);
            *h = height.at((c as f64 + a / g as f64) * t, (r as f64 + b / g as f64) * t);
        });
        let label = Label::new(tile, size);
        let inv = 1.0 / size as f64;
        rgb.par_chunks_mut(size * 3)
            .enumerate()
            .for_each(|(py, row)| {
                // Tile-local coordinates in [0, 1], v up (north), at texel centres.
                let ly = 1.0 - (py as f64 + 0.5) * inv;
                for px in 0..size {
                    let lx = (px as f64 + 0.5) * inv;
                    let hx = lx * g as f64;
                    let hy = ly * g as f64;
                    // hx, hy in (0, g): the cell below, clamped, and the fraction in it.
                    let (ix, iy) = ((hx as usize).min(g - 1), (hy as usize).min(g - 1));
                    let (fx, fy) = (hx - ix as f64, hy - iy as f64);
                    let at = |a: usize, b: usize| hs[b * (g + 1) + a];
                    let h0 = at(ix, iy) + (at(ix + 1, iy) - at(ix, iy)) * fx;
                    let h1 = at(ix, iy + 1) + (at(ix + 1, iy + 1) - at(ix, iy + 1)) * fx;
                    let h = h0 + (h1 - h0) * fy;
                    let col = self.color(c as f64 + lx, r as f64 + ly, h);
                    let col = label.apply(px, py, col);
                    let q = |v: f64| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
                    row[px * 3] = q(col[0]);
                    row[px * 3 + 1] = q(col[1]);
                    row[px * 3 + 2] = q(col[2]);
                }
            });
    }

    /// The colour at `(x, y)` in tile units (the whole terrain's coordinates over the
    /// tile side) where the relief is `h`.
    #[inline]
    fn color(&self, x: f64, y: f64, h: f64) -> [f64; 3] {
        let grain = self.grain.sample2([x, y]);
        let shade = 1.0 + 0.16 * grain;
        if h < 0.0 {
            let depth = (-h / 0.05).min(1.0);
            let c = mixc(SHALLOW, DEEP, depth);
            let s = 1.0 + 0.05 * grain;
            return [c[0] * s, c[1] * s, c[2] * s];
        }
        if h < 0.004 {
            return [SAND[0] * shade, SAND[1] * shade, SAND[2] * shade];
        }
        // Warped field grid: borders wander a little, roads curve.
        let wx = x + 0.06 * self.warp_x.sample2([x, y]);
        let wy = y + 0.06 * self.warp_y.sample2([x, y]);
        let mut col;
        if h > 0.11 {
            col = mixc(ROCK, SNOW, (h - 0.12) / 0.015);
        } else {
            let (pi, fx) = split(wx * PARCELS);
            let (pj, fy) = split(wy * PARCELS);
            let hash = mix64(
                self.parcels
                    ^ (pi as u64).wrapping_mul(0x8cb9_2ba7_2f3d_8dd7)
                    ^ (pj as u64).wrapping_mul(0xd6e8_feb8_6659_fd93),
            );
            let forest = h > 0.07 || hash.is_multiple_of(7);
            if forest {
                col = FOREST;
                let s = 1.0 + 0.25 * grain;
                col = [col[0] * s, col[1] * s, col[2] * s];
            } else {
                col = CROPS[((hash >> 8) % CROPS.len() as u64) as usize];
                // Crop rows along one of four directions.
                let along = match (hash >> 16) % 4 {
                    0 => fx,
                    1 => fy,
                    2 => (fx + fy) * 0.5,
                    _ => (fx - fy + 1.0) * 0.5,
                };
                let stripe = to_integer(along * 28.0) * 2.0; // 0..1
                let s = shade * (0.93 + 0.10 * stripe);
                col = [col[0] * s, col[1] * s, col[2] * s];
                if fx < HEDGE || fy < HEDGE {
                    col = HEDGE_COLOR;
                }
            }
            // Rocky where the relief is high.
            col = mixc(col, ROCK, (h - 0.09) / 0.02);
        }
        // Roads along every third parcel border.
        let dx = to_integer(wx * PARCELS / ROAD_EVERY) * ROAD_EVERY / PARCELS;
        let dy = to_integer(wy * PARCELS / ROAD_EVERY) * ROAD_EVERY / PARCELS;
        if dx < ROAD_HALF || dy < ROAD_HALF {
            col = ROAD;
            let (d, along) = if dx < dy { (dx, wy) } else { (dy, wx) };
            if d < LANE_HALF && to_integer(along * 60.0) < 0.25 {
                col = LANE;
            }
            let s = 1.0 + 0.04 * grain;
            col = [col[0] * s, col[1] * s, col[2] * s];
        }
        col
    }
}

/// 5 x 7 bitmaps of the digits, top row first, bit 4 = leftmost column.
const DIGITS: [[u8; 7]; 10] = [
    [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
    [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
    [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
    [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
    [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
    [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
    [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
    [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
    [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
    [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
];

/// A tile number drawn twice: large in the centre, small in the top-left corner, white
/// glyphs on a darkened plate.
struct Label {
    digits: Vec<u8>,
    /// (left, top, cell size) of each copy, texels.
    copies: [(usize, usize, usize); 2],
}

impl Label {
    fn new(tile: u32, size: usize) -> Label {
        let digits: Vec<u8> = tile.to_string().bytes().map(|b| b - b'0').collect();
        let cols = 6 * digits.len() - 1; // 5 per glyph + 1 between
        let big = (size / 48).max(1);
        let small = (size / 160).max(1);
        let centre = (
            (size.saturating_sub(cols * big)) / 2,
            (size.saturating_sub(7 * big)) / 2,
            big,
        );
        let corner = (2 * small, 2 * small, small);
        Label {
            digits,
            copies: [centre, corner],
        }
    }

    #[inline]
    fn apply(&self, px: usize, py: usize, col: [f64; 3]) -> [f64; 3] {
        let cols = 6 * self.digits.len() - 1;
        for &(left, top, cell) in &self.copies {
            // The plate: one cell of margin around the glyphs.
            let (x0, y0) = (left.saturating_sub(cell), top.saturating_sub(cell));
            let (x1, y1) = (left + (cols + 1) * cell, top + 8 * cell);
            if px < x0 || px >= x1 || py < y0 || py >= y1 {
                continue;
            }
            if px >= left && py >= top {
                let (gx, gy) = ((px - left) / cell, (py - top) / cell);
                if gy < 7 && gx < cols && gx % 6 < 5 {
                    let bits = DIGITS[self.digits[gx / 6] as usize][gy];
                    if bits >> (4 - gx % 6) & 1 == 1 {
                        return [1.0, 1.0, 1.0];
                    }
                }
            }
            return [col[0] * 0.35, col[1] * 0.35, col[2] * 0.35];
        }
        col
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_grids_are_the_most_square_factorisation() {
        assert_eq!(tile_grid(1), (1, 1));
        assert_eq!(tile_grid(4), (2, 2));
        assert_eq!(tile_grid(32), (8, 4));
        assert_eq!(tile_grid(12), (4, 3));
        assert_eq!(tile_grid(7), (7, 1));
        assert_eq!(tile_grid(0), (1, 1));
    }

    #[test]
    fn resolution_rounds_and_refuses_overflow() {
        assert_eq!(textured_resolution(2_000_000, 8, 4).unwrap(), 177);
        assert_eq!(textured_resolution(1, 2, 2).unwrap(), 1);
        assert!(textured_resolution(1 << 40, 1, 1).is_err());
        assert!(textured_resolution(100, 0, 1).is_err());
    }

    #[test]
    fn labels_draw_white_digits_on_a_plate() {
        let l = Label::new(7, 480);
        let grey = [0.5; 3];
        // Outside both copies: unchanged.
        assert_eq!(l.apply(470, 470, grey), grey);
        // '7': the top row is full.
        let (left, top, cell) = l.copies[0];
        assert_eq!(l.apply(left + cell / 2, top + cell / 2, grey), [1.0; 3]);
        // Bottom-left of a '7' is empty: the plate darkens.
        assert_eq!(l.apply(left, top + 6 * cell, grey), [0.5 * 0.35; 3]);
    }
}
