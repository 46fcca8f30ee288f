//! The best-first walk down the forest and the batched leaf tests (see the crate docs).

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use glam::DVec3;
use tessera_format::{Grid, ModelIndex, NodeRecord, PatchData, PatchReader, NO_NODE};

use crate::triangle::Shear;
use crate::{Hit, PickError, PickStats, Ray};

/// Leaves decoded per [`PatchReader::decode_patches`] call by default.
pub const DEFAULT_BATCH: usize = 4;

/// How [`pick_with`] reads patches.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PickOptions {
    /// Leaves decoded per [`PatchReader::decode_patches`] call (at least 1; default
    /// [`DEFAULT_BATCH`]). Larger batches mean fewer reads (a remote reader fetches
    /// patches adjacent in the file with one request) but may decode leaves beyond the
    /// hit; 1 decodes only what the order of entry distances makes necessary.
    pub batch: usize,
}

impl Default for PickOptions {
    fn default() -> Self {
        PickOptions {
            batch: DEFAULT_BATCH,
        }
    }
}

/// The nearest point where `ray` (model coordinates) meets the finest geometry of the
/// model `reader` holds, with [`PickOptions::default`]. See [`pick_with`].
pub fn pick(reader: &dyn PatchReader, ray: &Ray) -> Result<(Option<Hit>, PickStats), PickError> {
    pick_with(reader, ray, &PickOptions::default())
}

/// The nearest point where `ray` meets the finest geometry of the model: `Ok((None, _))`
/// when it meets nothing (in front of its origin). Walks the index reader's
/// [`PatchReader::latest_index`] when there is one (a paged index grown since
/// `index()`), else [`PatchReader::index`]; nodes whose children that index does not
/// show stand in for them (the hit is then not [`Hit::exact`]). Patches that fail to
/// read or decode are skipped and listed in [`PickStats::skipped`]. The only error is a
/// ray that cannot be traced ([`PickError::InvalidRay`]).
pub fn pick_with(
    reader: &dyn PatchReader,
    ray: &Ray,
    options: &PickOptions,
) -> Result<(Option<Hit>, PickStats), PickError> {
    let latest = reader.latest_index();
    let index = latest.as_deref().unwrap_or_else(|| reader.index());
    let header = index.header();
    let grid = Grid::of_header(header);
    let local = ray.local(header.cube_origin)?;
    let nodes = index.nodes();
    let pad = grid.step();
    let mut stats = PickStats::default();
    let mut queue = BinaryHeap::new();
    let push = |queue: &mut BinaryHeap<Item>, stats: &mut PickStats, i: u32| {
        let Some(n) = nodes.get(i as usize) else {
            return;
        };
        stats.nodes_visited += 1;
        let kind = kind(n, nodes.len());
        let sphere = match kind {
            Kind::Inner => n.saturated_sphere,
            Kind::Leaf { .. } => n.tight_sphere,
        };
        if let Some(entry) = local.sphere_entry(sphere, pad) {
            queue.push(Item {
                entry,
                node: i,
                kind,
            });
        }
    };
    // Roots come first in the node table.
    let roots = nodes.iter().take(header.root_count as usize);
    for (i, _) in roots.enumerate().filter(|(_, n)| n.parent == NO_NODE) {
        push(&mut queue, &mut stats, i as u32);
    }
    let shear = Shear::new(&local, grid.step());
    let mut scratch = Vec::new();
    let mut best: Option<(f64, u32, u32, DVec3, bool)> = None;
    // Nearest entry distance of a leaf that was skipped (failed to decode).
    let mut skipped_entry = f64::INFINITY;
    let batch_size = options.batch.max(1);
    let mut batch: Vec<(usize, f64, bool)> = Vec::with_capacity(batch_size);
    let mut ids: Vec<usize> = Vec::with_capacity(batch_size);
    loop {
        while batch.len() < batch_size {
            let Some(top) = queue.peek() else { break };
            if best.is_some_and(|b| b.0 <= top.entry) {
                break;
            }
            let Some(item) = queue.pop() else { break };
            match item.kind {
                Kind::Inner => {
                    for c in nodes[item.node as usize].children {
                        if c != NO_NODE {
                            push(&mut queue, &mut stats, c);
                        }
                    }
                }
                Kind::Leaf { exact } => batch.push((item.node as usize, item.entry, exact)),
            }
        }
        if batch.is_empty() {
            break;
        }
        ids.clear();
        ids.extend(batch.iter().map(|b| b.0));
        // Let a local reader start every read of the batch at once, and only of these
        // bytes (kernel read-ahead for the exact ranges), before the first decode waits
        // for its own: a page fault on a cold memory map reads the kernel's whole
        // read-around window (megabytes on some disks) one fault at a time.
        for &i in &ids {
            reader.advise(i);
        }
        let decoded = reader.decode_patches(&ids);
        // A reader that answers fewer nodes than asked: the rest count as skipped.
        let answers = decoded
            .into_iter()
            .map(Ok)
            .chain(std::iter::repeat_with(|| {
                Err("the reader returned no result for this node".to_string())
            }));
        for (&(node, entry, exact), answer) in batch.iter().zip(answers) {
            match answer.and_then(|r| r.map_err(|e| e.to_string())) {
                Ok(patch) => {
                    stats.patches_decoded += 1;
                    stats.triangles_tested += patch.triangle_count();
                    let limit = best.map_or(f64::INFINITY, |b| b.0);
                    if let Some(h) = shear.nearest(&patch, limit, &mut scratch) {
                        best = Some((h.t, node as u32, h.triangle, h.normal, exact));
                    }
                }
                Err(message) => {
                    skipped_entry = skipped_entry.min(entry);
                    stats.skipped.push((node as u32, message));
                }
            }
        }
        batch.clear();
    }
    let hit = best.map(|(t, node, triangle, normal, exact)| Hit {
        point: (local.model_origin + local.dir * t).to_array(),
        distance: t,
        node,
        triangle,
        normal: normal.to_array(),
        exact: exact && skipped_entry >= t,
    });
    Ok((hit, stats))
}

/// The nearest hit of `ray` among patches the caller already holds (e.g. those drawn),
/// without reading anything: `patches` are `(node, patch)` pairs of `index`'s nodes.
/// A patch is skipped without testing its triangles when the ray misses its node's
/// tight sphere (nodes `index` does not show are always tested). [`Hit::exact`] is true
/// when the hit node is a leaf of the model. The only error is a ray that cannot be
/// traced.
pub fn pick_resident<'a>(
    index: &ModelIndex,
    patches: impl IntoIterator<Item = (u32, &'a PatchData)>,
    ray: &Ray,
) -> Result<Option<Hit>, PickError> {
    let header = index.header();
    let grid = Grid::of_header(header);
    let local = ray.local(header.cube_origin)?;
    let shear = Shear::new(&local, grid.step());
    let mut scratch = Vec::new();
    let mut best: Option<(f64, u32, u32, DVec3)> = None;
    for (node, patch) in patches {
        let record = index.nodes().get(node as usize);
        if let Some(n) = record {
            match local.sphere_entry(n.tight_sphere, grid.step()) {
                Some(entry) if best.is_none_or(|b| entry < b.0) => {}
                _ => continue,
            }
        }
        let limit = best.map_or(f64::INFINITY, |b| b.0);
        if let Some(h) = shear.nearest(patch, limit, &mut scratch) {
            best = Some((h.t, node, h.triangle, h.normal));
        }
    }
    Ok(best.map(|(t, node, triangle, normal)| Hit {
        point: (local.model_origin + local.dir * t).to_array(),
        distance: t,
        node,
        triangle,
        normal: normal.to_array(),
        exact: index
            .nodes()
            .get(node as usize)
            .is_some_and(|n| n.children == [NO_NODE; 2]),
    }))
}

/// How the walk treats a node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    /// Children shown: opened when the ray meets its saturated sphere.
    Inner,
    /// Its own patch is tested (tight sphere): a leaf of the model (`exact`), or a node
    /// whose children the index does not show.
    Leaf { exact: bool },
}

fn kind(n: &NodeRecord, shown: usize) -> Kind {
    let mut present = n.children.iter().filter(|&&c| c != NO_NODE).peekable();
    if present.peek().is_none() {
        return Kind::Leaf { exact: true };
    }
    if present.all(|&c| (c as usize) < shown) {
        Kind::Inner
    } else {
        Kind::Leaf { exact: false }
    }
}

/// A queued node, ordered so the heap pops the smallest entry distance first (ties: the
/// lower node id, so picks are deterministic).
#[derive(Clone, Copy, Debug)]
struct Item {
    entry: f64,
    node: u32,
    kind: Kind,
}

impl PartialEq for Item {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Item {}

impl PartialOrd for Item {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Item {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .entry
            .total_cmp(&self.entry)
            .then(other.node.cmp(&self.node))
    }
}
