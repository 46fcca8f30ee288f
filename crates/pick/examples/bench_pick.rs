//! Times full-resolution picks on a model file.
//!
//! `cargo run --release -p tessera-pick --example bench_pick -- MODEL.tsr [--rays N] [--batch B]`
//!
//! Rays start on cameras around the bounding sphere (2 to 4 radii from its centre) and
//! aim at random points within 0.3 radii of the centre (deterministic). Each ray is
//! picked
//!
//! - cold: the model closed, the file's pages dropped from the page cache
//!   (`posix_fadvise(DONTNEED)`, Linux/Unix; elsewhere only a fresh open), the model
//!   opened again (timed apart: it reads and checks the whole index), then the pick;
//! - warm: on one open model after a first pass over every ray.
//!
//! Prints median / p90 / max milliseconds, and the patches decoded, triangles tested and
//! nodes visited per pick.

use std::path::PathBuf;
use std::time::Instant;

use tessera_format::Model;
use tessera_pick::{pick_with, PickOptions, PickStats, Ray};
use tessera_testkit::SplitMix64;

fn usage() -> ! {
    eprintln!("usage: bench_pick MODEL.tsr [--rays N] [--batch B]");
    std::process::exit(2)
}

/// Drops the file's pages from the page cache (best effort).
#[cfg(unix)]
fn drop_cache(path: &std::path::Path) {
    use std::os::unix::io::AsRawFd;
    if let Ok(f) = std::fs::File::open(path) {
        // SAFETY: a plain syscall on a valid descriptor.
        let rc = unsafe { libc::posix_fadvise(f.as_raw_fd(), 0, 0, libc::POSIX_FADV_DONTNEED) };
        if rc != 0 {
            eprintln!("posix_fadvise failed ({rc}): cold numbers are warm");
        }
    }
}

#[cfg(not(unix))]
fn drop_cache(_: &std::path::Path) {}

fn summary(name: &str, ms: &mut [f64]) {
    ms.sort_by(f64::total_cmp);
    let at = |q: f64| ms[((ms.len() - 1) as f64 * q).round() as usize];
    println!(
        "{name:>10}: median {:8.3} ms   p90 {:8.3} ms   max {:8.3} ms",
        at(0.5),
        at(0.9),
        ms[ms.len() - 1]
    );
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mut path: Option<PathBuf> = None;
    let mut rays = 100usize;
    let mut batch = PickOptions::default().batch;
    while let Some(a) = args.next() {
        match a.as_str() {
            "--rays" => {
                rays = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .unwrap_or_else(|| usage())
            }
            "--batch" => {
                batch = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .unwrap_or_else(|| usage())
            }
            "-h" | "--help" => usage(),
            _ if path.is_none() => path = Some(PathBuf::from(a)),
            _ => usage(),
        }
    }
    let path = path.unwrap_or_else(|| usage());
    let options = PickOptions { batch };
    let model = Model::open(&path).unwrap_or_else(|e| {
        eprintln!("{}: {e}", path.display());
        std::process::exit(1)
    });
    let h = *model.header();
    println!(
        "{}: {} nodes, {} input triangles, {} bytes; {rays} rays, batches of {batch}",
        path.display(),
        h.node_count,
        h.input_triangles,
        h.file_bytes
    );
    let [cx, cy, cz, r] = h.bounding_sphere;
    let mut rng = SplitMix64(42);
    let list: Vec<Ray> = (0..rays)
        .map(|_| {
            let u = rng.unit_vector();
            let d = r * (2.0 + 2.0 * rng.next_f64());
            let v = rng.unit_vector();
            let s = 0.3 * r * rng.next_f64().cbrt();
            Ray::between(
                [cx + u[0] * d, cy + u[1] * d, cz + u[2] * d],
                [cx + v[0] * s, cy + v[1] * s, cz + v[2] * s],
            )
        })
        .collect();
    drop(model);

    // Cold.
    let (mut open_ms, mut cold_ms) = (Vec::new(), Vec::new());
    let mut cold_stats = Vec::new();
    for ray in &list {
        drop_cache(&path);
        let t0 = Instant::now();
        let m = Model::open(&path).expect("open");
        let t1 = Instant::now();
        let (hit, stats) = pick_with(&m, ray, &options).expect("pick");
        let t2 = Instant::now();
        open_ms.push((t1 - t0).as_secs_f64() * 1e3);
        cold_ms.push((t2 - t1).as_secs_f64() * 1e3);
        cold_stats.push((hit.is_some(), stats));
    }

    // Warm: one pass to load, one timed.
    let m = Model::open(&path).expect("open");
    for ray in &list {
        let _ = pick_with(&m, ray, &options);
    }
    let mut warm_ms = Vec::new();
    for ray in &list {
        let t = Instant::now();
        let _ = pick_with(&m, ray, &options).expect("pick");
        warm_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }

    let hits = cold_stats.iter().filter(|s| s.0).count();
    let per = |f: fn(&PickStats) -> usize| -> (f64, usize) {
        let v: Vec<usize> = cold_stats.iter().map(|s| f(&s.1)).collect();
        (
            v.iter().sum::<usize>() as f64 / v.len() as f64,
            v.iter().copied().max().unwrap_or(0),
        )
    };
    let (pd, pdm) = per(|s| s.patches_decoded);
    let (tt, ttm) = per(|s| s.triangles_tested);
    let (nv, nvm) = per(|s| s.nodes_visited);
    let skipped: usize = cold_stats.iter().map(|s| s.1.skipped.len()).sum();
    println!("{hits} of {rays} rays hit; {skipped} patches skipped");
    println!(
        "per pick: patches decoded {pd:.1} (max {pdm}), triangles tested {tt:.0} (max {ttm}), nodes visited {nv:.0} (max {nvm})"
    );
    summary("open cold", &mut open_ms);
    summary("pick cold", &mut cold_ms);
    summary("pick warm", &mut warm_ms);
}
