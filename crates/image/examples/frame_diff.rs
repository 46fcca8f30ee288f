//! Pixel-change shares and PSNR between rendered frame directories (`frame_NNNNN.png`, as
//! `tessera render --out` writes them), for benchmarks such as `scripts/bench-morph`:
//!
//! ```text
//! frame_diff [--threshold T] [--per-frame] [--worst-diff OUT.png] DIR           (frame i vs i-1)
//! frame_diff [--threshold T] [--per-frame] [--worst-diff OUT.png] DIR_A DIR_B   (same-named frames)
//! frame_diff --psnr [--per-frame] DIR REFERENCE_DIR
//! ```
//!
//! `cargo build --release -p tessera-image --example frame_diff`. A frame's share is the
//! fraction of all its pixels whose largest RGB channel difference exceeds T (default 8).
//! With one directory each frame is compared with the one before it (the first frame has
//! no pair); with two, each frame of DIR_A with the same-named frame of DIR_B. Prints one
//! JSON line per frame with `--per-frame` (`{"frame":..,"index":..,"share":..,
//! "max_diff":..}` or `{"frame":..,"index":..,"psnr_db":..}`), then a summary line
//! (`{"summary":true,"frames":N,"mean":..,"p99":..,"max":..,"worst":..}`; p99 is the
//! nearest-rank 99th percentile; PSNR of identical frames counts as 99 dB).
//! `--worst-diff` writes the worst pair's differing pixels in red over the first frame
//! dimmed to grey.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Mutex;

use tessera_image::{diff_stats, psnr, Image};

struct Args {
    threshold: u8,
    per_frame: bool,
    psnr: bool,
    worst_diff: Option<PathBuf>,
    dirs: Vec<PathBuf>,
}

fn parse() -> Result<Args, String> {
    let mut a = Args {
        threshold: 8,
        per_frame: false,
        psnr: false,
        worst_diff: None,
        dirs: Vec::new(),
    };
    let mut it = std::env::args_os().skip(1);
    while let Some(arg) = it.next() {
        match arg.to_str() {
            Some("--threshold") => {
                let v = it.next().ok_or("--threshold needs a value")?;
                a.threshold = v
                    .to_str()
                    .and_then(|s| s.parse().ok())
                    .ok_or("--threshold takes a whole number from 0 to 255")?;
            }
            Some("--per-frame") => a.per_frame = true,
            Some("--psnr") => a.psnr = true,
            Some("--worst-diff") => {
                a.worst_diff = Some(it.next().ok_or("--worst-diff needs a path")?.into())
            }
            Some(s) if s.starts_with("--") => return Err(format!("unknown option {s}")),
            _ => a.dirs.push(arg.into()),
        }
    }
    match (a.psnr, a.dirs.len()) {
        (true, 2) | (false, 1) | (false, 2) => Ok(a),
        _ => Err("usage: frame_diff [--threshold T] [--per-frame] [--worst-diff OUT.png] DIR [DIR_B]\n       frame_diff --psnr [--per-frame] DIR REFERENCE_DIR".into()),
    }
}

fn png_names(dir: &Path) -> Result<Vec<String>, String> {
    let rd = std::fs::read_dir(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut names: Vec<String> = rd
        .filter_map(|e| e.ok())
        .filter_map(|e| e.file_name().into_string().ok())
        .filter(|n| n.ends_with(".png"))
        .collect();
    names.sort();
    if names.is_empty() {
        return Err(format!("no PNG frames in {}", dir.display()));
    }
    Ok(names)
}

fn load(dir: &Path, name: &str) -> Result<Image, String> {
    Image::load_png(&dir.join(name)).map_err(|e| e.to_string())
}

/// One compared pair: the index of the (second) frame, its value (share or PSNR) and the
/// largest channel difference.
type Row = (usize, f64, u8);

/// A pair to compare: the index of the (second) frame, the first frame's directory and
/// name, the second frame's directory and name.
type Pair<'a> = (usize, &'a Path, &'a str, &'a Path, &'a str);

/// What a pair yields: its value and the largest channel difference.
type Metric<'a> = dyn Fn(&Image, &Image) -> Result<(f64, u8), String> + Sync + 'a;

/// Compares the pairs on all cores, in contiguous chunks so that consecutive pairs reuse
/// the image loaded last.
fn compare(pairs: &[Pair], value: &Metric<'_>) -> Result<Vec<Row>, String> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let chunk = pairs.len().div_ceil(threads).max(1);
    let out = Mutex::new(Vec::with_capacity(pairs.len()));
    let failed: Mutex<Option<String>> = Mutex::new(None);
    std::thread::scope(|s| {
        for part in pairs.chunks(chunk) {
            let (out, failed) = (&out, &failed);
            s.spawn(move || {
                let mut cache: Option<(PathBuf, Image)> = None;
                for &(i, ad, an, bd, bn) in part {
                    let r = (|| {
                        let a = match cache.take() {
                            Some((p, img)) if p == ad.join(an) => img,
                            _ => load(ad, an)?,
                        };
                        let b = load(bd, bn)?;
                        let v = value(&a, &b).map_err(|e| format!("{an}: {e}"))?;
                        cache = Some((bd.join(bn), b));
                        Ok::<_, String>(v)
                    })();
                    match r {
                        Ok((v, m)) => out.lock().unwrap().push((i, v, m)),
                        Err(e) => {
                            failed.lock().unwrap().get_or_insert(e);
                            return;
                        }
                    }
                }
            });
        }
    });
    if let Some(e) = failed.into_inner().unwrap() {
        return Err(e);
    }
    let mut rows = out.into_inner().unwrap();
    rows.sort_by_key(|r| r.0);
    Ok(rows)
}

/// The worst pair's differing pixels in red over the first image dimmed to grey.
fn diff_image(a: &Image, b: &Image, threshold: u8) -> Image {
    let mut rgba = Vec::with_capacity(a.rgba.len());
    for (pa, pb) in a.rgba.chunks_exact(4).zip(b.rgba.chunks_exact(4)) {
        let d = (0..3).map(|c| pa[c].abs_diff(pb[c])).max().unwrap_or(0);
        if d > threshold {
            rgba.extend_from_slice(&[255, 0, 0, 255]);
        } else {
            let g = ((u32::from(pa[0]) + u32::from(pa[1]) + u32::from(pa[2])) / 6) as u8;
            rgba.extend_from_slice(&[g, g, g, 255]);
        }
    }
    Image {
        width: a.width,
        height: a.height,
        rgba,
    }
}

fn run(a: &Args) -> Result<(), String> {
    let names = png_names(&a.dirs[0])?;
    let mut pairs = Vec::new();
    if a.dirs.len() == 1 {
        let d = a.dirs[0].as_path();
        for (i, w) in names.windows(2).enumerate() {
            pairs.push((i + 1, d, w[0].as_str(), d, w[1].as_str()));
        }
    } else {
        let (da, db) = (a.dirs[0].as_path(), a.dirs[1].as_path());
        for (i, n) in names.iter().enumerate() {
            if !db.join(n).is_file() {
                return Err(format!("{}: missing", db.join(n).display()));
            }
            pairs.push((i, da, n.as_str(), db, n.as_str()));
        }
    }
    if pairs.is_empty() {
        return Err("fewer than two frames: nothing to compare".into());
    }
    let threshold = a.threshold;
    let rows = if a.psnr {
        compare(&pairs, &|x, y| {
            psnr(x, y)
                .map(|p| (p.min(99.0), 0))
                .ok_or_else(|| "sizes differ".to_string())
        })?
    } else {
        compare(&pairs, &|x, y| {
            let (count, max) = diff_stats(x, y, threshold).ok_or("sizes differ")?;
            Ok((
                count as f64 / (f64::from(x.width) * f64::from(x.height)),
                max,
            ))
        })?
    };
    let by_index = |i: usize| pairs.iter().find(|p| p.0 == i).unwrap();
    if a.per_frame {
        for &(i, v, m) in &rows {
            let name = by_index(i).4;
            if a.psnr {
                println!("{{\"frame\":\"{name}\",\"index\":{i},\"psnr_db\":{v:.4}}}");
            } else {
                println!(
                    "{{\"frame\":\"{name}\",\"index\":{i},\"share\":{v:.6},\"max_diff\":{m}}}"
                );
            }
        }
    }
    let mut sorted: Vec<f64> = rows.iter().map(|r| r.1).collect();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    let mean = sorted.iter().sum::<f64>() / n as f64;
    let p99 = sorted[((n as f64 * 0.99).ceil() as usize).clamp(1, n) - 1];
    // The worst frame: the largest share, or the lowest PSNR.
    let worst = if a.psnr {
        rows.iter().min_by(|x, y| x.1.total_cmp(&y.1))
    } else {
        rows.iter().max_by(|x, y| x.1.total_cmp(&y.1))
    }
    .unwrap();
    let (wi, _, _, _, wb) = *by_index(worst.0);
    let (min, max) = (sorted[0], sorted[n - 1]);
    println!(
        "{{\"summary\":true,\"frames\":{n},\"mean\":{mean:.6},\"p99\":{p99:.6},\"min\":{min:.6},\"max\":{max:.6},\"worst\":\"{wb}\",\"worst_index\":{wi}}}"
    );
    if let Some(out) = &a.worst_diff {
        let (_, pa, an, pb, bn) = *by_index(worst.0);
        let img = diff_image(&load(pa, an)?, &load(pb, bn)?, threshold);
        img.save_png(out).map_err(|e| e.to_string())?;
    }
    Ok(())
}

fn main() -> ExitCode {
    let args = match parse() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
