//! `tessera build`.

use crate::progress::Bars;
use anyhow::Context;
use serde_json::json;
use std::path::PathBuf;
use std::process::ExitCode;
use tessera_build::{build, BuildOptions, BuildReport};

#[derive(clap::Args)]
pub struct Args {
    /// Input mesh: .ply (ascii or binary), .obj, .stl, .gltf or .glb (optionally
    /// gzip-compressed, except glTF).
    input: PathBuf,
    /// Output model.
    #[arg(short, long)]
    output: PathBuf,
    /// Memory budget for the build's buffers (e.g. 512M, 1G).
    #[arg(long, default_value = "1G", value_parser = crate::parse_bytes)]
    memory: u64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Quantization: 2^bits grid cells along the bounding cube's edge (1..=21). Default:
    /// chosen from the input (a cell of at most 1/16 of the mean edge length, finer by up
    /// to 6 bits where the shortest sampled edge needs it).
    #[arg(long)]
    quant_bits: Option<u32>,
    /// Most triangles per leaf.
    #[arg(long, default_value_t = 4000)]
    leaf_triangles: u32,
    /// Target triangles per internal node.
    #[arg(long, default_value_t = 2000)]
    node_triangles: u32,
    /// Directory for temporary files (default: beside the output).
    #[arg(long)]
    tmp_dir: Option<PathBuf>,
    /// Nodes per index page (1..=65536): what a remote reader fetches of the tree at a
    /// time.
    #[arg(long, default_value_t = tessera_format::DEFAULT_PAGE_NODES,
          value_parser = clap::value_parser!(u32).range(1..=tessera_format::MAX_PAGE_NODES as i64))]
    index_page_nodes: u32,
    /// Ignore the input's vertex colours (build it as if it had none).
    #[arg(long)]
    ignore_colors: bool,
    /// Quadric weight of vertex colours when simplifying (0: colour does not steer the
    /// simplification).
    #[arg(long, default_value_t = tessera_build::DEFAULT_COLOR_WEIGHT)]
    color_weight: f32,
    /// Ignore the input's textures (faces in their material's colour).
    #[arg(long)]
    ignore_textures: bool,
    /// A folder under which the files the input names (glTF buffers and images, OBJ
    /// material libraries and their textures) may be read, besides the input's own
    /// folder (the only one by default): a reference outside both (`../x.bin`, an
    /// absolute path, a symlink out) is an error. Only regular files are ever read.
    #[arg(long, value_name = "DIR")]
    asset_root: Option<PathBuf>,
    /// Most triangles the input may have, checked against its header before anything
    /// is written (glTF, PLY, binary STL) and as triangles arrive (OBJ). The default,
    /// 2^32-1, admits any input whose vertices 32-bit indices can address.
    #[arg(long, value_name = "N", default_value_t = tessera_build::DEFAULT_MAX_INPUT_TRIANGLES)]
    max_input_triangles: u64,
    /// How patch textures are stored: bc7 (GPU block compression with its mips stored:
    /// a quarter of RGBA8's GPU memory, no image decode at load, within BC7's error of
    /// the source), png (lossless: the finest patches keep the source texels exactly,
    /// decoded and mipmapped at load) or jpeg (the smallest files).
    #[arg(long, default_value = "bc7", value_parser = ["bc7", "png", "jpeg"])]
    texture_codec: String,
    /// Cut every patch's texture from the source atlas, even where its seams hold the
    /// simplification back (by default such diamonds get charts of their own and
    /// textures baked from their children).
    #[arg(long)]
    no_recut: bool,
    /// JPEG quality of patch textures (1..=100).
    #[arg(long, default_value_t = 90, value_parser = clap::value_parser!(u8).range(1..=100))]
    texture_quality: u8,
    /// Build with the ranks of an MPI job: `mpirun -n N tessera build --mpi ...`, every
    /// rank with the same arguments and the input and output on a file system they
    /// share; rank 0 writes the model (byte for byte the single process's) and prints
    /// the report. Needs a tessera built with `--features mpi` (docs/mpi.md).
    #[arg(long)]
    mpi: bool,
    /// Print the report as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// No progress bars.
    #[arg(short, long)]
    quiet: bool,
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    if let Some(root) = &a.asset_root {
        anyhow::ensure!(
            root.is_dir(),
            "--asset-root {}: no such directory",
            root.display()
        );
    }
    let opts = BuildOptions {
        memory_bytes: a.memory,
        threads: a.threads,
        quant_bits: a.quant_bits,
        leaf_triangles: a.leaf_triangles,
        node_triangles: a.node_triangles,
        tmp_dir: a.tmp_dir,
        index_page_nodes: a.index_page_nodes,
        color_weight: a.color_weight,
        ignore_colors: a.ignore_colors,
        ignore_textures: a.ignore_textures,
        texture: tessera_build::texture::TextureOptions {
            codec: match a.texture_codec.as_str() {
                "jpeg" => tessera_format::TextureCodec::Jpeg,
                "png" => tessera_format::TextureCodec::Png,
                _ => tessera_format::TextureCodec::Bc7,
            },
            quality: a.texture_quality,
            recut: !a.no_recut,
        },
        asset_root: a.asset_root,
        max_input_triangles: a.max_input_triangles,
    };
    crate::progress::install_interrupt_handler();
    let r = if a.mpi {
        match build_mpi(&a.input, &a.output, &opts, a.quiet || a.json)? {
            Some(r) => r,
            // Not rank 0: rank 0 reports.
            None => return Ok(ExitCode::SUCCESS),
        }
    } else {
        let bars = Bars::new(a.quiet || a.json);
        build(&a.input, &a.output, &opts, &bars)
            .with_context(|| format!("building {}", a.output.display()))?
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report_json(&r))?);
    } else {
        print_report(&a.output, &r);
    }
    warn_collapsed(&r);
    for line in r.textures.iter().flat_map(|t| &t.unreadable_images) {
        eprintln!("warning: texture image {line}: its faces are drawn in their material's colour");
    }
    Ok(ExitCode::SUCCESS)
}

/// `--mpi`: this process's part of the job. Rank 0 gets the report; the other ranks
/// `None`, or on failure a quiet exit (rank 0 prints the error, once).
#[cfg(feature = "mpi")]
fn build_mpi(
    input: &std::path::Path,
    output: &std::path::Path,
    opts: &BuildOptions,
    quiet: bool,
) -> anyhow::Result<Option<BuildReport>> {
    use tessera_build::peers::Peers;
    crate::progress::install_patient_interrupt_handler();
    let peers =
        tessera_build::mpi_peers::MpiPeers::init().map_err(|e| anyhow::anyhow!("--mpi: {e}"))?;
    let rank = peers.rank();
    let bars = Bars::new(quiet || rank != 0);
    let r = tessera_build::build_distributed(input, output, opts, &bars, &peers);
    match r {
        Ok(r) => Ok((rank == 0).then_some(r)),
        Err(e) => {
            let interrupted = matches!(e, tessera_build::BuildError::Interrupted);
            if interrupted {
                // A rank died or the job was signalled: MPI_Finalize could wait for
                // ranks that are gone.
                peers.abandon();
            } else {
                drop(peers);
            }
            if rank != 0 && !interrupted {
                // Every rank has this error; rank 0 prints it.
                std::process::exit(1);
            }
            let e = anyhow::Error::new(e).context(format!("building {}", output.display()));
            Err(if interrupted {
                e.context(format!(
                    "rank {rank}: the MPI job stopped (another rank died or the job was signalled; \
                     mpirun names the rank); nothing was written"
                ))
            } else {
                e
            })
        }
    }
}

#[cfg(not(feature = "mpi"))]
fn build_mpi(
    _: &std::path::Path,
    _: &std::path::Path,
    _: &BuildOptions,
    _: bool,
) -> anyhow::Result<Option<BuildReport>> {
    anyhow::bail!(
        "--mpi: this tessera was built without MPI; build it with \
         `cargo build --release -p tessera-cli --features mpi` (needs Open MPI: scripts/setup)"
    )
}

pub fn report_json(r: &BuildReport) -> serde_json::Value {
    json!({
        "peak_rss_bytes": tessera_build::peak_rss_bytes(),
        "input_vertices": r.input_vertices,
        "input_triangles": r.input_triangles,
        "normals_computed": r.normals_computed,
        "nodes": r.nodes,
        "leaves": r.leaves,
        "levels": r.levels,
        "stored_triangles": r.stored_triangles,
        "output_bytes": r.output_bytes,
        "bytes_per_input_triangle": r.bytes_per_input_triangle(),
        "seconds": r.seconds,
        "input_triangles_per_second": r.triangles_per_second(),
        "quantization": { "bits": r.quant_bits, "step": r.quant_step, "max_error": r.quant_error_max, "mean_edge": r.mean_edge },
        "max_error": r.max_error,
        "textures": r.textures.as_ref().map(|t| json!({
            "source_images": t.source_images,
            "source_texels": t.source_texels,
            "patch_texels": t.texels,
            "leaf_texels": t.leaf_texels,
            "bytes": t.bytes,
            "bytes_per_source_texel": t.bytes as f64 / t.source_texels.max(1) as f64,
            "crops": t.crops,
            "atlases": t.atlases,
            "recut": t.recut,
            "solid_only": t.solid_only,
            "downsampled_to_fit": t.downsampled_to_fit,
            "unreadable_images": t.unreadable_images,
        })),
        "stages": r.stage_seconds.iter().map(|(n, s)| json!({"stage": n, "seconds": s})).collect::<Vec<_>>(),
        "ranks": r.ranks.iter().map(|k| json!({
            "rank": k.rank,
            "peak_rss_bytes": k.peak_rss_bytes,
            "stages": k.stage_seconds.iter().map(|(n, s)| json!({"stage": n, "seconds": s})).collect::<Vec<_>>(),
            "levels": k.levels.iter().map(|l| json!({
                "level": l.level,
                "diamonds": l.diamonds,
                "work_seconds": l.work_seconds,
                "exchange_seconds": l.exchange_seconds,
                "bytes_sent": l.bytes_sent,
                "bytes_received": l.bytes_received,
            })).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
        "warnings": {
            "degenerate_triangles_removed": r.degenerate_triangles_removed,
            "triangles_collapsed_by_grid": r.triangles_collapsed_by_grid,
            "quant_bits_to_keep_all": r.quant_bits_to_keep_all,
            "duplicate_triangles_removed": r.duplicate_triangles_removed,
            "oversized_leaves": r.oversized_leaves,
            "import_degenerate_faces_skipped": r.import.degenerate_faces_skipped,
            "import_short_faces_skipped": r.import.short_faces_skipped,
            "import_polygons_triangulated": r.import.polygons_triangulated,
            "import_ignored_statements": r.import.ignored_statements,
        }
    })
}

fn print_report(out: &std::path::Path, r: &BuildReport) {
    println!("built {}", out.display());
    println!(
        "  input        {} triangles, {} vertices{}",
        r.input_triangles,
        r.input_vertices,
        if r.normals_computed {
            " (normals computed)"
        } else {
            ""
        }
    );
    println!(
        "  hierarchy    {} nodes ({} leaves), {} levels, {} triangles stored",
        r.nodes, r.leaves, r.levels, r.stored_triangles
    );
    println!(
        "  output       {} bytes, {:.2} bytes/input triangle",
        r.output_bytes,
        r.bytes_per_input_triangle()
    );
    println!(
        "  quantization {} bits, step {:.3e}, max error {:.3e} (model units; mean edge {:.3e})",
        r.quant_bits, r.quant_step, r.quant_error_max, r.mean_edge
    );
    println!("  coarsest error {:.4e} (model units)", r.max_error);
    if let Some(t) = &r.textures {
        println!(
            "  textures     {} source images ({:.1} Mtexels) -> {:.1} Mtexels in patches \
             ({:.2}x the source; leaves {:.2}x), {} bytes ({:.3} bytes/source texel)",
            t.source_images,
            t.source_texels as f64 / 1e6,
            t.texels as f64 / 1e6,
            t.texels as f64 / t.source_texels.max(1) as f64,
            t.leaf_texels as f64 / t.source_texels.max(1) as f64,
            t.bytes,
            t.bytes as f64 / t.source_texels.max(1) as f64
        );
        println!(
            "               {} crops, {} atlases, {} re-cut, {} solid colour only, {} downsampled to fit {} texels",
            t.crops,
            t.atlases,
            t.recut,
            t.solid_only,
            t.downsampled_to_fit,
            tessera_format::MAX_TEXTURE_DIM
        );
    }
    println!(
        "  time         {:.2} s, {:.0} input triangles/s",
        r.seconds,
        r.triangles_per_second()
    );
    if let Some(rss) = tessera_build::peak_rss_bytes() {
        println!("  peak RSS     {:.1} MiB", rss as f64 / (1 << 20) as f64);
    }
    for (n, s) in &r.stage_seconds {
        println!("    {n:<16} {s:.2} s");
    }
    for k in &r.ranks {
        let sum = |f: fn(&tessera_build::LevelStats) -> f64| k.levels.iter().map(f).sum::<f64>();
        println!(
            "  rank {:<7} {} diamonds, {:.2} s simplifying, {:.2} s exchanging, {} bytes sent, peak RSS {:.1} MiB",
            k.rank,
            sum(|l| l.diamonds as f64),
            sum(|l| l.work_seconds),
            sum(|l| l.exchange_seconds),
            sum(|l| l.bytes_sent as f64),
            k.peak_rss_bytes as f64 / (1 << 20) as f64
        );
    }
    let w = r.degenerate_triangles_removed
        + r.duplicate_triangles_removed
        + r.import.degenerate_faces_skipped
        + r.import.short_faces_skipped;
    if w > 0 || r.oversized_leaves > 0 {
        println!(
            "  warnings     {} degenerate and {} duplicate triangles removed, {} bad faces skipped at import, {} leaves over the triangle limit",
            r.degenerate_triangles_removed,
            r.duplicate_triangles_removed,
            r.import.degenerate_faces_skipped + r.import.short_faces_skipped,
            r.oversized_leaves
        );
    }
}

/// Input lost to the grid: on stderr in every mode (also with --json and --quiet).
fn warn_collapsed(r: &BuildReport) {
    if r.triangles_collapsed_by_grid > 0 {
        eprintln!(
            "warning: {} input triangle(s) with a non-zero area fell onto shared grid points \
             at {} quantisation bits and were dropped; rebuild with --quant-bits {} to keep them",
            r.triangles_collapsed_by_grid,
            r.quant_bits,
            r.quant_bits_to_keep_all
                .unwrap_or(tessera_build::MAX_QUANT_BITS)
        );
    }
}
