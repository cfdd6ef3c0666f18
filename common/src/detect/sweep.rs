//! Threshold sweeps over one recorded run: each detector's per-tick statistic is recorded once
//! from the joined tick records ([`Recorder`]), then its alarm is replayed for any threshold
//! ([`tally`]) to give true- and false-positive rates per tick, false alarms per minute and the
//! mean detection delay (docs/detectors.md, "ROC and detection delay").
//!
//! The statistics are those of the metrics: χ² and CUSUM come from the same
//! [`RobotDetectors`] fed in the same order, `s_hat_norm` is the center's alarm replayed as a
//! statistic ([`super::s_hat`]); the alarm at a threshold is [`Verdict::alarm_at`] in every case,
//! and "attack in force" is [`super::in_force`].
//!
//! Definitions, per detector and threshold (over the ticks where the detector gives a verdict,
//! [`Verdict::watched`]; the others are counted apart):
//!
//! * TPR: alarm ticks while the attack is in force / watched ticks in force;
//! * FPR: alarm ticks while not in force / watched ticks not in force;
//! * false alarms: alarm rising edges while not in force, per minute of watched attack-free time;
//! * onsets: rising edges of "in force" (the first record too, if in force); an onset is detected
//!   by the first alarm at or after it while the attack is still in force, and its delay is the
//!   time from the onset to that alarm. Undetected onsets are counted, never averaged in.

use std::collections::BTreeMap;

use crate::records::TickRecord;
use crate::scenario::Resolved;
use crate::time::tick_time;

use super::s_hat::{self, HeldNorm};
use super::{in_force, RobotDetectors, Verdict, RESIDUAL, S_HAT_NORM};

/// One tick of one detector on one robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Tick time, s (the agent's record, as the metrics use).
    pub t: f64,
    /// The attack was in force ([`in_force`]).
    pub in_force: bool,
    pub verdict: Verdict,
}

/// What the alarm of one detector did over a series, at one threshold.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Tally {
    /// Watched ticks with the attack in force, and those with the alarm on.
    pub in_force_ticks: u64,
    pub in_force_alarms: u64,
    /// Watched ticks without the attack in force, and those with the alarm on.
    pub free_ticks: u64,
    pub free_alarms: u64,
    /// Ticks without a verdict (calibration window, χ² window filling, calibration failed).
    pub no_verdict_ticks: u64,
    /// Alarm rising edges while the attack was not in force.
    pub false_alarms: u64,
    /// Rising edges of "in force".
    pub onsets: u64,
    /// Onsets with an alarm at or after them while the attack was in force.
    pub detected: u64,
    /// Onsets whose tick before had the alarm on already (a detected onset of delay 0 without
    /// a detection of its own).
    pub alarm_on_at_onset: u64,
    /// Sum of the detected onsets' delays, s.
    pub delay_sum_s: f64,
}

impl Tally {
    /// True-positive rate per tick; `None` without a watched tick in force.
    pub fn tpr(&self) -> Option<f64> {
        (self.in_force_ticks > 0).then(|| self.in_force_alarms as f64 / self.in_force_ticks as f64)
    }

    /// False-positive rate per tick; `None` without a watched attack-free tick.
    pub fn fpr(&self) -> Option<f64> {
        (self.free_ticks > 0).then(|| self.free_alarms as f64 / self.free_ticks as f64)
    }

    /// Mean delay over the detected onsets, s; `None` when none was detected.
    pub fn mean_delay_s(&self) -> Option<f64> {
        (self.detected > 0).then(|| self.delay_sum_s / self.detected as f64)
    }

    /// False alarms per minute of watched attack-free time (`control_period_s` per tick);
    /// `None` without a watched attack-free tick.
    pub fn false_alarms_per_min(&self, control_period_s: f64) -> Option<f64> {
        let s = self.free_ticks as f64 * control_period_s;
        (self.free_ticks > 0 && s > 0.0).then(|| self.false_alarms as f64 * 60.0 / s)
    }

    /// Pools `other` (another robot) into this tally.
    pub fn add(&mut self, other: &Tally) {
        self.in_force_ticks += other.in_force_ticks;
        self.in_force_alarms += other.in_force_alarms;
        self.free_ticks += other.free_ticks;
        self.free_alarms += other.free_alarms;
        self.no_verdict_ticks += other.no_verdict_ticks;
        self.false_alarms += other.false_alarms;
        self.onsets += other.onsets;
        self.detected += other.detected;
        self.alarm_on_at_onset += other.alarm_on_at_onset;
        self.delay_sum_s += other.delay_sum_s;
    }
}

/// The alarm of `series` (one robot's ticks in order) replayed at `threshold`, tallied.
pub fn tally(series: &[Sample], threshold: f64) -> Tally {
    let mut out = Tally::default();
    let mut alarm = false;
    // The onset of the in-force interval under way, until it is detected.
    let mut waiting: Option<f64> = None;
    let mut was_in_force = false;
    for s in series {
        let before = alarm;
        alarm = s.verdict.alarm_at(threshold, before);
        if s.in_force && !was_in_force {
            out.onsets += 1;
            out.alarm_on_at_onset += u64::from(before);
            waiting = Some(s.t);
        }
        if !s.in_force {
            waiting = None;
            out.false_alarms += u64::from(alarm && !before);
        }
        if alarm && s.in_force {
            if let Some(onset) = waiting.take() {
                out.detected += 1;
                out.delay_sum_s += s.t - onset;
            }
        }
        if s.verdict.watched() {
            if s.in_force {
                out.in_force_ticks += 1;
                out.in_force_alarms += u64::from(alarm);
            } else {
                out.free_ticks += 1;
                out.free_alarms += u64::from(alarm);
            }
        } else {
            out.no_verdict_ticks += 1;
        }
        was_in_force = s.in_force;
    }
    out
}

/// The thresholds of a sweep: 0, `points` log-spaced from the smallest positive to the largest
/// finite statistic of `series` (one value when they coincide, none without such a statistic),
/// and the `configured` threshold; ascending, without repeats.
pub fn thresholds<'a>(
    series: impl IntoIterator<Item = &'a Sample>,
    points: usize,
    configured: Option<f64>,
) -> Vec<f64> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for s in series {
        if let Verdict::Watched { statistic: x, .. } = s.verdict {
            if x.is_finite() && x > 0.0 {
                lo = lo.min(x);
                hi = hi.max(x);
            }
        }
    }
    let mut out = vec![0.0];
    if lo.is_finite() && points > 0 {
        if points == 1 || lo == hi {
            out.push(lo);
        } else {
            let ratio = (hi / lo).ln();
            out.extend((0..points).map(|i| match i {
                0 => lo,
                i if i == points - 1 => hi,
                i => lo * (ratio * i as f64 / (points - 1) as f64).exp(),
            }));
        }
    }
    out.extend(configured.filter(|c| c.is_finite()));
    out.sort_by(f64::total_cmp);
    out.dedup();
    out
}

/// One detector's series on every robot of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectorSeries {
    /// `s_hat_norm` or a detector of [`super::RESIDUAL`] ([`super::names`]).
    pub name: &'static str,
    /// Its configured threshold; `None` when it has none (no χ² quantile could be had).
    pub configured: Option<f64>,
    /// Per robot, its ticks in order.
    pub robots: BTreeMap<u32, Vec<Sample>>,
}

/// What a [`Recorder`] gathered.
#[derive(Debug, Clone, PartialEq)]
pub struct Recorded {
    /// Δ, s.
    pub control_period_s: f64,
    /// The detectors in the order of [`super::names`].
    pub detectors: Vec<DetectorSeries>,
    /// Per robot, the ticks at which `s_hat_norm` replayed at its configured threshold differs
    /// from the center's recorded alarm (`CenterRecord::alarm`): 0 unless the records are not
    /// the center's every tick in order.
    pub s_hat_mismatches: BTreeMap<u32, u64>,
}

impl Recorded {
    /// The series of the detector `name`.
    pub fn detector(&self, name: &str) -> Option<&DetectorSeries> {
        self.detectors.iter().find(|d| d.name == name)
    }
}

#[derive(Debug, Clone)]
struct Robot {
    detectors: RobotDetectors,
    held: HeldNorm,
    /// Per detector of [`super::names`], its samples.
    series: Vec<Vec<Sample>>,
    mismatches: u64,
}

/// Records every detector's per-tick statistic from the joined tick records of a run.
#[derive(Debug, Clone)]
pub struct Recorder {
    control_period_s: f64,
    s_hat_threshold: f64,
    /// Per detector of [`super::RESIDUAL`], its configured threshold.
    residual_thresholds: Vec<Option<f64>>,
    robots: BTreeMap<u32, Robot>,
}

impl Recorder {
    /// For the agents and detectors of `resolved` (as [`crate::engine::evaluator_for`]).
    pub fn for_scenario(resolved: &Resolved) -> Self {
        let s = &resolved.scenario;
        let dt = s.control_period_s;
        let detection = s.controller.detection;
        let robots: BTreeMap<u32, Robot> = s
            .agents
            .iter()
            .map(|a| {
                let detectors =
                    RobotDetectors::new(&s.detectors, dt, s.controller.beta, a.model.dof());
                let robot = Robot {
                    detectors,
                    held: HeldNorm::new(detection.hold_s),
                    series: vec![Vec::new(); 1 + RESIDUAL.len()],
                    mismatches: 0,
                };
                (a.id, robot)
            })
            .collect();
        let first = robots.values().next().map(|r| &r.detectors);
        Self {
            control_period_s: dt,
            s_hat_threshold: detection.threshold,
            residual_thresholds: RESIDUAL
                .iter()
                .enumerate()
                .map(|(i, k)| match first {
                    Some(d) => d.threshold(i).ok(),
                    None => (k.threshold)(&s.detectors, 0).ok(),
                })
                .collect(),
            robots,
        }
    }

    /// Feeds one joined tick record (ticks of one agent in order; agents interleaved freely).
    pub fn push(&mut self, r: &TickRecord) {
        let Some(samples) = self.observe(r) else {
            return;
        };
        let Some(robot) = self.robots.get_mut(&r.agent.agent) else {
            return;
        };
        for (series, sample) in robot.series.iter_mut().zip(samples) {
            series.push(sample);
        }
    }

    /// Every detector's configured threshold, in the order of [`super::names`] (`None`: a
    /// detector without one, as χ² when no quantile could be had).
    pub fn configured(&self) -> Vec<(&'static str, Option<f64>)> {
        std::iter::once((S_HAT_NORM, Some(self.s_hat_threshold)))
            .chain(
                RESIDUAL
                    .iter()
                    .map(|k| k.name)
                    .zip(self.residual_thresholds.iter().copied()),
            )
            .collect()
    }

    /// Feeds one joined tick record as [`Self::push`] does, and returns the tick's sample of
    /// every detector (in the order of [`super::names`]) without keeping it: memory stays the
    /// same however long the run (the MCAP export writes them as they come). `None` for an
    /// agent the scenario does not have.
    pub fn observe(&mut self, r: &TickRecord) -> Option<Vec<Sample>> {
        let robot = self.robots.get_mut(&r.agent.agent)?;
        let (t, active) = (r.agent.t, in_force(r));
        let held = robot.held.push(
            tick_time(r.center.k, self.control_period_s),
            s_hat::norm(r.center.s_hat.as_slice()),
        );
        let s_hat = Verdict::Watched {
            statistic: held,
            threshold: self.s_hat_threshold,
        };
        robot.mismatches += u64::from(s_hat.alarm(false) != r.center.alarm);
        let residual = robot.detectors.push(r);
        Some(
            std::iter::once(&s_hat)
                .chain(residual)
                .map(|&verdict| Sample {
                    t,
                    in_force: active,
                    verdict,
                })
                .collect(),
        )
    }

    pub fn finish(self) -> Recorded {
        let configured = self.configured();
        let mut detectors: Vec<DetectorSeries> = configured
            .iter()
            .map(|&(name, configured)| DetectorSeries {
                name,
                configured,
                robots: BTreeMap::new(),
            })
            .collect();
        let mut s_hat_mismatches = BTreeMap::new();
        for (id, r) in self.robots {
            for (d, series) in detectors.iter_mut().zip(r.series) {
                d.robots.insert(id, series);
            }
            s_hat_mismatches.insert(id, r.mismatches);
        }
        Recorded {
            control_period_s: self.control_period_s,
            detectors,
            s_hat_mismatches,
        }
    }
}

/// One point of a sweep: a threshold, the pooled tally and each robot's.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    pub threshold: f64,
    /// The detector's configured threshold.
    pub configured: bool,
    /// Over every robot.
    pub pooled: Tally,
    pub robots: BTreeMap<u32, Tally>,
}

/// The sweep of one detector: its thresholds ([`thresholds`] over every robot's statistic, so
/// pooled and per-robot rows share them), ascending.
pub fn sweep(d: &DetectorSeries, points: usize) -> Vec<Point> {
    let grid = thresholds(d.robots.values().flatten(), points, d.configured);
    grid.into_iter()
        .map(|threshold| {
            let robots: BTreeMap<u32, Tally> = d
                .robots
                .iter()
                .map(|(id, s)| (*id, tally(s, threshold)))
                .collect();
            let mut pooled = Tally::default();
            for t in robots.values() {
                pooled.add(t);
            }
            Point {
                threshold,
                configured: d.configured == Some(threshold),
                pooled,
                robots,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests;
