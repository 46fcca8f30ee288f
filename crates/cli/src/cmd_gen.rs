//! `tessera gen`: deterministic, streamed test meshes.

use crate::progress::Bars;
use anyhow::Context;
use clap::Subcommand;
use std::path::PathBuf;
use std::process::ExitCode;
use tessera_gen::{
    ImageFormat, SphereOptions, TerrainOptions, TexturedOptions, TexturedReport, TileOptions,
};

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(Subcommand)]
enum What {
    /// A closed, watertight, noisy sphere (12 n^2 triangles, n = round(sqrt(N/12))).
    Sphere {
        /// About how many triangles (e.g. 1M, 30M, 1e9).
        #[arg(long, value_parser = parse_count)]
        triangles: u64,
        /// Output mesh (binary PLY), written atomically.
        #[arg(short, long)]
        output: PathBuf,
        /// Seed of the noise: the same seed writes the same file, byte for byte.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Also write per-vertex colours.
        #[arg(long)]
        colors: bool,
        /// Relative radial noise amplitude.
        #[arg(long, default_value_t = 0.05)]
        noise: f32,
        /// No progress bar.
        #[arg(short, long)]
        quiet: bool,
    },
    /// A heightfield terrain (open mesh with a boundary).
    Terrain {
        /// About how many triangles (e.g. 1M, 30M, 1e9).
        #[arg(long, value_parser = parse_count)]
        triangles: u64,
        /// Output mesh (binary PLY), written atomically.
        #[arg(short, long)]
        output: PathBuf,
        /// Seed of the relief: the same seed writes the same file, byte for byte.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Also write per-vertex colours (by height).
        #[arg(long)]
        colors: bool,
        /// No progress bar.
        #[arg(short, long)]
        quiet: bool,
    },
    /// A terrain over K tiles, one procedural aerial photo per tile (OBJ + MTL + images).
    ///
    /// Writes OUTPUT (OBJ), its MTL beside it and the images NAME-tile-KK.jpg (or .png),
    /// all atomically, images first and the OBJ last (an OBJ at the path means the rest
    /// is there). Each tile's faces use their own material and image; UVs map a tile onto
    /// its whole image, v = 0 at the bottom row (south). The photos follow the relief and
    /// show the tile number. Deterministic: the same options write the same bytes.
    Textured {
        /// About how many triangles (e.g. 2M): each tile gets n x n cells of two
        /// triangles, n = round(sqrt(N / 2K)).
        #[arg(long, value_parser = parse_count)]
        triangles: u64,
        /// The tiles: a count K (laid out on the most square grid, e.g. 32 -> 8x4) or
        /// COLSxROWS.
        #[arg(long, default_value = "16", value_parser = parse_tiles)]
        tiles: (u32, u32),
        /// Side of each tile's image, texels.
        #[arg(long, default_value_t = 4096, value_parser = clap::value_parser!(u32).range(8..=16384))]
        image_size: u32,
        /// Image format of the tiles.
        #[arg(long, default_value = "jpeg", value_parser = ["jpeg", "png"])]
        image_format: String,
        /// JPEG quality of the tiles (1..=100).
        #[arg(long, default_value_t = 90, value_parser = clap::value_parser!(u8).range(1..=100))]
        quality: u8,
        /// Output OBJ (e.g. out/terrain.obj); the MTL and images go beside it.
        #[arg(short, long)]
        output: PathBuf,
        /// Seed of the relief and of the photos.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// No progress bar.
        #[arg(short, long)]
        quiet: bool,
    },
    /// A scene file of K placed copies of built models (`.tsr`), for `view` and
    /// `render` (docs/scene.md): a square grid on the ground, each copy upright, about
    /// one unit across, turned about the up axis; deterministic.
    Scene {
        /// A built model to place (.tsr path or http:// URL), optionally with its up axis
        /// (`bunny.tsr@+y`; default: the axis its roots are tallest along); repeat to
        /// take several in turn.
        #[arg(long = "model", required = true, value_name = "MODEL.tsr[@AXIS]", value_parser = parse_model_up)]
        models: Vec<(PathBuf, Option<tessera_nav::UpAxis>)>,
        /// How many copies.
        #[arg(long)]
        copies: usize,
        /// Output scene file (JSON), written atomically; model paths in it are relative
        /// to its folder when they can be.
        #[arg(short, long)]
        output: PathBuf,
        /// The scene's up axis.
        #[arg(long, default_value = "+z")]
        up: tessera_nav::UpAxis,
        /// Grid cell size, in copy diameters.
        #[arg(long, default_value_t = 1.5)]
        spacing: f64,
        /// Copy sizes vary by this fraction either way.
        #[arg(long, default_value_t = 0.3)]
        size_variation: f64,
        /// Seed of the layout: the same seed writes the same file.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Unused (no progress to show).
        #[arg(short, long, hide = true)]
        quiet: bool,
    },
    /// K copies of a real scan laid out in a grid, as one mesh.
    Tile {
        /// The scan to copy (PLY, OBJ or STL).
        input: PathBuf,
        /// How many copies (laid out on a square grid, side by side).
        #[arg(long)]
        copies: u32,
        /// Output mesh (binary PLY), written atomically.
        #[arg(short, long)]
        output: PathBuf,
        /// No progress bar.
        #[arg(short, long)]
        quiet: bool,
    },
}

/// Accepts `1000000`, `1e6`, `10M`, `1G` (decimal multipliers for counts).
fn parse_count(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let (num, mult) = match t.chars().last() {
        Some('k' | 'K') => (&t[..t.len() - 1], 1e3),
        Some('m' | 'M') => (&t[..t.len() - 1], 1e6),
        Some('g' | 'G' | 'b' | 'B') => (&t[..t.len() - 1], 1e9),
        _ => (t, 1.0),
    };
    let n: f64 = num.parse().map_err(|_| format!("not a count: {s:?}"))?;
    if !(n.is_finite() && n >= 1.0) {
        return Err(format!("count must be >= 1: {s:?}"));
    }
    Ok((n * mult).round() as u64)
}

/// `PATH` or `PATH@AXIS` (an up axis: +x ... -z).
fn parse_model_up(s: &str) -> Result<(PathBuf, Option<tessera_nav::UpAxis>), String> {
    match s.rsplit_once('@') {
        Some((path, axis)) if !path.is_empty() && axis.len() == 2 => {
            let up = axis
                .parse::<tessera_nav::UpAxis>()
                .map_err(|e| e.to_string())?;
            Ok((PathBuf::from(path), Some(up)))
        }
        _ => Ok((PathBuf::from(s), None)),
    }
}

/// Accepts `K` (the most square grid of K tiles) or `COLSxROWS` (e.g. `8x4`).
fn parse_tiles(s: &str) -> Result<(u32, u32), String> {
    let t = s.trim().to_ascii_lowercase();
    let bad = || format!("not a tile count or COLSxROWS: {s:?}");
    let (cols, rows) = match t.split_once('x') {
        Some((c, r)) => (
            c.trim().parse::<u32>().map_err(|_| bad())?,
            r.trim().parse::<u32>().map_err(|_| bad())?,
        ),
        None => match t.parse::<u32>().map_err(|_| bad())? {
            0 => (0, 0),
            k => tessera_gen::tile_grid(k),
        },
    };
    if cols == 0 || rows == 0 {
        return Err(format!("need at least one tile: {s:?}"));
    }
    if u64::from(cols) * u64::from(rows) > 1 << 16 {
        return Err(format!("at most 65536 tiles: {s:?}"));
    }
    Ok((cols, rows))
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let (quiet, output) = match &a.what {
        What::Sphere { quiet, output, .. }
        | What::Terrain { quiet, output, .. }
        | What::Textured { quiet, output, .. }
        | What::Scene { quiet, output, .. }
        | What::Tile { quiet, output, .. } => (*quiet, output.clone()),
    };
    if let What::Scene {
        models,
        copies,
        up,
        spacing,
        size_variation,
        seed,
        ..
    } = a.what
    {
        return write_scene(&output, &models, copies, up, spacing, size_variation, seed);
    }
    let bars = Bars::new(quiet);
    if let What::Textured {
        triangles,
        tiles: (columns, rows),
        image_size,
        image_format,
        quality,
        seed,
        ..
    } = a.what
    {
        let image_format = if image_format == "png" {
            ImageFormat::Png
        } else {
            ImageFormat::Jpeg { quality }
        };
        let r = tessera_gen::write_textured_terrain(
            &output,
            &TexturedOptions {
                triangles,
                columns,
                rows,
                image_size,
                image_format,
                seed,
            },
            &bars,
        )
        .with_context(|| format!("generating {}", output.display()))?;
        print_textured(&r, image_size, image_format);
        return Ok(ExitCode::SUCCESS);
    }
    let report = match a.what {
        What::Sphere {
            triangles,
            seed,
            colors,
            noise,
            ..
        } => tessera_gen::write_sphere(
            &output,
            &SphereOptions {
                triangles,
                seed,
                colors,
                noise,
            },
            &bars,
        ),
        What::Terrain {
            triangles,
            seed,
            colors,
            ..
        } => tessera_gen::write_terrain(
            &output,
            &TerrainOptions {
                triangles,
                seed,
                colors,
            },
            &bars,
        ),
        What::Tile { input, copies, .. } => {
            tessera_gen::write_tiled(&input, &output, &TileOptions { copies }, &bars)
        }
        What::Textured { .. } | What::Scene { .. } => unreachable!("handled above"),
    }
    .with_context(|| format!("generating {}", output.display()))?;
    println!(
        "wrote {}: {} triangles, {} vertices",
        output.display(),
        report.triangles,
        report.vertices
    );
    Ok(ExitCode::SUCCESS)
}

/// `tessera gen scene`: each model opened for its bounding sphere and up axis, the
/// layout made (`tessera_scene::copies`), the file written atomically.
fn write_scene(
    output: &std::path::Path,
    models: &[(PathBuf, Option<tessera_nav::UpAxis>)],
    count: usize,
    up: tessera_nav::UpAxis,
    spacing: f64,
    size_variation: f64,
    seed: u64,
) -> anyhow::Result<ExitCode> {
    use std::io::Write;
    let out_dir = output
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    let out_dir = std::fs::canonicalize(out_dir).with_context(|| {
        format!(
            "cannot write {}: no folder {}",
            output.display(),
            out_dir.display()
        )
    })?;
    let mut placed = Vec::new();
    for (m, up) in models {
        let reader =
            crate::open::open_model(m).with_context(|| format!("cannot open {}", m.display()))?;
        let b = reader.index().header().bounding_sphere;
        let model_up =
            up.unwrap_or_else(|| tessera_nav::scene_points(reader.as_ref(), 20_000).guess_up());
        let s = m.to_string_lossy();
        let reference = if tessera_http::is_url(&s) {
            s.into_owned()
        } else {
            let abs = std::fs::canonicalize(m)?;
            abs.strip_prefix(&out_dir)
                .unwrap_or(&abs)
                .to_string_lossy()
                .into_owned()
        };
        placed.push((reference, b, model_up));
    }
    let scene = tessera_scene::copies(&tessera_scene::CopiesOptions {
        models: placed,
        count,
        up,
        spacing,
        size_variation,
        seed,
    })
    .map_err(|e| anyhow::anyhow!("cannot lay out the scene: {e}"))?;
    let text = scene.to_json_string();
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("cannot write {}: {e}", output.display());
    let mut f =
        tessera_format::AtomicFile::create(output, text.len()).map_err(|e| err(&e.source))?;
    f.write_all(text.as_bytes()).map_err(|e| err(&e))?;
    f.commit().map_err(|e| err(&e.source))?;
    println!(
        "wrote {}: {} copies of {} model(s), up {up}",
        output.display(),
        count,
        models.len()
    );
    Ok(ExitCode::SUCCESS)
}

fn print_textured(r: &TexturedReport, size: u32, format: ImageFormat) {
    let name = |p: &std::path::Path| {
        p.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
    println!(
        "wrote {}: {} triangles, {} positions, {} uvs ({} tiles of {}x{} cells), {:.1} MiB",
        r.obj.display(),
        r.mesh.triangles,
        r.mesh.vertices,
        r.uvs,
        r.images.len(),
        r.cells_per_tile,
        r.cells_per_tile,
        mib(r.obj_bytes)
    );
    println!("wrote {}: {} materials", r.mtl.display(), r.images.len());
    let range = match (r.images.first(), r.images.last()) {
        (Some(a), Some(b)) if r.images.len() > 1 => format!("{} .. {}", name(a), name(b)),
        (Some(a), _) => name(a),
        _ => String::new(),
    };
    let codec = match format {
        ImageFormat::Jpeg { quality } => format!("JPEG q{quality}"),
        ImageFormat::Png => "PNG".into(),
    };
    println!(
        "wrote {} images {range}: {size}x{size} {codec}, {:.1} MiB on disk",
        r.images.len(),
        mib(r.image_bytes)
    );
    println!(
        "source texels: {} ({:.1} Mtexels), {} bytes decoded as RGBA8 ({:.2} GiB, {:.2} GB)",
        r.texels,
        r.texels as f64 / 1e6,
        r.decoded_bytes,
        r.decoded_bytes as f64 / (1u64 << 30) as f64,
        r.decoded_bytes as f64 / 1e9
    );
}

#[cfg(test)]
mod tests {
    #[test]
    fn counts_parse() {
        assert_eq!(super::parse_count("10M"), Ok(10_000_000));
        assert_eq!(super::parse_count("1e6"), Ok(1_000_000));
        assert_eq!(super::parse_count("2500"), Ok(2500));
        assert!(super::parse_count("0").is_err());
        assert!(super::parse_count("abc").is_err());
    }

    #[test]
    fn tiles_parse() {
        assert_eq!(super::parse_tiles("32"), Ok((8, 4)));
        assert_eq!(super::parse_tiles("3x5"), Ok((3, 5)));
        assert_eq!(super::parse_tiles("1"), Ok((1, 1)));
        assert!(super::parse_tiles("0").is_err());
        assert!(super::parse_tiles("0x4").is_err());
        assert!(super::parse_tiles("4x").is_err());
        assert!(super::parse_tiles("300x300").is_err());
    }
}
