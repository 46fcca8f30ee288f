//! The quantisation grid every stored position lies on.
//!
//! Why it exists: the builder quantises input positions onto this grid, the header records
//! it (`cube_origin`, `cube_size`, `quant_bits`), and every reader turns grid points back
//! into model coordinates. One type keeps both directions of the formula in one place:
//! a grid point `q` is the model position `origin + q * size / 2^bits`.

use crate::records::Header;

/// `2^bits` cells along each edge of a cube of edge `size` whose min corner is `origin`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    /// Min corner of the bounding cube, model units.
    pub origin: [f64; 3],
    /// Edge length of the bounding cube, model units.
    pub size: f64,
    /// Cells per edge as a power of two (the format allows 1..=32).
    pub bits: u32,
}

impl Grid {
    /// The cube around a bounding box: min corner at the box's min, edge = longest side
    /// (1 for an empty, flat-to-a-point or non-finite box).
    pub fn new(min: [f64; 3], max: [f64; 3], bits: u32) -> Grid {
        let ext = (0..3).map(|i| max[i] - min[i]).fold(0.0, f64::max);
        let size = if ext > 0.0 && ext.is_finite() {
            ext
        } else {
            1.0
        };
        Grid {
            origin: min,
            size,
            bits,
        }
    }

    /// The grid a model's header records.
    pub fn of_header(h: &Header) -> Grid {
        Grid {
            origin: h.cube_origin,
            size: h.cube_size,
            bits: h.quant_bits,
        }
    }

    /// Cells along an edge, `2^bits` (exact in `f64`; `bits` is capped at 63 so a bad
    /// value cannot overflow the shift).
    fn cells(&self) -> f64 {
        (1u64 << self.bits.min(63)) as f64
    }

    /// Model units per grid step: `size / 2^bits`.
    pub fn step(&self) -> f64 {
        self.size / self.cells()
    }

    /// The largest distance between a point in the cube and its grid point: half a cell's
    /// diagonal, `step * sqrt(3) / 2`.
    pub fn max_error(&self) -> f64 {
        self.step() * 3f64.sqrt() / 2.0
    }

    /// Nearest grid point of a model position, clamped into `[0, 2^bits]`.
    pub fn quantize(&self, p: [f32; 3]) -> [u32; 3] {
        let n = self.cells();
        let cells_per_unit = n / self.size;
        std::array::from_fn(|i| {
            let t = (p[i] as f64 - self.origin[i]) * cells_per_unit;
            // Round half up by truncation after clamping (non-negative, so truncation is
            // floor): `f64::round` is a libm call on baseline x86-64, and this runs for
            // every input vertex.
            (t.clamp(0.0, n) + 0.5) as u32
        })
    }

    /// Model position of grid point `q`: `origin + q * step()`.
    pub fn position(&self, q: [u32; 3]) -> [f64; 3] {
        let s = self.step();
        std::array::from_fn(|i| self.origin[i] + q[i] as f64 * s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantize_clamps_and_rounds() {
        // Why: points outside the cube (rounding of the bounding box) must land on its
        // border, not wrap or saturate elsewhere; halves round up.
        let g = Grid::new([0.0; 3], [2.0, 1.0, 1.0], 4);
        assert_eq!(g.size, 2.0);
        assert_eq!(g.quantize([0.0, 0.0, 0.0]), [0, 0, 0]);
        assert_eq!(g.quantize([2.0, 1.0, 5.0]), [16, 8, 16]);
        assert_eq!(g.quantize([0.06, 0.07, -1.0]), [0, 1, 0]);
    }

    #[test]
    fn position_inverts_quantize_within_max_error() {
        // Why: the header's grid must give back every stored point to within half a cell
        // diagonal, far from the origin too (georeferenced models).
        let g = Grid {
            origin: [5.0e5, -2.0e3, 10.0],
            size: 64.0,
            bits: 10,
        };
        assert_eq!(g.step(), 1.0 / 16.0);
        for p in [[5.0e5f32, -2.0e3, 10.0], [500_031.3, -1_970.7, 73.9]] {
            let back = g.position(g.quantize(p));
            let d = (0..3)
                .map(|i| (back[i] - p[i] as f64).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(d <= g.max_error(), "{p:?} -> {back:?}");
        }
        assert_eq!(g.position([0, 0, 0]), g.origin);
    }

    #[test]
    fn degenerate_boxes_get_a_unit_cube_and_bad_bits_do_not_panic() {
        assert_eq!(Grid::new([1.0; 3], [1.0; 3], 8).size, 1.0);
        assert_eq!(Grid::new([0.0; 3], [f64::NAN; 3], 8).size, 1.0);
        let g = Grid {
            origin: [0.0; 3],
            size: 1.0,
            bits: 200,
        };
        assert!(g.step() > 0.0);
    }
}
