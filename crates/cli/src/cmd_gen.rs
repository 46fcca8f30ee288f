//! `tessera gen`: deterministic, streamed test meshes.

use crate::progress::Bars;
use anyhow::Context;
use clap::Subcommand;
use std::path::PathBuf;
use std::process::ExitCode;
use tessera_gen::{SphereOptions, TerrainOptions, TileOptions};

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

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let (quiet, output) = match &a.what {
        What::Sphere { quiet, output, .. }
        | What::Terrain { quiet, output, .. }
        | What::Tile { quiet, output, .. } => (*quiet, output.clone()),
    };
    let bars = Bars::new(quiet);
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
}
