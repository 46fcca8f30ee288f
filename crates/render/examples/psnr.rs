//! PSNR of every frame in one directory against the same-named frame in another:
//! `cargo run --release -p tessera-render --example psnr -- LOD_DIR REFERENCE_DIR`.
//! Prints one line per frame and the mean and minimum (identical frames count as 99 dB
//! in the mean, so one perfect frame does not make the mean infinite).

use std::path::PathBuf;
use std::process::ExitCode;

use tessera_render::{psnr, Image};

fn main() -> ExitCode {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    if args.len() != 2 {
        eprintln!("usage: psnr LOD_DIR REFERENCE_DIR");
        return ExitCode::from(2);
    }
    let mut names: Vec<_> = match std::fs::read_dir(&args[0]) {
        Ok(rd) => rd
            .filter_map(|e| e.ok())
            .map(|e| e.file_name())
            .filter(|n| n.to_string_lossy().ends_with(".png"))
            .collect(),
        Err(e) => {
            eprintln!("error: {}: {e}", args[0].display());
            return ExitCode::FAILURE;
        }
    };
    names.sort();
    let mut values = Vec::new();
    for n in &names {
        let a = Image::load_png(&args[0].join(n));
        let b = Image::load_png(&args[1].join(n));
        match (a, b) {
            (Ok(a), Ok(b)) => match psnr(&a, &b) {
                Some(p) => {
                    let p = p.min(99.0);
                    println!("{}: {p:.2} dB", n.to_string_lossy());
                    values.push(p);
                }
                None => {
                    eprintln!("error: {}: sizes differ", n.to_string_lossy());
                    return ExitCode::FAILURE;
                }
            },
            (Err(e), _) | (_, Err(e)) => {
                eprintln!("error: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    if values.is_empty() {
        eprintln!("error: no PNG frames in {}", args[0].display());
        return ExitCode::FAILURE;
    }
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let min = values.iter().copied().fold(f64::INFINITY, f64::min);
    println!(
        "frames {} mean_psnr_db {mean:.2} min_psnr_db {min:.2}",
        values.len()
    );
    ExitCode::SUCCESS
}
