//! The glTF node hierarchy flattened into mesh instances: every mesh a node of the shown
//! scene(s) carries, with the node's world transform (the product of its ancestors'
//! local transforms, each a matrix or translation x rotation x scale).
//!
//! Which nodes: those of the default scene; with no default scene, those of every scene
//! (a node shared by several scenes once); with no scene at all, every mesh once, in
//! place. Matrices are composed in `f64` so a long chain of transforms (or the
//! dequantising transform of `KHR_mesh_quantization`) loses nothing in `f32`.

use std::path::Path;

use ::gltf::json;

use crate::MeshError;

/// Column-major 4x4, as glTF stores matrices.
pub(crate) type Mat4 = [f64; 16];

pub(crate) const IDENTITY: Mat4 = [
    1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
];

/// Deepest node chain followed (a deeper one is surely a malformed file).
const MAX_DEPTH: usize = 4096;

/// One mesh placed in the world.
pub(crate) struct Instance {
    pub mesh: usize,
    /// The node that places it (`None`: no scenes, placed as it is).
    pub node: Option<usize>,
    pub world: Mat4,
}

pub(crate) fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut m = [0.0; 16];
    for col in 0..4 {
        for row in 0..4 {
            m[col * 4 + row] = (0..4).map(|k| a[k * 4 + row] * b[col * 4 + k]).sum();
        }
    }
    m
}

/// A node's local transform.
fn local(node: &json::scene::Node) -> Mat4 {
    if let Some(m) = node.matrix {
        return m.map(f64::from);
    }
    let t = node.translation.unwrap_or([0.0; 3]).map(f64::from);
    let s = node.scale.unwrap_or([1.0; 3]).map(f64::from);
    let [x, y, z, w] = node
        .rotation
        .map_or([0.0, 0.0, 0.0, 1.0], |r| r.0)
        .map(f64::from);
    // A rotation that is not a unit quaternion (rounded by the writer) is normalised.
    let len = (x * x + y * y + z * z + w * w).sqrt();
    let (x, y, z, w) = if len > 0.0 && len.is_finite() {
        (x / len, y / len, z / len, w / len)
    } else {
        (0.0, 0.0, 0.0, 1.0)
    };
    let r = [
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y + z * w),
        2.0 * (x * z - y * w),
        2.0 * (x * y - z * w),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z + x * w),
        2.0 * (x * z + y * w),
        2.0 * (y * z - x * w),
        1.0 - 2.0 * (x * x + y * y),
    ];
    [
        r[0] * s[0],
        r[1] * s[0],
        r[2] * s[0],
        0.0,
        r[3] * s[1],
        r[4] * s[1],
        r[5] * s[1],
        0.0,
        r[6] * s[2],
        r[7] * s[2],
        r[8] * s[2],
        0.0,
        t[0],
        t[1],
        t[2],
        1.0,
    ]
}

/// The mesh instances of the shown scene(s), in traversal order.
pub(crate) fn instances(path: &Path, root: &json::Root) -> Result<Vec<Instance>, MeshError> {
    let roots: Vec<usize> = match root.scene {
        Some(s) => {
            let scene = root.scenes.get(s.value()).ok_or_else(|| {
                MeshError::malformed(
                    path,
                    "scene",
                    format!(
                        "the default scene {} does not exist (the file has {} scenes)",
                        s.value(),
                        root.scenes.len()
                    ),
                )
            })?;
            scene.nodes.iter().map(|n| n.value()).collect()
        }
        None if !root.scenes.is_empty() => root
            .scenes
            .iter()
            .flat_map(|s| s.nodes.iter().map(|n| n.value()))
            .collect(),
        None => {
            return Ok((0..root.meshes.len())
                .map(|mesh| Instance {
                    mesh,
                    node: None,
                    world: IDENTITY,
                })
                .collect())
        }
    };
    let mut seen = vec![false; root.nodes.len()];
    let mut out = Vec::new();
    let mut stack: Vec<(usize, Mat4, usize)> = Vec::new();
    for r in roots {
        // A root shared by two scenes is shown once.
        if seen.get(r) == Some(&true) {
            continue;
        }
        stack.push((r, IDENTITY, 0));
        while let Some((n, parent, depth)) = stack.pop() {
            let node = root.nodes.get(n).ok_or_else(|| {
                MeshError::malformed(
                    path,
                    format!("node {n}"),
                    format!("does not exist (the file has {} nodes)", root.nodes.len()),
                )
            })?;
            if std::mem::replace(&mut seen[n], true) {
                return Err(MeshError::malformed(
                    path,
                    format!("node {n}"),
                    "is reached twice: it has two parents or is its own ancestor (the node hierarchy must be a set of trees)",
                ));
            }
            if depth > MAX_DEPTH {
                return Err(MeshError::malformed(
                    path,
                    format!("node {n}"),
                    format!("lies more than {MAX_DEPTH} levels deep"),
                ));
            }
            let world = mul(&parent, &local(node));
            if let Some(m) = node.mesh {
                out.push(Instance {
                    mesh: m.value(),
                    node: Some(n),
                    world,
                });
            }
            // Children pushed in reverse, so they are visited in order.
            for c in node.children.iter().flatten().rev() {
                stack.push((c.value(), world, depth + 1));
            }
        }
    }
    Ok(out)
}

/// The linear part of `m` applied to normals: the cofactor matrix (the inverse
/// transpose times the determinant, defined even for a singular matrix), signed so it
/// keeps the normals' side; and whether `m` mirrors (negative determinant), which flips
/// the winding of triangles.
pub(crate) fn normal_matrix(m: &Mat4) -> ([f64; 9], bool) {
    let a = |r: usize, c: usize| m[c * 4 + r];
    let cof = |r: usize, c: usize| {
        let (r1, r2) = ((r + 1) % 3, (r + 2) % 3);
        let (c1, c2) = ((c + 1) % 3, (c + 2) % 3);
        a(r1, c1) * a(r2, c2) - a(r1, c2) * a(r2, c1)
    };
    let det = a(0, 0) * cof(0, 0) + a(0, 1) * cof(0, 1) + a(0, 2) * cof(0, 2);
    let sign = if det < 0.0 { -1.0 } else { 1.0 };
    // Row-major 3x3 of the cofactors: n' = C n.
    let mut n = [0.0; 9];
    for r in 0..3 {
        for c in 0..3 {
            n[r * 3 + c] = sign * cof(r, c);
        }
    }
    (n, det < 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn apply3(n: &[f64; 9], v: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|r| (0..3).map(|c| n[r * 3 + c] * v[c]).sum())
    }

    #[test]
    fn trs_is_translation_times_rotation_times_scale() {
        let node = json::scene::Node {
            translation: Some([1.0, 2.0, 3.0]),
            // 90 degrees about z.
            rotation: Some(json::scene::UnitQuaternion([
                0.0,
                0.0,
                std::f32::consts::FRAC_1_SQRT_2,
                std::f32::consts::FRAC_1_SQRT_2,
            ])),
            scale: Some([2.0, 2.0, 2.0]),
            ..Default::default()
        };
        let m = local(&node);
        // (1, 0, 0) scaled to (2, 0, 0), rotated to (0, 2, 0), moved to (1, 4, 3).
        let p = [m[0] + m[12], m[1] + m[13], m[2] + m[14]];
        assert!(
            (p[0] - 1.0).abs() < 1e-6 && (p[1] - 4.0).abs() < 1e-6 && (p[2] - 3.0).abs() < 1e-6,
            "{p:?}"
        );
    }

    #[test]
    fn normals_follow_the_inverse_transpose() {
        // Scale x by 4: a normal of the plane x + y = 1, (1, 1, 0), leans toward y.
        let mut m = IDENTITY;
        m[0] = 4.0;
        let (n, mirrored) = normal_matrix(&m);
        assert!(!mirrored);
        let v = apply3(&n, [1.0, 1.0, 0.0]);
        assert!(v[1] > v[0] * 3.9, "{v:?}");
        // A mirror keeps normals pointing out of the mirrored surface.
        let mut m = IDENTITY;
        m[0] = -1.0;
        let (n, mirrored) = normal_matrix(&m);
        assert!(mirrored);
        assert_eq!(apply3(&n, [1.0, 0.0, 0.0]), [-1.0, 0.0, 0.0]);
    }
}
