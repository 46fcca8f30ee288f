//! `tessera info`: what is in a model file.

use anyhow::Context;
use serde_json::json;
use std::path::PathBuf;
use std::process::ExitCode;
use tessera_format::{Grid, ModelIndex, ATTR_COLORS, ATTR_NORMALS, ATTR_UVS, NODE_FLAG_LEAF};

#[derive(clap::Args)]
pub struct Args {
    /// The model: a .tsr file or an http:// URL of one (e.g. from `tessera serve`).
    model: PathBuf,
    /// Print JSON on stdout.
    #[arg(long)]
    json: bool,
}

pub fn info_json(m: &ModelIndex, file: &str) -> serde_json::Value {
    let h = m.header();
    let nodes = m.nodes();
    let mut per_level: Vec<(u64, u64, u64)> = vec![(0, 0, 0); h.level_count as usize];
    let (mut verts, mut tris, mut leaf_tris, mut leaves) = (0u64, 0u64, 0u64, 0u64);
    let mut min_err = f32::INFINITY;
    for n in nodes {
        verts += n.vertex_count as u64;
        tris += n.triangle_count as u64;
        if n.flags & NODE_FLAG_LEAF != 0 {
            leaves += 1;
            leaf_tris += n.triangle_count as u64;
        } else {
            min_err = min_err.min(n.error);
        }
        if let Some(l) = per_level.get_mut(n.level as usize) {
            l.0 += 1;
            l.1 += n.triangle_count as u64;
            l.2 += n.patch_bytes as u64;
        }
    }
    let mut attrs = vec!["positions"];
    if h.attributes & ATTR_NORMALS != 0 {
        attrs.push("normals");
    }
    if h.attributes & ATTR_COLORS != 0 {
        attrs.push("colors");
    }
    if h.attributes & ATTR_UVS != 0 {
        attrs.push("uvs");
    }
    let grid = Grid::of_header(h);
    let ix = m.index_stats();
    json!({
        "file": file,
        "format_version": h.version,
        "file_bytes": h.file_bytes,
        "attributes": attrs,
        "input": { "vertices": h.input_vertices, "triangles": h.input_triangles },
        "nodes": h.node_count,
        "roots": h.root_count,
        "levels": h.level_count,
        "leaves": leaves,
        "patches": h.node_count,
        "vertices": verts,
        "triangles": tris,
        "leaf_triangles": leaf_tris,
        "error": { "min_internal": if min_err.is_finite() { min_err } else { 0.0 }, "max": h.max_error },
        "quantization": { "bits": h.quant_bits, "step": grid.step(), "max_error": grid.max_error() },
        "cube": { "origin": h.cube_origin, "size": h.cube_size },
        "bounding_sphere": { "center": &h.bounding_sphere[..3], "radius": h.bounding_sphere[3] },
        "bytes": { "header": 256, "index": ix.index_bytes - 256, "patches": h.patch_data_bytes },
        "index": {
            "bytes": ix.index_bytes,
            "bytes_per_node": ix.bytes_per_node(h.node_count),
            "pages": ix.page_count,
            "page_nodes": ix.page_nodes,
            "first_frame_bytes": ix.first_frame_bytes,
        },
        "bytes_per_input_triangle": h.file_bytes as f64 / h.input_triangles.max(1) as f64,
        "builder": { "leaf_triangles_max": h.leaf_triangles_max, "node_triangles_target": h.node_triangles_target },
        "per_level": per_level.iter().enumerate().map(|(l, (n, t, b))| json!({"level": l, "nodes": n, "triangles": t, "patch_bytes": b})).collect::<Vec<_>>(),
    })
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let model =
        crate::open::open_model(&a.model).with_context(|| format!("{}", a.model.display()))?;
    let m = model.index();
    let mut j = info_json(m, &a.model.display().to_string());
    // The extent of the coarsest level (root patches) and the up axis guessed from it,
    // which `view` and `render --orbit` use unless given `--up`.
    let scene = tessera_viewer::scene_points(model.as_ref(), 1);
    let up = scene.guess_up();
    j["extent"] = json!({ "min": scene.min.to_array(), "max": scene.max.to_array() });
    j["up_guess"] = json!(up.to_string());
    if a.json {
        println!("{}", serde_json::to_string_pretty(&j)?);
        return Ok(ExitCode::SUCCESS);
    }
    let h = m.header();
    let grid = Grid::of_header(h);
    println!(
        "{}  (format v{}, {} bytes)",
        a.model.display(),
        h.version,
        h.file_bytes
    );
    println!(
        "  attributes      {}",
        j["attributes"]
            .as_array()
            .map(|a| a
                .iter()
                .filter_map(|x| x.as_str())
                .collect::<Vec<_>>()
                .join(", "))
            .unwrap_or_default()
    );
    println!(
        "  input           {} triangles, {} vertices",
        h.input_triangles, h.input_vertices
    );
    println!(
        "  nodes           {} ({} roots, {} leaves), {} levels",
        h.node_count, h.root_count, j["leaves"], h.level_count
    );
    println!(
        "  stored          {} triangles, {} vertices (leaves hold {} triangles)",
        j["triangles"], j["vertices"], j["leaf_triangles"]
    );
    println!(
        "  error           {} .. {} (model units, saturated)",
        j["error"]["min_internal"], h.max_error
    );
    println!(
        "  quantization    {} bits, step {:.4e}, max error {:.4e}",
        h.quant_bits,
        grid.step(),
        grid.max_error()
    );
    println!(
        "  bounding sphere center [{:.6}, {:.6}, {:.6}] radius {:.6}",
        h.bounding_sphere[0], h.bounding_sphere[1], h.bounding_sphere[2], h.bounding_sphere[3]
    );
    let size = scene.max - scene.min;
    println!(
        "  extent          {:.6} x {:.6} x {:.6} (roots); up axis guessed {} (the tallest; \
         `view`/`render --up` override)",
        size.x, size.y, size.z, up
    );
    let ix = m.index_stats();
    println!(
        "  bytes           header 256, index {}, patches {}",
        ix.index_bytes - 256,
        h.patch_data_bytes
    );
    println!(
        "  index           {:.1} bytes/node, {} pages of {} nodes; {} bytes to the first page",
        ix.bytes_per_node(h.node_count),
        ix.page_count,
        ix.page_nodes,
        ix.first_frame_bytes
    );
    println!(
        "  bytes/input tri {:.3}",
        j["bytes_per_input_triangle"].as_f64().unwrap_or(0.0)
    );
    println!("  level   nodes   triangles   patch bytes");
    if let Some(levels) = j["per_level"].as_array() {
        for l in levels {
            println!(
                "  {:>5} {:>7} {:>11} {:>13}",
                l["level"], l["nodes"], l["triangles"], l["patch_bytes"]
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
