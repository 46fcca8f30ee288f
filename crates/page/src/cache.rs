//! The resident-patch store: decoded patches in RAM, a byte budget, and LRU eviction.
//!
//! This is kept apart from the threads so the budget/eviction rules are plain,
//! single-threaded logic that can be property-tested on its own. The pager wraps it in
//! its one mutex.
//!
//! Rules:
//! - every resident patch has a unique "last used" tick; [`Cache::touch`] refreshes it;
//! - before a patch is admitted, least-recently-used patches that are not pinned are
//!   evicted until the new patch fits in the budget;
//! - if it still does not fit (everything left is pinned, or the patch alone is larger
//!   than the budget) it is admitted only while the resident total is within the
//!   budget, so the total never exceeds `budget + one patch`; otherwise it is refused.

use std::collections::BTreeMap;
use std::sync::Arc;

use rustc_hash::{FxHashMap, FxHashSet};
use tessera_format::PatchData;

/// Bytes a decoded patch occupies in RAM (array payloads; the small `Vec` headers are
/// not counted). This is what the RAM budget counts.
pub fn decoded_bytes(p: &PatchData) -> u64 {
    use std::mem::size_of;
    (p.positions.len() * size_of::<[u32; 3]>()
        + p.normals.len() * size_of::<[f32; 3]>()
        + p.colors.len() * size_of::<[u8; 4]>()
        + p.uvs.len() * size_of::<[f32; 2]>()
        + p.morph_targets.len() * size_of::<[u32; 3]>()
        + p.indices.len() * size_of::<u32>()) as u64
}

struct Entry {
    data: Arc<PatchData>,
    bytes: u64,
    tick: u64,
}

/// Outcome of [`Cache::admit`].
#[derive(Debug, PartialEq, Eq)]
pub struct Admit {
    /// Whether the patch is resident now (false: the budget is full of pinned patches).
    pub admitted: bool,
    /// Nodes evicted while making room (even when the patch was then refused).
    pub evicted: Vec<u32>,
}

/// Resident patches under a byte budget with LRU eviction (see the module docs).
pub struct Cache {
    budget: u64,
    resident_bytes: u64,
    entries: FxHashMap<u32, Entry>,
    /// tick -> node, oldest first.
    lru: BTreeMap<u64, u32>,
    pinned: FxHashSet<u32>,
    next_tick: u64,
}

impl Cache {
    pub fn new(budget: u64) -> Cache {
        Cache {
            budget,
            resident_bytes: 0,
            entries: FxHashMap::default(),
            lru: BTreeMap::new(),
            pinned: FxHashSet::default(),
            next_tick: 0,
        }
    }

    fn tick(&mut self) -> u64 {
        self.next_tick += 1;
        self.next_tick
    }

    pub fn resident_bytes(&self) -> u64 {
        self.resident_bytes
    }

    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    pub fn contains(&self, node: u32) -> bool {
        self.entries.contains_key(&node)
    }

    pub fn is_pinned(&self, node: u32) -> bool {
        self.pinned.contains(&node)
    }

    /// Replaces the pinned set.
    pub fn set_pinned(&mut self, nodes: &[u32]) {
        self.pinned.clear();
        self.pinned.extend(nodes.iter().copied());
    }

    /// Returns the patch and marks it most recently used.
    pub fn touch(&mut self, node: u32) -> Option<Arc<PatchData>> {
        let t = self.tick();
        let e = self.entries.get_mut(&node)?;
        self.lru.remove(&e.tick);
        e.tick = t;
        self.lru.insert(t, node);
        Some(e.data.clone())
    }

    /// Evicts the least recently used unpinned patch; `None` when all are pinned.
    fn evict_one(&mut self) -> Option<u32> {
        let (&tick, &node) = self.lru.iter().find(|(_, n)| !self.pinned.contains(n))?;
        self.lru.remove(&tick);
        if let Some(e) = self.entries.remove(&node) {
            self.resident_bytes -= e.bytes;
        }
        Some(node)
    }

    /// Admits a freshly decoded patch (see the module docs for the rules). A node that
    /// is already resident is just touched.
    pub fn admit(&mut self, node: u32, data: Arc<PatchData>, bytes: u64) -> Admit {
        if self.touch(node).is_some() {
            return Admit {
                admitted: true,
                evicted: Vec::new(),
            };
        }
        let mut evicted = Vec::new();
        while self.resident_bytes + bytes > self.budget {
            match self.evict_one() {
                Some(n) => evicted.push(n),
                None => break,
            }
        }
        if self.resident_bytes + bytes > self.budget && self.resident_bytes > self.budget {
            // Over budget with only pinned patches left: admitting would overshoot by
            // more than one patch.
            return Admit {
                admitted: false,
                evicted,
            };
        }
        let t = self.tick();
        self.lru.insert(t, node);
        self.entries.insert(
            node,
            Entry {
                data,
                bytes,
                tick: t,
            },
        );
        self.resident_bytes += bytes;
        Admit {
            admitted: true,
            evicted,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[derive(Debug, Clone)]
    enum Op {
        Admit(u32, u64),
        Touch(u32),
        Pin(Vec<u32>),
    }

    fn op() -> impl Strategy<Value = Op> {
        prop_oneof![
            4 => (0u32..40, 1u64..100).prop_map(|(n, b)| Op::Admit(n, b)),
            2 => (0u32..40).prop_map(Op::Touch),
            1 => proptest::collection::vec(0u32..40, 0..6).prop_map(Op::Pin),
        ]
    }

    proptest! {
        #[test]
        fn budget_and_pins_hold(budget in 50u64..400, ops in proptest::collection::vec(op(), 1..200)) {
            let mut c = Cache::new(budget);
            let mut sizes = FxHashMap::default();
            for o in ops {
                match o {
                    Op::Admit(n, b) => {
                        let was_pinned_resident: Vec<u32> = c
                            .entries
                            .keys()
                            .copied()
                            .filter(|k| c.is_pinned(*k))
                            .collect();
                        let a = c.admit(n, Arc::new(PatchData::default()), b);
                        if a.admitted && !sizes.contains_key(&n) {
                            sizes.insert(n, b);
                        }
                        for e in &a.evicted {
                            prop_assert!(!c.is_pinned(*e));
                            sizes.remove(e);
                        }
                        for p in was_pinned_resident {
                            prop_assert!(c.contains(p), "pinned {} evicted", p);
                        }
                        prop_assert!(c.resident_bytes() <= budget + 99);
                    }
                    Op::Touch(n) => {
                        prop_assert_eq!(c.touch(n).is_some(), c.contains(n));
                    }
                    Op::Pin(v) => c.set_pinned(&v),
                }
                prop_assert_eq!(c.resident_bytes(), sizes.values().sum::<u64>());
                prop_assert_eq!(c.len(), sizes.len());
                prop_assert_eq!(c.lru.len(), c.entries.len());
            }
        }
    }

    #[test]
    fn evicts_least_recently_used_first() {
        let mut c = Cache::new(30);
        for n in 0..3 {
            assert!(c.admit(n, Arc::new(PatchData::default()), 10).admitted);
        }
        c.touch(0);
        let a = c.admit(3, Arc::new(PatchData::default()), 10);
        assert_eq!(a.evicted, vec![1]);
        c.set_pinned(&[2]);
        let a = c.admit(4, Arc::new(PatchData::default()), 10);
        assert_eq!(a.evicted, vec![0]);
    }
}
