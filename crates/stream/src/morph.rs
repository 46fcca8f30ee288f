//! Per-frame geomorphing ratios of the drawn nodes (one per residency group) and the
//! arrival blend. The view ratio of a group is `tessera_select::group_ratio` (see
//! `tessera_select::morph` for the window and why it keeps the cut crack-free); this
//! module adds what needs memory across frames:
//!
//! - **Arrival blend.** A group whose patches arrived after the view already wanted them
//!   (progressive frames on a slow disk or network) would pop in at a view ratio well
//!   below 1. Such a group (newly drawn in place of its parent diamond, which the
//!   previous frame drew, with a view ratio under [`LATE_RATIO`]) instead enters at ratio
//!   1, its parent's exact shape, and blends to its view ratio over
//!   `MorphOptions::arrival_blend_s` seconds (`r = mix(1, view, s)`, `s` from 0 to 1).
//! - **Its safety.** A group not in use in the previous frame becomes usable only when
//!   every group it depends on was in use then (drawn or refined through) and is not
//!   blending (the scheduler asks [`Morph::blocks`]): the cut refines at most one level
//!   per frame, each late level blending in from the shape the previous frame showed,
//!   and none of a blending group's members refines under a moved vertex. A group one of
//!   whose members is refined anyway (it was in use before the blend began) is drawn
//!   unmorphed (ratio 0), the rule that keeps borders closed. While groups wait, the
//!   scheduler asks for the whole cut's patches, so the levels below load meanwhile.
//!
//! Cost: one ratio per drawn group (a few flops per member) plus one walk up the cut's
//! tree per frame; no per-vertex work.

use tessera_format::NO_NODE;
use tessera_select::{group_ratio, NodeView, ViewParams, DEFAULT_MORPH_WINDOW};

use crate::groups::Groups;

/// A newly drawn group whose view ratio is below this arrived late: it blends in.
pub const LATE_RATIO: f32 = 0.98;

/// Geomorphing options of a scheduler.
#[derive(Clone, Debug, PartialEq)]
pub struct MorphOptions {
    /// Morph at all (false: every ratio is 0, the plain cut). Default on.
    pub enabled: bool,
    /// The window: ratio 0 once the parent's projected error is this many tolerances.
    pub window: f32,
    /// Seconds over which a late group blends from its parent's shape to its view ratio
    /// (progressive frames; 0: no blend). Default 0.25.
    pub arrival_blend_s: f64,
}

impl Default for MorphOptions {
    fn default() -> Self {
        MorphOptions {
            enabled: true,
            window: DEFAULT_MORPH_WINDOW,
            arrival_blend_s: 0.25,
        }
    }
}

/// Summary of a frame's ratios (for `--stats`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MorphSummary {
    /// Mean ratio over the drawn nodes of non-root groups (0 when none).
    pub mean: f32,
    /// Largest ratio drawn.
    pub max: f32,
    /// Groups blending in after a late arrival.
    pub blending: usize,
}

/// The morph state of one scheduler.
pub(crate) struct Morph {
    /// Ratio per drawn node, parallel to the draw list of the last frame.
    pub ratios: Vec<f32>,
    /// Per group: stamp of the frame its ratio was computed in, and the ratio.
    memo: Vec<(u64, f32)>,
    /// Per node: last frame it was drawn (0: never).
    node_drawn: Vec<u64>,
    /// Per node: last frame it was refined (an ancestor of a drawn node; 0: never).
    refined: Vec<u64>,
    /// Per group: last frame one of its members was drawn (0: never).
    group_drawn: Vec<u64>,
    /// Per group: last frame one of its members was drawn or refined (0: never).
    group_used: Vec<u64>,
    /// Per group: when its arrival blend started (seconds; -inf: none).
    blend_start: Vec<f64>,
    stamp: u64,
    /// Time of the last update (seconds), for [`Morph::blocks`].
    now: f64,
}

impl Morph {
    pub fn new(nodes: usize, groups: usize) -> Morph {
        let mut m = Morph {
            ratios: Vec::new(),
            memo: Vec::new(),
            node_drawn: Vec::new(),
            refined: Vec::new(),
            group_drawn: Vec::new(),
            group_used: Vec::new(),
            blend_start: Vec::new(),
            stamp: 0,
            now: f64::NEG_INFINITY,
        };
        m.resize(nodes, groups);
        m
    }

    /// Grows the tables with the index (ids of the part already shown are stable).
    pub fn resize(&mut self, nodes: usize, groups: usize) {
        self.node_drawn.resize(nodes, 0);
        self.refined.resize(nodes, 0);
        self.memo.resize(groups, (0, 0.0));
        self.group_drawn.resize(groups, 0);
        self.group_used.resize(groups, 0);
        self.blend_start.resize(groups, f64::NEG_INFINITY);
    }

    /// Whether group `g` may not become usable now (`frame` is the current frame): it
    /// was not in use in the previous frame, and a parent of one of its members either
    /// belongs to a group blending in, or was itself hidden inside a coarser node the
    /// previous frame drew (refining there would skip a level). Parents that were culled
    /// (under a node refined through, drawn nowhere) do not hold it back. No group in use
    /// is ever taken back.
    pub fn blocks(&self, nv: &NodeView, groups: &Groups, g: u32, frame: u64, blend_s: f64) -> bool {
        if blend_s <= 0.0 || self.group_used[g as usize] + 1 >= frame {
            return false;
        }
        let hot = nv.nodes();
        let last = frame - 1;
        groups.members(g).iter().any(|&m| {
            let p = hot[m as usize].parent;
            if p == NO_NODE {
                return false;
            }
            let d = groups.of(p) as usize;
            if self.group_drawn[d] + 1 >= frame && self.now < self.blend_start[d] + blend_s {
                return true;
            }
            let mut x = p;
            loop {
                if self.node_drawn[x as usize] == last {
                    // Drawn last frame: `p` itself is one level up; an ancestor, more.
                    return x != p;
                }
                if self.refined[x as usize] == last {
                    return false;
                }
                x = hot[x as usize].parent;
                if x == NO_NODE {
                    return false;
                }
            }
        })
    }

    /// Sets the time `blocks` judges by (the frame's, before its selection).
    pub fn set_now(&mut self, now: f64) {
        self.now = now;
    }

    /// Computes the ratios of `draw` (the frame's final cut) for `view`: `blend`
    /// enables the arrival blend (progressive frames), `frame` is the frame counter
    /// (from 1), `now` its time in seconds.
    #[allow(clippy::too_many_arguments)]
    pub fn update(
        &mut self,
        nv: &NodeView,
        groups: &Groups,
        view: &ViewParams,
        draw: &[u32],
        opts: &MorphOptions,
        blend: bool,
        frame: u64,
        now: f64,
    ) -> MorphSummary {
        self.stamp += 1;
        self.now = now;
        let stamp = self.stamp;
        let hot = nv.nodes();
        self.ratios.clear();
        if !opts.enabled {
            self.ratios.resize(draw.len(), 0.0);
            self.mark_drawn(groups, draw, frame);
            return MorphSummary::default();
        }
        // The refined nodes: every ancestor of a drawn node.
        for &n in draw {
            let mut p = hot[n as usize].parent;
            while p != NO_NODE && self.refined[p as usize] != frame {
                self.refined[p as usize] = frame;
                self.group_used[groups.of(p) as usize] = frame;
                p = hot[p as usize].parent;
            }
        }
        let blend_s = if blend { opts.arrival_blend_s } else { 0.0 };
        let (mut sum, mut count, mut max, mut blending) = (0.0f64, 0usize, 0.0f32, 0usize);
        for &n in draw {
            let g = groups.of(n);
            let gi = g as usize;
            if self.memo[gi].0 != stamp {
                let members = groups.members(g);
                let parent = hot[n as usize].parent;
                let mut r = group_ratio(nv, view, members, opts.window);
                if parent == NO_NODE {
                    r = 0.0;
                } else if members.iter().any(|&m| self.refined[m as usize] == frame) {
                    // A member is refined: its children's borders do not move.
                    r = 0.0;
                    self.blend_start[gi] = f64::NEG_INFINITY;
                } else if blend_s > 0.0 {
                    let newly = self.group_drawn[gi] + 1 < frame;
                    if newly {
                        // Refined into (not coarsened back from its members' children,
                        // which the previous frame drew in their place).
                        let refining = members
                            .iter()
                            .all(|&m| self.refined[m as usize] + 1 != frame);
                        self.blend_start[gi] = if refining && r < LATE_RATIO {
                            now
                        } else {
                            f64::NEG_INFINITY
                        };
                    }
                    let s = ((now - self.blend_start[gi]) / blend_s).clamp(0.0, 1.0) as f32;
                    if s < 1.0 {
                        blending += 1;
                    }
                    r += (1.0 - r) * (1.0 - s);
                }
                self.memo[gi] = (stamp, r.clamp(0.0, 1.0));
            }
            let r = self.memo[gi].1;
            if hot[n as usize].parent != NO_NODE {
                sum += f64::from(r);
                count += 1;
            }
            max = max.max(r);
            self.ratios.push(r);
        }
        self.mark_drawn(groups, draw, frame);
        MorphSummary {
            mean: if count > 0 {
                (sum / count as f64) as f32
            } else {
                0.0
            },
            max,
            blending,
        }
    }

    fn mark_drawn(&mut self, groups: &Groups, draw: &[u32], frame: u64) {
        for &n in draw {
            self.node_drawn[n as usize] = frame;
            let g = groups.of(n) as usize;
            self.group_drawn[g] = frame;
            self.group_used[g] = frame;
        }
    }
}
