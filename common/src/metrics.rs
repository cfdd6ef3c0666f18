//! Run metrics from joined tick records: RMSE per robot (SPEC §7), time-to-detect per attack
//! onset and false alarms (SPEC §4.9).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

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
    pub rmse_rad: f64,
    /// Largest `|q_d − q|` over the run, rad.
    pub max_abs_error_rad: f64,
    /// Every rising edge of "attack in force", with its detection.
    pub onsets: Vec<Onset>,
    /// Alarm rising edges while no attack was in force.
    pub false_alarms: u64,
    /// Fraction of in-force ticks with the alarm on.
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
    onsets: Vec<Onset>,
    /// Index in `onsets` of the in-force interval under way.
    in_force: Option<usize>,
    prev_alarm: bool,
    false_alarms: u64,
    attacked_ticks: u64,
    attacked_alarm_ticks: u64,
    rejected: u64,
    rejected_torques: u64,
    state_resets: u64,
    history_misses: u64,
    missed: u64,
    agent_ticks: u64,
    uncontrolled: u64,
    diverged_at: Option<f64>,
}

impl Acc {
    /// The tracking error `q_d − q` of each of the `N` links: its square into the RMSE, its
    /// magnitude into the maximum, and divergence (non-finite state, or beyond the bound).
    fn track<const N: usize>(&mut self, r: &TickRecord) {
        let t = r.agent.t;
        let qd = self.trajectory.reference::<N>(t).q;
        let q = r.agent.q.to_vector::<N>();
        let mut diverged = r.agent.qd.as_slice().iter().any(|x| !x.is_finite());
        for i in 0..N {
            let e = qd[i] - q[i];
            self.sum_sq += e * e;
            diverged |= e.is_nan() || e.abs() > DIVERGENCE_BOUND_RAD;
            self.max_abs = self.max_abs.max(e.abs());
        }
        if diverged && self.diverged_at.is_none() {
            self.diverged_at = Some(t);
        }
        self.count += N as u64;
    }
}

/// Accumulates metrics tick by tick.
#[derive(Debug, Clone)]
pub struct Evaluator {
    agents: BTreeMap<u32, Acc>,
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
                        onsets: Vec::new(),
                        in_force: None,
                        prev_alarm: false,
                        false_alarms: 0,
                        attacked_ticks: 0,
                        attacked_alarm_ticks: 0,
                        rejected: 0,
                        rejected_torques: 0,
                        state_resets: 0,
                        history_misses: 0,
                        missed: 0,
                        agent_ticks: 0,
                        uncontrolled: 0,
                        diverged_at: None,
                    },
                )
            })
            .collect();
        Self { agents }
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
        let alarm = r.center.alarm;
        if r.attack.active {
            acc.attacked_ticks += 1;
            let i = *acc.in_force.get_or_insert_with(|| {
                acc.onsets.push(Onset {
                    t_s: t,
                    time_to_detect_s: None,
                    until_s: None,
                });
                acc.onsets.len() - 1
            });
            if alarm {
                acc.attacked_alarm_ticks += 1;
                let onset = &mut acc.onsets[i];
                if onset.time_to_detect_s.is_none() {
                    onset.time_to_detect_s = Some(t - onset.t_s);
                }
            }
        } else {
            if let Some(i) = acc.in_force.take() {
                acc.onsets[i].until_s = Some(t);
            }
            if alarm && !acc.prev_alarm {
                acc.false_alarms += 1;
            }
        }
        acc.prev_alarm = alarm;
        acc.rejected += u64::from(r.center.rejected_input);
        acc.rejected_torques += u64::from(r.center.rejected_torque);
        acc.state_resets += u64::from(r.center.state_reset);
        acc.history_misses += u64::from(r.center.history_miss);
        acc.missed += u64::from(r.agent.missed);
        acc.agent_ticks += 1;
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
        self.agents
            .into_iter()
            .map(|(id, a)| {
                let m = AgentMetrics {
                    rmse_rad: if a.count > 0 {
                        (a.sum_sq / a.count as f64).sqrt()
                    } else {
                        f64::NAN
                    },
                    max_abs_error_rad: a.max_abs,
                    onsets: a.onsets,
                    false_alarms: a.false_alarms,
                    alarm_coverage: if a.attacked_ticks > 0 {
                        a.attacked_alarm_ticks as f64 / a.attacked_ticks as f64
                    } else {
                        0.0
                    },
                    attacked_ticks: a.attacked_ticks,
                    rejected_inputs: a.rejected,
                    rejected_torques: a.rejected_torques,
                    state_resets: a.state_resets,
                    history_misses: a.history_misses,
                    deadline_misses: a.missed,
                    agent_ticks: a.agent_ticks,
                    uncontrolled_ticks: a.uncontrolled,
                    diverged_at_s: a.diverged_at,
                    ticks: a.ticks,
                };
                (id, m)
            })
            .collect()
    }
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
            },
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
