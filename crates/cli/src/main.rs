//! `tessera`: build, inspect, verify and cut multiresolution models; generate test meshes.
//!
//! A thin layer over the library crates: parse arguments, call one library function,
//! print the result. Errors are printed once, on one line, with a non-zero exit.

mod cmd_build;
mod cmd_demo;
mod cmd_export_tiles;
mod cmd_extract;
mod cmd_gen;
mod cmd_info;
mod cmd_render;
mod cmd_serve;
mod cmd_verify;
mod cmd_view;
mod open;
mod progress;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "tessera",
    version,
    about = "Multiresolution rendering of huge triangle meshes"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Build a multiresolution model (.tsr) from a PLY, OBJ or STL mesh.
    Build(cmd_build::Args),
    /// Print a model's header, counts, errors and sizes.
    Info(cmd_info::Args),
    /// Check everything checkable in a model; exit 0 only if it is valid.
    Verify(cmd_verify::Args),
    /// Select a cut of the hierarchy and write it as one mesh (PLY, glTF or GLB).
    Extract(cmd_extract::Args),
    /// Export a model as an OGC 3D Tiles 1.1 tileset (tileset.json + one .glb per tile).
    ExportTiles(cmd_export_tiles::Args),
    /// Generate deterministic test meshes (binary PLY; OBJ + MTL + images for `textured`).
    Gen(cmd_gen::Args),
    /// Render a camera path or an orbit to PNG frames with per-frame statistics.
    Render(cmd_render::Args),
    /// Serve models over HTTP: range requests, ETags, CORS, a JSON catalogue.
    Serve(cmd_serve::Args),
    /// Build the bundled Nefertiti scan (once, into a cache) and open it in the viewer
    /// (without a display: render an orbit to PNG files).
    Demo(cmd_demo::Args),
    /// Open a model in a window: navigate, pick and measure at full resolution.
    View(cmd_view::Args),
}

fn main() -> ExitCode {
    // Die quietly on a closed pipe (`tessera info m.tsr | head`) like other Unix tools,
    // instead of panicking in println!.
    #[cfg(unix)]
    // SAFETY: resetting a signal disposition at startup, before any thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    quiet_mesa_runtime_dir();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("TESSERA_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .with_target(false)
        // Colour codes only on a terminal: not in logs, pipes and CI output.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Build(a) => cmd_build::run(a),
        Command::Info(a) => cmd_info::run(a),
        Command::Verify(a) => cmd_verify::run(a),
        Command::Extract(a) => cmd_extract::run(a),
        Command::ExportTiles(a) => cmd_export_tiles::run(a),
        Command::Gen(a) => cmd_gen::run(a),
        Command::Render(a) => cmd_render::run(a),
        Command::Serve(a) => cmd_serve::run(a),
        Command::View(a) => cmd_view::run(a),
        Command::Demo(a) => cmd_demo::run(a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Mesa's drivers print "error: XDG_RUNTIME_DIR is invalid or not set" (harmless, but it
/// reads like a failure of ours) when the variable is missing, as on headless machines
/// and in CI. Give them a private directory instead, before any thread or driver starts.
fn quiet_mesa_runtime_dir() {
    #[cfg(unix)]
    {
        use std::os::unix::fs::{DirBuilderExt, MetadataExt};
        if std::env::var_os("XDG_RUNTIME_DIR").is_some() {
            return;
        }
        // SAFETY: getuid has no preconditions.
        let uid = unsafe { libc::getuid() };
        let dir = std::env::temp_dir().join(format!("tessera-runtime-{uid}"));
        let _ = std::fs::DirBuilder::new().mode(0o700).create(&dir);
        // Use it only if it is ours and private (what Mesa checks, too).
        if let Ok(m) = std::fs::metadata(&dir) {
            if m.is_dir() && m.uid() == uid && m.mode() & 0o077 == 0 {
                std::env::set_var("XDG_RUNTIME_DIR", &dir);
            }
        }
    }
}

/// Parse a byte size like `1G`, `512M`, `64k`, `1000000`.
pub fn parse_bytes(s: &str) -> Result<u64, String> {
    let s = s.trim();
    let (num, mult) = match s.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let m = match c.to_ascii_uppercase() {
                'K' => 1u64 << 10,
                'M' => 1 << 20,
                'G' => 1 << 30,
                'T' => 1 << 40,
                _ => return Err(format!("unknown size suffix in {s:?} (use K, M, G or T)")),
            };
            (&s[..i], m)
        }
        _ => (s, 1),
    };
    let n: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("not a size: {s:?}"))?;
    if !(n.is_finite() && n > 0.0) {
        return Err(format!("size must be positive: {s:?}"));
    }
    Ok((n * mult as f64) as u64)
}

#[cfg(test)]
mod tests {
    #[test]
    fn sizes_parse() {
        assert_eq!(super::parse_bytes("1G"), Ok(1 << 30));
        assert_eq!(super::parse_bytes("512m"), Ok(512 << 20));
        assert_eq!(super::parse_bytes("1000"), Ok(1000));
        assert!(super::parse_bytes("1X").is_err());
        assert!(super::parse_bytes("-1G").is_err());
    }
}
