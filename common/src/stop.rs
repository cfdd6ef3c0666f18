//! The launcher's stop: a value that `main` owns (it wires SIGINT and SIGTERM to it) and passes
//! down to every phase of a command — before the start, during the run, while the report is
//! written — so that an interrupt stops at once, keeps what is done and says so. A library
//! caller makes its own (`Stop::new()`) and raises it from wherever it likes.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

/// A shared stop request: the number of the signal that asked for it (0 while none). Clones
/// share it.
#[derive(Debug, Clone, Default)]
pub struct Stop {
    signal: Arc<AtomicUsize>,
}

/// An interrupt before the start: nothing was recorded, nothing is kept.
pub const BEFORE_THE_START: &str =
    "before the start: every process was stopped, nothing was recorded";
/// An interrupt during the run: the run directory keeps what was recorded.
pub const DURING_THE_RUN: &str = "during the run: every process was stopped";
/// An interrupt while the report was written: the run's summary, `rmse.md` and traces are kept,
/// the report is not (it is written whole or not at all).
pub const WHILE_REPORTING: &str = "while the report was written: the run directory keeps summary.json, rmse.md and the traces; the report was not made (`fdi-launch report RUN_DIR` makes it)";

/// The signal numbers a stop is raised with by `fdi-launch` (Linux).
pub const SIGINT: i32 = 2;
/// See [`SIGINT`].
pub const SIGTERM: i32 = 15;

/// `SIGINT`, `SIGTERM`, or `signal N`.
pub fn signal_name(signal: i32) -> String {
    match signal {
        SIGINT => "SIGINT".into(),
        SIGTERM => "SIGTERM".into(),
        n => format!("signal {n}"),
    }
}

/// The launcher was interrupted (SIGINT, SIGTERM). `fdi-launch` exits with `128 + signal`, as
/// a shell reports a process killed by it.
#[derive(Debug, Clone, Copy, thiserror::Error)]
#[error("interrupted by {} {phase}", signal_name(*.signal))]
pub struct Interrupted {
    pub signal: i32,
    /// When, and what was kept: [`BEFORE_THE_START`], [`DURING_THE_RUN`],
    /// [`WHILE_REPORTING`].
    pub phase: &'static str,
}

impl Interrupted {
    /// The exit status `fdi-launch` ends with: 130 for SIGINT, 143 for SIGTERM.
    pub fn exit_code(&self) -> u8 {
        u8::try_from(128 + self.signal).unwrap_or(1)
    }
}

impl Stop {
    /// A stop nobody has raised.
    pub fn new() -> Self {
        Self::default()
    }

    /// The shared cell, for a signal handler to store the signal's number into.
    pub fn cell(&self) -> Arc<AtomicUsize> {
        Arc::clone(&self.signal)
    }

    /// Raises the stop as `signal` would.
    pub fn raise(&self, signal: i32) {
        self.signal
            .store(usize::try_from(signal).unwrap_or(1), Ordering::SeqCst);
    }

    /// The signal received and not yet taken, if any.
    pub fn pending(&self) -> Option<i32> {
        match self.signal.load(Ordering::SeqCst) {
            0 => None,
            sig => i32::try_from(sig).ok(),
        }
    }

    /// Takes the signal received (a phase that acted on it), so that later phases see only a
    /// new one.
    pub fn take(&self) -> Option<i32> {
        match self.signal.swap(0, Ordering::SeqCst) {
            0 => None,
            sig => i32::try_from(sig).ok(),
        }
    }

    /// `Err(Interrupted)` naming `phase` when a signal is pending.
    pub fn check(&self, phase: &'static str) -> Result<(), Interrupted> {
        match self.pending() {
            Some(signal) => Err(Interrupted { signal, phase }),
            None => Ok(()),
        }
    }
}

/// The environment variable naming a [`hold`] point.
pub const HOLD_VAR: &str = "FDI_HOLD";
/// The longest a [`hold`] lasts.
pub const HOLD_LIMIT: std::time::Duration = std::time::Duration::from_secs(120);

/// A point where the launcher can be held for a test of what an interrupt does there
/// (docs/faults.md, "Hold points"): when the environment variable [`HOLD_VAR`] names `point`,
/// waits until `stop` is raised (at most [`HOLD_LIMIT`]); otherwise returns at once. The
/// only point is `report` (the report's staging folder made, no figure drawn yet), so that a
/// test signals the launcher while it writes the report, whatever the machine's speed.
pub fn hold(point: &str, stop: &Stop) {
    if std::env::var_os(HOLD_VAR).is_none_or(|v| v != point) {
        return;
    }
    let began = std::time::Instant::now();
    while stop.pending().is_none() && began.elapsed() < HOLD_LIMIT {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_raised_stop_is_pending_until_taken_and_shared_by_clones() {
        let stop = Stop::new();
        let other = stop.clone();
        assert!(stop.check(DURING_THE_RUN).is_ok());
        other.raise(SIGTERM);
        let e = stop.check(DURING_THE_RUN).expect_err("raised");
        assert_eq!(e.exit_code(), 143);
        assert_eq!(
            e.to_string(),
            "interrupted by SIGTERM during the run: every process was stopped"
        );
        assert_eq!(stop.take(), Some(SIGTERM));
        assert_eq!(other.pending(), None);
    }
}
