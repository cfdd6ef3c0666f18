//! Run directories: `runs/<timestamp>-<name>/` with the scenario as used, the traces,
//! `summary.json` and the RMSE table as markdown and CSV.

use std::fmt::Write as _;
use std::path::Path;

use fdi_common::run_dir::RunDir;

use anyhow::{Context, Result};
use fdi_common::control::ControllerMode;
use fdi_common::detect;
use fdi_common::engine::RunSummary;
use fdi_common::metrics::{AgentMetrics, DetectorMetrics};

/// The RMSE of one robot as a table cell, or `diverged at t = … s` for a robot that diverged.
pub fn rmse_cell(m: &AgentMetrics, decimals: usize) -> String {
    match m.diverged_at_s {
        Some(t) => format!("diverged at t = {t:.3} s"),
        None => format!("{:.decimals$}", m.rmse_rad),
    }
}

/// What a partial run's figures cover, e.g. `partial run (interrupted by SIGINT): every metric
/// covers the 2862 ticks recorded (2.862 s) of 20000 planned`; `None` for a whole run.
pub fn partial_notice(s: &RunSummary) -> Option<String> {
    s.partial.as_ref().map(|p| {
        format!(
            "partial run ({}): every metric covers the {} ticks recorded ({:.3} s) of {} planned",
            p.reason, s.ticks, s.sim_s, p.planned_ticks
        )
    })
}

/// The share of the planned run some metrics cover: `5552 of 6000 ticks (92.5 %)`.
pub fn coverage(ticks: u64, planned: u64) -> String {
    if planned == 0 {
        return format!("{ticks} ticks");
    }
    format!(
        "{ticks} of {planned} ticks ({:.1} %)",
        100.0 * ticks as f64 / planned as f64
    )
}

/// The table of a run's metrics the command line prints after a run (one row per robot: RMSE,
/// maximum error, onsets and their time to detect, false alarms, deadline misses, uncontrolled
/// ticks, coverage), as markdown, each line ending in a newline.
pub fn metrics_table(s: &RunSummary) -> String {
    let mut t = String::from("| robot | RMSE (rad) | max abs error (rad) | onsets: time to detect (s) | false alarms | deadline misses | uncontrolled ticks | metrics cover |\n|---|---|---|---|---|---|---|---|\n");
    for (id, m) in &s.metrics {
        let _ = writeln!(
            t,
            "| {id} | {} | {:.4} | {} | {} | {} | {} | {} |",
            rmse_cell(m, 4),
            m.max_abs_error_rad,
            describe_onsets(&m.onsets),
            m.false_alarms,
            m.deadline_misses,
            m.uncontrolled_ticks,
            coverage(m.ticks, s.planned_ticks)
        );
    }
    t
}

/// A line per robot whose control center reset its observer and estimator (their state
/// became non-finite, docs/faults.md): the estimate `Ŝ` and the alarms of such a robot are not
/// the estimator's at work, whatever its RMSE says.
///
/// Under the traditional controller (no estimator: `Ŝ ≡ 0`, the torque does not read the
/// observer) what a reset spoils is the observer's record and what reads it.
pub fn state_reset_warnings(s: &RunSummary) -> Vec<String> {
    let traditional = s.controller == ControllerMode::Traditional.as_str();
    s.metrics
        .iter()
        .filter(|(_, m)| m.state_resets > 0)
        .map(|(id, m)| {
            let times = format!(
                "{} time{}",
                m.state_resets,
                if m.state_resets == 1 { "" } else { "s" }
            );
            if traditional {
                format!(
                    "robot {id}: the control center reset its observer {times} (its state \
                     became non-finite): the traditional controller's torque does not read it, \
                     but its q̂ in the traces and the residual detectors do (report.md: state \
                     resets)"
                )
            } else {
                format!(
                    "robot {id}: the control center reset its observer and estimator {times} \
                     (their state became non-finite): its Ŝ and alarms are not the \
                     estimator's at work (report.md: state resets)"
                )
            }
        })
        .collect()
}

/// A line per robot some of whose torques the control center replaced by the last good one
/// (computed non-finite, or a controller program's answer non-finite or of the wrong joint
/// count, docs/faults.md): for those ticks the robot did not get its controller's torque.
pub fn rejected_torque_warnings(s: &RunSummary) -> Vec<String> {
    s.metrics
        .iter()
        .filter(|(_, m)| m.rejected_torques > 0)
        .map(|(id, m)| {
            format!(
                "robot {id}: {} torque{} replaced by the last good one (non-finite, or a \
                 controller program's answer of the wrong joint count): for those ticks it did \
                 not get its controller's torque (rmse.md: rejected torques)",
                m.rejected_torques,
                if m.rejected_torques == 1 {
                    " was"
                } else {
                    "s were"
                }
            )
        })
        .collect()
}

/// Onsets as `t: time to detect` (`never` when undetected); a long train is summarised.
pub fn describe_onsets(onsets: &[fdi_common::metrics::Onset]) -> String {
    let one = |o: &fdi_common::metrics::Onset| {
        format!(
            "{:.1}: {}",
            o.t_s,
            o.time_to_detect_s
                .map_or("never".into(), |d| format!("{d:.3}"))
        )
    };
    if onsets.len() <= 4 {
        return onsets.iter().map(one).collect::<Vec<_>>().join(", ");
    }
    let mut detected: Vec<f64> = onsets.iter().filter_map(|o| o.time_to_detect_s).collect();
    detected.sort_by(f64::total_cmp);
    let median = detected
        .get(detected.len() / 2)
        .map_or("-".into(), |d| format!("{d:.3}"));
    format!(
        "{} onsets (first {}), {} detected, median {median}",
        onsets.len(),
        one(&onsets[0]),
        detected.len()
    )
}

/// Writes `summary.json`, `rmse.md` and `rmse.csv`.
pub fn write_summary(run: &RunDir, s: &RunSummary) -> Result<()> {
    let dir = run.path();
    write_summary_json(dir, serde_json::to_value(s)?)?;
    write_tables(dir, s)
}

/// [`write_summary`] of a run that kept `traces` of its traces: `summary.json` says so in its
/// `traces` field (`full`, `decimate=K`, `none`); its metrics and digest cover every tick.
pub fn write_run_summary(
    run: &RunDir,
    s: &RunSummary,
    traces: crate::traces::Traces,
) -> Result<()> {
    let dir = run.path();
    let mut v = serde_json::to_value(s)?;
    v["traces"] = serde_json::Value::String(traces.to_string());
    write_summary_json(dir, v)?;
    write_tables(dir, s)
}

fn write_summary_json(dir: &Path, v: serde_json::Value) -> Result<()> {
    std::fs::write(
        fdi_common::run_dir::RunDir::new(dir).summary(),
        serde_json::to_string_pretty(&v)? + "\n",
    )
    .context("writing summary.json")
}

/// The network path of a run split over hosts, in a line (None on one host): whether it was
/// authenticated, and the frames refused on it.
pub fn network_line(s: &RunSummary) -> Option<String> {
    let n = s.network.as_ref()?;
    let how = if n.authenticated {
        "TLS with mutual authentication and per-host access control"
    } else {
        "plain TCP, NOT authenticated: anyone on the network could read and write it (the \
         deployment file says `insecure = true`)"
    };
    let refused = match n.refused_frames {
        0 => "no frame refused".to_string(),
        k => format!(
            "{k} frames REFUSED on the run's keys ({}): the run's data may have been altered \
             outside the attacker process, its results cannot be attributed to its attack",
            n.refusals.join("; ")
        ),
    };
    Some(format!("network path: {how}; {refused}"))
}

/// What the live server of a run watched live (`--live`) did, in a line (None otherwise).
pub fn live_line(s: &RunSummary) -> Option<String> {
    let l = s.live.as_ref()?;
    let mut line = format!(
        "live: {} served {} clients; {} ticks published ({} messages)",
        l.address, l.clients, l.ticks_published, l.messages_published
    );
    if l.records_dropped > 0 {
        line.push_str(&format!(
            "; {} records DROPPED (the server fell behind; the run did not wait): the live \
             detector statistics stopped at the first",
            l.records_dropped
        ));
    }
    if l.events_dropped > 0 {
        line.push_str(&format!(
            "; {} events and latency stamps dropped",
            l.events_dropped
        ));
    }
    if l.client_messages_dropped > 0 {
        line.push_str(&format!(
            "; {} messages dropped for slow clients (oldest first; the run did not wait)",
            l.client_messages_dropped
        ));
    }
    if l.clients_let_go > 0 {
        line.push_str(&format!(
            "; {} clients let go (control messages unread, or too many connections)",
            l.clients_let_go
        ));
    }
    if l.clients_outside_the_door > 0 {
        line.push_str(&format!(
            "; {} clients connected to the server's loopback port directly, not through its door \
             (a process of this machine: docs/security.md)",
            l.clients_outside_the_door
        ));
    }
    if let Some(e) = &l.error {
        line.push_str(&format!("; a message could not be made: {e}"));
    }
    Some(line)
}

/// The attack of a run as its header names it: `attack paper`, or `attack: external program
/// python3 attacker.py` when a program took the attacker role (its attack profile, `none`,
/// would misstate the run).
pub fn attack_words(s: &RunSummary) -> String {
    if s.attack
        .starts_with(fdi_common::scenario::EXTERNAL_ATTACK_PREFIX)
    {
        format!("attack: {}", s.attack)
    } else {
        format!("attack {}", s.attack)
    }
}

/// The controller and numerics options of a run beyond its mode (which its header names):
/// `the paper's calibration (docs/model.md, "Gains")` or each difference with the paper's value.
pub fn numerics_line(s: &RunSummary) -> String {
    let beyond_mode: Vec<_> = s
        .numerics
        .iter()
        .filter(|d| d.field != "controller.mode")
        .cloned()
        .collect();
    fdi_common::numerics::describe(&beyond_mode)
}

fn write_tables(dir: &Path, s: &RunSummary) -> Result<()> {
    let mut md = format!(
        "# RMSE of run `{}` ({} engine, {} clock, {} controller, attack `{}`)\n\nNumerics: {}.\n\n",
        s.scenario,
        s.engine,
        s.clock,
        s.controller,
        s.attack,
        numerics_line(s)
    );
    if let Some(notice) = partial_notice(s) {
        let _ = writeln!(md, "**{notice}.**\n");
    }
    md.push_str("| robot | RMSE (rad) | max abs error (rad) | false alarms | deadline misses | rejected inputs | rejected torques | state resets | uncontrolled ticks | metrics cover |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for (id, m) in &s.metrics {
        let _ = writeln!(
            md,
            "| {id} | {} | {:.5} | {} | {} | {} | {} | {} | {} | {} |",
            rmse_cell(m, 5),
            m.max_abs_error_rad,
            m.false_alarms,
            m.deadline_misses,
            m.rejected_inputs,
            m.rejected_torques,
            m.state_resets,
            m.uncontrolled_ticks,
            coverage(m.ticks, s.planned_ticks)
        );
    }
    if !s.lost_agents.is_empty() {
        let _ = writeln!(
            md,
            "\nDeadline misses count every step the robot itself recorded, the uncontrolled ones too; the other columns cover only the ticks the control center computed."
        );
    }
    md.push_str(&detector_tables(s, 2));
    std::fs::write(dir.join("rmse.md"), md).context("writing rmse.md")?;
    std::fs::write(dir.join("rmse.csv"), rmse_csv(s)?).context("writing rmse.csv")?;
    Ok(())
}

/// The detectors of a robot's metrics in table order: the built-in ones ([`detect::names`]),
/// then a monitor program's (`[roles.monitor]`, under its own name).
pub fn detector_names(m: &AgentMetrics) -> Vec<&str> {
    let mut names: Vec<&str> = detect::names();
    names.extend(
        m.detectors
            .keys()
            .map(String::as_str)
            .filter(|n| detect::title(n).is_none()),
    );
    names
}

/// `a`, `a and b`, `a, b and c`.
pub fn join_words<S: AsRef<str>>(words: &[S]) -> String {
    match words {
        [] => String::new(),
        [one] => one.as_ref().to_string(),
        [init @ .., last] => {
            let init: Vec<&str> = init.iter().map(AsRef::as_ref).collect();
            format!("{} and {}", init.join(", "), last.as_ref())
        }
    }
}

/// The detectors side by side (`rmse.md`, `report.md`): per robot a table with a column per
/// detector ([`detector_names`]), under a heading of `level` (`##` for 2), each robot one level
/// below. Empty for a summary without detector metrics (written before they existed).
pub fn detector_tables(s: &RunSummary, level: usize) -> String {
    let mut md = String::new();
    if s.metrics.values().all(|m| m.detectors.is_empty()) {
        return md;
    }
    let (h, h_robot) = ("#".repeat(level), "#".repeat(level + 1));
    let _ = writeln!(md, "\n{h} Detectors side by side\n");
    let phrases: Vec<&str> = detect::RESIDUAL.iter().map(|k| k.phrase).collect();
    let _ = writeln!(
        md,
        "The paper's alarm (`s_hat_norm`: ‖Ŝ‖ above its threshold for its hold time) beside {} \
         on the observer's residual, calibrated at the start of the run \
         (docs/detectors.md). Times to detect in s from each onset; `already on`: the alarm was on at \
         the tick before the onset (no detection of its own); `missed`: no alarm while that \
         attack was in force; `not watched`: it ended before the detector started watching. \
         False alarms count alarm rising edges while no attack was in force, per minute of the \
         attack-free time the detector watched.",
        join_words(&phrases)
    );
    let monitors: std::collections::BTreeSet<&str> = s
        .metrics
        .values()
        .flat_map(|m| m.detectors.keys().map(String::as_str))
        .filter(|n| detect::title(n).is_none())
        .collect();
    for n in &monitors {
        let _ = writeln!(
            md,
            "\n`{n}`: the verdicts of the monitor program (`[roles.monitor]`, docs/protocol.md), \
             as it published them; `missing` counts the ticks it gave no verdict on."
        );
    }
    for (id, m) in &s.metrics {
        if m.detectors.is_empty() {
            continue;
        }
        // Not `Robot {id}`: report.md's figure sections are `## Robot {id}`.
        let _ = writeln!(md, "\n{h_robot} Detectors of robot {id}\n");
        let names = detector_names(m);
        let cols: Vec<Option<&DetectorMetrics>> =
            names.iter().map(|n| m.detectors.get(*n)).collect();
        detector_rows(&mut md, m, &names, &cols);
        calibration_line(&mut md, &cols);
    }
    md
}

/// The rows of one robot's detector table: a column per detector of `cols`.
fn detector_rows(
    md: &mut String,
    m: &AgentMetrics,
    names: &[&str],
    cols: &[Option<&DetectorMetrics>],
) {
    let mut head = vec![""];
    head.extend(names);
    md.push_str(&md_table_head(&head));
    let mut row = |label: String, cell: &dyn Fn(&DetectorMetrics) -> String| {
        let cells: Vec<String> = cols
            .iter()
            .map(|d| d.map_or_else(|| "absent".into(), cell))
            .collect();
        let _ = writeln!(md, "| {label} | {} |", cells.join(" | "));
    };
    for (i, o) in m.onsets.iter().enumerate() {
        row(
            format!("onset at {:.3} s: time to detect (s)", o.t_s),
            &|d| time_to_detect_cell(d, i, o.t_s),
        );
    }
    if m.onsets.is_empty() {
        row("attack onsets".into(), &|_| "none".into());
    }
    row("false alarms".into(), &|d| d.false_alarms.to_string());
    row("false alarms per minute".into(), &|d| {
        d.false_alarms_per_min.map_or_else(
            || "no attack-free time watched".into(),
            |x| format!("{x:.2}"),
        )
    });
    row("alarm share of attack-free time".into(), &|d| {
        d.false_alarm_share
            .map_or_else(|| "—".into(), |x| format!("{:.1} %", 100.0 * x))
    });
    row("coverage of attacked ticks".into(), &|d| {
        d.coverage
            .map_or_else(|| "no attack".into(), |x| format!("{:.1} %", 100.0 * x))
    });
    row("watching from (s)".into(), &|d| {
        d.watched_from_s
            .map_or_else(|| "never".into(), |t| format!("{t:.3}"))
    });
    row("threshold".into(), &|d| {
        d.threshold
            .map_or_else(|| "none".into(), |t| format!("{t:.4}"))
    });
    row("non-finite / missing ticks".into(), &|d| {
        format!("{} / {}", d.non_finite, d.missing)
    });
}

/// How the residual detectors of `cols` were calibrated, and why they never watched if so.
fn calibration_line(md: &mut String, cols: &[Option<&DetectorMetrics>]) {
    if let Some(c) = cols.iter().flatten().find_map(|d| d.calibration.as_ref()) {
        let _ = write!(
            md,
            "\nCalibration over the first {} s: {} residuals",
            c.window_s, c.samples
        );
        if c.attacked_ticks > 0 {
            let _ = write!(
                md,
                ", {} ticks of it with the attack in force (the covariance includes the attack)",
                c.attacked_ticks
            );
        }
        match &c.failed {
            Some(why) => {
                let titles: Vec<&str> = detect::RESIDUAL.iter().map(|k| k.title).collect();
                let _ = writeln!(
                    md,
                    ". **The {} detectors never watched: {why}.**",
                    join_words(&titles)
                );
            }
            None => md.push_str(".\n"),
        }
    }
}

/// One detector's time to detect onset `i` (at `t_s`) as a cell.
fn time_to_detect_cell(d: &DetectorMetrics, i: usize, t_s: f64) -> String {
    let Some(o) = d.onsets.get(i).filter(|o| o.t_s == t_s) else {
        return "absent".into();
    };
    match (o.time_to_detect_s, o.until_s, d.watched_from_s) {
        (Some(_), _, _) if d.alarm_on_at_onset.get(i) == Some(&true) => "already on".into(),
        (Some(x), _, _) => format!("{x:.3}"),
        (None, Some(until), Some(from)) if until <= from => "not watched".into(),
        (None, _, None) => "not watched".into(),
        (None, _, _) => "missed".into(),
    }
}

/// `rmse.csv`: one row per robot.
fn rmse_csv(s: &RunSummary) -> Result<Vec<u8>> {
    const HEADER: [&str; 13] = [
        "robot",
        "rmse_rad",
        "max_abs_error_rad",
        "false_alarms",
        "deadline_misses",
        "rejected_inputs",
        "rejected_torques",
        "state_resets",
        "diverged_at_s",
        "ticks",
        "agent_ticks",
        "uncontrolled_ticks",
        "planned_ticks",
    ];
    let rows = s.metrics.iter().map(|(id, m)| {
        [
            id.clone(),
            m.rmse_rad.to_string(),
            m.max_abs_error_rad.to_string(),
            m.false_alarms.to_string(),
            m.deadline_misses.to_string(),
            m.rejected_inputs.to_string(),
            m.rejected_torques.to_string(),
            m.state_resets.to_string(),
            m.diverged_at_s.map_or(String::new(), |t| t.to_string()),
            m.ticks.to_string(),
            m.agent_ticks.to_string(),
            m.uncontrolled_ticks.to_string(),
            s.planned_ticks.to_string(),
        ]
    });
    csv_bytes(&HEADER, rows).context("writing rmse.csv")
}

/// The text of a CSV file: the `header` record, then `rows`, fields quoted where CSV needs it.
/// Callers format the fields: floats with `{}`, the shortest text that parses back to the same
/// `f64` (the csv crate's own serializer would write `1.0` and `1e-7` instead).
pub fn csv_bytes<R, F>(header: &[&str], rows: impl IntoIterator<Item = R>) -> Result<Vec<u8>>
where
    R: IntoIterator<Item = F>,
    F: AsRef<[u8]>,
{
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(header)?;
    for row in rows {
        w.write_record(row)?;
    }
    w.into_inner().map_err(|e| e.into_error().into())
}

/// The head of a markdown table: the row of `columns` and the separator under it,
/// `| a | b |\n|---|---|\n`.
pub fn md_table_head(columns: &[&str]) -> String {
    let mut head = format!("| {} |\n|", columns.join(" | "));
    head.push_str(&"---|".repeat(columns.len()));
    head.push('\n');
    head
}

/// An error and its causes, joined by `: `, leaving out a cause whose text is already there (an
/// I/O error is often both the tail of its context's message and that context's source, and
/// was printed twice: `No space left on device (os error 28): No space left on device (os
/// error 28)`).
pub fn describe_error(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if text.is_empty() || out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

/// A summary of two robots for the tests of its files: robot 1 without attack onsets, robot 2
/// diverged, with one onset detected and one not.
#[doc(hidden)]
pub fn sample_summary() -> RunSummary {
    let metrics = |rmse: f64, onsets: serde_json::Value, diverged: Option<f64>| {
        serde_json::json!({
            "rmse_rad": rmse, "max_abs_error_rad": 0.25, "onsets": onsets, "false_alarms": 2,
            "alarm_coverage": 0.5, "attacked_ticks": 10, "rejected_inputs": 3,
            "rejected_torques": 4, "state_resets": 5, "history_misses": 0,
            "deadline_misses": 6, "agent_ticks": 100, "uncontrolled_ticks": 7,
            "diverged_at_s": diverged, "ticks": 99
        })
    };
    let onsets = serde_json::json!([
        { "t_s": 0.001, "time_to_detect_s": 0.061 },
        { "t_s": 0.05, "time_to_detect_s": null },
    ]);
    serde_json::from_value(serde_json::json!({
        "scenario": "paper", "engine": "inproc", "clock": "lockstep",
        "controller": "proposed", "attack": "paper", "seed": 1, "agents": 2, "ticks": 99,
        "planned_ticks": 100, "sim_s": 0.099, "wall_s": 0.01, "rmse_rad": {},
        "trace_digest": "", "metrics": {
            "1": metrics(1.0 / 3.0, serde_json::json!([]), None),
            "2": metrics(1e-7, onsets, Some(0.0625)),
        }
    }))
    .expect("a summary")
}

#[cfg(test)]
mod tests {
    #[test]
    fn every_robot_whose_torques_were_replaced_is_named_with_its_count() {
        let mut s = super::sample_summary();
        let lines = super::rejected_torque_warnings(&s);
        assert_eq!(lines.len(), 2);
        assert!(
            lines[0].starts_with("robot 1: 4 torques were replaced"),
            "{lines:?}"
        );
        for (id, n) in [("1", 0), ("2", 1)] {
            if let Some(m) = s.metrics.get_mut(id) {
                m.rejected_torques = n;
            }
        }
        let lines = super::rejected_torque_warnings(&s);
        assert_eq!(lines.len(), 1);
        assert!(
            lines[0].starts_with("robot 2: 1 torque was replaced"),
            "{lines:?}"
        );
    }

    #[test]
    fn every_robot_whose_state_was_reset_is_named_with_its_count() {
        let mut s = super::sample_summary();
        let lines = super::state_reset_warnings(&s);
        assert_eq!(lines.len(), 2);
        assert!(lines[0].starts_with("robot 1: ") && lines[0].contains(" 5 times "));
        if let Some(m) = s.metrics.get_mut("2") {
            m.state_resets = 1;
        }
        if let Some(m) = s.metrics.get_mut("1") {
            m.state_resets = 0;
        }
        let lines = super::state_reset_warnings(&s);
        assert_eq!(lines.len(), 1);
        assert!(
            lines[0].starts_with("robot 2: ") && lines[0].contains(" 1 time "),
            "{lines:?}"
        );
        assert!(lines[0].contains("observer and estimator"), "{lines:?}");
        // The traditional controller has no estimator, and its torque does not read the
        // observer: the line says what a reset spoils there.
        s.controller = "traditional".into();
        let lines = super::state_reset_warnings(&s);
        assert!(
            lines[0].starts_with("robot 2: the control center reset its observer 1 time ")
                && lines[0].contains("torque does not read it"),
            "{lines:?}"
        );
    }

    #[test]
    fn rmse_csv_has_a_header_and_a_row_per_robot() {
        let bytes = super::rmse_csv(&super::sample_summary()).expect("csv");
        let text = std::str::from_utf8(&bytes).expect("utf-8");
        assert!(
            text.ends_with("\n2,0.0000001,0.25,2,6,3,4,5,0.0625,99,100,7,100\n"),
            "{text}"
        );
        let mut r = csv::Reader::from_reader(bytes.as_slice());
        let header = r.headers().expect("header").clone();
        assert_eq!(header.len(), 13);
        assert_eq!((&header[0], &header[8]), ("robot", "diverged_at_s"));
        let rows: Vec<csv::StringRecord> = r.records().map(|x| x.expect("row")).collect();
        assert_eq!(rows.len(), 2);
        assert_eq!(&rows[0][0], "1");
        assert_eq!(
            rows[0][1].parse::<f64>().expect("rmse").to_bits(),
            (1.0_f64 / 3.0).to_bits()
        );
        assert_eq!((&rows[0][8], &rows[1][8]), ("", "0.0625"));
        assert_eq!(&rows[1][12], "100");
    }

    #[test]
    fn detector_tables_put_the_three_side_by_side_and_old_summaries_get_none() {
        let mut s = super::sample_summary();
        assert_eq!(
            super::detector_tables(&s, 2),
            "",
            "a summary from before the detectors"
        );
        let detector = |ttd: [Option<f64>; 2], on: [bool; 2], from: f64| {
            serde_json::from_value::<fdi_common::metrics::DetectorMetrics>(serde_json::json!({
                "onsets": [
                    { "t_s": 0.001, "time_to_detect_s": ttd[0], "until_s": 0.01 },
                    { "t_s": 0.05, "time_to_detect_s": ttd[1] },
                ],
                "alarm_on_at_onset": on, "false_alarms": 3, "false_alarms_per_min": 1.5,
                "attack_free_watched_s": 120.0, "false_alarm_share": 0.25, "coverage": null,
                "watched_from_s": from, "threshold": 33.37684, "non_finite": 1, "missing": 2,
                "calibration": {
                    "window_s": 2.0, "samples": 1999, "attacked_ticks": 5, "non_finite": 0,
                    "residual_rms": [1e-4], "failed": null
                }
            }))
            .expect("detector metrics")
        };
        let m = s.metrics.get_mut("2").expect("robot 2");
        m.detectors.insert(
            "s_hat_norm".into(),
            detector([Some(0.061), None], [false, false], 0.0),
        );
        m.detectors.insert(
            "chi2".into(),
            detector([None, Some(0.0)], [false, true], 0.02),
        );
        let md = super::detector_tables(&s, 2);
        // Every detector after `s_hat_norm` and `chi2` has no metrics here: `absent`.
        let absent = " absent |".repeat(fdi_common::detect::names().len() - 2);
        let row = |cells: &str| format!("{cells}{absent}");
        for line in [
            "## Detectors side by side".to_string(),
            "### Detectors of robot 2".to_string(),
            format!("|  | {} |", fdi_common::detect::names().join(" | ")),
            row("| onset at 0.001 s: time to detect (s) | 0.061 | not watched |"),
            row("| onset at 0.050 s: time to detect (s) | missed | already on |"),
            row("| false alarms per minute | 1.50 | 1.50 |"),
            row("| alarm share of attack-free time | 25.0 % | 25.0 % |"),
            row("| coverage of attacked ticks | no attack | no attack |"),
            row("| non-finite / missing ticks | 1 / 2 | 1 / 2 |"),
            "Calibration over the first 2 s: 1999 residuals, 5 ticks of it with the attack in force"
                .to_string(),
        ] {
            assert!(md.contains(&line), "{line}:\n{md}");
        }
        assert!(!md.contains("robot 1"), "robot 1 has no detector metrics");
    }

    #[test]
    fn md_table_head_has_a_separator_cell_per_column() {
        assert_eq!(
            super::md_table_head(&["robot", "RMSE (rad)"]),
            "| robot | RMSE (rad) |\n|---|---|\n"
        );
    }
}
