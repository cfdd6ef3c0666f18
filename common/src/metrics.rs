//! Run metrics from joined tick records: RMSE per robot (docs/model.md, "Reproduction"), time-to-detect per attack
//! onset and false alarms (docs/detectors.md), for the paper's alarm and, side by side, for the
//! classical detectors of [`crate::detect`].

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::control::ControllerConfig;
use crate::detect::{self, DetectorsConfig, RobotDetectors, Verdict};
use crate::model::{EulerLagrange, ForLinks, ModelConfig};
use crate::records::TickRecord;
use crate::trajectory::TrajectoryConfig;

/// A robot whose tracking error exceeds this (rad), or whose true state is not finite, has
/// diverged: the run failed for it, whatever its RMSE says.
pub const DIVERGENCE_BOUND_RAD: f64 = 100.0;

/// Detection outcome for one attack onset.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Onset {
    /// Onset time, s: a tick at which the attack is in force (non-zero injection) and was not
    /// at the tick before.
    pub t_s: f64,
    /// Time from onset to the first alarm while this in-force interval lasts; `None` if the
    /// interval ended (or the run did) without one.
    pub time_to_detect_s: Option<f64>,
    /// End of the in-force interval, s (the first tick no longer in force); `None` when the
    /// attack was still in force at the end of the record.
    #[serde(default)]
    pub until_s: Option<f64>,
}

/// Metrics of one agent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AgentMetrics {
    /// `sqrt(mean over ticks and links of (q_d − q)²)`, rad.
    #[serde(with = "crate::json_float")]
    pub rmse_rad: f64,
    /// Largest `|q_d − q|` over the run, rad.
    #[serde(with = "crate::json_float")]
    pub max_abs_error_rad: f64,
    /// Every rising edge of "attack in force", with its detection.
    pub onsets: Vec<Onset>,
    /// Alarm rising edges while no attack was in force.
    pub false_alarms: u64,
    /// Fraction of in-force ticks with the alarm on.
    #[serde(with = "crate::json_float")]
    pub alarm_coverage: f64,
    /// Ticks with the attack in force.
    #[serde(default)]
    pub attacked_ticks: u64,
    pub rejected_inputs: u64,
    /// Torques the center computed non-finite and replaced by the last good one.
    #[serde(default)]
    pub rejected_torques: u64,
    /// Resets of non-finite observer or estimator state.
    #[serde(default)]
    pub state_resets: u64,
    /// Ticks whose torque history lookup failed (`e_u`, `u_τ` held).
    #[serde(default)]
    pub history_misses: u64,
    /// Steps the robot itself recorded as missing their deadline (no command due in force), over
    /// every tick it recorded: those the control center never saw (the robot uncontrolled) too.
    pub deadline_misses: u64,
    /// Ticks the robot itself recorded (its own trace), controlled or not.
    #[serde(default)]
    pub agent_ticks: u64,
    /// Of `agent_ticks`, those with no control-center record: the robot ran without control
    /// (its measurement never reached the center, or the center had given it up). Left out of
    /// every metric but `deadline_misses`.
    #[serde(default)]
    pub uncontrolled_ticks: u64,
    /// First tick time at which the true state was non-finite or the tracking error exceeded
    /// [`DIVERGENCE_BOUND_RAD`]; `None` when the robot stayed bounded.
    #[serde(default)]
    pub diverged_at_s: Option<f64>,
    /// Ticks these metrics cover.
    #[serde(default)]
    pub ticks: u64,
    /// Per detector (`s_hat_norm`, `chi2`, `cusum`, [`detect::NAMES`]): its detection metrics,
    /// side by side. `onsets`, `false_alarms` and `alarm_coverage` above are those of
    /// `s_hat_norm`. Empty in summaries written before the detectors existed.
    #[serde(default)]
    pub detectors: BTreeMap<String, DetectorMetrics>,
}

/// Detection metrics of one detector on one robot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DetectorMetrics {
    /// Every rising edge of "attack in force", with this detector's time to detect (counted
    /// from the onset, so an onset during the calibration window waits for its end).
    pub onsets: Vec<Onset>,
    /// Per onset: the alarm was already on at the tick before it, so its time to detect is 0
    /// without a detection of this attack.
    pub alarm_on_at_onset: Vec<bool>,
    /// Alarm rising edges while no attack was in force.
    pub false_alarms: u64,
    /// `false_alarms` per minute of the attack-free time the detector watched; `None` when it
    /// watched no attack-free tick.
    pub false_alarms_per_min: Option<f64>,
    /// Attack-free time the detector watched, s (its calibration window left out).
    #[serde(with = "crate::json_float")]
    pub attack_free_watched_s: f64,
    /// Fraction of the attack-free ticks it watched with the alarm on; `None` as above. A
    /// detector whose alarm never clears raises few false alarms but a share near 1.
    pub false_alarm_share: Option<f64>,
    /// Fraction of all attacked ticks (the calibration window's too) with the alarm on; `None`
    /// without attacked ticks.
    pub coverage: Option<f64>,
    /// First tick time the detector gave a verdict; `None` if it never did.
    pub watched_from_s: Option<f64>,
    /// The threshold of its statistic (`‖Ŝ‖`, the χ² window sum, the CUSUM's `h`); `None`
    /// when it has none (no quantile could be had).
    pub threshold: Option<f64>,
    /// Ticks whose residual or statistic was not finite (alarm on for each).
    pub non_finite: u64,
    /// Ticks without a residual (no record of the tick before): the alarm kept its state.
    pub missing: u64,
    /// The calibration of the residual's covariance (`chi2`, `cusum`; `None` for `s_hat_norm`).
    pub calibration: Option<CalibrationMetrics>,
}

/// How a robot's detectors were calibrated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalibrationMetrics {
    /// The window, s from the start of the run.
    pub window_s: f64,
    /// Residuals the covariance was estimated from.
    pub samples: u64,
    /// Ticks of the window with the attack in force: the covariance includes the attack (the
    /// paper's attacks on robots 1, 3 and 4 start at t = 0).
    pub attacked_ticks: u64,
    /// Ticks of the window whose residual was not finite (left out).
    pub non_finite: u64,
    /// RMS of each residual entry over the window (`sqrt(diag Σ)`).
    pub residual_rms: Vec<f64>,
    /// Why the detectors never watched: the calibration failed, or the record ended before the
    /// window did.
    pub failed: Option<String>,
}

/// Alarm bookkeeping of one detector: onsets and their detection, false alarms, coverage.
#[derive(Debug, Clone, Default)]
struct AlarmTally {
    onsets: Vec<Onset>,
    alarm_on_at_onset: Vec<bool>,
    /// Index in `onsets` of the in-force interval under way.
    in_force: Option<usize>,
    prev_alarm: bool,
    false_alarms: u64,
    attacked_ticks: u64,
    attacked_alarm_ticks: u64,
    free_watched_ticks: u64,
    free_alarm_ticks: u64,
    watched_from: Option<f64>,
    non_finite: u64,
    missing: u64,
}

impl AlarmTally {
    /// One tick at `t`: the attack in force or not, the detector's alarm, and whether it was
    /// watching.
    fn push(&mut self, t: f64, active: bool, alarm: bool, watched: bool) {
        if watched && self.watched_from.is_none() {
            self.watched_from = Some(t);
        }
        if active {
            self.attacked_ticks += 1;
            let i = *self.in_force.get_or_insert_with(|| {
                self.alarm_on_at_onset.push(self.prev_alarm);
                self.onsets.push(Onset {
                    t_s: t,
                    time_to_detect_s: None,
                    until_s: None,
                });
                self.onsets.len() - 1
            });
            if alarm {
                self.attacked_alarm_ticks += 1;
                let onset = &mut self.onsets[i];
                if onset.time_to_detect_s.is_none() {
                    onset.time_to_detect_s = Some(t - onset.t_s);
                }
            }
        } else {
            if let Some(i) = self.in_force.take() {
                self.onsets[i].until_s = Some(t);
            }
            if alarm && !self.prev_alarm {
                self.false_alarms += 1;
            }
            if watched {
                self.free_watched_ticks += 1;
                self.free_alarm_ticks += u64::from(alarm);
            }
        }
        self.prev_alarm = alarm;
    }

    /// A verdict of a residual detector.
    fn push_verdict(&mut self, t: f64, active: bool, v: Verdict) {
        self.non_finite += u64::from(v == Verdict::NonFinite);
        self.missing += u64::from(v == Verdict::Missing);
        self.push(t, active, v.alarm(self.prev_alarm), v.watched());
    }

    /// Fraction of attacked ticks with the alarm on (0 without attacked ticks: the field
    /// `alarm_coverage` as it always was).
    fn coverage_or_zero(&self) -> f64 {
        self.coverage().unwrap_or(0.0)
    }

    fn coverage(&self) -> Option<f64> {
        (self.attacked_ticks > 0)
            .then(|| self.attacked_alarm_ticks as f64 / self.attacked_ticks as f64)
    }

    fn metrics(
        &self,
        control_period_s: f64,
        threshold: Option<f64>,
        calibration: Option<CalibrationMetrics>,
    ) -> DetectorMetrics {
        let free_s = self.free_watched_ticks as f64 * control_period_s;
        let watched_free = self.free_watched_ticks > 0 && free_s > 0.0;
        DetectorMetrics {
            onsets: self.onsets.clone(),
            alarm_on_at_onset: self.alarm_on_at_onset.clone(),
            false_alarms: self.false_alarms,
            false_alarms_per_min: watched_free.then(|| self.false_alarms as f64 * 60.0 / free_s),
            attack_free_watched_s: free_s,
            false_alarm_share: watched_free
                .then(|| self.free_alarm_ticks as f64 / self.free_watched_ticks as f64),
            coverage: self.coverage(),
            watched_from_s: self.watched_from,
            threshold,
            non_finite: self.non_finite,
            missing: self.missing,
            calibration,
        }
    }
}

/// The residual detectors of one robot ([`detect::RESIDUAL`]), with their tallies.
#[derive(Debug, Clone)]
struct Detectors {
    detectors: RobotDetectors,
    /// One per detector of [`detect::RESIDUAL`].
    tallies: Vec<AlarmTally>,
    /// Ticks of the calibration window with the attack in force.
    calibration_attacked: u64,
    window_s: f64,
}

/// Adds one record's squared tracking errors into an [`Acc`], for the model's number of links.
type TrackingFn = fn(&mut Acc, &TickRecord);

#[derive(Debug, Clone)]
struct Acc {
    trajectory: TrajectoryConfig,
    tracking: TrackingFn,
    sum_sq: f64,
    count: u64,
    ticks: u64,
    max_abs: f64,
    /// The paper's alarm (`CenterRecord::alarm`).
    s_hat_norm: AlarmTally,
    /// The classical detectors, when the evaluator has their configuration.
    detectors: Option<Detectors>,
    /// A monitor program's verdicts (`[roles.monitor]`), when the run has one.
    monitor: Option<AlarmTally>,
    links: usize,
    rejected: u64,
    rejected_torques: u64,
    state_resets: u64,
    history_misses: u64,
    missed: u64,
    agent_ticks: u64,
    uncontrolled: u64,
    diverged_at: Option<f64>,
    /// `‖q_d − q‖` of the last tick, rad.
    last_error: f64,
}

impl Acc {
    /// The tracking error `q_d − q` of each of the `N` links: its square into the RMSE, its
    /// magnitude into the maximum, and divergence (non-finite state, or beyond the bound).
    fn track<const N: usize>(&mut self, r: &TickRecord) {
        let t = r.agent.t;
        let qd = self.trajectory.position::<N>(t);
        let q = r.agent.q.to_vector::<N>();
        let mut diverged = r.agent.qd.as_slice().iter().any(|x| !x.is_finite());
        let mut tick_sq = 0.0;
        for i in 0..N {
            let e = qd[i] - q[i];
            self.sum_sq += e * e;
            tick_sq += e * e;
            diverged |= e.is_nan() || e.abs() > DIVERGENCE_BOUND_RAD;
            self.max_abs = self.max_abs.max(e.abs());
        }
        if diverged && self.diverged_at.is_none() {
            self.diverged_at = Some(t);
        }
        self.last_error = tick_sq.sqrt();
        self.count += N as u64;
    }
}

/// Accumulates metrics tick by tick.
#[derive(Debug, Clone)]
pub struct Evaluator {
    agents: BTreeMap<u32, Acc>,
    /// Δ, s, once [`Self::with_detectors`] set it (false alarms per minute).
    control_period_s: Option<f64>,
    /// The threshold of the paper's alarm on `‖Ŝ‖`.
    s_hat_threshold: Option<f64>,
    /// The monitor's name among the detectors ([`Self::with_monitor`]).
    monitor_name: Option<String>,
}

impl Evaluator {
    /// `agents`: `(id, desired trajectory, robot model)`.
    pub fn new(agents: impl IntoIterator<Item = (u32, TrajectoryConfig, ModelConfig)>) -> Self {
        struct Tracking;
        impl ForLinks for Tracking {
            type Output = TrackingFn;
            fn call<const N: usize>(self, _: Box<dyn EulerLagrange<N>>) -> TrackingFn {
                Acc::track::<N>
            }
        }
        let agents = agents
            .into_iter()
            .map(|(id, trajectory, model)| {
                (
                    id,
                    Acc {
                        trajectory,
                        tracking: model.with_links(Tracking),
                        sum_sq: 0.0,
                        count: 0,
                        ticks: 0,
                        max_abs: 0.0,
                        s_hat_norm: AlarmTally::default(),
                        detectors: None,
                        monitor: None,
                        links: model.dof(),
                        rejected: 0,
                        rejected_torques: 0,
                        state_resets: 0,
                        history_misses: 0,
                        missed: 0,
                        agent_ticks: 0,
                        uncontrolled: 0,
                        diverged_at: None,
                        last_error: 0.0,
                    },
                )
            })
            .collect();
        Self {
            agents,
            control_period_s: None,
            s_hat_threshold: None,
            monitor_name: None,
        }
    }

    /// Reports a monitor program's verdicts (`TickRecord::monitor`) beside the detectors, as
    /// detector `name`: a tick without a verdict counts as missing (the alarm keeps its state).
    pub fn with_monitor(mut self, name: &str) -> Self {
        for acc in self.agents.values_mut() {
            acc.monitor = Some(AlarmTally::default());
        }
        self.monitor_name = Some(name.to_string());
        self
    }

    /// Runs the classical detectors of `config` beside the paper's alarm on every agent, and
    /// reports all three per agent in [`AgentMetrics::detectors`]. `control_period_s`: Δ;
    /// `controller`: its β (for the `psi2` residual) and the paper's alarm threshold.
    pub fn with_detectors(
        mut self,
        config: &DetectorsConfig,
        control_period_s: f64,
        controller: &ControllerConfig,
    ) -> Self {
        let beta = controller.beta;
        self.s_hat_threshold = Some(controller.detection.threshold);
        for acc in self.agents.values_mut() {
            acc.detectors = Some(Detectors {
                detectors: RobotDetectors::new(config, control_period_s, beta, acc.links),
                tallies: vec![AlarmTally::default(); detect::RESIDUAL.len()],
                calibration_attacked: 0,
                window_s: config.calibration_s(),
            });
        }
        self.control_period_s = Some(control_period_s);
        self
    }

    /// Feeds one joined tick record (ticks of one agent in order; other agents' records are
    /// interleaved freely).
    pub fn push(&mut self, r: &TickRecord) {
        let Some(acc) = self.agents.get_mut(&r.agent.agent) else {
            return;
        };
        let t = r.agent.t;
        (acc.tracking)(acc, r);
        acc.ticks += 1;
        let active = detect::in_force(r);
        acc.s_hat_norm.push(t, active, r.center.alarm, true);
        if let Some(d) = &mut acc.detectors {
            let verdicts = d.detectors.push(r);
            for (tally, v) in d.tallies.iter_mut().zip(verdicts) {
                tally.push_verdict(t, active, *v);
            }
            if active && r.center.k < d.detectors.calibration_ticks() {
                d.calibration_attacked += 1;
            }
        }
        if let Some(m) = &mut acc.monitor {
            match r.monitor {
                Some(v) => m.push(t, active, v.alarm, true),
                None => m.push_verdict(t, active, Verdict::Missing),
            }
        }
        acc.rejected += u64::from(r.center.rejected_input);
        acc.rejected_torques += u64::from(r.center.rejected_torque);
        acc.state_resets += u64::from(r.center.state_reset);
        acc.history_misses += u64::from(r.center.history_miss);
        acc.missed += u64::from(r.agent.missed);
        acc.agent_ticks += 1;
    }

    /// Whether detector `detector` of agent `agent` is alarming after the last tick pushed: the
    /// index is the detector's in [`detect::names`] (the paper's `s_hat_norm`, then
    /// [`detect::RESIDUAL`]). `None` for an agent or a detector the evaluator does not have
    /// (the residual detectors need [`Self::with_detectors`]).
    pub fn alarm(&self, agent: u32, detector: usize) -> Option<bool> {
        let acc = self.agents.get(&agent)?;
        match detector.checked_sub(1) {
            None => Some(acc.s_hat_norm.prev_alarm),
            Some(i) => acc.detectors.as_ref()?.tallies.get(i).map(|t| t.prev_alarm),
        }
    }

    /// Agent `agent`'s tracking error `‖q_d − q‖` at the last tick pushed, rad, and whether it
    /// has diverged (at that tick or before; [`DIVERGENCE_BOUND_RAD`]). `None` for an agent
    /// the evaluator does not have.
    pub fn tracking(&self, agent: u32) -> Option<(f64, bool)> {
        let acc = self.agents.get(&agent)?;
        Some((acc.last_error, acc.diverged_at.is_some()))
    }

    /// Feeds a tick the robot recorded that has no control-center record: it ran uncontrolled.
    /// Only its deadline miss and the count of such ticks are kept (no RMSE, no detection: the
    /// center computed nothing for it).
    pub fn push_uncontrolled(&mut self, a: &crate::records::AgentRecord) {
        let Some(acc) = self.agents.get_mut(&a.agent) else {
            return;
        };
        acc.missed += u64::from(a.missed);
        acc.agent_ticks += 1;
        acc.uncontrolled += 1;
    }

    pub fn finish(self) -> BTreeMap<u32, AgentMetrics> {
        let (dt, s_hat_threshold) = (self.control_period_s, self.s_hat_threshold);
        let monitor_name = self.monitor_name;
        self.agents
            .into_iter()
            .map(|(id, a)| {
                let mut detectors = match (&a.detectors, dt) {
                    (Some(d), Some(dt)) => detector_metrics(&a, d, dt, s_hat_threshold),
                    _ => BTreeMap::new(),
                };
                if let (Some(m), Some(name), Some(dt)) = (&a.monitor, &monitor_name, dt) {
                    detectors.insert(name.clone(), m.metrics(dt, None, None));
                }
                let m = AgentMetrics {
                    rmse_rad: if a.count > 0 {
                        (a.sum_sq / a.count as f64).sqrt()
                    } else {
                        f64::NAN
                    },
                    // No tick covered (an agent whose trace stayed on a lost host): no maximum,
                    // as no RMSE, rather than a zero that reads as a perfect run.
                    max_abs_error_rad: if a.count > 0 { a.max_abs } else { f64::NAN },
                    alarm_coverage: a.s_hat_norm.coverage_or_zero(),
                    attacked_ticks: a.s_hat_norm.attacked_ticks,
                    false_alarms: a.s_hat_norm.false_alarms,
                    onsets: a.s_hat_norm.onsets,
                    rejected_inputs: a.rejected,
                    rejected_torques: a.rejected_torques,
                    state_resets: a.state_resets,
                    history_misses: a.history_misses,
                    deadline_misses: a.missed,
                    agent_ticks: a.agent_ticks,
                    uncontrolled_ticks: a.uncontrolled,
                    diverged_at_s: a.diverged_at,
                    ticks: a.ticks,
                    detectors,
                };
                (id, m)
            })
            .collect()
    }
}

/// Every detector's metrics of one agent, by name.
fn detector_metrics(
    a: &Acc,
    d: &Detectors,
    dt: f64,
    s_hat_threshold: Option<f64>,
) -> BTreeMap<String, DetectorMetrics> {
    let cal = d.detectors.calibration();
    let calibration = CalibrationMetrics {
        window_s: d.window_s,
        samples: cal.samples,
        attacked_ticks: d.calibration_attacked,
        non_finite: cal.non_finite,
        residual_rms: cal.rms,
        failed: cal.failed,
    };
    let residual = detect::RESIDUAL
        .iter()
        .zip(&d.tallies)
        .enumerate()
        .map(|(i, (k, tally))| {
            let threshold = d.detectors.threshold(i).ok();
            (
                k.name,
                tally.metrics(dt, threshold, Some(calibration.clone())),
            )
        });
    std::iter::once((
        detect::S_HAT_NORM,
        a.s_hat_norm.metrics(dt, s_hat_threshold, None),
    ))
    .chain(residual)
    .map(|(name, m)| (name.to_string(), m))
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::records::{AgentRecord, AttackRecord, CenterRecord, Joints};
    use crate::trajectory::LinkTrajectory;
    use crate::units::AngleUnit;

    fn at_rest() -> TrajectoryConfig {
        TrajectoryConfig {
            units: AngleUnit::Rad,
            ramp_rate: 0.0,
            links: vec![LinkTrajectory::Constant { value: 0.0 }; 2],
            start: Vec::new(),
        }
    }

    fn record(k: u64, q: f64, active: bool, alarm: bool) -> TickRecord {
        let j = |x: f64| Joints::from_slice(&[x, 0.0]);
        TickRecord {
            agent: AgentRecord {
                k,
                agent: 1,
                t: k as f64 * 1e-3,
                q: j(q),
                qd: j(0.0),
                qdd: j(0.0),
                y: j(q),
                yd: j(0.0),
                u_applied: j(0.0),
                tau: 0.003,
                missed: false,
            },
            attack: AttackRecord {
                k,
                agent: 1,
                alpha_position: j(if active { 1.0 } else { 0.0 }),
                alpha_velocity: j(0.0),
                y: j(q),
                yd: j(0.0),
                active,
                delivery: Default::default(),
            },
            center: CenterRecord {
                k,
                agent: 1,
                s_hat: j(0.0),
                q_hat: j(0.0),
                qd_hat: j(0.0),
                qdd_hat: j(0.0),
                u: j(0.0),
                alarm,
                rejected_input: false,
                rejected_torque: false,
                state_reset: false,
                history_miss: false,
                missing_input: false,
            },
            actuation: None,
            monitor: None,
        }
    }

    fn evaluate(records: impl IntoIterator<Item = TickRecord>) -> AgentMetrics {
        let two_link = ModelConfig::TwoLink(crate::model::TwoLinkParams::PAPER);
        let mut e = Evaluator::new([(1, at_rest(), two_link)]);
        for r in records {
            e.push(&r);
        }
        e.finish().remove(&1).expect("agent 1")
    }

    /// Regression: a pulse train was one onset with the attack "in force" over the whole run
    /// (robot 4's alarm coverage read 0.9 %).
    #[test]
    fn every_rising_edge_of_a_pulse_train_is_an_onset_with_its_own_detection() {
        // 5 pulses of 100 ticks every 1000 ticks; the alarm comes 30 ticks into pulses 0, 2, 4
        // and stays on 10 ticks after each of them ends.
        let m = evaluate((0..5000).map(|k| {
            let pulse = k / 1000;
            let phase = k % 1000;
            let active = phase < 100;
            let alarm = pulse % 2 == 0 && (30..110).contains(&phase);
            record(k, 0.0, active, alarm)
        }));
        assert_eq!(m.onsets.len(), 5);
        for (i, o) in m.onsets.iter().enumerate() {
            assert!((o.t_s - i as f64).abs() < 1e-12, "{o:?}");
            assert!((o.until_s.expect("ended") - (i as f64 + 0.1)).abs() < 1e-12);
            match i % 2 {
                0 => assert!((o.time_to_detect_s.expect("detected") - 0.030).abs() < 1e-12),
                _ => assert_eq!(o.time_to_detect_s, None),
            }
        }
        assert_eq!(m.attacked_ticks, 500);
        // 70 of each detected pulse's 100 in-force ticks carry the alarm.
        assert!((m.alarm_coverage - 3.0 * 70.0 / 500.0).abs() < 1e-12);
        // The alarm was already on when each detected pulse ended: no rising edge outside.
        assert_eq!(m.false_alarms, 0);
        assert_eq!(m.diverged_at_s, None);
        assert_eq!(m.ticks, 5000);
    }

    /// Regression (issue 18): the ticks a robot ran uncontrolled (no control-center record)
    /// were left out of everything, its deadline misses too, so a robot that ran 20 s without
    /// control showed 1–3 misses.
    #[test]
    fn uncontrolled_ticks_count_their_deadline_misses_but_no_tracking_metric() {
        let two_link = ModelConfig::TwoLink(crate::model::TwoLinkParams::PAPER);
        let mut e = Evaluator::new([(1, at_rest(), two_link)]);
        for k in 0..100 {
            e.push(&record(k, 0.01, false, false));
        }
        for k in 100..400 {
            let mut a = record(k, 50.0, false, false).agent;
            a.missed = k % 3 == 0;
            e.push_uncontrolled(&a);
        }
        let m = e.finish().remove(&1).expect("agent 1");
        assert_eq!(m.ticks, 100);
        assert_eq!(m.agent_ticks, 400);
        assert_eq!(m.uncontrolled_ticks, 300);
        assert_eq!(m.deadline_misses, 100);
        assert!((m.max_abs_error_rad - 0.01).abs() < 1e-12, "{m:?}");
    }

    fn with_detectors(records: impl IntoIterator<Item = TickRecord>) -> AgentMetrics {
        let r = crate::scenario::paper().expect("paper");
        let two_link = ModelConfig::TwoLink(crate::model::TwoLinkParams::PAPER);
        let mut e = Evaluator::new([(1, at_rest(), two_link)]).with_detectors(
            &DetectorsConfig::defaults(),
            1e-3,
            &r.scenario.controller,
        );
        for r in records {
            e.push(&r);
        }
        e.finish().remove(&1).expect("agent 1")
    }

    /// The paper's alarm as one detector among three: its entry holds the same onsets, false
    /// alarms and coverage as the fields every reader has, plus the rates per attack-free time.
    #[test]
    fn the_s_hat_norm_entry_repeats_the_alarm_fields_and_adds_rates_per_attack_free_minute() {
        let records = || {
            (0..5000).map(|k| {
                let phase = k % 1000;
                let active = phase < 100;
                // Detected pulses 0, 2, 4 (30 ticks in); a false alarm of 50 ticks at 500 in
                // pulses 1 and 3.
                let alarm = (k / 1000 % 2 == 0 && (30..110).contains(&phase))
                    || (k / 1000 % 2 == 1 && (500..550).contains(&phase));
                record(k, 0.0, active, alarm)
            })
        };
        let m = with_detectors(records());
        assert_eq!(
            evaluate(records()).detectors,
            BTreeMap::new(),
            "no detectors without their configuration"
        );
        let s = &m.detectors[detect::S_HAT_NORM];
        assert_eq!(s.onsets, m.onsets);
        assert_eq!(s.alarm_on_at_onset, [false; 5]);
        assert_eq!(s.false_alarms, m.false_alarms);
        assert_eq!(m.false_alarms, 2);
        assert_eq!(s.coverage, Some(m.alarm_coverage));
        assert_eq!(s.threshold, Some(0.6));
        // 4500 attack-free ticks of 1 ms: 4.5 s, 2 false alarms: 26.67 per minute; the alarm
        // was on for 10 ticks after each of the three detected pulses and 50 in each false one.
        assert!((s.attack_free_watched_s - 4.5).abs() < 1e-9);
        let per_min = s.false_alarms_per_min.expect("watched");
        assert!((per_min - 2.0 * 60.0 / 4.5).abs() < 1e-9, "{per_min}");
        let share = s.false_alarm_share.expect("watched");
        assert!((share - 130.0 / 4500.0).abs() < 1e-12, "{share}");
        assert_eq!(s.watched_from_s, Some(0.0));
        assert_eq!(s.calibration, None);
    }

    /// The helper's records carry a residual of zero after the first ticks: the χ² and CUSUM
    /// detectors cannot calibrate, and say so instead of reporting rates.
    #[test]
    fn detectors_that_cannot_calibrate_report_why_and_no_rate() {
        let m = with_detectors((0..3000).map(|k| record(k, 0.0, k >= 2500, false)));
        for name in [detect::CHI2, detect::CUSUM] {
            let d = &m.detectors[name];
            let cal = d.calibration.as_ref().expect("calibrated detectors");
            let why = cal.failed.as_deref().expect("failed");
            assert!(
                why.contains("every residual of the calibration window is zero"),
                "{why}"
            );
            assert_eq!((cal.samples, cal.attacked_ticks), (1999, 0));
            assert_eq!(d.watched_from_s, None);
            assert_eq!((d.false_alarms_per_min, d.false_alarm_share), (None, None));
            assert_eq!(d.coverage, Some(0.0));
            assert_eq!(d.onsets.len(), 1);
            assert_eq!(d.onsets[0].time_to_detect_s, None);
        }
        let short = with_detectors((0..1500).map(|k| record(k, 0.0, k < 10, false)));
        let cal = short.detectors[detect::CHI2]
            .calibration
            .as_ref()
            .expect("calibration");
        assert_eq!(cal.attacked_ticks, 10);
        let why = cal.failed.as_deref().expect("never calibrated");
        assert!(
            why.contains("ended before the detectors could watch"),
            "{why}"
        );
    }

    #[test]
    fn an_alarm_rising_while_no_attack_is_in_force_is_a_false_alarm() {
        let m = evaluate((0..300).map(|k| record(k, 0.0, false, (100..150).contains(&k))));
        assert_eq!(m.false_alarms, 1);
        assert!(m.onsets.is_empty());
    }

    #[test]
    fn a_state_beyond_the_bound_or_not_finite_is_divergence_at_its_first_tick() {
        let m = evaluate((0..100).map(|k| {
            let q = if k < 40 {
                0.01
            } else {
                10f64.powi(k as i32 - 38)
            };
            record(k, q, false, false)
        }));
        // 10^2 = 100 rad at k = 40 is at the bound, 10^3 at k = 41 beyond it.
        assert_eq!(m.diverged_at_s, Some(0.041));
        let m =
            evaluate((0..10).map(|k| record(k, if k < 7 { 0.0 } else { f64::NAN }, false, false)));
        assert_eq!(m.diverged_at_s, Some(0.007));
        assert!(m.rmse_rad.is_nan());
    }
}
