//! A small hand-built but fully valid model: roots 0 and 1, node 0 has children 2 and 3.

use std::path::{Path, PathBuf};

use bytemuck::Zeroable;
use tessera_format::*;

use super::{quant_min, terrain_patch};

pub const STEP: f64 = 0.001;

pub struct Fixture {
    pub dir: tempfile::TempDir,
    pub path: PathBuf,
    pub header: Header,
    pub nodes: Vec<NodeRecord>,
    pub patches: Vec<PatchData>,
    pub spooled: Vec<SpooledPatch>,
    pub spool: PatchSpool,
}

fn tight_sphere(p: &PatchData) -> [f32; 4] {
    let mut lo = [f64::MAX; 3];
    let mut hi = [f64::MIN; 3];
    for q in &p.positions {
        for k in 0..3 {
            lo[k] = lo[k].min(q[k] as f64 * STEP);
            hi[k] = hi[k].max(q[k] as f64 * STEP);
        }
    }
    let c: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
    let r = p
        .positions
        .iter()
        .map(|q| {
            (0..3)
                .map(|k| (q[k] as f64 * STEP - c[k]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max);
    [
        c[0] as f32,
        c[1] as f32,
        c[2] as f32,
        (r * 1.0001 + 1e-6) as f32,
    ]
}

fn enclose(outer: [f32; 4], inner: [f32; 4]) -> [f32; 4] {
    let d = (0..3)
        .map(|k| (outer[k] as f64 - inner[k] as f64).powi(2))
        .sum::<f64>()
        .sqrt();
    let r = (outer[3] as f64).max(d + inner[3] as f64 + 1e-4);
    [outer[0], outer[1], outer[2], r as f32]
}

pub fn patches() -> Vec<PatchData> {
    let mut v = Vec::new();
    for (i, morph) in [false, false, true, true].into_iter().enumerate() {
        v.push(terrain_patch(4 + i, 20.0, morph, 11 + i as u64));
    }
    v
}

impl Fixture {
    pub fn new() -> Fixture {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.tsr");
        let patches = patches();
        let spool = PatchSpool::new(dir.path()).unwrap();
        let mut nodes = Vec::new();
        let mut spooled = Vec::new();
        // Append out of order, as the builder may.
        let mut order: Vec<usize> = (0..patches.len()).rev().collect();
        order.rotate_left(1);
        let mut tmp = vec![SpooledPatch::default(); patches.len()];
        for &i in &order {
            let q = quant_min(&patches[i]);
            tmp[i] = spool
                .append(&encode_patch(&patches[i], ATTR_NORMALS, q))
                .unwrap();
        }
        for (i, p) in patches.iter().enumerate() {
            let mut n = NodeRecord::zeroed();
            n.tet_path = 0;
            n.vertex_count = p.vertex_count() as u32;
            n.triangle_count = p.triangle_count() as u32;
            n.children = [NO_NODE; 2];
            n.parent = NO_NODE;
            n.diamond = i as u32; // numbered by first appearance (docs/format.md)
            n.root = if i == 1 { 1 } else { 0 };
            n.flags = NODE_FLAG_LEAF;
            n.tight_sphere = tight_sphere(p);
            n.saturated_sphere = n.tight_sphere;
            n.normal_cone = [0.0, 0.0, 0.0, -1.0];
            n.quant_min = quant_min(p);
            nodes.push(n);
        }
        nodes[0].children = [2, 3];
        nodes[0].flags = 0;
        nodes[0].error = 0.5;
        for c in [2, 3] {
            nodes[c].parent = 0;
            nodes[c].level = 1;
            nodes[c].tet_path = c as u64 - 2;
            nodes[0].saturated_sphere =
                enclose(nodes[0].saturated_sphere, nodes[c].saturated_sphere);
        }
        spooled.extend_from_slice(&tmp);
        let mut header = Header::zeroed();
        header.attributes = ATTR_NORMALS;
        header.quant_bits = 16;
        header.cube_origin = [1000.0, 2000.0, -5.0];
        header.cube_size = 65536.0 * STEP;
        header.bounding_sphere = [1032.0, 2032.0, 27.0, 56.0];
        header.root_count = 2;
        header.level_count = 2;
        header.max_error = 0.5;
        header.input_triangles = 1000;
        header.leaf_triangles_max = 8000;
        header.node_triangles_target = 4000;
        let f = Fixture {
            dir,
            path,
            header,
            nodes,
            patches,
            spooled,
            spool,
        };
        f.write(&f.nodes);
        f
    }

    pub fn write(&self, nodes: &[NodeRecord]) {
        write_model(&self.path, &self.header, nodes, &self.spooled, &self.spool).unwrap();
    }

    pub fn bytes(&self) -> Vec<u8> {
        std::fs::read(&self.path).unwrap()
    }

    /// Writes `bytes` to a new file in the fixture directory and opens it.
    pub fn open_bytes(&self, name: &str, bytes: &[u8]) -> Result<Model, FormatError> {
        let p = self.dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        Model::open(&p)
    }

    pub fn files_in_dir(&self) -> Vec<String> {
        list(self.dir.path())
    }
}

pub fn list(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}
