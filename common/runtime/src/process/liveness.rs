//! Which realtime peers are still heard from, and when a lost one can no longer rejoin.

use std::time::Duration;

/// Silence after which a realtime peer is declared lost, ns, at the least ([`lost_after_ns`]).
/// With a liveness check every [`LIVENESS_CHECK`] the loss is reported within 45 ms of the last
/// message.
pub const LOST_AFTER_NS: u64 = 40_000_000;
/// ... and in control periods: a peer is heard from once a period, so a run whose period is
/// longer than 1 ms gives each peer this many of them.
pub const LOST_AFTER_PERIODS: u64 = 40;

/// Silence after which a realtime peer of a run with control period `control_period_s` is
/// declared lost, ns: [`LOST_AFTER_NS`] or [`LOST_AFTER_PERIODS`] periods, the longer (40 ms
/// at the paper's 1 kHz; a run with a 40 s period would have lost every peer between two of
/// its ticks).
pub fn lost_after_ns(control_period_s: f64) -> u64 {
    // A float too large for u64 saturates.
    let periods = (LOST_AFTER_PERIODS as f64 * control_period_s * 1e9) as u64;
    LOST_AFTER_NS.max(periods)
}

/// The wall-clock instant after which a realtime peer that is still lost stays lost: the run's
/// end (epoch + duration) plus the loss limit of its control period.
pub fn realtime_end_ns(epoch_ns: u64, duration_s: f64, control_period_s: f64) -> u64 {
    epoch_ns
        .saturating_add((duration_s * 1e9) as u64)
        .saturating_add(lost_after_ns(control_period_s))
}
/// How often a realtime event-driven process checks liveness while idle.
pub const LIVENESS_CHECK: Duration = Duration::from_millis(5);

/// Which peers (agents) are still heard from. Pure bookkeeping on monotonic-clock stamps.
#[derive(Debug, Clone)]
pub struct Liveness {
    last_seen_ns: Vec<u64>,
    lost_at_ns: Vec<Option<u64>>,
    after_ns: u64,
}

impl Liveness {
    /// `n` peers, all heard from at `now_ns`.
    pub fn new(n: usize, now_ns: u64, after_ns: u64) -> Self {
        Self {
            last_seen_ns: vec![now_ns; n],
            lost_at_ns: vec![None; n],
            after_ns,
        }
    }

    /// Peer `i` was heard from at `now_ns` (never moves its stamp back: a message sent before
    /// the realtime epoch does not shorten the grace the epoch gives). A peer declared lost
    /// rejoins: returns how long it had been silent, ns.
    pub fn seen(&mut self, i: usize, now_ns: u64) -> Option<u64> {
        let s = self.last_seen_ns.get_mut(i)?;
        let silent = now_ns.saturating_sub(*s);
        *s = (*s).max(now_ns);
        self.lost_at_ns.get_mut(i)?.take().map(|_| silent)
    }

    /// Whether peer `i` is done with: finished normally, or lost and the run's wall-clock end
    /// (`end_ns`: epoch + duration + the loss limit) has passed, so it can no longer rejoin.
    pub fn settled(&self, i: usize, finished: bool, now_ns: u64, end_ns: u64) -> bool {
        finished || (self.is_lost(i) && now_ns >= end_ns)
    }

    /// Peers silent for longer than the limit and not yet declared lost; declares them lost.
    /// `finished(i)` excludes peers that ended normally.
    pub fn newly_lost(&mut self, now_ns: u64, finished: impl Fn(usize) -> bool) -> Vec<usize> {
        let mut out = Vec::new();
        for (i, (seen, lost)) in self
            .last_seen_ns
            .iter()
            .zip(self.lost_at_ns.iter_mut())
            .enumerate()
        {
            if lost.is_none() && !finished(i) && now_ns.saturating_sub(*seen) > self.after_ns {
                *lost = Some(now_ns);
                out.push(i);
            }
        }
        out
    }

    /// The silence after which a peer is declared lost, ns.
    pub fn limit_ns(&self) -> u64 {
        self.after_ns
    }

    /// How long peer `i` has been silent at `now_ns`.
    pub fn silence_ns(&self, i: usize, now_ns: u64) -> u64 {
        self.last_seen_ns
            .get(i)
            .map_or(0, |s| now_ns.saturating_sub(*s))
    }

    pub fn is_lost(&self, i: usize) -> bool {
        self.lost_at_ns.get(i).is_some_and(Option::is_some)
    }
}

#[cfg(test)]
mod liveness_tests {
    use super::Liveness;

    #[test]
    fn a_peer_is_lost_once_after_the_silence_limit_and_finished_peers_never() {
        let mut l = Liveness::new(3, 0, 40);
        l.seen(0, 30);
        assert!(l.newly_lost(40, |_| false).is_empty());
        assert_eq!(l.newly_lost(41, |i| i == 2), vec![1]);
        assert!(l.is_lost(1) && !l.is_lost(0) && !l.is_lost(2));
        assert_eq!(l.newly_lost(71, |i| i == 2), vec![0]);
        assert!(l.newly_lost(1000, |i| i == 2).is_empty(), "reported once");
        // A stamp older than the start (a message sent before the epoch) keeps the start.
        let mut e = Liveness::new(1, 100, 40);
        e.seen(0, 50);
        assert!(e.newly_lost(130, |_| false).is_empty());
    }

    /// Regression (issue 51): the loss limit was 40 ms whatever the control period, so a
    /// realtime run with a 40 s period would have declared every agent lost between two ticks.
    #[test]
    fn the_loss_limit_is_40_ms_or_40_control_periods_the_longer() {
        use super::{lost_after_ns, realtime_end_ns};
        assert_eq!(lost_after_ns(0.001), 40_000_000, "the paper's 1 kHz");
        assert_eq!(lost_after_ns(1e-6), 40_000_000, "1 MHz");
        assert_eq!(lost_after_ns(40.0), 1_600_000_000_000);
        assert_eq!(lost_after_ns(1e300), u64::MAX, "saturates");
        assert_eq!(
            realtime_end_ns(5, 1.0, 0.001),
            5 + 1_000_000_000 + 40_000_000
        );
        assert_eq!(realtime_end_ns(u64::MAX - 1, 1.0, 40.0), u64::MAX);
    }
}
