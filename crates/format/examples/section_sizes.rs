//! Where a model's bytes go: re-encodes every patch with and without each optional
//! section and prints the difference per stored triangle. A tuning aid for the codec.
//!
//! `cargo run --release -p tessera-format --example section_sizes -- MODEL.tsr`

use tessera_format::{encode_patch, Model, PatchData, ATTR_NORMALS};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args()
        .nth(1)
        .ok_or("usage: section_sizes MODEL.tsr")?;
    let m = Model::open(&path)?;
    let attrs = m.header().attributes;
    let (mut full, mut no_morph, mut no_normals, mut geometry, mut indices, mut tris) =
        (0usize, 0usize, 0usize, 0usize, 0usize, 0usize);
    for (i, n) in m.nodes().iter().enumerate() {
        let p = m.decode_patch(i)?;
        tris += p.triangle_count();
        full += n.patch_bytes as usize;
        let without_morph = PatchData {
            morph_targets: vec![],
            ..p.clone()
        };
        no_morph += encode_patch(&without_morph, attrs, n.quant_min).len();
        let bare = PatchData {
            normals: vec![],
            ..without_morph.clone()
        };
        no_normals += encode_patch(&bare, attrs & !ATTR_NORMALS, n.quant_min).len();
        geometry += encode_patch(&bare, attrs & !ATTR_NORMALS, n.quant_min).len();
        let idx_only = PatchData {
            positions: vec![n.quant_min; bare.positions.len()],
            ..bare.clone()
        };
        indices += encode_patch(&idx_only, attrs & !ATTR_NORMALS, n.quant_min).len();
    }
    let per = |b: usize| b as f64 / tris.max(1) as f64;
    println!(
        "stored triangles {tris}, patch bytes {full} ({:.3} B/tri)",
        per(full)
    );
    println!("  morph targets  {:.3} B/tri", per(full - no_morph));
    println!("  normals        {:.3} B/tri", per(no_morph - no_normals));
    println!("  positions      {:.3} B/tri", per(geometry - indices));
    println!("  indices (+headers) {:.3} B/tri", per(indices));
    println!(
        "  node table     {:.3} B/tri",
        (m.nodes().len() * 128) as f64 / tris.max(1) as f64
    );
    Ok(())
}
