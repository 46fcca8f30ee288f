//! Growing a paged index off the frame's thread: [`ThreadGrower`], the native
//! `tessera_stream::IndexGrower` (the browser's is a task on its event loop).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use tessera_format::{ModelIndex, PatchReader};
use tessera_stream::IndexGrower;

/// Reads more of a model's paged index on a thread of its own
/// ([`PatchReader::grow_index`]: pages doubled until another level shows); the next
/// frame takes it ([`PatchReader::latest_index`]). One read at a time; a model whose
/// index is whole never starts one (the driver asks only while the index is partial).
pub struct ThreadGrower {
    model: Arc<dyn PatchReader>,
    /// The index as grown since `model.index()` was read (None: not grown).
    grown: Option<Arc<ModelIndex>>,
    growing: Arc<AtomicBool>,
}

impl ThreadGrower {
    /// The grower of `model`'s index.
    pub fn new(model: Arc<dyn PatchReader>) -> ThreadGrower {
        ThreadGrower {
            model,
            grown: None,
            growing: Arc::new(AtomicBool::new(false)),
        }
    }
}

impl IndexGrower for ThreadGrower {
    fn index(&self) -> &ModelIndex {
        self.grown.as_deref().unwrap_or(self.model.index())
    }

    fn grow(&mut self, _time_s: f64) {
        if self.growing.swap(true, Ordering::AcqRel) {
            return;
        }
        let (model, growing) = (self.model.clone(), self.growing.clone());
        std::thread::spawn(move || {
            model.grow_index();
            growing.store(false, Ordering::Release);
        });
    }

    fn take(&mut self, _time_s: f64) -> Option<Arc<ModelIndex>> {
        let ix = self.model.latest_index()?;
        if ix.nodes().len() <= self.index().nodes().len() {
            return None;
        }
        self.grown = Some(ix.clone());
        Some(ix)
    }

    fn growing(&self) -> bool {
        self.growing.load(Ordering::Acquire)
    }
}
