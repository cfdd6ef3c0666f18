//! Clocks of the hosts of a run against one another: a request answered with the answering
//! host's CLOCK_MONOTONIC, and the offset estimated from round trips.

use std::time::Duration;

use fdi_runtime::ipc::monotonic_ns;

use crate::error::NetError;
use crate::session::{Answering, Net};

impl Net {
    /// Answers clock requests on `key` with this host's CLOCK_MONOTONIC (ns, little endian).
    pub fn answer_clock(&self, key: &str) -> Result<Answering, NetError> {
        self.answer(key, |_| Ok(monotonic_ns().to_le_bytes().to_vec()))
    }

    /// Estimates the offset of the clock answering on `key` from this host's CLOCK_MONOTONIC
    /// by `rounds` round trips, keeping the fastest (its midpoint is the least uncertain).
    pub fn clock_offset(&self, key: &str, rounds: usize) -> Result<ClockOffset, NetError> {
        let mut best: Option<ClockOffset> = None;
        for _ in 0..rounds.max(1) {
            let t0 = monotonic_ns();
            let answer = self.request(key, &[], Duration::from_secs(5))?;
            let t1 = monotonic_ns();
            let Ok(bytes) = <[u8; 8]>::try_from(answer.as_slice()) else {
                return Err(NetError::Frame {
                    key: key.into(),
                    what: format!("a clock answer of {} bytes, not 8", answer.len()),
                });
            };
            let theirs = u64::from_le_bytes(bytes);
            let rtt_ns = t1.saturating_sub(t0);
            let mid = t0 / 2 + t1 / 2;
            let Ok(offset_ns) = i64::try_from(i128::from(theirs) - i128::from(mid)) else {
                return Err(NetError::Frame {
                    key: key.into(),
                    what: format!("a clock of {theirs} ns, out of range against ours ({mid} ns)"),
                });
            };
            if best.is_none_or(|b| rtt_ns < b.rtt_ns) {
                best = Some(ClockOffset { offset_ns, rtt_ns });
            }
        }
        best.ok_or_else(|| NetError::NoAnswer {
            key: key.into(),
            timeout: Duration::from_secs(5),
        })
    }
}

/// A remote clock against this host's: theirs = ours + `offset_ns`, known to within half of
/// `rtt_ns`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClockOffset {
    pub offset_ns: i64,
    pub rtt_ns: u64,
}
