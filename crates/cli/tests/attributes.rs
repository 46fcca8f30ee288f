//! Per-vertex normals and colours of the input survive into the model (issue 2: "Per-vertex
//! colour and normals survive into the file").

use std::collections::HashMap;
use std::path::Path;
use tessera_build::{build, BuildOptions, NoProgress};
use tessera_format::{Model, NODE_FLAG_LEAF};
use tessera_mesh::{MeshError, MeshHeader, MeshVisitor, Vertex};

struct Collect(Vec<Vertex>, MeshHeader);

impl MeshVisitor for Collect {
    fn header(&mut self, h: &MeshHeader) -> Result<(), MeshError> {
        self.1 = h.clone();
        Ok(())
    }
    fn vertex(&mut self, v: &Vertex) -> Result<(), MeshError> {
        self.0.push(*v);
        Ok(())
    }
    fn triangle(&mut self, _: [u32; 3]) -> Result<(), MeshError> {
        Ok(())
    }
}

#[test]
fn scan_normals_and_colours_survive_into_the_leaves() {
    let input = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/gargo-color.ply"
    ));
    if !input.exists() {
        eprintln!(
            "note: {} is absent (../shared/data); skipping",
            input.display()
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("gargo.tsr");
    build(input, &out, &BuildOptions::default(), &NoProgress).unwrap();
    let m = Model::open(&out).unwrap();
    let h = *m.header();
    let mut stored: HashMap<[u32; 3], Vec<([f32; 3], [u8; 4])>> = HashMap::new();
    for (i, n) in m.nodes().iter().enumerate() {
        if n.flags & NODE_FLAG_LEAF == 0 {
            continue;
        }
        let p = m.decode_patch(i).unwrap();
        assert_eq!(p.colors.len(), p.positions.len(), "the model keeps colours");
        for k in 0..p.positions.len() {
            stored
                .entry(p.positions[k])
                .or_default()
                .push((p.normals[k], p.colors[k]));
        }
    }
    let mut c = Collect(Vec::new(), MeshHeader::default());
    tessera_mesh::read_mesh(input, &mut c).unwrap();
    assert!(c.1.attributes.normals && c.1.attributes.colors);
    let cells = (1u64 << h.quant_bits) as f64;
    let mut worst_deg = 0.0f64;
    let mut checked = 0;
    for v in &c.0 {
        let q: [u32; 3] = std::array::from_fn(|a| {
            ((v.position[a] as f64 - h.cube_origin[a]) / h.cube_size * cells)
                .round()
                .clamp(0.0, cells) as u32
        });
        let Some(candidates) = stored.get(&q) else {
            continue;
        }; // unreferenced input vertex
        let len = v.normal.iter().map(|x| x * x).sum::<f32>().sqrt();
        let n_in = v.normal.map(|x| x / len);
        let best = candidates
            .iter()
            .filter(|(_, col)| *col == v.color)
            .map(|(n, _)| {
                (n[0] * n_in[0] + n[1] * n_in[1] + n[2] * n_in[2])
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees() as f64
            })
            .fold(f64::INFINITY, f64::min);
        assert!(best.is_finite(), "input colour {:?} lost at {q:?}", v.color);
        worst_deg = worst_deg.max(best);
        checked += 1;
    }
    assert!(checked > 20_000, "checked only {checked} vertices");
    // Octahedral 2 x 8-bit normals: worst-case error ~0.6 degrees.
    assert!(worst_deg < 1.0, "a normal moved by {worst_deg} degrees");
}
