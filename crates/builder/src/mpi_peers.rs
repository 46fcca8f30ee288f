//! [`Peers`] over MPI (`--features mpi`; rsmpi on Open MPI): the ranks of
//! `mpirun -n N tessera build --mpi ...`.
//!
//! An exchange is an all-to-all of the message sizes, then one non-blocking send and
//! receive per pair of ranks (in pieces of at most [`PIECE_BYTES`]), all polled while
//! `cancelled()` is checked: when mpirun stops the job because a rank died (it sends
//! SIGTERM to the others), a rank waiting here returns [`PeerError::Cancelled`], and the
//! builder removes its temporary files before the process exits.

use crate::peers::{PeerError, Peers};
use mpi::request::{Request, StaticScope};
use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::traits::*;
use std::sync::atomic::{AtomicU64, Ordering};

/// MPI counts are `i32`: messages travel in pieces of at most 1 GiB.
const PIECE_BYTES: usize = 1 << 30;

/// How long to sleep between polls of unfinished requests: short next to a level's
/// exchange (milliseconds to seconds), long enough not to spin a core that the other
/// ranks on the host could use.
const POLL_SLEEP: std::time::Duration = std::time::Duration::from_micros(200);

/// The test hook of `crates/cli/tests/mpi.rs`: `TESSERA_MPI_TEST_KILL=R:K` makes rank
/// R kill itself (SIGKILL, as a crashed node would vanish) when it enters exchange K
/// (counted from 0).
const KILL_HOOK: &str = "TESSERA_MPI_TEST_KILL";

/// This process's place in the MPI job. Create it once, at the start of `main`; dropping
/// it finalises MPI.
pub struct MpiPeers {
    world: SimpleCommunicator,
    exchanges: AtomicU64,
    kill_at: Option<(usize, u64)>,
    // Last: finalised after the communicator is dropped.
    _universe: mpi::environment::Universe,
}

// SAFETY: the builder calls `exchange` from one thread at a time (the thread that runs
// the build; MPI is initialised with `Threading::Serialized`, which allows any thread),
// and `rank`/`size` read values MPI fixes at start.
unsafe impl Sync for MpiPeers {}

impl MpiPeers {
    /// Initialises MPI. An error when the process was not started by mpirun in a way
    /// MPI accepts, or MPI cannot serialise calls from several threads.
    pub fn init() -> Result<MpiPeers, String> {
        let (universe, threading) = mpi::initialize_with_threading(mpi::Threading::Serialized)
            .ok_or_else(|| "MPI is already initialised".to_string())?;
        if threading < mpi::Threading::Serialized {
            return Err(format!(
                "this MPI library offers threading level {threading:?}; the build needs Serialized"
            ));
        }
        let kill_at = std::env::var(KILL_HOOK).ok().and_then(|v| {
            let (r, k) = v.split_once(':')?;
            Some((r.parse().ok()?, k.parse().ok()?))
        });
        Ok(MpiPeers {
            world: universe.world(),
            exchanges: AtomicU64::new(0),
            kill_at,
            _universe: universe,
        })
    }

    /// Ends this process's part without finalising MPI: after an interrupted exchange
    /// (a rank died, mpirun is stopping the job), MPI_Finalize could wait for ranks that
    /// are gone.
    pub fn abandon(self) {
        std::mem::forget(self);
    }
}

/// A `'static` view of a buffer that outlives every request made on it: the request
/// completes before the buffer is dropped, or both are leaked.
///
/// # Safety
/// The caller keeps `b` alive and unmoved until the request completes, or leaks it.
unsafe fn forever<T>(b: &[T]) -> &'static [T] {
    std::slice::from_raw_parts(b.as_ptr(), b.len())
}

/// See [`forever`].
unsafe fn forever_mut<T>(b: &mut [T]) -> &'static mut [T] {
    std::slice::from_raw_parts_mut(b.as_mut_ptr(), b.len())
}

/// Polls `requests` until all complete; on `cancelled`, leaks the unfinished ones (and
/// the caller leaks their buffers).
fn poll<D: ?Sized>(
    mut requests: Vec<Request<'static, D, StaticScope>>,
    cancelled: &dyn Fn() -> bool,
) -> Result<(), PeerError> {
    loop {
        requests = requests
            .into_iter()
            .filter_map(|r| r.test().err())
            .collect();
        if requests.is_empty() {
            return Ok(());
        }
        if cancelled() {
            std::mem::forget(requests);
            return Err(PeerError::Cancelled);
        }
        std::thread::sleep(POLL_SLEEP);
    }
}

impl Peers for MpiPeers {
    fn rank(&self) -> usize {
        self.world.rank() as usize
    }
    fn size(&self) -> usize {
        self.world.size() as usize
    }
    fn exchange(
        &self,
        outgoing: Vec<Vec<u8>>,
        cancelled: &dyn Fn() -> bool,
    ) -> Result<Vec<Vec<u8>>, PeerError> {
        let size = self.size();
        let me = self.rank();
        if outgoing.len() != size {
            return Err(PeerError::Failed(format!(
                "{} messages for {size} ranks",
                outgoing.len()
            )));
        }
        let k = self.exchanges.fetch_add(1, Ordering::Relaxed);
        if self.kill_at == Some((me, k)) {
            // SAFETY: raising a signal has no preconditions.
            unsafe { libc::raise(libc::SIGKILL) };
        }
        // 1. Sizes.
        let sizes: Vec<u64> = outgoing.iter().map(|m| m.len() as u64).collect();
        let mut incoming_sizes = vec![0u64; size];
        {
            // SAFETY: both buffers live until the request completes, or are leaked.
            let req = unsafe {
                self.world.immediate_all_to_all_into(
                    StaticScope,
                    forever(&sizes),
                    forever_mut(&mut incoming_sizes),
                )
            };
            if let Err(e) = poll(vec![req], cancelled) {
                std::mem::forget(sizes);
                std::mem::forget(incoming_sizes);
                return Err(e);
            }
        }
        // 2. The messages, pieces tagged by their index.
        let mut incoming: Vec<Vec<u8>> = incoming_sizes
            .iter()
            .enumerate()
            .map(|(from, &n)| {
                if from == me {
                    Vec::new()
                } else {
                    vec![0u8; n as usize]
                }
            })
            .collect();
        let mut requests = Vec::new();
        for (to, m) in outgoing.iter().enumerate() {
            if to == me {
                continue;
            }
            for (tag, piece) in m.chunks(PIECE_BYTES).enumerate() {
                // SAFETY: `outgoing` lives until the requests complete, or is leaked.
                requests.push(unsafe {
                    self.world
                        .process_at_rank(to as i32)
                        .immediate_send_with_tag(StaticScope, forever(piece), tag as i32)
                });
            }
        }
        for (from, buf) in incoming.iter_mut().enumerate() {
            if from == me {
                continue;
            }
            for (tag, piece) in buf.chunks_mut(PIECE_BYTES).enumerate() {
                // SAFETY: `incoming` lives until the requests complete, or is leaked.
                requests.push(unsafe {
                    self.world
                        .process_at_rank(from as i32)
                        .immediate_receive_into_with_tag(
                            StaticScope,
                            forever_mut(piece),
                            tag as i32,
                        )
                });
            }
        }
        if let Err(e) = poll(requests, cancelled) {
            std::mem::forget(outgoing);
            std::mem::forget(incoming);
            return Err(e);
        }
        let mut outgoing = outgoing;
        incoming[me] = std::mem::take(&mut outgoing[me]);
        Ok(incoming)
    }
}
