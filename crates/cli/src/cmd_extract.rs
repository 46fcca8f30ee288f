//! `tessera extract`: select a cut of a model's hierarchy and write it as one mesh.
//!
//! The cut is chosen exactly as every other consumer chooses it (top down, saturated
//! errors, `tessera_select::select_cut`), or is the uniform cut at one level. The selected
//! patches are decoded and merged into one indexed mesh by welding bit-identical vertices
//! (`tessera_extract::extract_nodes`: positions share one global grid, so border vertices
//! shared by two patches are identical), and written in model coordinates as a binary PLY
//! (`tessera_extract::write_cut_ply`) or as glTF 2.0 (`.glb`, or `.gltf` with its buffer
//! embedded; `tessera_extract::write_cut_gltf`): the extension of `-o` decides. A textured
//! model's glTF keeps one primitive per patch with that patch's texture. The edge report
//! of the welded mesh (boundary and non-manifold edges) is printed: on a closed input any
//! cut must be a closed manifold, so this doubles as the crack check.
//!
//! MODEL is a path or an `http://` URL (`crate::open`): a remote model fetches only the
//! patches of the cut, adjacent ones coalesced into one range request, and the output is
//! byte for byte the local one's.

use anyhow::{bail, Context};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use tessera_extract::{
    extract_nodes, extract_nodes_keeping, write_cut_gltf, write_cut_ply, GltfContainer, GltfContent,
};
use tessera_format::{Grid, PatchReader, ATTR_TEXTURE};
use tessera_select::{select_cut, uniform_level_cut, Camera, Criterion};

/// The output formats, for `--help`.
const OUTPUT_HELP: &str = "\
Output formats (chosen by the extension of -o):
  .ply   Binary PLY: the welded cut, positions in model coordinates, normals, colours
         (RGBA bytes) and the source texture coordinates where the model has them.
  .glb   glTF 2.0 binary, one file (MeshLab, Blender, glTF viewers). Positions in model
         coordinates (f32), normals, indices (u16 where they fit, else u32). Untextured model: one primitive, the
         same welded mesh as the PLY, with COLOR_0 (linear RGBA floats) when the model has
         colours. Textured model: one primitive and one material per patch, its
         baseColorTexture that patch's texture (PNG, lossless; clamp to edge, linear
         filtering) and TEXCOORD_0 the coordinates in it; no vertex colours.
  .gltf  The same document as JSON text with the buffer (images included) embedded as a
         base64 data: URI: one self-contained file, about a third larger than the .glb.
Either glTF can be built again with `tessera build` (each patch texture becomes a source
image). Files are written atomically: nothing appears at the path unless it was all
written.";

/// What `-o` asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Output {
    Ply,
    Gltf(GltfContainer),
}

impl Output {
    fn of_path(path: &Path) -> anyhow::Result<Output> {
        if let Some(c) = GltfContainer::of_path(path) {
            return Ok(Output::Gltf(c));
        }
        match path.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("ply") => Ok(Output::Ply),
            Some(e) => bail!(
                "{}: cannot write .{e} files: name the output .ply, .glb or .gltf",
                path.display()
            ),
            None => bail!(
                "{}: the output needs an extension that names its format: .ply, .glb or .gltf",
                path.display()
            ),
        }
    }
}

#[derive(clap::Args)]
#[command(after_help = OUTPUT_HELP)]
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
    /// Output mesh: .ply (binary PLY), .glb (binary glTF) or .gltf (glTF, embedded
    /// buffer); written atomically. See the formats below.
    #[arg(short, long, value_name = "CUT.ply|CUT.glb|CUT.gltf")]
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

/// Fails early, before any patch is read, when the output's directory does not exist.
fn check_output_dir(out: &Path) -> anyhow::Result<()> {
    let dir = match out.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => return Ok(()),
    };
    if !dir.is_dir() {
        bail!(
            "cannot write {}: directory {} does not exist",
            out.display(),
            dir.display()
        );
    }
    Ok(())
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let output = Output::of_path(&a.output)?;
    check_output_dir(&a.output)?;
    let m = crate::open::open_model(&a.model).with_context(|| format!("{}", a.model.display()))?;
    let m = m.as_ref();
    let (nodes, criterion) = select(m, &a)?;
    let grid = Grid::of_header(m.index().header());
    let textured = m.index().header().attributes & ATTR_TEXTURE != 0;
    // The file name only: local and remote extracts of one model are the same bytes.
    let title = format!("tessera extract of {}", model_name(&a.model));
    let cut_line = |n: usize| format!("cut {criterion}, {n} nodes");
    let writing = || format!("writing {}", a.output.display());
    // The format error names the node ("patch checksum mismatch for node 12 ...").
    let in_model = || format!("{}", a.model.display());
    let (x, gltf) = match output {
        Output::Ply => {
            let x = extract_nodes(m, &nodes).with_context(in_model)?;
            let comments = vec![title, cut_line(x.nodes.len())];
            write_cut_ply(&grid, &x.mesh, &a.output, comments).with_context(writing)?;
            (x, None)
        }
        Output::Gltf(container) => {
            let name = format!("{title}, {}", cut_line(nodes.len()));
            if textured {
                let (x, patches) = extract_nodes_keeping(m, &nodes).with_context(in_model)?;
                let refs: Vec<(u32, &tessera_format::PatchData)> =
                    x.nodes.iter().copied().zip(&patches).collect();
                let s = write_cut_gltf(
                    &grid,
                    GltfContent::Textured(&refs),
                    &a.output,
                    container,
                    &name,
                )
                .with_context(writing)?;
                (x, Some(s))
            } else {
                let x = extract_nodes(m, &nodes).with_context(in_model)?;
                let s = write_cut_gltf(
                    &grid,
                    GltfContent::Welded(&x.mesh),
                    &a.output,
                    container,
                    &name,
                )
                .with_context(writing)?;
                (x, Some(s))
            }
        }
    };

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
            "format": match output {
                Output::Ply => "ply",
                Output::Gltf(GltfContainer::Binary) => "glb",
                Output::Gltf(GltfContainer::Embedded) => "gltf",
            },
            "gltf": gltf.as_ref().map(|s| json!({
                "bytes": s.bytes,
                "primitives": s.primitives,
                "textures": s.textures,
                "texture_bytes": s.texture_bytes,
            })),
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
        if let Some(s) = &gltf {
            println!(
                "  glTF       {} bytes, {} primitives, {} patch textures ({} bytes of PNG)",
                s.bytes, s.primitives, s.textures, s.texture_bytes
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
