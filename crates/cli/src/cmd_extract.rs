//! `tessera extract`: select a cut of a model's hierarchy and write it as one mesh.
//!
//! The cut is chosen exactly as every other consumer chooses it (top down, saturated
//! errors, `tessera_select::select_cut`), or is the uniform cut at one level. The selected
//! patches are decoded and merged into one indexed mesh by welding bit-identical vertices
//! (`tessera_select::extract_nodes`: positions share one global grid, so border vertices
//! shared by two patches are identical), and written as a binary PLY in model coordinates
//! (`tessera_select::write_cut_ply`). The edge report of the written mesh (boundary and
//! non-manifold edges) is printed: on a closed input any cut must be a closed manifold, so
//! this doubles as the crack check.
//!
//! MODEL is a path or an `http://` URL (`crate::open`): a remote model fetches only the
//! patches of the cut, adjacent ones coalesced into one range request, and the output is
//! byte for byte the local one's.

use anyhow::{bail, Context};
use serde_json::json;
use std::path::PathBuf;
use std::process::ExitCode;
use tessera_format::{Grid, PatchReader};
use tessera_select::{
    extract_nodes, select_cut, uniform_level_cut, write_cut_ply, Camera, Criterion,
};

#[derive(clap::Args)]
#[command(group(
    clap::ArgGroup::new("criterion")
        .required(true)
        .multiple(false)
        .args(["max_error", "camera", "level"])
))]
pub struct Args {
    /// The model: a .tsr path or an http:// URL of one.
    model: PathBuf,
    /// View-independent cut: the coarsest nodes whose saturated error is at most E
    /// (model units). 0 selects the leaves, i.e. the full-resolution input.
    #[arg(long, value_name = "E", allow_negative_numbers = true)]
    max_error: Option<f32>,
    /// View-dependent cut for this camera (JSON, model coordinates; see docs/camera.md).
    #[arg(long, value_name = "CAM.json", requires = "tolerance")]
    camera: Option<PathBuf>,
    /// Screen-space error tolerance in pixels of the camera's image height (with --camera).
    #[arg(long, value_name = "PX", allow_negative_numbers = true, conflicts_with_all = ["max_error", "level"])]
    tolerance: Option<f32>,
    /// With --camera: keep what lies outside the view frustum or faces away from the eye
    /// (the cut then covers the whole model, at view-dependent resolution).
    #[arg(long, conflicts_with_all = ["max_error", "level"])]
    no_cull: bool,
    /// Uniform cut: every node at level L (0 = roots), plus the leaves above that level
    /// where the hierarchy is shallower. Levels run from 0 to the model's level count - 1
    /// (see `tessera info`).
    #[arg(long, value_name = "L")]
    level: Option<u32>,
    /// Output mesh (binary PLY), written atomically.
    #[arg(short, long, value_name = "CUT.ply")]
    output: PathBuf,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    json: bool,
}

/// Chooses the node indices of a cut. `level` is checked against the model.
fn select(m: &dyn PatchReader, a: &Args) -> anyhow::Result<(Vec<u32>, serde_json::Value)> {
    let h = m.index().header();
    let nodes = m.index().nodes();
    if let Some(e) = a.max_error {
        if !(e.is_finite() && e >= 0.0) {
            bail!("--max-error must be a finite number >= 0, got {e}");
        }
        let cut = select_cut(h, nodes, &Criterion::MaxError { max_error: e });
        return Ok((cut.nodes, json!({ "max_error": e })));
    }
    if let Some(level) = a.level {
        if level >= h.level_count {
            bail!(
                "{}: --level {level} is out of range: the model has {} levels (0..={})",
                a.model.display(),
                h.level_count,
                h.level_count.saturating_sub(1)
            );
        }
        return Ok((
            uniform_level_cut(nodes, level as u8),
            json!({ "level": level }),
        ));
    }
    let (Some(cam_path), Some(tolerance)) = (&a.camera, a.tolerance) else {
        bail!("one of --max-error, --camera (with --tolerance) or --level is required");
    };
    if !(tolerance.is_finite() && tolerance >= 0.0) {
        bail!("--tolerance must be a finite number of pixels >= 0, got {tolerance}");
    }
    // CameraError already names the file and the field.
    let camera = Camera::from_json_file(cam_path)?;
    let cull = !a.no_cull;
    let cut = select_cut(
        h,
        nodes,
        &Criterion::View {
            camera,
            tolerance_px: tolerance,
            cull,
        },
    );
    Ok((
        cut.nodes,
        json!({ "camera": cam_path.display().to_string(), "tolerance_px": tolerance, "cull": cull }),
    ))
}

/// The last segment of a model path or URL (`m.tsr` of `/data/m.tsr` and of
/// `http://host/models/m.tsr`).
fn model_name(model: &std::path::Path) -> String {
    let s = model.to_string_lossy();
    let s = s.split(['?', '#']).next().unwrap_or_default();
    s.rsplit(['/', '\\']).next().unwrap_or_default().to_string()
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let m = crate::open::open_model(&a.model).with_context(|| format!("{}", a.model.display()))?;
    let m = m.as_ref();
    let (nodes, criterion) = select(m, &a)?;
    // The format error names the node ("patch checksum mismatch for node 12 ...").
    let x = extract_nodes(m, &nodes).with_context(|| format!("{}", a.model.display()))?;
    let comments = vec![
        // The file name only: local and remote extracts of one model are the same bytes.
        format!("tessera extract of {}", model_name(&a.model)),
        format!("cut {criterion}, {} nodes", x.nodes.len()),
    ];
    write_cut_ply(
        &Grid::of_header(m.index().header()),
        &x.mesh,
        &a.output,
        comments,
    )
    .with_context(|| format!("writing {}", a.output.display()))?;

    let max_node_error = x.max_node_error(m);
    let levels = x.level_range(m);
    let e = &x.edges;
    if a.json {
        let j = json!({
            "model": a.model.display().to_string(),
            "output": a.output.display().to_string(),
            "criterion": criterion,
            "nodes": x.nodes.len(),
            "triangles": x.mesh.triangle_count(),
            "vertices": x.mesh.positions.len(),
            "levels": levels.map(|(min, max)| json!({ "min": min, "max": max })),
            "max_node_error": max_node_error,
            "edges": {
                "total": e.edges,
                "boundary": e.boundary_edges,
                "nonmanifold": e.nonmanifold_edges,
                "degenerate_triangles": e.degenerate_triangles,
            },
            "closed_manifold": e.is_closed_manifold(),
        });
        println!("{}", serde_json::to_string_pretty(&j)?);
    } else {
        println!("wrote {}", a.output.display());
        println!("  cut        {criterion}");
        match levels {
            None => println!("  nodes      0 (everything culled)"),
            Some((lmin, lmax)) => println!(
                "  nodes      {} (levels {lmin}..={lmax}, largest error {max_node_error:.4e})",
                x.nodes.len()
            ),
        }
        println!(
            "  mesh       {} triangles, {} vertices",
            x.mesh.triangle_count(),
            x.mesh.positions.len()
        );
        println!(
            "  edges      {} edges, {} boundary, {} non-manifold, {} degenerate triangles{}",
            e.edges,
            e.boundary_edges,
            e.nonmanifold_edges,
            e.degenerate_triangles,
            if e.is_closed_manifold() {
                " (closed manifold)"
            } else {
                ""
            }
        );
    }
    Ok(ExitCode::SUCCESS)
}
