//! `tessera info`: what is in a model file.

use anyhow::Context;
use serde_json::json;
use std::path::PathBuf;
use std::process::ExitCode;
use tessera_format::{
    Grid, ModelIndex, ATTR_COLORS, ATTR_NORMALS, ATTR_TEXTURE, ATTR_UVS, NODE_FLAG_LEAF,
};

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
    let mut per_level: Vec<(u64, u64, u64, u64)> = vec![(0, 0, 0, 0); h.level_count as usize];
    let (mut texels, mut leaf_texels, mut largest) = (0u64, 0u64, [0u16; 2]);
    let (mut verts, mut tris, mut leaf_tris, mut leaves) = (0u64, 0u64, 0u64, 0u64);
    let mut min_err = f32::INFINITY;
    for n in nodes {
        let t = u64::from(n.texture_size[0]) * u64::from(n.texture_size[1]);
        texels += t;
        if u32::from(n.texture_size[0]) * u32::from(n.texture_size[1])
            > u32::from(largest[0]) * u32::from(largest[1])
        {
            largest = n.texture_size;
        }
        verts += n.vertex_count as u64;
        tris += n.triangle_count as u64;
        if n.flags & NODE_FLAG_LEAF != 0 {
            leaves += 1;
            leaf_tris += n.triangle_count as u64;
            leaf_texels += t;
        } else {
            min_err = min_err.min(n.error);
        }
        if let Some(l) = per_level.get_mut(n.level as usize) {
            l.0 += 1;
            l.1 += n.triangle_count as u64;
            l.2 += n.patch_bytes as u64;
            l.3 += t;
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
    if h.attributes & ATTR_TEXTURE != 0 {
        attrs.push("textures");
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
        "textures": (h.attributes & ATTR_TEXTURE != 0).then(|| json!({
            "codec": h.patch_texture_codec().map(|c| c.name()),
            "texels": texels,
            "leaf_texels": leaf_texels,
            "largest": largest,
            "mean_texels_per_patch": texels as f64 / h.node_count.max(1) as f64,
        })),
        "per_level": per_level.iter().enumerate().map(|(l, (n, t, b, x))| json!({"level": l, "nodes": n, "triangles": t, "patch_bytes": b, "texels": x})).collect::<Vec<_>>(),
    })
}

/// Everything `info` reads from a remote model (the first request, the whole index and
/// the root patches) must arrive within this; a stalled server fails sooner, at the
/// client's own timeouts (nothing for 5 s, or a read slower than its deadline: see
/// `tessera_http`). Before issue 29 a silent server took 180 s.
const INFO_DEADLINE: std::time::Duration = std::time::Duration::from_secs(15);

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let arg = a.model.to_string_lossy();
    let model: std::sync::Arc<dyn tessera_format::PatchReader> = if tessera_http::is_url(&arg) {
        let opts = tessera_http::HttpOptions {
            deadline: Some(INFO_DEADLINE),
        };
        // The error names the URL already.
        std::sync::Arc::new(tessera_http::RemoteModel::open_with(&arg, &opts)?)
    } else {
        crate::open::open_model(&a.model).with_context(|| format!("{}", a.model.display()))?
    };
    let m = model.index();
    let mut j = info_json(m, &a.model.display().to_string());
    // The extent of the coarsest level (root patches) and the up axis guessed from it,
    // which `view` and `render --orbit` use unless given `--up`.
    let scene = tessera_nav::scene_points(model.as_ref(), 1);
    let up = scene.guess_up();
    j["extent"] = json!({ "min": scene.min.to_array(), "max": scene.max.to_array() });
    j["up_guess"] = json!(up.to_string());
    // Texture bytes: the texture block length in each patch header (local files).
    if m.header().attributes & ATTR_TEXTURE != 0 {
        if let Ok(local) = tessera_format::Model::open(&a.model) {
            let bytes: u64 = (0..m.nodes().len())
                .filter_map(|i| local.patch_bytes(i).ok())
                .filter_map(|b| {
                    b.get(44..48)
                        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
                })
                .map(u64::from)
                .sum();
            j["textures"]["bytes"] = json!(bytes);
            j["textures"]["bytes_per_input_triangle"] =
                json!(bytes as f64 / m.header().input_triangles.max(1) as f64);
        }
    }
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
    if let Some(t) = j["textures"].as_object() {
        println!(
            "  textures        {} {:.2} Mtexels in patch textures ({:.2} M in leaves), largest {}x{}, {:.0} texels/patch{}",
            t["codec"].as_str().unwrap_or("?"),
            t["texels"].as_f64().unwrap_or(0.0) / 1e6,
            t["leaf_texels"].as_f64().unwrap_or(0.0) / 1e6,
            t["largest"][0],
            t["largest"][1],
            t["mean_texels_per_patch"].as_f64().unwrap_or(0.0),
            match t.get("bytes").and_then(|b| b.as_u64()) {
                Some(b) => format!(
                    ", {b} bytes ({:.2} bytes/input triangle)",
                    b as f64 / h.input_triangles.max(1) as f64
                ),
                None => String::new(),
            }
        );
    }
    let textured = j["textures"].is_object();
    println!(
        "  level   nodes   triangles   patch bytes{}",
        if textured { "    texels" } else { "" }
    );
    if let Some(levels) = j["per_level"].as_array() {
        for l in levels {
            println!(
                "  {:>5} {:>7} {:>11} {:>13}{}",
                l["level"],
                l["nodes"],
                l["triangles"],
                l["patch_bytes"],
                if textured {
                    format!(" {:>9}", l["texels"])
                } else {
                    String::new()
                }
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
