//! `tessera export-tiles`: a model as an OGC 3D Tiles 1.1 tileset
//! (`tessera_tiles::export_tiles`; the mapping is in docs/tiles.md).

use anyhow::bail;
use serde_json::json;
use std::path::PathBuf;
use std::process::ExitCode;

use crate::progress::Bars;
use tessera_tiles::{export_tiles, frame, TilesOptions};

#[derive(clap::Args)]
#[command(after_help = "\
Writes DIR/tileset.json (3D Tiles 1.1, refine REPLACE) and DIR/tiles/*.glb, one binary
glTF per node of the hierarchy (the roots in one), for CesiumJS, 3DTilesRendererJS and
other 3D Tiles clients; any cut they draw is crack-free (docs/tiles.md). Model axes are
the tileset's (+Z up); --origin or --ecef puts the model's origin on the Earth with x
east, y north, z up. Serve the directory with `tessera serve --tiles DIR`.")]
pub struct Args {
    /// The model (.tsr).
    model: PathBuf,
    /// The output directory (created; it must not exist, be empty, or hold a tileset
    /// and --force be given).
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
    /// Replace an output directory that holds a tileset.
    #[arg(long)]
    force: bool,
    /// Place the model's origin at this WGS84 longitude, latitude (degrees) and
    /// ellipsoidal height (metres), east-north-up.
    #[arg(
        long,
        value_name = "LON,LAT,HEIGHT",
        allow_hyphen_values = true,
        conflicts_with = "ecef"
    )]
    origin: Option<String>,
    /// Place the model's origin at this Earth-centred point (metres), east-north-up.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    ecef: Option<String>,
    /// Worker threads (default: one per core).
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    json: bool,
}

/// Three comma-separated finite numbers.
fn three(flag: &str, s: &str) -> anyhow::Result<[f64; 3]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            anyhow::anyhow!("{flag} wants three numbers separated by commas, got {s:?}")
        })?;
    match v[..] {
        [a, b, c] if v.iter().all(|x| x.is_finite()) => Ok([a, b, c]),
        _ => bail!("{flag} wants three finite numbers separated by commas, got {s:?}"),
    }
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let placement = match (&a.origin, &a.ecef) {
        (Some(s), _) => {
            let [lon, lat, h] = three("--origin", s)?;
            Some(
                frame::enu_at_geodetic(lon, lat, h)
                    .map_err(|e| anyhow::anyhow!("--origin: {e}"))?,
            )
        }
        (None, Some(s)) => Some(
            frame::enu_at_ecef(three("--ecef", s)?).map_err(|e| anyhow::anyhow!("--ecef: {e}"))?,
        ),
        (None, None) => None,
    };
    if a.threads == Some(0) {
        bail!("--threads must be at least 1");
    }
    let opts = TilesOptions {
        placement,
        threads: a.threads,
        force: a.force,
    };
    let bars = Bars::new(a.quiet || a.json);
    crate::progress::install_interrupt_handler();
    let s = export_tiles(&a.model, &a.output, &opts, &bars)?;
    let per_triangle = s.bytes as f64 / s.input_triangles.max(1) as f64;
    if a.json {
        println!(
            "{}",
            json!({
                "output": a.output.display().to_string(),
                "tiles": s.tiles,
                "files": s.files,
                "bytes": s.bytes,
                "tileset_bytes": s.tileset_bytes,
                "textures": s.textures,
                "levels": s.levels,
                "triangles": s.triangles,
                "input_triangles": s.input_triangles,
                "bytes_per_input_triangle": per_triangle,
                "model_bytes": s.model_bytes,
                "seconds": s.seconds,
            })
        );
    } else {
        println!("wrote {}", a.output.join("tileset.json").display());
        println!(
            "  tiles        {} ({} levels), {} triangles in all",
            s.tiles, s.levels, s.triangles
        );
        println!(
            "  files        {} ({} .glb + tileset.json of {} bytes), {} textures",
            s.files,
            s.files - 1,
            s.tileset_bytes,
            s.textures
        );
        println!(
            "  bytes        {} ({per_triangle:.2} per input triangle; the model: {}, {:.2})",
            s.bytes,
            s.model_bytes,
            s.model_bytes as f64 / s.input_triangles.max(1) as f64
        );
        println!("  time         {:.2} s", s.seconds);
    }
    Ok(ExitCode::SUCCESS)
}
