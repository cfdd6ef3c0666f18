//! `fdi-launch detect TARGET`: ROC and detection delay of every detector over one recorded run
//! (docs/detectors.md, "ROC and detection delay").
//!
//! The run's traces are joined as `report` joins them ([`join::join_run_until`]); the joined
//! records feed [`Recorder`], which keeps each detector's per-tick statistic, and every
//! threshold of the sweep replays the alarm from it ([`fdi_common::detect::sweep`]). Nothing is
//! simulated again. (`fdi-launch detect` runs a scenario TARGET first, by `run`'s own code path.)

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use fdi_common::detect::sweep::{self, Point, Recorded, Recorder, Tally};
use fdi_common::engine::RunSummary;
use fdi_common::scenario::{self, Resolved};

use crate::detect_figures::{self, Swept};
use crate::join;
use crate::output::csv_bytes;
use fdi_common::run_dir::RunDir;
use fdi_common::stop::Stop;

/// An interrupt while the sweep ran: what it would have written is not.
pub const WHILE_SWEEPING: &str =
    "while the detectors were swept: the run directory is as it was, the sweep's outputs were not written";

/// The columns of `roc.csv`.
pub const CSV_HEADER: [&str; 15] = [
    "detector",
    "agent",
    "threshold",
    "configured",
    "tpr",
    "fpr",
    "false_alarms_per_min",
    "mean_delay_s",
    "detected_onsets",
    "onsets",
    "alarm_on_at_onset",
    "in_force_ticks",
    "attack_free_ticks",
    "no_verdict_ticks",
    "note",
];

/// Sweeps every detector's threshold over the recorded run in `run_dir` and writes `roc.csv`,
/// the ROC and the delay figures into `out` (default `<run dir>/detect`); says the summary
/// (`log`), returns the files written.
pub fn sweep_run(
    run: &RunDir,
    out: Option<&Path>,
    points: u32,
    stop: &Stop,
) -> Result<Vec<PathBuf>> {
    let run_dir = run.path();
    let out = out.map_or_else(|| run.file("detect"), Path::to_path_buf);
    let (resolved, recorded, summary) = record(run_dir, stop)?;
    let swept: Vec<Swept> = recorded
        .detectors
        .iter()
        .map(|d| Swept {
            name: d.name,
            points: sweep::sweep(d, points as usize),
        })
        .collect();
    stop.check(WHILE_SWEEPING)?;
    for w in cross_check(&swept, &summary) {
        log::warn!("{w}");
    }
    print_summary(&swept, recorded.control_period_s);
    write(&out, &resolved, &swept, recorded.control_period_s)
}

/// Joins the traces of `run_dir` and records every detector's statistic; the summary the join
/// recomputed comes along (for [`cross_check`]).
fn record(run_dir: &Path, stop: &Stop) -> Result<(Resolved, Recorded, RunSummary)> {
    let dir = RunDir::new(run_dir);
    let scenario_path = dir.scenario();
    if !scenario_path.is_file() {
        bail!(
            "{}: not found: {} is not a run directory written by `fdi-launch run`",
            scenario_path.display(),
            run_dir.display()
        );
    }
    let resolved = scenario::load_written(&scenario_path)
        .with_context(|| format!("reading the scenario of run {}", run_dir.display()))?;
    crate::traces::require_every_tick(&RunDir::new(run_dir), "detect")?;
    let traces = dir.traces();
    if !traces.is_dir() {
        bail!(
            "{}: not found: run {} has no traces to replay (a run directory written by `fdi-launch run` keeps them there)",
            traces.display(),
            run_dir.display()
        );
    }
    log::info!("detect: joining the traces of {}", run_dir.display());
    let mut recorder = Recorder::for_scenario(&resolved);
    let mut records = 0u64;
    let joined = join::join_run_until(
        &resolved,
        run_dir,
        f64::NAN,
        |r| {
            records += 1;
            recorder.push(r);
        },
        || Ok(stop.check(WHILE_SWEEPING)?),
    )
    .with_context(|| format!("joining the traces in {}", traces.display()))?;
    for w in &joined.warnings {
        log::warn!("{w}");
    }
    if records == 0 {
        bail!(
            "{}: the traces hold no tick that the control center computed: nothing to sweep",
            traces.display()
        );
    }
    let recorded = recorder.finish();
    log::info!(
        "detect: {records} tick records of {} robots",
        resolved.agent_count()
    );
    for (id, n) in &recorded.s_hat_mismatches {
        if *n > 0 {
            log::warn!(
                "robot {id}: the ‖Ŝ‖ alarm replayed at its threshold differs from the center's recorded alarm at {n} ticks (the records are not every tick the center computed, in order)"
            );
        }
    }
    Ok((resolved, recorded, joined.summary))
}

/// At each detector's configured threshold, the sweep must give what the metrics of the same
/// records gave (false alarms, onsets detected, alarmed share of attack-free time): the
/// differences, in words.
fn cross_check(swept: &[Swept], summary: &RunSummary) -> Vec<String> {
    let mut out = Vec::new();
    for s in swept {
        let Some(at) = s.points.iter().find(|p| p.configured) else {
            continue;
        };
        for (id, t) in &at.robots {
            let Some(m) = summary
                .metrics
                .get(&id.to_string())
                .and_then(|m| m.detectors.get(s.name))
            else {
                continue;
            };
            let detected = m
                .onsets
                .iter()
                .filter(|o| o.time_to_detect_s.is_some())
                .count() as u64;
            if t.false_alarms != m.false_alarms
                || t.onsets != m.onsets.len() as u64
                || t.detected != detected
                || t.fpr() != m.false_alarm_share
            {
                out.push(format!(
                    "{} on robot {id} at its threshold {}: the sweep counts {} false alarms, {} of {} onsets detected, FPR {:?}; the metrics {}, {detected} of {}, {:?}",
                    s.name,
                    at.threshold,
                    t.false_alarms,
                    t.detected,
                    t.onsets,
                    t.fpr(),
                    m.false_alarms,
                    m.onsets.len(),
                    m.false_alarm_share
                ));
            }
        }
    }
    out
}

/// A rate (four decimals), or why there is none.
fn rate(x: Option<f64>, undefined: &str) -> String {
    x.map_or(undefined.to_string(), |x| format!("{x:.4}"))
}

/// Says the pooled figures of every detector at its configured threshold.
fn print_summary(swept: &[Swept], dt: f64) {
    for s in swept {
        let grid = s.points.len();
        let Some(at) = s.points.iter().find(|p| p.configured) else {
            log::info!(
                "detect: {}: {grid} thresholds, no configured threshold",
                s.name
            );
            continue;
        };
        let t = &at.pooled;
        let delay = t
            .mean_delay_s()
            .map_or("none detected".to_string(), |d| format!("{d:.3} s"));
        log::info!(
            "detect: {}: {grid} thresholds; at its threshold {}: TPR {}, FPR {}, {} false alarms/min, mean delay {delay} ({} of {} onsets detected, {} with the alarm already on), {} ticks without verdict",
            s.name,
            detect_figures::short(at.threshold),
            rate(t.tpr(), "undefined (no watched tick in force)"),
            rate(t.fpr(), "undefined (no watched attack-free tick)"),
            t.false_alarms_per_min(dt)
                .map_or("undefined".to_string(), |x| format!("{x:.2}")),
            t.detected,
            t.onsets,
            t.alarm_on_at_onset,
            t.no_verdict_ticks
        );
    }
    if swept
        .iter()
        .all(|s| s.points.iter().all(|p| p.pooled.onsets == 0))
    {
        log::info!(
            "detect: the run has no attack onset: the true-positive rate and the detection delay are undefined (left empty in roc.csv, with a note); only false-positive rates and false alarms are measured"
        );
    }
}

/// Why a row's empty fields are empty.
fn note(t: &Tally) -> String {
    let mut why = Vec::new();
    if t.onsets == 0 {
        why.push("no attack onset: TPR and delay undefined".to_string());
    } else if t.in_force_ticks == 0 {
        why.push("no watched tick with the attack in force: TPR undefined".to_string());
    }
    if t.onsets > 0 && t.detected == 0 {
        why.push(format!("none of {} onsets detected: no delay", t.onsets));
    }
    if t.free_ticks == 0 {
        why.push("no watched attack-free tick: FPR and false alarms undefined".to_string());
    }
    why.join("; ")
}

fn opt(x: Option<f64>) -> String {
    x.map_or(String::new(), |x| x.to_string())
}

/// The row of one tally.
fn row(name: &str, agent: &str, p: &Point, t: &Tally, configured: bool, dt: f64) -> Vec<String> {
    vec![
        name.to_string(),
        agent.to_string(),
        p.threshold.to_string(),
        configured.to_string(),
        opt(t.tpr()),
        opt(t.fpr()),
        opt(t.false_alarms_per_min(dt)),
        opt(t.mean_delay_s()),
        t.detected.to_string(),
        t.onsets.to_string(),
        t.alarm_on_at_onset.to_string(),
        t.in_force_ticks.to_string(),
        t.free_ticks.to_string(),
        t.no_verdict_ticks.to_string(),
        note(t),
    ]
}

/// `roc.csv`: per detector, the pooled rows (`agent` = `all`), then each robot's, thresholds
/// ascending.
pub fn csv(swept: &[Swept], dt: f64) -> Result<Vec<u8>> {
    let mut rows = Vec::new();
    for s in swept {
        for p in &s.points {
            rows.push(row(s.name, "all", p, &p.pooled, p.configured, dt));
        }
        let ids: Vec<u32> = s
            .points
            .first()
            .map(|p| p.robots.keys().copied().collect())
            .unwrap_or_default();
        for id in ids {
            for p in &s.points {
                if let Some(t) = p.robots.get(&id) {
                    rows.push(row(s.name, &id.to_string(), p, t, p.configured, dt));
                }
            }
        }
    }
    csv_bytes(&CSV_HEADER, rows).context("writing roc.csv")
}

/// Writes `roc.csv` and the figures into `out`; returns the paths written.
fn write(out: &Path, resolved: &Resolved, swept: &[Swept], dt: f64) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let csv_path = out.join("roc.csv");
    std::fs::write(&csv_path, csv(swept, dt)?)
        .with_context(|| format!("writing {}", csv_path.display()))?;
    let mut written = vec![csv_path];
    let title = format!(
        "{} (attack {}), pooled over {} robots",
        resolved.scenario.name,
        resolved.attack.name,
        resolved.agent_count()
    );
    match detect_figures::roc(swept, &title) {
        Some(fig) => written.extend(
            crate::plot::save_figure(&fig, &out.join("roc"), detect_figures::ROC_SIZE)
                .context("figure roc")?,
        ),
        None => log::info!(
            "detect: no ROC figure: no threshold has both a true- and a false-positive rate"
        ),
    }
    match detect_figures::delay(swept, &title) {
        Some(fig) => written.extend(
            crate::plot::save_figure(&fig, &out.join("delay"), detect_figures::DELAY_SIZE)
                .context("figure delay")?,
        ),
        None => log::info!(
            "detect: no delay figure: no threshold detected an onset where a false-positive rate is defined"
        ),
    }
    Ok(written)
}
