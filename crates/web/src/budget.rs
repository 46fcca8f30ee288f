//! One memory budget for every model on a page: the views (`Viewer`) and three.js
//! models (`Stream`) of one page register here, and each frame of each one gets its
//! scheduler's budgets from one [`BudgetSplit`] of the page's totals by the models'
//! demand, the rule the desktop viewer uses for the models of its scene (see
//! `tessera_stream::split`): the model filling the screen gets the memory, one far away
//! or showing little gives it back.
//!
//! The page's totals are the largest of the registered models' own budgets (each
//! model's `memoryBytes`, split as at open: half for the store, a quarter for decoded
//! patches), and a model never gets more than its own: two views opened with the
//! default 512 MiB share 256 MiB of store between them, not 512. Each view still has
//! its own WebGL context and GPU cache; its buffers grow only as far as the share it
//! is given (they never shrink).
//!
//! The views of a page run their frames in turn (each its own `requestAnimationFrame`);
//! each frame records its model's demand and takes its budgets from the split of the
//! last demands of all. Plain Rust, tested natively.

use std::cell::RefCell;

use tessera_stream::{BudgetSplit, ModelDemand};

/// A model's registration ([`PageBudgets::register`]).
pub type ModelId = u64;

struct Entry {
    id: ModelId,
    /// The model's own (store, RAM) budgets: its share never exceeds them.
    cap: (u64, u64),
    demand: ModelDemand,
}

/// The models of one page and the split of its budgets. See the module docs.
pub struct PageBudgets {
    models: Vec<Entry>,
    split: BudgetSplit,
    next_id: ModelId,
}

impl Default for PageBudgets {
    fn default() -> PageBudgets {
        PageBudgets::new()
    }
}

impl PageBudgets {
    pub fn new() -> PageBudgets {
        PageBudgets {
            models: Vec::new(),
            split: BudgetSplit::new(0, 0),
            next_id: 1,
        }
    }

    /// Registers a model whose own budgets are `cap` (store, RAM bytes).
    pub fn register(&mut self, cap: (u64, u64)) -> ModelId {
        let id = self.next_id;
        self.next_id += 1;
        self.models.push(Entry {
            id,
            cap,
            demand: ModelDemand::default(),
        });
        self.restart();
        id
    }

    /// Forgets a model (disposed); what it held goes to the others.
    pub fn unregister(&mut self, id: ModelId) {
        self.models.retain(|e| e.id != id);
        self.restart();
    }

    /// Changes a model's own budgets (`Stream::set_memory_bytes`).
    pub fn set_cap(&mut self, id: ModelId, cap: (u64, u64)) {
        if let Some(e) = self.models.iter_mut().find(|e| e.id == id) {
            e.cap = cap;
        }
        self.set_totals();
    }

    /// Models registered.
    pub fn len(&self) -> usize {
        self.models.len()
    }

    pub fn is_empty(&self) -> bool {
        self.models.is_empty()
    }

    /// The page's (store, RAM) totals: the largest of the models' own budgets.
    pub fn totals(&self) -> (u64, u64) {
        self.split.totals()
    }

    /// Model `id`'s frame at `time_s`: records its demand and gives its (store, RAM)
    /// budgets for this frame, its share of the page's totals at most its own.
    pub fn update(&mut self, id: ModelId, time_s: f64, demand: ModelDemand) -> (u64, u64) {
        let Some(i) = self.models.iter().position(|e| e.id == id) else {
            return (0, 0);
        };
        self.models[i].demand = demand;
        let demands: Vec<ModelDemand> = self.models.iter().map(|e| e.demand).collect();
        let (store, ram) = self.split.update(time_s, &demands)[i];
        let cap = self.models[i].cap;
        (store.min(cap.0), ram.min(cap.1))
    }

    /// A new split (the number or order of models changed: the smoothed demands are
    /// per position).
    fn restart(&mut self) {
        self.split = BudgetSplit::new(0, 0);
        self.set_totals();
    }

    fn set_totals(&mut self) {
        let store = self.models.iter().map(|e| e.cap.0).max().unwrap_or(0);
        let ram = self.models.iter().map(|e| e.cap.1).max().unwrap_or(0);
        self.split.set_totals(store, ram);
    }
}

thread_local! {
    /// The page's budgets (wasm32 runs the page's models on one thread).
    pub static PAGE: RefCell<PageBudgets> = RefCell::new(PageBudgets::new());
}

/// A model's place in [`PAGE`], given up when dropped.
pub struct Registration {
    id: ModelId,
}

impl Registration {
    /// Registers a model with its own budgets `cap` in [`PAGE`].
    pub fn new(cap: (u64, u64)) -> Registration {
        Registration {
            id: PAGE.with(|p| p.borrow_mut().register(cap)),
        }
    }

    /// This frame's budgets ([`PageBudgets::update`]).
    pub fn update(&self, time_s: f64, demand: ModelDemand) -> (u64, u64) {
        PAGE.with(|p| p.borrow_mut().update(self.id, time_s, demand))
    }

    /// Changes this model's own budgets.
    pub fn set_cap(&self, cap: (u64, u64)) {
        PAGE.with(|p| p.borrow_mut().set_cap(self.id, cap))
    }

    /// The number of models on the page now.
    pub fn page_models(&self) -> usize {
        PAGE.with(|p| p.borrow().len())
    }
}

/// A view's (or a three.js model's) budgets come from its share of the page's.
impl tessera_stream::Budgets for Registration {
    fn share(
        &mut self,
        time_s: f64,
        demands: &[ModelDemand],
        _usable_store: u64,
    ) -> Option<Vec<(u64, u64)>> {
        Some(demands.iter().map(|&d| self.update(time_s, d)).collect())
    }
}

impl Drop for Registration {
    fn drop(&mut self) {
        // (`try_with`: a thread's locals may be gone when it ends.)
        let _ = PAGE.try_with(|p| p.borrow_mut().unregister(self.id));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use ModelDemand as D;

    #[test]
    fn one_model_keeps_its_own_budget() {
        let mut p = PageBudgets::new();
        let a = p.register((1000, 500));
        assert_eq!(p.update(a, 0.0, D::new(200, 10, 10)), (1000, 500));
        assert_eq!(p.update(a, 0.1, D::new(5000, 10, 900)), (1000, 500));
    }

    #[test]
    fn two_models_share_the_largest_budget_by_demand() {
        let mut p = PageBudgets::new();
        let a = p.register((1000, 400));
        let b = p.register((1000, 400));
        assert_eq!(p.totals(), (1000, 400));
        // Both over-subscribed: shares follow demand (3:1 beyond the roots).
        let _ = p.update(a, 0.0, D::new(3000, 0, 0));
        let (sa, _) = p.update(a, 0.0, D::new(3000, 0, 0));
        let (sb, _) = p.update(b, 0.0, D::new(1000, 0, 0));
        let (sa2, ra) = p.update(a, 0.0, D::new(3000, 0, 0));
        assert!(sa <= 1000);
        assert_eq!((sa2, sb), (750, 250), "{sa2} {sb}");
        let (_, rb) = p.update(b, 0.0, D::new(1000, 0, 0));
        assert!(ra + rb <= 400 && ra > rb, "{ra} {rb}");
    }

    #[test]
    fn a_share_never_exceeds_the_models_own_budget() {
        let mut p = PageBudgets::new();
        let small = p.register((100, 50));
        let big = p.register((1000, 500));
        let _ = p.update(big, 0.0, D::new(0, 0, 0));
        let (s, r) = p.update(small, 0.0, D::new(5000, 0, 0));
        assert_eq!((s, r), (100, 50));
        // The big one, alone on screen, gets the rest of the page's total.
        let (s, _) = p.update(big, 0.0, D::new(5000, 0, 0));
        assert!(s <= 1000 && s >= 450, "{s}");
    }

    #[test]
    fn a_disposed_model_gives_its_share_back() {
        let mut p = PageBudgets::new();
        let a = p.register((1000, 400));
        let b = p.register((1000, 400));
        let _ = p.update(a, 0.0, D::new(3000, 0, 0));
        let _ = p.update(b, 0.0, D::new(3000, 0, 0));
        let (sa, _) = p.update(a, 0.0, D::new(3000, 0, 0));
        assert_eq!(sa, 500);
        p.unregister(b);
        assert_eq!(p.len(), 1);
        assert_eq!(p.update(a, 0.1, D::new(3000, 0, 0)), (1000, 400));
        // An unknown model gets nothing.
        assert_eq!(p.update(b, 0.2, D::new(3000, 0, 0)), (0, 0));
    }

    #[test]
    fn registrations_share_the_thread_page() {
        let a = Registration::new((1000, 400));
        {
            let b = Registration::new((1000, 400));
            assert_eq!(a.page_models(), 2);
            let _ = a.update(0.0, D::new(3000, 0, 0));
            let _ = b.update(0.0, D::new(1000, 0, 0));
            assert_eq!(a.update(0.0, D::new(3000, 0, 0)).0, 750);
        }
        assert_eq!(a.page_models(), 1);
        assert_eq!(a.update(0.1, D::new(3000, 0, 0)), (1000, 400));
    }
}
