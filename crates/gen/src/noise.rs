//! Deterministic hash-based value noise.
//!
//! Everything here is plain IEEE-754 `f64` arithmetic (`+ - * /`, `floor`, comparisons),
//! whose results are exactly specified, plus integer hashing: no `sin`, `exp`, `pow` or any
//! other libm function whose last bit may differ between platforms. Rust never contracts
//! `a * b + c` into a fused multiply-add on its own, so the same inputs give the same bits
//! on every machine.

/// SplitMix64 finaliser: a strong 64-bit mixing function.
#[inline]
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Derive an independent stream key from a seed and a purpose tag.
#[inline]
pub(crate) fn derive_key(seed: u64, tag: u64) -> u64 {
    mix64(seed ^ mix64(tag.wrapping_add(0x9e37_79b9_7f4a_7c15)))
}

/// A uniform value in `[0, 1)` from a hash.
#[inline]
pub(crate) fn unit_from_hash(h: u64) -> f64 {
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

const KX: u64 = 0x8cb9_2ba7_2f3d_8dd7;
const KY: u64 = 0xd6e8_feb8_6659_fd93;
const KZ: u64 = 0xa076_1d64_78bd_642f;

/// A value in `[-1, 1)` from a lattice hash (the top 53 bits, converted exactly).
///
/// One xor-shift-multiply round suffices: the inputs are already products of the lattice
/// coordinates with large odd constants, and only the well-mixed top bits are used.
#[inline]
fn lattice_value(h: u64) -> f64 {
    let h = (h ^ (h >> 32)).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    let h = h ^ (h >> 29);
    // Below 2^53, so the signed conversion (one instruction) is exact.
    ((h >> 11) as i64) as f64 * (2.0 / (1u64 << 53) as f64) - 1.0
}

/// The value attached to the integer lattice point `(x, y, z)`.
#[cfg(test)]
fn lattice3(key: u64, x: i64, y: i64, z: i64) -> f64 {
    lattice_value(
        key ^ (x as u64).wrapping_mul(KX)
            ^ (y as u64).wrapping_mul(KY)
            ^ (z as u64).wrapping_mul(KZ),
    )
}

/// `floor(x)` as an integer and the fraction `x - floor(x)`, exact for |x| < 2^62 (no libm
/// call: `f64::floor` is a function call on baseline x86-64).
#[inline]
pub(crate) fn split(x: f64) -> (i64, f64) {
    let t = x as i64; // truncates towards zero
    let i = if (t as f64) > x { t - 1 } else { t };
    (i, x - i as f64)
}

/// Cubic smoothstep `3t^2 - 2t^3` on `[0, 1]`.
#[inline]
pub(crate) fn smoothstep(t: f64) -> f64 {
    t * t * (3.0 - 2.0 * t)
}

#[inline]
fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

/// One axis of a lattice cell around coordinate `p`: the hashes of the lattice planes
/// below and above it (`k`: the axis's multiplier, XORed into a corner's key) and the
/// smoothstep weight between them.
#[inline]
fn axis(p: f64, k: u64) -> (u64, u64, f64) {
    let (i, f) = split(p);
    let h0 = (i as u64).wrapping_mul(k);
    let h1 = (i as u64).wrapping_add(1).wrapping_mul(k);
    (h0, h1, smoothstep(f))
}

/// 3D value noise in `[-1, 1]`: random values on the integer lattice, interpolated with
/// smoothstep weights (C1-continuous).
#[inline]
pub(crate) fn value3(key: u64, p: [f64; 3]) -> f64 {
    let (hx0, hx1, tx) = axis(p[0], KX);
    let (hy0, hy1, ty) = axis(p[1], KY);
    let (hz0, hz1, tz) = axis(p[2], KZ);
    let c000 = lattice_value(key ^ hx0 ^ hy0 ^ hz0);
    let c100 = lattice_value(key ^ hx1 ^ hy0 ^ hz0);
    let c010 = lattice_value(key ^ hx0 ^ hy1 ^ hz0);
    let c110 = lattice_value(key ^ hx1 ^ hy1 ^ hz0);
    let c001 = lattice_value(key ^ hx0 ^ hy0 ^ hz1);
    let c101 = lattice_value(key ^ hx1 ^ hy0 ^ hz1);
    let c011 = lattice_value(key ^ hx0 ^ hy1 ^ hz1);
    let c111 = lattice_value(key ^ hx1 ^ hy1 ^ hz1);
    let x00 = lerp(c000, c100, tx);
    let x10 = lerp(c010, c110, tx);
    let x01 = lerp(c001, c101, tx);
    let x11 = lerp(c011, c111, tx);
    lerp(lerp(x00, x10, ty), lerp(x01, x11, ty), tz)
}

/// 2D value noise in `[-1, 1]` (as [`value3`] on the plane `z = 0`'s lattice, with four
/// corners instead of eight: half the cost, for per-texel work).
#[inline]
pub(crate) fn value2(key: u64, p: [f64; 2]) -> f64 {
    let (hx0, hx1, tx) = axis(p[0], KX);
    let (hy0, hy1, ty) = axis(p[1], KY);
    let c00 = lattice_value(key ^ hx0 ^ hy0);
    let c10 = lattice_value(key ^ hx1 ^ hy0);
    let c01 = lattice_value(key ^ hx0 ^ hy1);
    let c11 = lattice_value(key ^ hx1 ^ hy1);
    lerp(lerp(c00, c10, tx), lerp(c01, c11, tx), ty)
}

/// Fractional Brownian motion: a sum of value-noise octaves, each at twice the frequency
/// and half the amplitude of the previous one, normalised to `[-1, 1]`.
#[derive(Clone, Debug)]
pub(crate) struct Fbm {
    octaves: Vec<Octave>,
    norm: f64,
}

#[derive(Clone, Copy, Debug)]
struct Octave {
    key: u64,
    frequency: f64,
    amplitude: f64,
    offset: [f64; 3],
}

impl Fbm {
    /// `octaves` octaves starting at `base_frequency` (lattice cells per unit length).
    pub(crate) fn new(seed: u64, tag: u64, octaves: u32, base_frequency: f64) -> Fbm {
        let mut list = Vec::with_capacity(octaves as usize);
        let mut frequency = base_frequency;
        let mut amplitude = 1.0;
        let mut norm = 0.0;
        for k in 0..u64::from(octaves.max(1)) {
            let key = derive_key(seed, tag.wrapping_mul(1000).wrapping_add(k));
            // A per-octave shift so the octaves' lattices do not line up at the origin.
            let offset = [
                unit_from_hash(mix64(key ^ 1)) * 1000.0,
                unit_from_hash(mix64(key ^ 2)) * 1000.0,
                unit_from_hash(mix64(key ^ 3)) * 1000.0,
            ];
            list.push(Octave {
                key,
                frequency,
                amplitude,
                offset,
            });
            norm += amplitude;
            frequency *= 2.0;
            amplitude *= 0.5;
        }
        Fbm {
            octaves: list,
            norm: 1.0 / norm,
        }
    }

    /// The sum over the octaves of `each(octave, q)`, `q` being `p` (2 or 3 coordinates)
    /// at the octave's frequency and offset, times the normalisation: the one loop of
    /// every sampler, so they all see the same lattice.
    #[inline]
    fn octaves_at<const N: usize>(
        &self,
        p: [f64; N],
        each: impl Fn(&Octave, [f64; N]) -> f64,
    ) -> f64 {
        let mut sum = 0.0;
        for o in &self.octaves {
            let q = std::array::from_fn(|i| p[i] * o.frequency + o.offset[i]);
            sum += each(o, q);
        }
        sum * self.norm
    }

    /// The noise value in `[-1, 1]` at `p`.
    #[inline]
    pub(crate) fn sample(&self, p: [f64; 3]) -> f64 {
        self.octaves_at(p, |o, q| o.amplitude * value3(o.key, q))
    }

    /// The 2D noise value in `[-1, 1]` at `p` ([`value2`] octaves).
    #[inline]
    pub(crate) fn sample2(&self, p: [f64; 2]) -> f64 {
        self.octaves_at(p, |o, q| o.amplitude * value2(o.key, q))
    }

    /// Ridged variant in `[0, 1]`: each octave contributes `(1 - |n|)^2`, sharp crests where
    /// the noise crosses zero.
    #[inline]
    pub(crate) fn ridged(&self, p: [f64; 3]) -> f64 {
        self.octaves_at(p, |o, q| {
            let r = 1.0 - value3(o.key, q).abs();
            o.amplitude * r * r
        })
    }
}

/// Piecewise-linear colour ramp: `stops` sorted by position, `t` clamped to their range.
pub(crate) fn ramp(stops: &[(f64, [f64; 3])], t: f64) -> [u8; 4] {
    let rgb = if t <= stops[0].0 {
        stops[0].1
    } else if t >= stops[stops.len() - 1].0 {
        stops[stops.len() - 1].1
    } else {
        let mut out = stops[0].1;
        for w in stops.windows(2) {
            let (t0, c0) = w[0];
            let (t1, c1) = w[1];
            if t >= t0 && t <= t1 {
                let s = if t1 > t0 { (t - t0) / (t1 - t0) } else { 0.0 };
                out = [
                    lerp(c0[0], c1[0], s),
                    lerp(c0[1], c1[1], s),
                    lerp(c0[2], c1[2], s),
                ];
                break;
            }
        }
        out
    };
    let q = |c: f64| (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    [q(rgb[0]), q(rgb[1]), q(rgb[2]), 255]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_noise_is_bounded_and_continuous() {
        let key = derive_key(7, 1);
        let mut prev = value3(key, [0.0, 0.0, 0.0]);
        for i in 1..10_000 {
            let t = i as f64 * 0.001;
            let v = value3(key, [t, 0.5 * t, -0.25 * t]);
            assert!((-1.0..=1.0).contains(&v));
            assert!((v - prev).abs() < 0.01, "jump at {t}: {prev} -> {v}");
            prev = v;
        }
    }

    #[test]
    fn value_noise_hits_lattice_values() {
        let key = derive_key(3, 9);
        assert_eq!(value3(key, [2.0, -3.0, 5.0]), lattice3(key, 2, -3, 5));
    }

    #[test]
    fn fbm_is_bounded_and_seed_dependent() {
        let a = Fbm::new(1, 0, 6, 2.0);
        let b = Fbm::new(2, 0, 6, 2.0);
        let mut differ = false;
        for i in 0..1000 {
            let p = [i as f64 * 0.013, (i as f64 * 0.007).fract(), -0.3];
            let va = a.sample(p);
            assert!((-1.0..=1.0).contains(&va));
            assert!((0.0..=1.0).contains(&a.ridged(p)));
            differ |= va != b.sample(p);
        }
        assert!(differ);
    }

    #[test]
    fn lattice_values_look_uniform_and_independent() {
        let key = derive_key(1, 1);
        let n = 40i64;
        let v = |x, y, z| lattice3(key, x - n / 2, y - n / 2, z - n / 2);
        let (mut sum, mut sq) = (0.0, 0.0);
        let mut corr = [0.0f64; 3];
        let mut count = 0.0;
        for x in 0..n {
            for y in 0..n {
                for z in 0..n {
                    let a = v(x, y, z);
                    sum += a;
                    sq += a * a;
                    corr[0] += a * v(x + 1, y, z);
                    corr[1] += a * v(x, y + 1, z);
                    corr[2] += a * v(x + 1, y + 1, z + 1);
                    count += 1.0;
                }
            }
        }
        assert!((sum / count).abs() < 0.02, "mean {}", sum / count);
        assert!(
            (sq / count - 1.0 / 3.0).abs() < 0.02,
            "variance {}",
            sq / count
        );
        for c in corr {
            assert!(
                (c / count).abs() < 0.02,
                "neighbour covariance {}",
                c / count
            );
        }
    }

    #[test]
    fn value2_is_bounded_continuous_and_hits_lattice_values() {
        let key = derive_key(5, 2);
        let mut prev = value2(key, [0.0, 0.0]);
        for i in 1..10_000 {
            let t = i as f64 * 0.001;
            let v = value2(key, [t, -0.5 * t]);
            assert!((-1.0..=1.0).contains(&v));
            assert!((v - prev).abs() < 0.01, "jump at {t}: {prev} -> {v}");
            prev = v;
        }
        assert_eq!(value2(key, [2.0, -3.0]), lattice3(key, 2, -3, 0));
        let f = Fbm::new(1, 3, 5, 2.0);
        for i in 0..1000 {
            let v = f.sample2([i as f64 * 0.013, i as f64 * -0.029]);
            assert!((-1.0..=1.0).contains(&v));
        }
    }

    #[test]
    fn split_is_floor() {
        for x in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.75,
            -2.75,
            1e12 + 0.5,
            -1e12 - 0.5,
            -1e-300,
        ] {
            let (i, f) = split(x);
            assert_eq!(i as f64, x.floor(), "{x}");
            assert_eq!(f, x - x.floor(), "{x}");
        }
    }

    #[test]
    fn ramp_endpoints() {
        let stops = [(0.0, [0.0, 0.0, 0.0]), (1.0, [1.0, 1.0, 1.0])];
        assert_eq!(ramp(&stops, -1.0), [0, 0, 0, 255]);
        assert_eq!(ramp(&stops, 2.0), [255, 255, 255, 255]);
        assert_eq!(ramp(&stops, 0.5), [128, 128, 128, 255]);
    }
}
