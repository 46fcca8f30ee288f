//! The diamond hierarchy as a 3D Tiles tree (`docs/tiles.md` has the argument).
//!
//! One tile per node with a parent, one root tile for all the roots. A tile's content is
//! its node's patch, its `geometricError` the node's saturated error (scaled by
//! [`LEVEL_ERROR_SCALE`] per level, so that it strictly decreases down the tree) and its
//! bounding sphere the node's saturated sphere; `refine` is `REPLACE` (inherited from the root).
//! A 3D Tiles client refines a tile when `geometricError * height_px / (2 d tan(fov/2))`
//! exceeds its maximum screen-space error, `d` the distance from the eye to the bounding
//! volume: Tessera's own test (`tessera_select::needs_refinement`) with the tolerance
//! renamed. Mates of a diamond carry bit-identical errors and spheres, so they decide
//! alike whatever client rounds how; saturated errors never grow toward the leaves and
//! saturated spheres are nested, so no tile refines unless its parent did. Together:
//! every cut a client picks is a top-down saturated cut, which the builder makes
//! crack-free.
//!
//! The roots: the six root tetrahedra share the cube's diagonal as their refinement
//! edge, so the builder gives them one diamond (one error, one sphere); the root tile
//! draws them together and refines them together. Should a model's roots differ, the
//! root tile takes the largest root error and the sphere around all root spheres, which
//! keeps both properties (one decision for all roots; no child above its parent).

use tessera_format::{Header, NodeRecord, NO_NODE};

/// Each level down the tree scales `geometricError` by this (1 - 2^-20), so that a
/// child's error is strictly below its parent's even where their saturated errors are
/// equal (saturation makes them equal often). 3DTilesRendererJS (0.5.3,
/// `traverseFunctions.js`, its issue #1304) refines a tile *unconditionally* when its
/// error is not below its nearest ancestor's, whatever the screen-space error: with
/// equal errors it refined some mates and not others, and the exported 30M-triangle
/// sphere showed cracks there. Mates share their level, so they keep identical errors;
/// the change to any screen-space error is under 2^-20 x 64 levels = 6e-5 of it.
pub const LEVEL_ERROR_SCALE: f64 = 1.0 - 1.0 / 1048576.0;

/// A node's `geometricError`: its saturated error scaled by [`LEVEL_ERROR_SCALE`] once
/// per level.
pub fn tile_error(error: f32, level: u8) -> f64 {
    f64::from(error) * LEVEL_ERROR_SCALE.powi(i32::from(level))
}

/// One tile of the tree.
#[derive(Clone, Debug, PartialEq)]
pub struct Tile {
    /// The nodes whose patches are the tile's content (the roots for the root tile,
    /// else one node).
    pub nodes: Vec<u32>,
    /// `geometricError`: the saturated error of the nodes (model units), scaled by
    /// [`LEVEL_ERROR_SCALE`] per level.
    pub error: f64,
    /// `boundingVolume.sphere`: the saturated sphere, model coordinates (centre xyz,
    /// radius).
    pub sphere: [f64; 4],
    /// Indices of the child tiles in [`TileTree::tiles`].
    pub children: Vec<usize>,
    /// Triangles of the content (0: the tile has no content).
    pub triangles: u64,
}

/// The tree of a model's tiles; tile 0 is the root.
#[derive(Clone, Debug, PartialEq)]
pub struct TileTree {
    pub tiles: Vec<Tile>,
}

/// Why a node table cannot become a tile tree.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    #[error("the model has no nodes")]
    Empty,
    #[error("node {node}: {detail}")]
    Node { node: u32, detail: String },
}

/// A saturated sphere (relative to the cube origin, f32) in model coordinates.
pub fn model_sphere(h: &Header, s: [f32; 4]) -> [f64; 4] {
    [
        h.cube_origin[0] + f64::from(s[0]),
        h.cube_origin[1] + f64::from(s[1]),
        h.cube_origin[2] + f64::from(s[2]),
        f64::from(s[3]),
    ]
}

/// The smallest sphere around `a` holding `b` too (exact for equal spheres).
fn sphere_around(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let dist = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    if dist + b[3] <= a[3] {
        return a;
    }
    if dist + a[3] <= b[3] {
        return b;
    }
    let r = (dist + a[3] + b[3]) / 2.0;
    let t = (r - a[3]) / dist;
    [a[0] + d[0] * t, a[1] + d[1] * t, a[2] + d[2] * t, r]
}

impl TileTree {
    /// The tree of a node table (`header.root_count` roots first, children after their
    /// parents, as `tessera-format` checks when it reads a model).
    pub fn plan(h: &Header, nodes: &[NodeRecord]) -> Result<TileTree, PlanError> {
        let roots = (h.root_count as usize).min(nodes.len());
        if roots == 0 {
            return Err(PlanError::Empty);
        }
        let first = &nodes[0];
        let mut root = Tile {
            nodes: (0..roots as u32).collect(),
            error: tile_error(first.error, first.level),
            sphere: model_sphere(h, first.saturated_sphere),
            children: Vec::new(),
            triangles: 0,
        };
        for n in &nodes[..roots] {
            root.error = root.error.max(tile_error(n.error, n.level));
            root.sphere = sphere_around(root.sphere, model_sphere(h, n.saturated_sphere));
            root.triangles += u64::from(n.triangle_count);
        }
        let mut tiles = vec![root];
        // (tile index, node) pairs still to expand; the root tile's children are every
        // root's children.
        let mut stack: Vec<(usize, u32)> = (0..roots as u32).rev().map(|r| (0, r)).collect();
        while let Some((tile, node)) = stack.pop() {
            let n = &nodes[node as usize];
            for &c in &n.children {
                if c == NO_NODE {
                    continue;
                }
                if c as usize >= nodes.len() || c <= node {
                    return Err(PlanError::Node {
                        node,
                        detail: format!("child {c} is out of order or out of range"),
                    });
                }
                let cn = &nodes[c as usize];
                let t = tiles.len();
                tiles.push(Tile {
                    nodes: vec![c],
                    error: tile_error(cn.error, cn.level),
                    sphere: model_sphere(h, cn.saturated_sphere),
                    children: Vec::new(),
                    triangles: u64::from(cn.triangle_count),
                });
                tiles[tile].children.push(t);
                stack.push((t, c));
            }
        }
        Ok(TileTree { tiles })
    }

    /// The content URI of tile `t` (relative to `tileset.json`), if it has content.
    pub fn content_uri(&self, t: usize) -> Option<String> {
        let tile = &self.tiles[t];
        (tile.triangles > 0).then(|| {
            if t == 0 {
                "tiles/root.glb".to_string()
            } else {
                format!("tiles/{}.glb", tile.nodes[0])
            }
        })
    }

    /// Writes the `tileset.json` document to `w`: 3D Tiles 1.1, `REPLACE`, spheres and
    /// errors as [`Tile`] says, in tileset coordinates (model coordinates minus
    /// `origin`), with `root_transform` (column-major 4x4, tileset to world) on the
    /// root. Each tile's `extras.tessera_nodes` lists the nodes of its content. Streamed
    /// tile by tile (a model of millions of nodes never holds its document in memory);
    /// the recursion is as deep as the hierarchy (at most 64 levels).
    pub fn write_tileset_json(
        &self,
        w: &mut dyn std::io::Write,
        origin: [f64; 3],
        root_transform: [f64; 16],
        generator: &str,
    ) -> std::io::Result<()> {
        let js = |v: serde_json::Value| serde_json::to_string(&v).map_err(std::io::Error::other);
        write!(
            w,
            "{{\"asset\":{},\"geometricError\":{},\"root\":",
            js(serde_json::json!({ "version": "1.1", "generator": generator }))?,
            js(serde_json::json!(self.tiles[0].error))?
        )?;
        self.write_tile(w, 0, origin, &root_transform, &js)?;
        writeln!(w, "}}")
    }

    fn write_tile(
        &self,
        w: &mut dyn std::io::Write,
        t: usize,
        origin: [f64; 3],
        root_transform: &[f64; 16],
        js: &dyn Fn(serde_json::Value) -> std::io::Result<String>,
    ) -> std::io::Result<()> {
        use serde_json::json;
        let tile = &self.tiles[t];
        let s = tile.sphere;
        let sphere = [s[0] - origin[0], s[1] - origin[1], s[2] - origin[2], s[3]];
        write!(
            w,
            "{{\"boundingVolume\":{{\"sphere\":{}}},\"geometricError\":{}",
            js(json!(sphere))?,
            js(json!(tile.error))?
        )?;
        if t == 0 {
            write!(
                w,
                ",\"refine\":\"REPLACE\",\"transform\":{}",
                js(json!(root_transform.to_vec()))?
            )?;
        }
        if let Some(uri) = self.content_uri(t) {
            write!(w, ",\"content\":{{\"uri\":{}}}", js(json!(uri))?)?;
        }
        write!(
            w,
            ",\"extras\":{{\"tessera_nodes\":{}}}",
            js(json!(tile.nodes))?
        )?;
        if !tile.children.is_empty() {
            write!(w, ",\"children\":[")?;
            for (k, &c) in tile.children.iter().enumerate() {
                if k > 0 {
                    write!(w, ",")?;
                }
                self.write_tile(w, c, origin, root_transform, js)?;
            }
            write!(w, "]")?;
        }
        write!(w, "}}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A node record with the fields the plan reads.
    fn node(children: [u32; 2], error: f32, sphere: [f32; 4], tris: u32) -> NodeRecord {
        NodeRecord {
            children,
            error,
            saturated_sphere: sphere,
            tight_sphere: sphere,
            triangle_count: tris,
            parent: NO_NODE,
            ..NodeRecord::default()
        }
    }

    fn header(roots: u32) -> Header {
        let mut h: Header = bytemuck::Zeroable::zeroed();
        h.root_count = roots;
        h.cube_origin = [10.0, 20.0, 30.0];
        h
    }

    #[test]
    fn roots_share_a_tile_and_children_follow_their_nodes() {
        // Why: the root tile must carry every root (they refine as one diamond) and every
        // other node must appear once, under its parent's tile, with its own error and
        // sphere moved into model coordinates.
        const N: u32 = NO_NODE;
        let s = |x: f32, r: f32| [x, 0.0, 0.0, r];
        let nodes = vec![
            node([2, 3], 4.0, s(4.0, 5.0), 100),
            node([4, N], 4.0, s(4.0, 5.0), 50),
            node([N, N], 0.0, s(2.0, 2.0), 10),
            node([N, N], 0.0, s(6.0, 2.0), 0),
            node([N, N], 0.0, s(5.0, 1.0), 20),
        ];
        let t = TileTree::plan(&header(2), &nodes).unwrap();
        assert_eq!(t.tiles.len(), 4);
        assert_eq!(t.tiles[0].nodes, [0, 1]);
        assert_eq!(t.tiles[0].error, 4.0);
        assert_eq!(t.tiles[0].sphere, [14.0, 20.0, 30.0, 5.0]);
        assert_eq!(t.tiles[0].triangles, 150);
        let kids: Vec<u32> = t.tiles[0]
            .children
            .iter()
            .map(|&c| t.tiles[c].nodes[0])
            .collect();
        assert_eq!(kids, [2, 3, 4]);
        assert_eq!(t.content_uri(0).as_deref(), Some("tiles/root.glb"));
        // Node 3 holds no triangles: a tile without content.
        let empty = t.tiles.iter().position(|x| x.nodes == [3]).unwrap();
        assert_eq!(t.content_uri(empty), None);
        let mut bytes = Vec::new();
        t.write_tileset_json(&mut bytes, [14.0, 20.0, 30.0], IDENTITY, "test")
            .unwrap();
        let j: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
        assert_eq!(j["asset"]["version"], "1.1");
        assert_eq!(j["root"]["refine"], "REPLACE");
        assert_eq!(
            j["root"]["boundingVolume"]["sphere"],
            serde_json::json!([0.0, 0.0, 0.0, 5.0])
        );
        assert_eq!(j["root"]["children"].as_array().unwrap().len(), 3);
        assert!(j["root"]["children"][1].get("content").is_none());
        assert_eq!(
            j["root"]["children"][2]["extras"]["tessera_nodes"],
            serde_json::json!([4])
        );
    }

    #[test]
    fn differing_roots_get_the_largest_error_and_a_sphere_around_all() {
        // Why: the root tile's decision stands for every root, so it must not refine
        // later than any root would alone (largest error, sphere holding each).
        const N: u32 = NO_NODE;
        let nodes = vec![
            node([N, N], 1.0, [0.0, 0.0, 0.0, 1.0], 1),
            node([N, N], 3.0, [4.0, 0.0, 0.0, 1.0], 1),
        ];
        let t = TileTree::plan(&header(2), &nodes).unwrap();
        assert_eq!(t.tiles[0].error, 3.0);
        assert_eq!(t.tiles[0].sphere, [12.0, 20.0, 30.0, 3.0]);
    }

    #[test]
    fn errors_strictly_decrease_down_the_tree_and_mates_keep_theirs() {
        // Why: 3DTilesRendererJS refines a tile unconditionally when its error is not
        // below its parent's; saturation often gives a child its parent's error.
        const N: u32 = NO_NODE;
        let mut nodes = vec![
            node([1, 2], 2.0, [0.0, 0.0, 0.0, 4.0], 1),
            node([N, N], 2.0, [-1.0, 0.0, 0.0, 2.0], 1),
            node([N, N], 2.0, [1.0, 0.0, 0.0, 2.0], 1),
        ];
        nodes[1].level = 1;
        nodes[2].level = 1;
        let t = TileTree::plan(&header(1), &nodes).unwrap();
        let (root, a, b) = (t.tiles[0].error, t.tiles[1].error, t.tiles[2].error);
        assert!(a < root && a > root * 0.999_999, "{a} vs {root}");
        assert_eq!(a, b, "mates (one level, one saturated error) stay equal");
        assert_eq!(tile_error(0.0, 7), 0.0);
        // Over the deepest hierarchy the scale stays within 1e-4 of the error.
        assert!(tile_error(1.0, 64) > 0.9999);
    }

    #[test]
    fn a_child_before_its_parent_is_an_error_not_a_loop() {
        let nodes = vec![node([0, NO_NODE], 1.0, [0.0; 4], 1)];
        assert!(TileTree::plan(&header(1), &nodes).is_err());
        assert!(matches!(
            TileTree::plan(&header(0), &nodes),
            Err(PlanError::Empty)
        ));
    }

    const IDENTITY: [f64; 16] = [
        1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
    ];
}
