//! The detectors' statistics of a joined tick, for both exports (`detectors.csv`, the
//! `/agent<id>/detectors` topics) and the live view: every detector's statistic of each joined
//! tick computed by [`Recorder::observe`] and handed on at once: nothing is kept, so memory
//! does not grow with the run.

use std::collections::BTreeMap;

use anyhow::Result;
use fdi_common::detect::sweep::{Recorder, Sample};
use fdi_common::detect::Verdict;
use fdi_common::records::TickRecord;
use serde_json::{Map, Value};

use super::{fields_of, RunInfo, Sink, DETECTORS};

/// One detector at one tick.
#[derive(Debug, Clone, Copy)]
pub struct Statistic {
    /// The detector's name (`s_hat_norm`, `chi2`, …: [`fdi_common::detect::names`]).
    pub name: &'static str,
    /// Its statistic; `None` without a verdict (calibrating, missing, …).
    pub value: Option<f64>,
    /// Its configured threshold; `None` before it is calibrated.
    pub threshold: Option<f64>,
    /// `watched`, `calibrating`, `non-finite`, `missing` or `uncalibrated`.
    pub verdict: &'static str,
    /// Its alarm at the configured threshold.
    pub alarm: bool,
}

/// Every detector at one joined tick of one robot.
#[derive(Debug)]
pub struct Tick<'a> {
    pub agent: u32,
    pub k: u64,
    /// The tick time `t_k`, s.
    pub t: f64,
    /// An attack was in force on the measurement or the torque.
    pub in_force: bool,
    /// In the order of [`fdi_common::detect::names`].
    pub statistics: &'a [Statistic],
}

/// The names of the detectors of `info`'s run, in the order of [`Tick::statistics`].
pub fn names(info: &RunInfo) -> Vec<&'static str> {
    Recorder::for_scenario(&info.resolved)
        .configured()
        .into_iter()
        .map(|(name, _)| name)
        .collect()
}

/// What a verdict says: statistic (when watched), name.
fn verdict(v: Verdict) -> (Option<f64>, &'static str) {
    match v {
        Verdict::Watched { statistic, .. } => (Some(statistic), "watched"),
        Verdict::Calibrating => (None, "calibrating"),
        Verdict::NonFinite => (None, "non-finite"),
        Verdict::Missing => (None, "missing"),
        Verdict::Uncalibrated => (None, "uncalibrated"),
    }
}

/// Detector `name` (configured `threshold`) at a tick of `sample`; `alarm`: its alarm so far,
/// updated.
fn statistic(
    (name, threshold): (&'static str, Option<f64>),
    sample: &Sample,
    alarm: &mut bool,
) -> Statistic {
    let (value, state) = verdict(sample.verdict);
    *alarm = sample.verdict.alarm(*alarm);
    Statistic {
        name,
        value,
        threshold,
        verdict: state,
        alarm: *alarm,
    }
}

/// The detectors of a run, fed its joined ticks in the join's order (tick, then robot).
pub struct Stats {
    recorder: Recorder,
    configured: Vec<(&'static str, Option<f64>)>,
    /// Per robot, each detector's alarm at its configured threshold so far.
    alarms: BTreeMap<u32, Vec<bool>>,
    statistics: Vec<Statistic>,
}

impl Stats {
    /// The detectors `info`'s scenario configures, before its first tick.
    pub fn new(info: &RunInfo) -> Self {
        let recorder = Recorder::for_scenario(&info.resolved);
        let configured = recorder.configured();
        Self {
            statistics: Vec::with_capacity(configured.len()),
            recorder,
            configured,
            alarms: BTreeMap::new(),
        }
    }

    /// The statistics of the joined tick `r` (every tick must come, in order); `None` for a
    /// tick the detectors do not judge.
    pub fn observe(&mut self, info: &RunInfo, r: &TickRecord) -> Option<Tick<'_>> {
        let samples = self.recorder.observe(r)?;
        let (agent, k) = (r.agent.agent, r.center.k);
        let n = self.configured.len();
        let alarms = self.alarms.entry(agent).or_insert_with(|| vec![false; n]);
        self.statistics.clear();
        self.statistics.extend(
            self.configured
                .iter()
                .zip(&samples)
                .zip(alarms.iter_mut())
                .map(|((c, sample), alarm)| statistic(*c, sample, alarm)),
        );
        Some(Tick {
            agent,
            k,
            t: info.t(k),
            in_force: samples.first().is_some_and(|s| s.in_force),
            statistics: &self.statistics,
        })
    }
}

/// The `/agent<id>/detectors` message of `tick`, into `w`.
pub fn message(w: &mut impl Sink, tick: &Tick) -> Result<()> {
    let mut msg = Map::new();
    msg.insert("k".into(), Value::from(tick.k));
    msg.insert("t_s".into(), Value::from(tick.t));
    msg.insert("in_force".into(), Value::from(tick.in_force));
    for s in tick.statistics {
        let [value, threshold, verdict, alarm] = fields_of(s.name);
        msg.insert(value, s.value.map_or(Value::Null, Value::from));
        msg.insert(threshold, s.threshold.map_or(Value::Null, Value::from));
        msg.insert(verdict, Value::from(s.verdict));
        msg.insert(alarm, Value::from(s.alarm));
    }
    w.message(
        tick.agent,
        "detectors",
        &DETECTORS,
        tick.t,
        &Value::Object(msg),
    )
}
