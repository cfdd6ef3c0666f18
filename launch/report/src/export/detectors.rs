//! The detectors' statistics of a run, for both exports (`detectors.csv`, the
//! `/agent<id>/detectors` topics): the run's traces joined as `fdi-launch detect` joins them, and
//! every detector's statistic of each joined tick computed by [`Recorder::observe`] and handed
//! on at once: nothing is kept, so memory does not grow with the run.

use std::cell::Cell;
use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};
use fdi_common::detect::sweep::{Recorder, Sample};
use fdi_common::detect::Verdict;
use fdi_common::records::TickRecord;

use super::sources::RunInfo;
use crate::join;
use crate::traces::{recorded, Recorded};

/// One detector at one tick.
#[derive(Debug, Clone, Copy)]
pub(super) struct Statistic {
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
pub(super) struct Tick<'a> {
    pub agent: u32,
    pub k: u64,
    /// The tick time `t_k`, s.
    pub t: f64,
    /// An attack was in force on the measurement or the torque.
    pub in_force: bool,
    /// In the order of [`fdi_common::detect::names`].
    pub statistics: &'a [Statistic],
}

/// The fields of detector `name` in both exports, in the order of [`Statistic`]'s: statistic,
/// configured threshold, verdict, alarm.
pub(super) fn fields_of(name: &str) -> [String; 4] {
    [
        name.to_string(),
        format!("{name}_threshold"),
        format!("{name}_verdict"),
        format!("{name}_alarm"),
    ]
}

/// The names of the detectors of `info`'s run, in the order of [`Tick::statistics`].
pub(super) fn names(info: &RunInfo) -> Vec<&'static str> {
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

/// Hands `emit` every joined tick of the traces of `run_dir` with its detectors' statistics,
/// in the join's order (tick, then robot). The number of ticks handed on, or the line that
/// says why there are none: traces that keep every K-th tick only (`--traces decimate=K`)
/// cannot give them (a detector's statistic follows every tick), and none is made up. The
/// first error of `emit` stops the join and is the error. The join's warnings go to stderr (a
/// damaged trace is named by the export of its own records).
pub(super) fn each_tick(
    run_dir: &Path,
    info: &RunInfo,
    mut emit: impl FnMut(&Tick) -> Result<()>,
) -> Result<Result<u64, String>> {
    if let Recorded::Decimated(k) = recorded(run_dir)? {
        return Ok(Err(format!(
            "no detector statistics: the traces keep every {k}-th tick only \
             (`--traces decimate={k}`) and the detectors need every tick"
        )));
    }
    let mut recorder = Recorder::for_scenario(&info.resolved);
    let configured = recorder.configured();
    // Per robot, each detector's alarm at its configured threshold so far.
    let mut alarms: BTreeMap<u32, Vec<bool>> = BTreeMap::new();
    let mut statistics = Vec::with_capacity(configured.len());
    let mut n = 0;
    // The first error of `emit`: it stops the join and is the error.
    let mut failure: Option<anyhow::Error> = None;
    let stopped = Cell::new(false);
    let joined = join::join_run_until(
        &info.resolved,
        run_dir,
        f64::NAN,
        |r: &TickRecord| {
            if failure.is_some() {
                return;
            }
            let Some(samples) = recorder.observe(r) else {
                return;
            };
            let (agent, k) = (r.agent.agent, r.center.k);
            let alarms = alarms
                .entry(agent)
                .or_insert_with(|| vec![false; configured.len()]);
            statistics.clear();
            statistics.extend(
                configured
                    .iter()
                    .zip(&samples)
                    .zip(alarms.iter_mut())
                    .map(|((c, sample), alarm)| statistic(*c, sample, alarm)),
            );
            let tick = Tick {
                agent,
                k,
                t: info.t(k),
                in_force: samples.first().is_some_and(|s| s.in_force),
                statistics: &statistics,
            };
            match emit(&tick) {
                Ok(()) => n += 1,
                Err(e) => {
                    failure = Some(e);
                    stopped.set(true);
                }
            }
        },
        || {
            if stopped.get() {
                bail!("a detector statistic could not be written");
            }
            Ok(())
        },
    );
    if let Some(e) = failure {
        return Err(e);
    }
    let joined = joined.with_context(|| {
        format!(
            "joining the traces in {} for the detector statistics",
            fdi_common::run_dir::RunDir::new(run_dir).traces().display()
        )
    })?;
    for warning in &joined.warnings {
        eprintln!("fdi-launch: warning: detector statistics: {warning}");
    }
    Ok(Ok(n))
}
