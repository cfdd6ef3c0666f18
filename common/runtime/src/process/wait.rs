//! How a process waits for its peers: a bounded spin, then a block on its wake-up event.

use std::time::{Duration, Instant};

use crate::ipc::{Inbox, IpcError, Payload, Waker};

/// How long a process waits for the launcher's start before giving up.
pub const START_TIMEOUT: Duration = Duration::from_secs(60);
/// Longest single block on a wake-up event; shutdown is checked at least this often.
pub const WAIT_SLICE: Duration = Duration::from_millis(50);

/// How a lockstep process waits for its peers: poll its wake-up event (yielding the CPU between
/// polls) for up to `spin`, then block on it. Blocking costs a scheduler wake-up (tens of µs on
/// the 2-vCPU machines); polling with `sched_yield` hands the CPU to whichever process has work.
/// A zero `spin` blocks at once. Set by `FDI_SPIN_US` (the launcher passes it on).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WaitStrategy {
    pub spin: Duration,
}

/// Default bounded spin before blocking, µs (chosen by measurement, see docs/performance.md).
pub const DEFAULT_SPIN_US: u64 = 200;

impl WaitStrategy {
    /// Lockstep spins `FDI_SPIN_US` (default [`DEFAULT_SPIN_US`]) before blocking; realtime
    /// never spins (the attacker and the center are purely event-driven there, so that the
    /// agents keep the CPU for their deadlines) unless `FDI_SPIN_US` says otherwise.
    pub fn for_clock(clock: fdi_common::scenario::ClockMode) -> Self {
        let env = std::env::var("FDI_SPIN_US")
            .ok()
            .and_then(|v| v.parse().ok());
        let us = match clock {
            fdi_common::scenario::ClockMode::Lockstep => env.unwrap_or(DEFAULT_SPIN_US),
            fdi_common::scenario::ClockMode::Realtime => env.unwrap_or(0),
        };
        Self {
            spin: Duration::from_micros(us),
        }
    }

    /// Returns once `inbox` holds a message (or `waker` was rung), or after [`WAIT_SLICE`]. The
    /// spin polls the inbox's shared-memory queue (no system call) and yields between polls;
    /// the pending notification is consumed once work is found.
    pub fn wait<T: Payload>(
        &self,
        waker: &impl Waker,
        inbox: &impl Inbox<T>,
    ) -> Result<bool, IpcError> {
        self.wait_until(waker, || inbox.has_messages())
    }

    /// [`Self::wait`] for a process with several inboxes: the spin polls `has_input`.
    pub fn wait_until(
        &self,
        waker: &impl Waker,
        has_input: impl Fn() -> Result<bool, IpcError>,
    ) -> Result<bool, IpcError> {
        if !self.spin.is_zero() {
            let began = Instant::now();
            while began.elapsed() < self.spin {
                if has_input()? {
                    waker.wait(Duration::ZERO)?;
                    return Ok(true);
                }
                std::thread::yield_now();
            }
        }
        // The realtime processes' own blocking wait, so that the transport floor measured with
        // this strategy waits exactly as they do.
        waker.wait_precise(WAIT_SLICE)
    }

    /// How a relay of measurements (attacker, control center) waits for its next input: in
    /// realtime it wakes at each arrival and at least every [`super::liveness::LIVENESS_CHECK`]
    /// (to notice a silent agent); in lockstep as [`Self::wait_until`].
    pub fn wait_for_input(
        &self,
        clock: fdi_common::scenario::ClockMode,
        waker: &impl Waker,
        has_input: impl Fn() -> Result<bool, IpcError>,
    ) -> Result<bool, IpcError> {
        match clock {
            fdi_common::scenario::ClockMode::Realtime => {
                waker.wait_precise(super::liveness::LIVENESS_CHECK)
            }
            fdi_common::scenario::ClockMode::Lockstep => self.wait_until(waker, has_input),
        }
    }
}
