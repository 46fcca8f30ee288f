//! A small fast hasher for the welding and edge-counting maps.
//!
//! Why it exists: those maps hold millions of small integer keys that never come from an
//! adversary, so SipHash's DoS resistance buys nothing and costs several times the
//! hashing time. This is the multiply-rotate hash of rustc's FxHasher (a few lines, not
//! worth a dependency).

use std::hash::{BuildHasherDefault, Hasher};

/// rustc's Fx constant (from the golden ratio, odd, good bit mixing under multiply).
const SEED: u64 = 0x51_7c_c1_b7_27_22_0a_95;

#[derive(Clone, Copy, Default)]
pub(crate) struct FxHasher {
    hash: u64,
}

impl FxHasher {
    #[inline]
    fn add(&mut self, word: u64) {
        self.hash = (self.hash.rotate_left(5) ^ word).wrapping_mul(SEED);
    }
}

impl Hasher for FxHasher {
    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        let mut chunks = bytes.chunks_exact(8);
        for c in &mut chunks {
            self.add(u64::from_le_bytes([
                c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7],
            ]));
        }
        let rest = chunks.remainder();
        if !rest.is_empty() {
            let mut buf = [0u8; 8];
            buf[..rest.len()].copy_from_slice(rest);
            self.add(u64::from_le_bytes(buf));
        }
    }

    #[inline]
    fn write_u8(&mut self, i: u8) {
        self.add(u64::from(i));
    }

    #[inline]
    fn write_u32(&mut self, i: u32) {
        self.add(u64::from(i));
    }

    #[inline]
    fn write_u64(&mut self, i: u64) {
        self.add(i);
    }

    #[inline]
    fn write_usize(&mut self, i: usize) {
        self.add(i as u64);
    }

    #[inline]
    fn finish(&self) -> u64 {
        self.hash
    }
}

pub(crate) type FxBuildHasher = BuildHasherDefault<FxHasher>;

#[cfg(test)]
mod tests {
    use super::*;
    use std::hash::BuildHasher;

    #[test]
    fn distinct_small_keys_hash_apart() {
        // Not a quality test, just a guard that the hasher is wired and mixes its input.
        let b = FxBuildHasher::default();
        let h = |k: [u32; 3]| b.hash_one(k);
        assert_ne!(h([0, 0, 1]), h([0, 1, 0]));
        assert_ne!(h([1, 0, 0]), h([0, 0, 1]));
        assert_eq!(h([7, 8, 9]), h([7, 8, 9]));
    }
}
