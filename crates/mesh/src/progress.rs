//! The progress protocol of long work: the builder's stages and the generators report
//! through [`Progress`]; the CLI maps it to progress bars, tests and libraries ignore it
//! ([`NoProgress`]).
//!
//! Why it lives here: `tessera-mesh` is the lowest crate both the builder and the
//! generators depend on, so there is one trait for every long-running library call.

/// Long work reports through this; the CLI maps it to progress bars, tests ignore it.
pub trait Progress: Sync {
    /// A new stage begins with `total` units of work (0 when unknown).
    fn stage(&self, name: &str, total: u64);
    /// `n` more units done.
    fn advance(&self, n: u64);
    /// The current stage is done.
    fn finish_stage(&self);
    /// Whether the user asked to stop (e.g. Ctrl-C). Work that polls it checks between
    /// units of work and returns its own "interrupted" error (the builder's
    /// `BuildError::Interrupted`), removing its temporary files.
    fn cancelled(&self) -> bool {
        false
    }
}

/// A [`Progress`] that reports nothing.
pub struct NoProgress;

impl Progress for NoProgress {
    fn stage(&self, _: &str, _: u64) {}
    fn advance(&self, _: u64) {}
    fn finish_stage(&self) {}
}
