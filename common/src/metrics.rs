//! Run metrics from joined tick records: RMSE per robot (SPEC §7), time-to-detect per attack
//! onset and false alarms (SPEC §4.9).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::records::TickRecord;
use crate::trajectory::TrajectoryConfig;

/// Detection outcome for one attack onset.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Onset {
    /// Onset time, s.
    pub t_s: f64,
    /// Time from onset to the first alarm while the attack lasts; `None` if never raised.
    pub time_to_detect_s: Option<f64>,
}

/// Metrics of one agent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AgentMetrics {
    /// `sqrt(mean over ticks and links of (q_d − q)²)`, rad.
    pub rmse_rad: f64,
    /// Largest `|q_d − q|` over the run, rad.
    pub max_abs_error_rad: f64,
    pub onsets: Vec<Onset>,
    /// Alarm rising edges while no attack was in force.
    pub false_alarms: u64,
    /// Fraction of attacked ticks with the alarm on.
    pub alarm_coverage: f64,
    pub rejected_inputs: u64,
    pub deadline_misses: u64,
}

#[derive(Debug, Clone)]
struct Acc {
    trajectory: TrajectoryConfig,
    onsets: Vec<f64>,
    sum_sq: f64,
    count: u64,
    max_abs: f64,
    detected: Vec<Option<f64>>,
    prev_alarm: bool,
    false_alarms: u64,
    attacked_ticks: u64,
    attacked_alarm_ticks: u64,
    rejected: u64,
    missed: u64,
}

/// Accumulates metrics tick by tick.
#[derive(Debug, Clone)]
pub struct Evaluator {
    agents: BTreeMap<u32, Acc>,
}

impl Evaluator {
    /// `agents`: `(id, desired trajectory, attack onsets)`.
    pub fn new(agents: impl IntoIterator<Item = (u32, TrajectoryConfig, Vec<f64>)>) -> Self {
        let agents = agents
            .into_iter()
            .map(|(id, trajectory, onsets)| {
                let n = onsets.len();
                (
                    id,
                    Acc {
                        trajectory,
                        onsets,
                        sum_sq: 0.0,
                        count: 0,
                        max_abs: 0.0,
                        detected: vec![None; n],
                        prev_alarm: false,
                        false_alarms: 0,
                        attacked_ticks: 0,
                        attacked_alarm_ticks: 0,
                        rejected: 0,
                        missed: 0,
                    },
                )
            })
            .collect();
        Self { agents }
    }

    pub fn push<const N: usize>(&mut self, r: &TickRecord) {
        let Some(acc) = self.agents.get_mut(&r.agent.agent) else {
            return;
        };
        let t = r.agent.t;
        let qd = acc.trajectory.reference::<N>(t).q;
        let q = r.agent.q.to_vector::<N>();
        for i in 0..N {
            let e = qd[i] - q[i];
            acc.sum_sq += e * e;
            acc.max_abs = acc.max_abs.max(e.abs());
        }
        acc.count += N as u64;
        let alarm = r.center.alarm;
        if r.attack.active {
            acc.attacked_ticks += 1;
            if alarm {
                acc.attacked_alarm_ticks += 1;
                // The latest onset at or before t that is still undetected.
                if let Some(i) = acc.onsets.iter().rposition(|o| *o <= t) {
                    if acc.detected[i].is_none() {
                        acc.detected[i] = Some(t - acc.onsets[i]);
                    }
                }
            }
        } else if alarm && !acc.prev_alarm {
            acc.false_alarms += 1;
        }
        acc.prev_alarm = alarm;
        acc.rejected += u64::from(r.center.rejected_input);
        acc.missed += u64::from(r.agent.missed);
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
                    onsets: a
                        .onsets
                        .iter()
                        .zip(&a.detected)
                        .map(|(t, d)| Onset {
                            t_s: *t,
                            time_to_detect_s: *d,
                        })
                        .collect(),
                    false_alarms: a.false_alarms,
                    alarm_coverage: if a.attacked_ticks > 0 {
                        a.attacked_alarm_ticks as f64 / a.attacked_ticks as f64
                    } else {
                        0.0
                    },
                    rejected_inputs: a.rejected,
                    deadline_misses: a.missed,
                };
                (id, m)
            })
            .collect()
    }
}
