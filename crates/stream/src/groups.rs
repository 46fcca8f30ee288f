//! Residency groups: the nodes that must become resident, and be evicted, together so
//! that a cut drawn from partly resident data stays crack-free.
//!
//! A diamond `D` (the nodes of one level sharing a refinement edge, simplified as one
//! unit with its outer border locked) has one saturated error and sphere, so its nodes
//! always take the same refinement decision; the faces between them are NOT locked, so
//! they must refine together. Refining them means drawing their children: the **group**
//! of `D` is the set of children of all of `D`'s nodes. Roots form one-node groups.
//!
//! Two rules make a residency-limited cut equal to a full cut with some diamonds
//! coarsened, which is crack-free (see `tessera_select::residency`):
//! 1. a group counts only when all its members are resident (so all of `D` refines or
//!    none of it does);
//! 2. a group counts only when every node of `D` is itself reachable: each of `D`'s nodes
//!    belongs to some parent group, and those groups must count too (recursively, up to
//!    the roots). Otherwise one node of `D` could refine while another, whose parent
//!    stayed coarse, is not even reached, and the refined side would meet a coarser
//!    patch across an unlocked face.
//!
//! [`Groups::dependencies`] lists, per group, the groups of `D`'s nodes (rule 2).

use rustc_hash::FxHashMap;
use tessera_format::{NodeRecord, NO_NODE};
use tessera_select::NodeView;

/// Group structure of one model. Built once per model.
pub struct Groups {
    /// Group of each node.
    of_node: Vec<u32>,
    /// CSR: members of group g are `members[member_start[g]..member_start[g+1]]`.
    member_start: Vec<u32>,
    members: Vec<u32>,
    /// CSR: groups that must be usable for group g to be usable.
    dep_start: Vec<u32>,
    deps: Vec<u32>,
}

impl Groups {
    /// Builds the groups from the node table (parents from the sanitised `NodeView`).
    pub fn new(nv: &NodeView, records: &[NodeRecord]) -> Groups {
        let hot = nv.nodes();
        let n = hot.len().min(records.len());
        // Group key: the parent's diamond id, or a per-root key.
        let mut key_to_group: FxHashMap<(bool, u32), u32> = FxHashMap::default();
        let mut of_node = vec![0u32; n];
        for i in 0..n {
            let p = hot[i].parent;
            let key = if p == NO_NODE || p as usize >= n {
                (true, i as u32)
            } else {
                (false, records[p as usize].diamond)
            };
            let next = key_to_group.len() as u32;
            of_node[i] = *key_to_group.entry(key).or_insert(next);
        }
        let g = key_to_group.len();
        let mut member_start = vec![0u32; g + 1];
        for &grp in &of_node {
            member_start[grp as usize + 1] += 1;
        }
        for k in 0..g {
            member_start[k + 1] += member_start[k];
        }
        let mut fill = member_start.clone();
        let mut members = vec![0u32; n];
        for (i, &grp) in of_node.iter().enumerate() {
            members[fill[grp as usize] as usize] = i as u32;
            fill[grp as usize] += 1;
        }
        // Dependencies: group(key = diamond d) depends on the groups of all nodes whose
        // diamond is d.
        let mut by_diamond: FxHashMap<u32, Vec<u32>> = FxHashMap::default();
        for (i, r) in records.iter().enumerate().take(n) {
            by_diamond.entry(r.diamond).or_default().push(of_node[i]);
        }
        let mut dep_lists: Vec<Vec<u32>> = vec![Vec::new(); g];
        for (&(is_root, id), &grp) in &key_to_group {
            if is_root {
                continue;
            }
            if let Some(list) = by_diamond.get(&id) {
                let mut l = list.clone();
                l.sort_unstable();
                l.dedup();
                // A corrupt table could make a group depend on itself; drop that edge.
                l.retain(|&d| d != grp);
                dep_lists[grp as usize] = l;
            }
        }
        let mut dep_start = Vec::with_capacity(g + 1);
        let mut deps = Vec::new();
        dep_start.push(0);
        for l in dep_lists {
            deps.extend_from_slice(&l);
            dep_start.push(deps.len() as u32);
        }
        Groups {
            of_node,
            member_start,
            members,
            dep_start,
            deps,
        }
    }

    /// Number of groups.
    pub fn len(&self) -> usize {
        self.member_start.len() - 1
    }

    /// True when there are no groups.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The group of `node`.
    #[inline]
    pub fn of(&self, node: u32) -> u32 {
        self.of_node[node as usize]
    }

    /// Members of group `g`.
    #[inline]
    pub fn members(&self, g: u32) -> &[u32] {
        &self.members
            [self.member_start[g as usize] as usize..self.member_start[g as usize + 1] as usize]
    }

    /// Groups that must be usable before `g` is.
    #[inline]
    pub fn dependencies(&self, g: u32) -> &[u32] {
        &self.deps[self.dep_start[g as usize] as usize..self.dep_start[g as usize + 1] as usize]
    }
}

/// Per-frame memo of "group usable" (complete and all dependencies usable).
pub struct Readiness {
    stamp: Vec<u64>,
    value: Vec<bool>,
}

impl Readiness {
    pub fn new(groups: usize) -> Readiness {
        Readiness {
            stamp: vec![u64::MAX; groups],
            value: vec![false; groups],
        }
    }

    /// Whether group `g` is usable in this `epoch`; `complete(g)` says whether all of a
    /// group's members are resident. Iterative (no recursion depth limit): dependency
    /// chains are as long as the hierarchy is deep, and a corrupt table cannot make it
    /// loop because a group on the current path counts as not usable.
    pub fn ready(
        &mut self,
        groups: &Groups,
        g: u32,
        epoch: u64,
        complete: &impl Fn(u32) -> bool,
    ) -> bool {
        const IN_PROGRESS: u64 = u64::MAX - 1;
        if self.stamp[g as usize] == epoch {
            return self.value[g as usize];
        }
        // Explicit DFS stack of (group, next dependency index).
        let mut stack: Vec<(u32, usize)> = vec![(g, 0)];
        self.stamp[g as usize] = IN_PROGRESS;
        while let Some(&(cur, next)) = stack.last() {
            if next == 0 && !complete(cur) {
                self.finish(&mut stack, false, epoch);
                continue;
            }
            let deps = groups.dependencies(cur);
            if next < deps.len() {
                let d = deps[next];
                if let Some(top) = stack.last_mut() {
                    top.1 = next + 1;
                }
                let s = self.stamp[d as usize];
                if s == epoch {
                    if !self.value[d as usize] {
                        self.finish(&mut stack, false, epoch);
                    }
                } else if s == IN_PROGRESS {
                    self.finish(&mut stack, false, epoch);
                } else {
                    self.stamp[d as usize] = IN_PROGRESS;
                    stack.push((d, 0));
                }
            } else {
                stack.pop();
                self.stamp[cur as usize] = epoch;
                self.value[cur as usize] = true;
            }
        }
        self.value[g as usize]
    }

    /// Marks the whole current path not usable (a failed dependency fails its users).
    fn finish(&mut self, stack: &mut Vec<(u32, usize)>, value: bool, epoch: u64) {
        for (grp, _) in stack.drain(..) {
            self.stamp[grp as usize] = epoch;
            self.value[grp as usize] = value;
        }
    }
}
