//! Write one mesh: `cargo run -p tessera-gen --example gen_one -- sphere|terrain TRIANGLES OUT.ply [SEED]`.

use std::path::Path;

use tessera_gen::{write_sphere, write_terrain, SphereOptions, TerrainOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 4 {
        return Err("usage: gen_one sphere|terrain TRIANGLES OUT.ply [SEED]".into());
    }
    let triangles: u64 = args[2].parse()?;
    let seed: u64 = args.get(4).map(|s| s.parse()).transpose()?.unwrap_or(0);
    let out = Path::new(&args[3]);
    let report = match args[1].as_str() {
        "sphere" => write_sphere(
            out,
            &SphereOptions {
                triangles,
                seed,
                colors: true,
                ..Default::default()
            },
            &tessera_gen::NoProgress,
        )?,
        "terrain" => write_terrain(
            out,
            &TerrainOptions {
                triangles,
                seed,
                colors: true,
            },
            &tessera_gen::NoProgress,
        )?,
        other => return Err(format!("unknown generator {other}").into()),
    };
    println!("{report:?}");
    Ok(())
}
