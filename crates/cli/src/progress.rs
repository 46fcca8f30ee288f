//! Maps the libraries' `Progress` reports to indicatif bars on stderr (hidden when stderr
//! is not a terminal, so logs and CI output stay clean).

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use tessera_mesh::Progress;

/// Set by the first Ctrl-C (SIGINT/SIGTERM); the libraries poll it through
/// `Progress::cancelled` and unwind, removing their temporary files.
static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    if INTERRUPTED.swap(true, Ordering::SeqCst) {
        // A second Ctrl-C: stop at once (async-signal-safe exit).
        unsafe { libc::_exit(130) };
    }
}

/// Under mpirun: every signal only asks for the stop. mpirun, stopping a job, sends
/// SIGINT, SIGTERM and after `odls_base_sigkill_timeout` (1 s) SIGKILL; exiting at the
/// second signal would leave the temporary files the first one was removing.
extern "C" fn on_signal_patient(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// Route SIGINT and SIGTERM to a graceful stop (the first one) of long commands.
pub fn install_interrupt_handler() {
    install(on_signal);
}

/// [`install_interrupt_handler`] for a rank of an MPI job: repeated signals do not
/// exit at once (mpirun escalates to SIGKILL itself).
#[cfg_attr(not(feature = "mpi"), allow(dead_code))]
pub fn install_patient_interrupt_handler() {
    install(on_signal_patient);
}

fn install(on_signal: extern "C" fn(libc::c_int)) {
    let handler = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
    // SAFETY: the handler only touches an atomic and calls `_exit`.
    unsafe {
        libc::signal(libc::SIGINT, handler);
        libc::signal(libc::SIGTERM, handler);
    }
}

/// Whether a Ctrl-C (SIGINT/SIGTERM) arrived since [`install_interrupt_handler`].
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

pub struct Bars {
    bar: Mutex<Option<ProgressBar>>,
    quiet: bool,
}

impl Bars {
    pub fn new(quiet: bool) -> Bars {
        Bars {
            bar: Mutex::new(None),
            quiet,
        }
    }
}

impl Progress for Bars {
    fn stage(&self, name: &str, total: u64) {
        let Ok(mut b) = self.bar.lock() else { return };
        if let Some(old) = b.take() {
            old.finish_and_clear();
        }
        let bar = if self.quiet {
            ProgressBar::hidden()
        } else {
            ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr())
        };
        let style = if total > 0 {
            ProgressStyle::with_template(
                "{msg:>22} [{bar:40}] {human_pos}/{human_len} ({per_sec}, {eta})",
            )
        } else {
            ProgressStyle::with_template("{msg:>22} {spinner} {human_pos}")
        };
        if let Ok(s) = style {
            bar.set_style(s.progress_chars("=> "));
        }
        bar.set_message(name.to_string());
        *b = Some(bar);
    }
    fn advance(&self, n: u64) {
        if let Ok(b) = self.bar.lock() {
            if let Some(bar) = b.as_ref() {
                bar.inc(n);
            }
        }
    }
    fn cancelled(&self) -> bool {
        INTERRUPTED.load(Ordering::Relaxed)
    }
    fn finish_stage(&self) {
        if let Ok(mut b) = self.bar.lock() {
            if let Some(bar) = b.take() {
                bar.finish_and_clear();
            }
        }
    }
}
