//! The paper's alarm as a per-tick statistic, replayed from the control center's records.
//!
//! [`crate::control::Detector`] raises its alarm at tick `k` when `‖Ŝ‖` has exceeded the
//! threshold at every tick it was fed since one at least `hold_s` before `t_k`, and clears it as
//! soon as `‖Ŝ‖` is at or below the threshold. Let `j` be the latest tick with
//! `t_k − t_j ≥ hold_s`: the alarm is on at `k` exactly when `min over the ticks j..=k of ‖Ŝ‖`
//! exceeds the threshold (the ticks `t_k − t_i ≥ hold_s` are a prefix of the record, because the
//! tick times increase). That minimum, the *held norm*, is a statistic whose alarm at any
//! threshold is [`super::exceeds`]; before any tick is `hold_s` old it is `−∞` (no alarm at any
//! threshold). A `‖Ŝ‖` that is NaN counts as `−∞`: the center's `NaN > threshold` is false and
//! restarts the hold.
//!
//! To reproduce the center's alarm bit for bit, feed the tick times the center used
//! ([`crate::time::tick_time`] of `CenterRecord::k`) and `‖Ŝ‖` of `CenterRecord::s_hat`
//! ([`norm`], the same arithmetic as the center's), every record of the robot in order.

use std::collections::VecDeque;

use nalgebra::DVectorView;

/// `‖Ŝ‖`, the Euclidean norm the center's detector is fed.
pub fn norm(s_hat: &[f64]) -> f64 {
    DVectorView::from_slice(s_hat, s_hat.len()).norm()
}

/// The held norm of one robot, tick by tick.
#[derive(Debug, Clone)]
pub struct HeldNorm {
    hold_s: f64,
    /// Times of the ticks from the latest one `hold_s` old (or the first) to the newest.
    times: VecDeque<f64>,
    /// Index (in the record) of the front of `times`.
    start: u64,
    /// Index the next tick gets.
    next: u64,
    /// Candidates of the window's minimum: `(index, norm)`, norms increasing.
    mins: VecDeque<(u64, f64)>,
}

impl HeldNorm {
    pub fn new(hold_s: f64) -> Self {
        Self {
            hold_s,
            times: VecDeque::new(),
            start: 0,
            next: 0,
            mins: VecDeque::new(),
        }
    }

    /// Feeds `‖Ŝ‖` of the robot's next tick, at its tick time `t`; returns the held norm.
    pub fn push(&mut self, t: f64, norm: f64) -> f64 {
        let norm = if norm.is_nan() {
            f64::NEG_INFINITY
        } else {
            norm
        };
        let i = self.next;
        self.next += 1;
        self.times.push_back(t);
        while self.mins.back().is_some_and(|&(_, m)| m >= norm) {
            self.mins.pop_back();
        }
        self.mins.push_back((i, norm));
        while self.times.len() >= 2 && t - self.times[1] >= self.hold_s {
            self.times.pop_front();
            self.start += 1;
        }
        while self.mins.front().is_some_and(|&(j, _)| j < self.start) {
            self.mins.pop_front();
        }
        match (self.times.front(), self.mins.front()) {
            (Some(&t0), Some(&(_, m))) if t - t0 >= self.hold_s => m,
            _ => f64::NEG_INFINITY,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::Detector;
    use crate::detect::exceeds;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Random norms around the threshold, runs of every length, NaN and ∞ among them: the held
    /// norm's alarm equals the center's detector at every tick, for several hold times.
    #[test]
    fn the_held_norm_above_the_threshold_is_the_detectors_alarm() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for hold_s in [0.0, 0.001, 0.0025, 0.05, 0.3] {
            let (threshold, dt) = (0.6, 1e-3);
            let mut d = Detector::new(threshold, hold_s);
            let mut h = HeldNorm::new(hold_s);
            let mut alarms = 0;
            let mut level = 0.5;
            for k in 0..20_000u64 {
                if rng.random_bool(0.02) {
                    level = rng.random_range(0.3..0.9);
                }
                let mut norm = level + rng.random_range(-0.05..0.05);
                if rng.random_bool(0.001) {
                    norm = f64::NAN;
                } else if rng.random_bool(0.001) {
                    norm = f64::INFINITY;
                }
                let t = crate::time::tick_time(k, dt);
                let want = d.update(t, norm);
                let got = exceeds(h.push(t, norm), threshold);
                assert_eq!(got, want, "hold {hold_s}, tick {k}");
                alarms += u64::from(want);
            }
            assert!(alarms > 100, "hold {hold_s}: only {alarms} alarm ticks");
        }
    }

    #[test]
    fn no_tick_hold_old_yet_is_minus_infinity_and_the_window_minimum_follows() {
        // Whole seconds: the differences of the times are exact.
        let mut h = HeldNorm::new(2.0);
        assert_eq!(h.push(0.0, 1.0), f64::NEG_INFINITY);
        assert_eq!(h.push(1.0, 2.0), f64::NEG_INFINITY);
        // t = 2: the window is 0..=2.
        assert_eq!(h.push(2.0, 3.0), 1.0);
        // t = 3: 1..=3.
        assert_eq!(h.push(3.0, 4.0), 2.0);
        assert_eq!(h.push(4.0, 0.5), 0.5);
        assert_eq!(h.push(5.0, 5.0), 0.5);
        assert_eq!(h.push(6.0, 6.0), 0.5);
        assert_eq!(h.push(7.0, 7.0), 5.0);
        // A gap of records: the window reaches back to the latest tick 2 s old.
        assert_eq!(h.push(10.0, 8.0), 7.0);
        assert_eq!(h.push(11.0, f64::NAN), f64::NEG_INFINITY);
        assert_eq!(
            h.push(13.0, 9.0),
            f64::NEG_INFINITY,
            "the NaN is in the window"
        );
        assert_eq!(h.push(14.0, 9.0), f64::NEG_INFINITY, "above for 1 s only");
        assert_eq!(h.push(15.0, 9.0), 9.0);
    }

    #[test]
    fn the_norm_is_the_euclidean_norm() {
        assert_eq!(norm(&[3.0, 4.0]), 5.0);
        assert_eq!(norm(&[]), 0.0);
    }
}
