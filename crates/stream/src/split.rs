//! One store budget and one RAM budget shared by the models of a scene: each frame,
//! [`BudgetSplit::update`] turns every model's demand into its scheduler's budgets
//! ([`crate::Scheduler::set_budgets`]), so memory goes where the screen needs it.
//!
//! **The rule.** Every model first gets its floor, the bytes of its pinned roots (they
//! are never evicted, so a budget below them could never be met). What is left, `R`,
//! goes by demand: a model's demand is its view's [`crate::FrameStats::wanted_bytes`]
//! beyond the floor, the bytes of the whole cut the view needs at the tolerance, a
//! figure of the view and the index alone, not of what happens to be resident. So:
//! - **over-subscribed** (the demands exceed `R`): each model gets `R` in proportion to
//!   its demand, i.e. the same fraction of what its view needs. Demand already weighs
//!   the screen: with one tolerance in pixels, a model far away, small on screen, out
//!   of the frustum or hidden needs few bytes (none), one filling the screen many; and
//!   an equal fraction of each cut is the cheapest fair stand-in for an equal
//!   screen-space error, without any per-node bidding between schedulers. Because
//!   demand does not depend on the budget, there is no feedback (a share would not grow
//!   because it was large), and the split settles as soon as the views stop;
//! - **under-subscribed**: every demand is met in full, and the surplus keeps what the
//!   models hold beyond their demand (cached groups of earlier views) in proportion to
//!   it, so nothing is evicted while there is room and a model turned back to is still
//!   there; only when the surplus is short do those caches shrink, each by the same
//!   fraction.
//!
//! **Smoothing.** A demand rises at once (a model coming into view is served in its
//! first frame) but falls with a half-life of [`DEMAND_HALF_LIFE_S`] (peak hold with
//! exponential release) and snaps to zero below 1/256 of the budget: a camera sweeping
//! past, or a cut flickering between two levels, does not evict what it will want back
//! a moment later, and a model leaving the view releases its memory within about a
//! second. On top, a model's budget changes only when its new share differs from the
//! current one by more than 1/[`DEAD_BAND_DIVISOR`] of the total (or falls to its
//! floor, or stays above what the model holds: lowering it then evicts nothing), so
//! small wobbles cause no evict/re-upload churn. Shares never sum above the total.
//!
//! **RAM** (decoded patches: loads in flight, groups waiting for siblings, prefetch)
//! follows the store split, since a model's loads scale with its store demand, with
//! 1/8 of the RAM budget split evenly so every shown model can still complete a group.

/// Half-life of a falling demand, seconds.
pub const DEMAND_HALF_LIFE_S: f64 = 0.25;
/// Budgets move only by more than `total / DEAD_BAND_DIVISOR`.
pub const DEAD_BAND_DIVISOR: u64 = 64;

/// What [`BudgetSplit::update`] needs to know of one model each frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ModelDemand {
    /// The last frame's [`crate::FrameStats::wanted_bytes`] (0 when hidden).
    pub wanted_bytes: u64,
    /// Bytes that cannot be evicted ([`crate::Scheduler::pinned_bytes`]).
    pub pinned_bytes: u64,
    /// Bytes held now ([`crate::Scheduler::resident_bytes`]).
    pub resident_bytes: u64,
}

impl ModelDemand {
    pub fn new(wanted_bytes: u64, pinned_bytes: u64, resident_bytes: u64) -> Self {
        Self {
            wanted_bytes,
            pinned_bytes,
            resident_bytes,
        }
    }

    /// A model's demand: the `wanted_bytes` of its last frame's stats, none when it is
    /// not shown, and what its scheduler holds.
    pub fn of(scheduler: &crate::Scheduler, wanted_bytes: u64, shown: bool) -> Self {
        Self::new(
            if shown { wanted_bytes } else { 0 },
            scheduler.pinned_bytes(),
            scheduler.resident_bytes(),
        )
    }
}

/// Per-model budgets from one store total and one RAM total. See the module docs.
#[derive(Clone, Debug)]
pub struct BudgetSplit {
    store_total: u64,
    ram_total: u64,
    /// Smoothed demand per model.
    smoothed: Vec<f64>,
    /// (store, RAM) budget per model.
    budgets: Vec<(u64, u64)>,
    last_time: Option<f64>,
}

impl BudgetSplit {
    /// A split of `store_total` and `ram_total` bytes (no model yet).
    pub fn new(store_total: u64, ram_total: u64) -> BudgetSplit {
        BudgetSplit {
            store_total,
            ram_total,
            smoothed: Vec::new(),
            budgets: Vec::new(),
            last_time: None,
        }
    }

    /// Changes the totals from the next update on (a store that can hold less than
    /// its budget: see `tessera_render::GpuCache::usable_bytes`).
    pub fn set_totals(&mut self, store_total: u64, ram_total: u64) {
        self.store_total = store_total;
        self.ram_total = ram_total;
    }

    /// The totals being split.
    pub fn totals(&self) -> (u64, u64) {
        (self.store_total, self.ram_total)
    }

    /// The (store, RAM) budgets of the last update, per model.
    pub fn budgets(&self) -> &[(u64, u64)] {
        &self.budgets
    }

    /// The budgets for this frame (`time_s`: the frame's time, any origin) from each
    /// model's demand; the number of models may change between calls.
    pub fn update(&mut self, time_s: f64, models: &[ModelDemand]) -> &[(u64, u64)] {
        let n = models.len();
        let total = self.store_total;
        let dt = match self.last_time {
            Some(t) if time_s >= t => time_s - t,
            _ => 0.0,
        };
        self.last_time = Some(time_s);
        let release = 0.5f64.powf(dt / DEMAND_HALF_LIFE_S);
        self.smoothed.resize(n, 0.0);
        let snap = total as f64 / 256.0;
        for (s, m) in self.smoothed.iter_mut().zip(models) {
            let held = *s * release;
            *s = (m.wanted_bytes as f64).max(if held < snap { 0.0 } else { held });
        }
        let target = self.targets(models);
        // Dead band: a budget falling by little is kept, unless it falls to the floor
        // (a model with nothing to show gives everything back); rising ones take what
        // the others left, in proportion to how far they are below their targets.
        let band = total / DEAD_BAND_DIVISOR;
        // `hold`: keep the budgets the dead band allows. Only while that starves no
        // model whose whole demand the split meets (under-subscribed): a budget held
        // above its target must not leave such a model below what its view needs for
        // good (a view scrolled back to would miss the last group of its cut by the
        // few bytes a hidden one keeps). Over-subscribed, every model is short of its
        // demand anyway and the band holds.
        let split = |hold: bool| -> (Vec<u64>, bool) {
            let mut store: Vec<u64> = if self.budgets.len() != n {
                target.clone()
            } else {
                (0..n)
                    .map(|i| {
                        let cur = self.budgets[i].0;
                        // (Lowering a budget above what the model holds costs nothing.)
                        let held = hold
                            && target[i] < cur
                            && cur - target[i] <= band
                            && target[i] > models[i].pinned_bytes
                            && target[i] < models[i].resident_bytes;
                        if held {
                            cur
                        } else {
                            target[i].min(cur)
                        }
                    })
                    .collect()
            };
            let room = total.saturating_sub(store.iter().sum());
            let short: Vec<u64> = (0..n)
                .map(|i| target[i] - target[i].min(store[i]))
                .collect();
            let short_sum: u64 = short.iter().sum();
            for i in 0..n {
                if short_sum > 0 {
                    let add = (room as f64 * short[i] as f64 / short_sum as f64) as u64;
                    store[i] += add.min(short[i]);
                }
            }
            let starved = (0..n).any(|i| {
                let needs = models[i].wanted_bytes.max(models[i].pinned_bytes);
                target[i] >= needs && store[i] < needs
            });
            (store, starved)
        };
        let (mut store, starved) = split(true);
        if starved {
            store = split(false).0;
        }
        if store.iter().sum::<u64>() > total.max(target.iter().sum()) {
            store = target;
        }
        let even = self.ram_total / 8 / n.max(1) as u64;
        let by_share = self.ram_total - even * n as u64;
        self.budgets = store
            .iter()
            .map(|&b| {
                let frac = if total == 0 {
                    0.0
                } else {
                    b as f64 / total as f64
                };
                (b, even + (by_share as f64 * frac.min(1.0)) as u64)
            })
            .collect();
        &self.budgets
    }

    /// This frame's target store budgets (the rule of the module docs, exactly).
    fn targets(&self, models: &[ModelDemand]) -> Vec<u64> {
        let total = self.store_total as f64;
        let floors: Vec<f64> = models.iter().map(|m| m.pinned_bytes as f64).collect();
        let floor_sum: f64 = floors.iter().sum();
        if floor_sum >= total {
            return models.iter().map(|m| m.pinned_bytes).collect();
        }
        let rest = total - floor_sum;
        let demand: Vec<f64> = self
            .smoothed
            .iter()
            .zip(&floors)
            .map(|(d, f)| (d - f).max(0.0))
            .collect();
        let demand_sum: f64 = demand.iter().sum();
        let shares: Vec<f64> = if demand_sum >= rest {
            demand.iter().map(|d| rest * d / demand_sum).collect()
        } else {
            let surplus = rest - demand_sum;
            let cached: Vec<f64> = models
                .iter()
                .zip(demand.iter().zip(&floors))
                .map(|(m, (d, f))| (m.resident_bytes as f64 - f - d).max(0.0))
                .collect();
            let cached_sum: f64 = cached.iter().sum();
            demand
                .iter()
                .zip(&cached)
                .map(|(d, c)| {
                    let extra = if cached_sum > 0.0 {
                        surplus * c / cached_sum
                    } else {
                        surplus / models.len() as f64
                    };
                    d + extra
                })
                .collect()
        };
        floors
            .iter()
            .zip(&shares)
            .map(|(f, s)| (f + s).floor() as u64)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use ModelDemand as D;

    #[test]
    fn the_model_on_screen_gets_the_memory() {
        let mut s = BudgetSplit::new(1000, 100);
        // A wants far more than the budget, B (off screen) nothing.
        let b = s
            .update(0.0, &[D::new(5000, 10, 10), D::new(0, 20, 500)])
            .to_vec();
        assert_eq!(b[1].0, 20, "B down to its roots: {b:?}");
        assert_eq!(b[0].0, 980);
        assert!(b.iter().map(|x| x.0).sum::<u64>() <= 1000);
        assert!(b[0].1 > b[1].1 && b.iter().map(|x| x.1).sum::<u64>() <= 100);
    }

    #[test]
    fn over_subscribed_shares_follow_demand() {
        let mut s = BudgetSplit::new(1000, 0);
        let b = s
            .update(0.0, &[D::new(3000, 0, 0), D::new(1000, 0, 0)])
            .to_vec();
        assert_eq!(b[0].0, 750);
        assert_eq!(b[1].0, 250);
    }

    #[test]
    fn surplus_keeps_caches() {
        let mut s = BudgetSplit::new(1000, 0);
        // Demands 300 + 100 fit; A holds 200 beyond its demand, B nothing.
        let b = s
            .update(0.0, &[D::new(300, 0, 500), D::new(100, 0, 100)])
            .to_vec();
        assert_eq!(b[0].0, 900, "{b:?}");
        assert_eq!(b[1].0, 100);
    }

    #[test]
    fn falling_demand_is_released_smoothly_and_rising_at_once() {
        let mut s = BudgetSplit::new(1 << 20, 0);
        let big = 4 << 20;
        s.update(0.0, &[D::new(big, 0, 0), D::new(0, 0, 0)]);
        // B comes into view: served in the same frame (in proportion to the two).
        let b = s
            .update(0.01, &[D::new(0, 0, 0), D::new(big, 0, 0)])
            .to_vec();
        assert!(b[1].0 > (1 << 20) * 4 / 10, "{b:?}");
        assert!(
            b[0].0 > (1 << 20) * 4 / 10,
            "A is released gradually: {b:?}"
        );
        // A second later A's demand has decayed to nothing.
        let mut t = 0.01;
        let mut last = b;
        while t < 3.0 {
            t += 0.05;
            last = s.update(t, &[D::new(0, 0, 0), D::new(big, 0, 0)]).to_vec();
        }
        assert_eq!(last[0].0, 0, "{last:?}");
        assert_eq!(last[1].0, 1 << 20);
    }

    #[test]
    fn small_changes_do_not_move_budgets() {
        let mut s = BudgetSplit::new(1 << 20, 0);
        // Both hold their whole share.
        let held = 1 << 19;
        let b0 = s
            .update(0.0, &[D::new(3 << 20, 0, held), D::new(3 << 20, 0, held)])
            .to_vec();
        // B's demand rises by 2%: A's share would fall by ~0.5% of the total, which
        // would evict: kept.
        let up = (3 << 20) * 102 / 100;
        let b1 = s
            .update(0.02, &[D::new(3 << 20, 0, held), D::new(up, 0, held)])
            .to_vec();
        assert_eq!(b0, b1);
        assert!(b1.iter().map(|x| x.0).sum::<u64>() <= 1 << 20);
        // Had A held less than its share, lowering it would cost nothing: applied.
        let b2 = s
            .update(0.04, &[D::new(3 << 20, 0, held / 2), D::new(up, 0, held)])
            .to_vec();
        assert!(b2[0].0 < b1[0].0 && b2[1].0 > b1[1].0, "{b1:?} -> {b2:?}");
    }

    #[test]
    fn the_dead_band_never_starves_a_demand_the_budget_can_meet() {
        let total = 1u64 << 20;
        let mut s = BudgetSplit::new(total, 0);
        // A shows nothing and holds a cache (the surplus keeps it); B's cut fits.
        let cache = total - 600_000;
        let b0 = s
            .update(0.0, &[D::new(0, 0, cache), D::new(600_000, 0, 600_000)])
            .to_vec();
        assert_eq!(b0[1].0, 600_000);
        assert_eq!(b0[0].0, cache);
        // B needs 10 kB more, less than the dead band of A's fall: A gives it anyway,
        // or B would miss the last group of its cut for good.
        assert!(10_000 < total / DEAD_BAND_DIVISOR);
        let b1 = s
            .update(0.02, &[D::new(0, 0, cache), D::new(610_000, 0, 600_000)])
            .to_vec();
        assert_eq!(b1[1].0, 610_000, "{b0:?} -> {b1:?}");
        assert_eq!(b1[0].0, cache - 10_000, "{b0:?} -> {b1:?}");
    }

    #[test]
    fn floors_always_hold() {
        let mut s = BudgetSplit::new(100, 0);
        let b = s
            .update(0.0, &[D::new(1000, 60, 60), D::new(1000, 70, 70)])
            .to_vec();
        assert_eq!(b, vec![(60, 0), (70, 0)]);
    }
}
