//! Native half of the WebAssembly selection timing (`scripts/bench-web`; the wasm half
//! is the browser module's `ProbeBench`, `crates/web/src/probe.rs`, driven by
//! `scripts/wasm/bench.mjs`): the same [`Bench`] over the same model and orbit, each
//! frame timed around the call with `Instant` (the wasm host times the same call with
//! `performance.now()`). Prints one JSON object, the same fields as bench.mjs.
//!
//! `cargo run --release -p tessera-stream --example bench-frames -- MODEL.tsr
//!  [frames 24] [passes 5] [width 1280] [height 720] [distance 2.0]`

use std::time::Instant;

use tessera_stream::bench::{Bench, BenchOptions};

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let model = a
        .first()
        .expect("usage: bench-frames MODEL.tsr [frames] [passes] [width] [height] [distance]");
    let num = |i: usize, d: f64| a.get(i).map_or(d, |s| s.parse().expect("a number"));
    let opts = BenchOptions {
        frames: num(1, 24.0) as u32,
        width: num(3, 1280.0) as u32,
        height: num(4, 720.0) as u32,
        distance: num(5, 2.0),
    };
    let passes = num(2, 5.0) as u32;
    let t = Instant::now();
    let bytes = std::fs::read(model).expect("read the model");
    let read_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    let mut b = Bench::open(bytes, &opts).expect("open the model");
    let open_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    let warm = b.warm();
    let warm_ms = t.elapsed().as_secs_f64() * 1e3;
    let mut ms = Vec::new();
    let (mut nodes, mut tris, mut sel) = (0u64, 0u64, 0.0f64);
    for _ in 0..passes {
        for k in 0..b.frames() {
            let t = Instant::now();
            let s = b.frame(k);
            ms.push(t.elapsed().as_secs_f64() * 1e3);
            nodes += s.selected_nodes as u64;
            tris += s.triangles;
            sel += s.selection_ms;
        }
    }
    let n = ms.len().max(1) as f64;
    let mean = ms.iter().sum::<f64>() / n;
    ms.sort_by(f64::total_cmp);
    let q = |p: f64| ms[((ms.len() - 1) as f64 * p).round() as usize];
    println!(
        "{{\"target\": \"native\", \"model_nodes\": {}, \"read_ms\": {read_ms:.1}, \"open_ms\": {open_ms:.1}, \
         \"warm_passes\": {}, \"warm_ms\": {warm_ms:.1}, \"frames_timed\": {}, \"ms_per_frame_mean\": {mean:.4}, \
         \"ms_per_frame_median\": {:.4}, \"ms_per_frame_p95\": {:.4}, \"ms_per_frame_min\": {:.4}, \
         \"ms_per_frame_max\": {:.4}, \"drawn_nodes_mean\": {:.1}, \"triangles_mean\": {:.0}, \
         \"checksum\": \"{nodes}/{tris}\", \"scheduler_selection_ms_mean\": {:.4}}}",
        b.nodes(),
        warm.map_or("null".to_string(), |p| p.to_string()),
        ms.len(),
        q(0.5),
        q(0.95),
        ms[0],
        ms[ms.len() - 1],
        nodes as f64 / n,
        tris as f64 / n,
        sel / n
    );
}
