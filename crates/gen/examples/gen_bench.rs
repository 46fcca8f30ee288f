//! Time the generators: `cargo run --release -p tessera-gen --example gen_bench -- [triangles] [dir]`.

use std::path::PathBuf;
use std::time::Instant;

use tessera_gen::{write_sphere, write_terrain, SphereOptions, TerrainOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let triangles: u64 = args
        .next()
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(10_000_000);
    let dir = PathBuf::from(
        args.next()
            .unwrap_or_else(|| std::env::temp_dir().display().to_string()),
    );
    for colors in [false, true] {
        let path = dir.join("gen_bench_sphere.ply");
        let t = Instant::now();
        let r = write_sphere(
            &path,
            &SphereOptions {
                triangles,
                colors,
                ..Default::default()
            },
            &tessera_gen::NoProgress,
        )?;
        let s = t.elapsed().as_secs_f64();
        println!(
            "sphere colors={colors}: {} triangles, {} vertices in {s:.2} s = {:.1} M triangles/s",
            r.triangles,
            r.vertices,
            r.triangles as f64 / s / 1e6
        );
        std::fs::remove_file(&path)?;
    }
    let path = dir.join("gen_bench_terrain.ply");
    let t = Instant::now();
    let r = write_terrain(
        &path,
        &TerrainOptions {
            triangles,
            seed: 0,
            colors: false,
        },
        &tessera_gen::NoProgress,
    )?;
    let s = t.elapsed().as_secs_f64();
    println!(
        "terrain: {} triangles in {s:.2} s = {:.1} M triangles/s",
        r.triangles,
        r.triangles as f64 / s / 1e6
    );
    std::fs::remove_file(&path)?;
    Ok(())
}
