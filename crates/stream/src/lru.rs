//! Least-recently-used entries under a byte budget: the one eviction rule of the RAM
//! cache (decoded patches by node) and the GPU cache (uploaded groups).
//!
//! Recency is a **frame number** the caller passes in, one counter for the whole
//! viewer, never mixed with any other epoch: an entry used in frame `f` has
//! `used >= f`, and [`Lru::victim`] only offers entries with `used < keep_since`. The
//! scheduler passes `keep_since = frame` for the GPU (nothing touched this frame is
//! evicted this frame) and `keep_since = frame - 1` for RAM (patches of groups still
//! waiting for siblings, touched in the previous frame, survive the next frame's
//! arrivals). Pinned entries (the roots) are never offered.
//!
//! Entries are ordered by `(used, key)` in a `BTreeSet`, so finding the oldest costs
//! O(log n) instead of a scan over every entry; a victim that the caller prefers
//! (hysteresis: "not needed even by a closer view") is looked for among the oldest
//! [`PREFERENCE_WINDOW`] candidates only, so one eviction never costs more than that.

use std::collections::BTreeSet;

use rustc_hash::FxHashMap;

/// `used` value of pinned entries.
const PINNED: u64 = u64::MAX;

/// Candidates examined for a preferred victim before the oldest one is taken.
pub const PREFERENCE_WINDOW: usize = 256;

struct Entry<V> {
    value: V,
    bytes: u64,
    used: u64,
}

/// Entries keyed by `u32` with a size in bytes, a budget, and LRU order by frame.
/// See the module docs.
pub struct Lru<V> {
    budget: u64,
    bytes: u64,
    entries: FxHashMap<u32, Entry<V>>,
    order: BTreeSet<(u64, u32)>,
}

impl<V> Lru<V> {
    /// An empty cache of `budget` bytes.
    pub fn new(budget: u64) -> Lru<V> {
        Lru {
            budget,
            bytes: 0,
            entries: FxHashMap::default(),
            order: BTreeSet::new(),
        }
    }

    /// The budget in bytes.
    pub fn budget(&self) -> u64 {
        self.budget
    }

    /// Bytes of all entries.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Changes the budget. Nothing is removed here: the caller makes room when it sees
    /// fit ([`Lru::shrink`], or victims one by one), so entries still in use survive.
    pub fn set_budget(&mut self, budget: u64) {
        self.budget = budget;
    }

    /// Whether the entries exceed the budget (after it was lowered).
    pub fn over_budget(&self) -> bool {
        self.bytes > self.budget
    }

    /// Bytes of `key`'s entry.
    pub fn bytes_of(&self, key: u32) -> Option<u64> {
        self.entries.get(&key).map(|e| e.bytes)
    }

    /// Keys of entries used at or after `frame`, oldest first (not pinned ones).
    pub fn used_since(&self, frame: u64) -> Vec<u32> {
        self.order.range((frame, 0)..).map(|&(_, k)| k).collect()
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Whether `key` is present.
    pub fn contains(&self, key: u32) -> bool {
        self.entries.contains_key(&key)
    }

    /// The value of `key` (not a use).
    pub fn get(&self, key: u32) -> Option<&V> {
        self.entries.get(&key).map(|e| &e.value)
    }

    /// Frame in which `key` was last used; `None` if absent, `Some(u64::MAX)` if pinned.
    pub fn last_used(&self, key: u32) -> Option<u64> {
        self.entries.get(&key).map(|e| e.used)
    }

    /// Whether adding `bytes` would exceed the budget.
    pub fn would_exceed(&self, bytes: u64) -> bool {
        self.bytes.saturating_add(bytes) > self.budget
    }

    /// Marks `key` used in `frame` (recency never goes back); returns its value.
    pub fn touch(&mut self, key: u32, frame: u64) -> Option<&V> {
        let e = self.entries.get_mut(&key)?;
        if e.used != PINNED && e.used < frame {
            self.order.remove(&(e.used, key));
            e.used = frame;
            self.order.insert((frame, key));
        }
        Some(&e.value)
    }

    /// Never offers `key` as a victim from now on (until removed).
    pub fn pin(&mut self, key: u32) {
        if let Some(e) = self.entries.get_mut(&key) {
            if e.used != PINNED {
                self.order.remove(&(e.used, key));
                e.used = PINNED;
            }
        }
    }

    /// Adds `key` used in `frame`, or, if present, adds `bytes` to it and touches it
    /// (the GPU cache grows a group member by member); the old value is kept then.
    pub fn insert(&mut self, key: u32, value: V, bytes: u64, frame: u64) {
        self.bytes += bytes;
        if let Some(e) = self.entries.get_mut(&key) {
            e.bytes += bytes;
            self.touch(key, frame);
            return;
        }
        self.entries.insert(
            key,
            Entry {
                value,
                bytes,
                used: frame,
            },
        );
        self.order.insert((frame, key));
    }

    /// Removes `key`, returning its value and bytes.
    pub fn remove(&mut self, key: u32) -> Option<(V, u64)> {
        let e = self.entries.remove(&key)?;
        if e.used != PINNED {
            self.order.remove(&(e.used, key));
        }
        self.bytes -= e.bytes;
        Some((e.value, e.bytes))
    }

    /// The entry to evict next: among entries last used before `keep_since` (never the
    /// pinned ones), the least recently used that `prefer` accepts within the
    /// [`PREFERENCE_WINDOW`] oldest, else the least recently used. `None` when every
    /// entry was used at or after `keep_since`.
    pub fn victim(&self, keep_since: u64, prefer: impl Fn(u32) -> bool) -> Option<u32> {
        let mut oldest = None;
        for &(used, key) in self.order.iter().take(PREFERENCE_WINDOW) {
            if used >= keep_since {
                break;
            }
            if prefer(key) {
                return Some(key);
            }
            oldest.get_or_insert(key);
        }
        oldest
    }

    /// Keys of entries last used before `keep_since`, oldest first (not pinned ones).
    pub fn unused_since(&self, keep_since: u64) -> Vec<u32> {
        self.order
            .iter()
            .take_while(|&&(used, _)| used < keep_since)
            .map(|&(_, k)| k)
            .collect()
    }

    /// Makes room for `bytes` by removing victims (see [`Lru::victim`]) until they fit,
    /// returning what was removed. If they still do not fit (everything left is recent
    /// or pinned) the caller decides: see [`Lru::admit`].
    fn make_room(&mut self, bytes: u64, keep_since: u64) -> Vec<(u32, V)> {
        let mut out = Vec::new();
        while self.would_exceed(bytes) {
            let Some(k) = self.victim(keep_since, |_| false) else {
                break;
            };
            if let Some((v, _)) = self.remove(k) {
                out.push((k, v));
            }
        }
        out
    }

    /// Removes least recently used entries last used before `keep_since` until the
    /// entries fit the budget (after [`Lru::set_budget`] lowered it), returning them.
    pub fn shrink(&mut self, keep_since: u64) -> Vec<(u32, V)> {
        self.make_room(0, keep_since)
    }

    /// Admits a new entry after [`Lru::make_room`]: when it still does not fit it is
    /// admitted only while the total is within the budget, so the total never exceeds
    /// `budget + one entry`. Returns whether it was admitted and what was evicted.
    pub fn admit(&mut self, key: u32, value: V, bytes: u64, frame: u64) -> (bool, Vec<(u32, V)>) {
        if self.contains(key) {
            self.touch(key, frame);
            return (true, Vec::new());
        }
        let evicted = self.make_room(bytes, frame.saturating_sub(1));
        if self.would_exceed(bytes) && self.bytes > self.budget {
            return (false, evicted);
        }
        self.insert(key, value, bytes, frame);
        (true, evicted)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn victims_are_oldest_first_and_never_recent_or_pinned() {
        let mut c: Lru<()> = Lru::new(100);
        for (k, f) in [(1, 1), (2, 2), (3, 3), (4, 4)] {
            c.insert(k, (), 10, f);
        }
        assert_eq!(c.victim(5, |_| false), Some(1));
        c.touch(1, 5);
        assert_eq!(c.victim(5, |_| false), Some(2));
        assert_eq!(
            c.victim(5, |k| k == 3),
            Some(3),
            "preferred within the window"
        );
        c.pin(2);
        assert_eq!(c.victim(5, |_| false), Some(3));
        assert_eq!(
            c.victim(3, |_| false),
            None,
            "3 and 4 are used at or after frame 3"
        );
        assert_eq!(c.unused_since(5), vec![3, 4]);
        // Recency never goes back.
        c.touch(4, 1);
        assert_eq!(c.last_used(4), Some(4));
    }

    #[test]
    fn insert_of_a_present_key_grows_it() {
        let mut c: Lru<u8> = Lru::new(100);
        c.insert(7, 1, 10, 1);
        c.insert(7, 2, 5, 3);
        assert_eq!(c.bytes(), 15);
        assert_eq!(c.get(7), Some(&1));
        assert_eq!(c.last_used(7), Some(3));
        assert_eq!(c.remove(7), Some((1, 15)));
        assert_eq!(c.bytes(), 0);
    }

    #[derive(Debug, Clone)]
    enum Op {
        Admit(u32, u64),
        Touch(u32),
        NextFrame,
    }

    fn op() -> impl Strategy<Value = Op> {
        prop_oneof![
            4 => (0u32..40, 1u64..100).prop_map(|(n, b)| Op::Admit(n, b)),
            2 => (0u32..40).prop_map(Op::Touch),
            1 => Just(Op::NextFrame),
        ]
    }

    proptest! {
        /// The RAM cache's rules: within budget + one entry, nothing used in this or
        /// the previous frame evicted, bytes always the sum of the entries.
        #[test]
        fn budget_and_recent_entries_hold(budget in 50u64..400, ops in proptest::collection::vec(op(), 1..200)) {
            let mut c: Lru<()> = Lru::new(budget);
            let mut sizes: FxHashMap<u32, u64> = FxHashMap::default();
            let mut frame = 1u64;
            for o in ops {
                match o {
                    Op::Admit(n, b) => {
                        let recent: Vec<u32> = sizes
                            .keys()
                            .copied()
                            .filter(|&k| c.last_used(k).unwrap() + 1 >= frame)
                            .collect();
                        let (admitted, evicted) = c.admit(n, (), b, frame);
                        if admitted {
                            sizes.entry(n).or_insert(b);
                        }
                        for (e, _) in &evicted {
                            prop_assert!(!recent.contains(e), "recent {} evicted", e);
                            sizes.remove(e);
                        }
                        prop_assert!(c.bytes() <= budget + 99);
                    }
                    Op::Touch(n) => {
                        prop_assert_eq!(c.touch(n, frame).is_some(), sizes.contains_key(&n));
                    }
                    Op::NextFrame => frame += 1,
                }
                prop_assert_eq!(c.bytes(), sizes.values().sum::<u64>());
                prop_assert_eq!(c.len(), sizes.len());
                prop_assert_eq!(c.order.len(), c.entries.len());
            }
        }
    }
}
