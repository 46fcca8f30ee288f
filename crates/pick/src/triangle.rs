//! The exact ray/triangle test over a decoded patch.
//!
//! Woop, Benthin and Wald, "Watertight Ray/Triangle Intersection" (JCGT 2013), in `f64`:
//! vertices are moved to the ray origin and sheared so the ray becomes the +Z axis;
//! the three edge functions are then 2D cross products of the sheared vertices. An edge
//! shared by two triangles gives the same value with opposite sign in both (IEEE
//! rounding is symmetric), so a ray through a shared edge or vertex hits at least one of
//! them: no ray slips through a closed mesh between its triangles.

use glam::DVec3;
use tessera_format::PatchData;

use crate::ray::LocalRay;

/// The ray's shear: `kz` the axis of the largest direction component, `kx`, `ky` the
/// others (swapped for a negative `kz` to keep the winding), `s` the shear factors.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Shear {
    k: [usize; 3],
    s: [f64; 3],
    origin: DVec3,
    dir: DVec3,
    step: f64,
}

/// The nearest hit within one patch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PatchHit {
    /// Distance along the unit direction.
    pub t: f64,
    /// Triangle index in the patch.
    pub triangle: u32,
    /// Unit geometric normal facing the ray origin.
    pub normal: DVec3,
}

impl Shear {
    /// The shear of `ray` for positions on a grid of `step` model units per cell.
    pub fn new(ray: &LocalRay, step: f64) -> Shear {
        let d = ray.dir;
        let kz = d.abs().max_position();
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        Shear {
            k: [kx, ky, kz],
            s: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]],
            origin: ray.origin,
            dir: d,
            step,
        }
    }

    /// Grid point `q` relative to the ray origin, local frame.
    #[inline]
    fn relative(&self, q: [u32; 3]) -> DVec3 {
        DVec3::new(
            f64::from(q[0]) * self.step,
            f64::from(q[1]) * self.step,
            f64::from(q[2]) * self.step,
        ) - self.origin
    }

    /// The nearest hit of the ray with a triangle of `patch` at a distance in
    /// `[0, limit)`; both faces count. `scratch` holds the sheared vertices (reused
    /// between patches). Indices out of range (never in a decoded patch) are skipped.
    pub fn nearest(
        &self,
        patch: &PatchData,
        limit: f64,
        scratch: &mut Vec<[f64; 3]>,
    ) -> Option<PatchHit> {
        let [kx, ky, kz] = self.k;
        let [sx, sy, sz] = self.s;
        scratch.clear();
        scratch.extend(patch.positions.iter().map(|&q| {
            let p = self.relative(q);
            [p[kx] - sx * p[kz], p[ky] - sy * p[kz], sz * p[kz]]
        }));
        let verts = scratch.as_slice();
        let mut best: Option<(f64, usize)> = None;
        let mut limit = limit;
        for (i, tri) in patch.indices.chunks_exact(3).enumerate() {
            let (Some(a), Some(b), Some(c)) = (
                verts.get(tri[0] as usize),
                verts.get(tri[1] as usize),
                verts.get(tri[2] as usize),
            ) else {
                continue;
            };
            let u = c[0] * b[1] - c[1] * b[0];
            let v = a[0] * c[1] - a[1] * c[0];
            let w = b[0] * a[1] - b[1] * a[0];
            if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
                continue;
            }
            let det = u + v + w;
            if det == 0.0 {
                continue;
            }
            let t = (u * a[2] + v * b[2] + w * c[2]) / det;
            if t >= 0.0 && t < limit {
                limit = t;
                best = Some((t, i));
            }
        }
        let (t, i) = best?;
        let tri = &patch.indices[3 * i..3 * i + 3];
        let p = |k: usize| self.relative(patch.positions[tri[k] as usize]);
        let (a, b, c) = (p(0), p(1), p(2));
        let mut n = (b - a).cross(c - a).normalize_or_zero();
        if n.dot(self.dir) > 0.0 {
            n = -n;
        }
        Some(PatchHit {
            t,
            triangle: i as u32,
            normal: n,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Ray;

    fn patch(positions: Vec<[u32; 3]>, indices: Vec<u32>) -> PatchData {
        PatchData {
            positions,
            indices,
            ..Default::default()
        }
    }

    fn shear(o: [f64; 3], d: [f64; 3]) -> Shear {
        Shear::new(&Ray::new(o, d).local([0.0; 3]).unwrap(), 1.0)
    }

    #[test]
    fn both_faces_hit_and_normal_faces_the_origin() {
        let p = patch(vec![[0, 0, 5], [4, 0, 5], [0, 4, 5]], vec![0, 1, 2]);
        let mut s = Vec::new();
        let h = shear([1.0, 1.0, 0.0], [0.0, 0.0, 1.0])
            .nearest(&p, f64::INFINITY, &mut s)
            .unwrap();
        assert!((h.t - 5.0).abs() < 1e-12);
        assert_eq!(h.normal, DVec3::new(0.0, 0.0, -1.0));
        let h = shear([1.0, 1.0, 9.0], [0.0, 0.0, -3.0])
            .nearest(&p, f64::INFINITY, &mut s)
            .unwrap();
        assert!((h.t - 4.0).abs() < 1e-12);
        assert_eq!(h.normal, DVec3::new(0.0, 0.0, 1.0));
        // Behind the origin, beyond the limit, beside the triangle: no hit.
        let sh = shear([1.0, 1.0, 9.0], [0.0, 0.0, 1.0]);
        assert_eq!(sh.nearest(&p, f64::INFINITY, &mut s), None);
        let sh = shear([1.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        assert_eq!(sh.nearest(&p, 4.0, &mut s), None);
        let sh = shear([3.0, 3.0, 0.0], [0.0, 0.0, 1.0]);
        assert_eq!(sh.nearest(&p, f64::INFINITY, &mut s), None);
    }

    #[test]
    fn rays_through_shared_edges_and_vertices_never_slip_through() {
        // Why: a fan of triangles around a vertex, rays aimed exactly at the shared
        // vertex and along shared edges from skew directions: the watertight test must
        // report a hit for each (Moller-Trumbore can miss these).
        let p = patch(
            vec![
                [10, 10, 10],
                [20, 10, 10],
                [10, 20, 10],
                [0, 10, 10],
                [10, 0, 10],
            ],
            vec![0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 1],
        );
        let mut s = Vec::new();
        for target in [[10.0, 10.0, 10.0], [15.0, 10.0, 10.0], [10.0, 13.0, 10.0]] {
            for o in [[-3.1, 7.7, -20.3], [31.0, -2.9, 40.1], [10.3, 9.1, 0.7]] {
                let d = [target[0] - o[0], target[1] - o[1], target[2] - o[2]];
                let h = shear(o, d).nearest(&p, f64::INFINITY, &mut s);
                assert!(h.is_some(), "ray from {o:?} to {target:?} slipped through");
            }
        }
        // The nearest of two stacked triangles wins.
        let p = patch(
            vec![
                [0, 0, 8],
                [9, 0, 8],
                [0, 9, 8],
                [0, 0, 3],
                [9, 0, 3],
                [0, 9, 3],
            ],
            vec![0, 1, 2, 3, 4, 5],
        );
        let h = shear([1.0, 1.0, 0.0], [0.0, 0.0, 1.0])
            .nearest(&p, f64::INFINITY, &mut s)
            .unwrap();
        assert_eq!((h.triangle, h.t), (1, 3.0));
    }
}
