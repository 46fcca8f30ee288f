//! The processes of a distributed build ("ranks") and the one operation the builder
//! needs between them: an all-to-all exchange of byte messages.
//!
//! ATP (section 5.3, parallel construction) builds the forest's subtrees and each level's
//! diamonds on separate processors; here every rank runs the same import and partition
//! (the input is read whole by each: see docs/mpi.md), simplifies its own share of each
//! level's diamonds, and exchanges patches at the end of the level (see
//! `hierarchy::Distribution`). The transport is behind [`Peers`] so that the builder
//! needs no MPI by default: [`Solo`] is the single process (no exchange at all),
//! [`LocalPeers`] runs ranks as threads of one process (the tests), and with the `mpi`
//! feature [`crate::mpi_peers::MpiPeers`] is the real thing.
//!
//! Every rank calls [`Peers::exchange`] the same number of times in the same order:
//! the builder reaches each exchange point also after an error (carrying the error as
//! its message), so that no rank waits forever for one that gave up.

use std::sync::{Condvar, Mutex};

/// Why an exchange did not complete.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PeerError {
    /// `cancelled()` turned true while waiting (Ctrl-C, or mpirun stopping the job
    /// because another rank died).
    Cancelled,
    /// The transport failed; the message says how.
    Failed(String),
}

/// The ranks of a build, seen from one of them.
pub trait Peers: Sync {
    /// This process's rank, `0..size()`. Rank 0 writes the model.
    fn rank(&self) -> usize;
    /// How many ranks take part.
    fn size(&self) -> usize;
    /// Sends `outgoing[r]` to rank `r` (`outgoing.len() == size()`, this rank's own
    /// entry included) and returns what every rank sent this one, by source rank.
    /// Collective: returns when every rank has called it. Polls `cancelled` while it
    /// waits and returns [`PeerError::Cancelled`] when it turns true.
    fn exchange(
        &self,
        outgoing: Vec<Vec<u8>>,
        cancelled: &dyn Fn() -> bool,
    ) -> Result<Vec<Vec<u8>>, PeerError>;
}

/// The single process: rank 0 of 1. The builder never exchanges anything with it.
pub struct Solo;

impl Peers for Solo {
    fn rank(&self) -> usize {
        0
    }
    fn size(&self) -> usize {
        1
    }
    fn exchange(
        &self,
        outgoing: Vec<Vec<u8>>,
        _: &dyn Fn() -> bool,
    ) -> Result<Vec<Vec<u8>>, PeerError> {
        Ok(outgoing)
    }
}

/// Ranks as threads of one process, for tests of the distributed build without MPI:
/// [`LocalPeers::group`] makes `n` handles, one per thread, that exchange through a
/// shared table. A rank that stops waiting (cancelled) stops the others waiting too, as
/// mpirun stops the job when a rank exits.
pub struct LocalPeers {
    rank: usize,
    shared: std::sync::Arc<LocalTable>,
}

struct LocalTable {
    size: usize,
    state: Mutex<LocalState>,
    turn: Condvar,
}

struct LocalState {
    /// Exchanges completed so far (the round every rank is in or past).
    round: u64,
    /// `mail[to][from]` of the current round.
    mail: Vec<Vec<Option<Vec<u8>>>>,
    /// Ranks that posted this round; ranks that collected it.
    posted: usize,
    collected: usize,
    /// A rank stopped waiting (cancelled): as mpirun stops the job when a rank exits,
    /// every rank waiting returns [`PeerError::Cancelled`].
    gone: bool,
}

impl LocalPeers {
    /// `n` ranks, to be moved to one thread each.
    pub fn group(n: usize) -> Vec<LocalPeers> {
        let shared = std::sync::Arc::new(LocalTable {
            size: n,
            state: Mutex::new(LocalState {
                round: 0,
                mail: vec![vec![None; n]; n],
                posted: 0,
                collected: 0,
                gone: false,
            }),
            turn: Condvar::new(),
        });
        (0..n)
            .map(|rank| LocalPeers {
                rank,
                shared: shared.clone(),
            })
            .collect()
    }
}

impl Peers for LocalPeers {
    fn rank(&self) -> usize {
        self.rank
    }
    fn size(&self) -> usize {
        self.shared.size
    }
    fn exchange(
        &self,
        outgoing: Vec<Vec<u8>>,
        cancelled: &dyn Fn() -> bool,
    ) -> Result<Vec<Vec<u8>>, PeerError> {
        let t = &*self.shared;
        if outgoing.len() != t.size {
            return Err(PeerError::Failed(format!(
                "{} messages for {} ranks",
                outgoing.len(),
                t.size
            )));
        }
        let poisoned = || PeerError::Failed("a rank panicked".into());
        let tick = std::time::Duration::from_millis(5);
        let mut s = t.state.lock().map_err(|_| poisoned())?;
        // Wait until the previous round has been collected by everyone.
        while s.posted == t.size {
            if cancelled() || s.gone {
                s.gone = true;
                t.turn.notify_all();
                return Err(PeerError::Cancelled);
            }
            s = t.turn.wait_timeout(s, tick).map_err(|_| poisoned())?.0;
        }
        let round = s.round;
        for (to, m) in outgoing.into_iter().enumerate() {
            s.mail[to][self.rank] = Some(m);
        }
        s.posted += 1;
        t.turn.notify_all();
        while s.posted < t.size && s.round == round {
            if cancelled() || s.gone {
                s.gone = true;
                t.turn.notify_all();
                return Err(PeerError::Cancelled);
            }
            s = t.turn.wait_timeout(s, tick).map_err(|_| poisoned())?.0;
        }
        let got: Vec<Vec<u8>> = s.mail[self.rank]
            .iter_mut()
            .map(|m| m.take().unwrap_or_default())
            .collect();
        s.collected += 1;
        if s.collected == t.size {
            s.posted = 0;
            s.collected = 0;
            s.round += 1;
            t.turn.notify_all();
        }
        Ok(got)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three threads, three rounds: every message reaches its rank, in its round.
    #[test]
    fn local_peers_deliver_each_round() {
        let handles: Vec<_> = LocalPeers::group(3)
            .into_iter()
            .map(|p| {
                std::thread::spawn(move || {
                    let mut seen = Vec::new();
                    for round in 0..3u8 {
                        let out = (0..3)
                            .map(|to| vec![p.rank() as u8, to as u8, round])
                            .collect();
                        seen.push(p.exchange(out, &|| false).unwrap());
                    }
                    (p.rank(), seen)
                })
            })
            .collect();
        for h in handles {
            let (rank, seen) = h.join().unwrap();
            for (round, got) in seen.iter().enumerate() {
                for (from, m) in got.iter().enumerate() {
                    assert_eq!(m, &vec![from as u8, rank as u8, round as u8]);
                }
            }
        }
    }

    /// A rank that never comes: the others give up when cancelled instead of hanging.
    #[test]
    fn local_peers_stop_when_cancelled() {
        let mut g = LocalPeers::group(2);
        let p0 = g.remove(0);
        let start = std::time::Instant::now();
        let r = p0.exchange(vec![vec![], vec![]], &|| start.elapsed().as_millis() > 50);
        assert_eq!(r, Err(PeerError::Cancelled));
    }
}
