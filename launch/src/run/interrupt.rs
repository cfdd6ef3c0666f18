//! The launcher's interrupt (SIGINT, SIGTERM): one flag for the whole process, set by a
//! handler installed before anything of a run exists, and checked at every phase — before the
//! start, during the run, while the report is written — so that an interrupt always stops at
//! once, keeps what is done and says so (`fdi-launch` exits 128 + signal).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

use crate::runtime::Interrupted;

static FLAG: OnceLock<Arc<AtomicUsize>> = OnceLock::new();

/// The flag: the number of the last signal received, 0 while none (or since [`take`]). The
/// handlers are installed on first use.
pub fn flag() -> Arc<AtomicUsize> {
    Arc::clone(FLAG.get_or_init(|| {
        let flag = Arc::new(AtomicUsize::new(0));
        for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
            // Registering only fails for a forbidden signal (SIGKILL, ...); these are not.
            if let Err(e) = signal_hook::flag::register_usize(sig, Arc::clone(&flag), sig as usize)
            {
                eprintln!("fdi-launch: warning: cannot handle signal {sig}: {e}");
            }
        }
        flag
    }))
}

/// Installs the handlers (idempotent). From then on SIGINT and SIGTERM no longer kill the
/// launcher: every phase checks [`pending`].
pub fn install() {
    let _ = flag();
}

/// The signal received and not yet taken, if any.
pub fn pending() -> Option<i32> {
    match FLAG.get()?.load(Ordering::SeqCst) {
        0 => None,
        sig => i32::try_from(sig).ok(),
    }
}

/// Takes the signal received (a phase that acted on it), so that later phases see only a new
/// one.
pub fn take() -> Option<i32> {
    match FLAG.get()?.swap(0, Ordering::SeqCst) {
        0 => None,
        sig => i32::try_from(sig).ok(),
    }
}

/// `Err(Interrupted)` naming `phase` when a signal is pending.
pub fn check(phase: &'static str) -> anyhow::Result<()> {
    match pending() {
        Some(signal) => Err(Interrupted { signal, phase }.into()),
        None => Ok(()),
    }
}
