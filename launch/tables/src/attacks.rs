//! The attack-class table (`fdi-launch attacks`, `docs/attacks.md`): every shipped attack class
//! on the paper's robots, under the traditional and the proposed controller, with the detection
//! of each detector and what the receivers counted.

use fdi_common::stop::Stop;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use anyhow::{anyhow, Context, Result};
use fdi_common::detect;
use fdi_common::engine::{run_inproc_any, RunSummary};
use fdi_common::metrics::AgentMetrics;
use fdi_common::observe::{Finish, Progress, Work};
use fdi_common::records::TickRecord;
use fdi_common::scenario::{ControllerMode, Resolved};
use serde::Serialize;

use crate::tables::{rmse_chart, MadeWith, Owned, Table};
use fdi_report::output::{csv_bytes, md_table_head, rmse_cell};
use fdi_report::plot::PALETTE;

use fdi_campaign::classes::{Class, Detection, CLASSES};

/// How to make the attack-class table (`fdi-launch attacks`).
#[derive(Debug, Clone, Default)]
pub struct AttacksOptions {
    /// Folder that receives `attacks.md`, `.csv`, `.json` and the bar chart; `None`: a new
    /// folder `runs/<timestamp>-attacks`.
    pub out: Option<PathBuf>,
    /// Shorten every run to this many seconds (`None`: each scenario's own, 40 s).
    pub duration_s: Option<f64>,
    /// Base scenario (`None`: the embedded paper scenario): its robots, gains and numerics
    /// under every class (a class's own scenario file gives its attack and detectors only).
    pub scenario: Option<PathBuf>,
    pub numerics: fdi_orchestrator::request::NumericsArgs,
    pub set: fdi_orchestrator::request::SetArgs,
    /// Told the runs' progress.
    pub progress: fdi_common::observe::Observer,
}

/// What the table keeps of one run: its summary, and per robot the ticks whose measurement
/// the control center found missing (dropped, forged, replayed, not yet delivered).
struct Outcome {
    summary: RunSummary,
    missing_inputs: BTreeMap<u32, u64>,
}

/// The scenario of `class` on `base` under `mode`, shortened to `duration_s`, checked as
/// the command line's overrides are.
fn class_scenario(
    class: &Class,
    base: &Resolved,
    mode: ControllerMode,
    duration_s: Option<f64>,
) -> Result<Resolved> {
    let mut r = class.source.resolve(base)?;
    r.scenario.controller.mode = mode;
    if let Some(d) = duration_s {
        r.scenario.duration_s = d;
    }
    fdi_orchestrator::run::check_overrides(r)
}

/// Runs one class under one controller, in-process.
fn run_one(
    class: &Class,
    base: &Resolved,
    mode: ControllerMode,
    duration_s: Option<f64>,
) -> Result<Outcome> {
    let r = class_scenario(class, base, mode, duration_s)?;
    let mut missing_inputs = BTreeMap::new();
    let summary = run_inproc_any(&r, |rec: &TickRecord| {
        if rec.center.missing_input {
            *missing_inputs.entry(rec.agent.agent).or_insert(0) += 1;
        }
    })
    .context("in-process engine")?;
    Ok(Outcome {
        summary,
        missing_inputs,
    })
}

/// One row: one robot under one class.
#[derive(Debug, Serialize)]
struct Row {
    class: &'static str,
    robot: u32,
    traditional_rmse_rad: f64,
    proposed_rmse_rad: f64,
    traditional_diverged_at_s: Option<f64>,
    proposed_diverged_at_s: Option<f64>,
    #[serde(skip)]
    traditional_cell: String,
    #[serde(skip)]
    proposed_cell: String,
    /// Per detector of [`detect::names()`] the run has, under the proposed controller.
    detectors: BTreeMap<&'static str, Detection>,
    /// Proposed run: ticks the center found its measurement missing.
    missing_inputs: u64,
    /// Proposed run: steps the agent held its torque for want of the due command.
    deadline_misses: u64,
}

fn metrics_of(s: &RunSummary, robot: u32) -> Result<&AgentMetrics> {
    s.metrics
        .get(&robot.to_string())
        .ok_or_else(|| anyhow!("run `{}` has no robot {robot}", s.attack))
}

/// The rows of a class: its robots that the base scenario has (a class none of whose robots
/// is there is refused, naming them).
fn rows_of(
    class: &Class,
    base: &Resolved,
    traditional: &Outcome,
    proposed: &Outcome,
) -> Result<Vec<Row>> {
    let present: Vec<u32> = class
        .robots
        .iter()
        .copied()
        .filter(|&id| base.scenario.agents.iter().any(|a| a.id == id))
        .collect();
    if present.is_empty() {
        return Err(anyhow!(
            "attack class `{}` reports robots {:?}, and the base scenario has none of them",
            class.name,
            class.robots
        ));
    }
    present
        .into_iter()
        .map(|robot| {
            let t = metrics_of(&traditional.summary, robot)?;
            let p = metrics_of(&proposed.summary, robot)?;
            Ok(Row {
                class: class.name,
                robot,
                traditional_rmse_rad: t.rmse_rad,
                proposed_rmse_rad: p.rmse_rad,
                traditional_diverged_at_s: t.diverged_at_s,
                proposed_diverged_at_s: p.diverged_at_s,
                traditional_cell: rmse_cell(t, 4),
                proposed_cell: rmse_cell(p, 4),
                detectors: detect::names()
                    .into_iter()
                    .filter_map(|n| Some((n, Detection::of(p.detectors.get(n)?))))
                    .collect(),
                missing_inputs: proposed.missing_inputs.get(&robot).copied().unwrap_or(0),
                deadline_misses: p.deadline_misses,
            })
        })
        .collect()
}

/// `attacks.md` (without its leading `# `), as printed.
fn markdown(rows: &[Row], duration_s: Option<f64>, made: &MadeWith) -> String {
    let span = duration_s.map_or_else(
        || "each scenario's full duration (40 s)".to_string(),
        |d| format!("{d} s"),
    );
    let mut md = format!(
        "Attack classes on the paper's robots: RMSE (rad) under the traditional and the proposed \
         controller, and detection under the proposed controller; in-process engine, {span}\n\n{}",
        made.md()
    );
    let mut head = vec!["class", "robot", "RMSE traditional", "RMSE proposed"];
    let titles: Vec<String> = detect::names()
        .into_iter()
        .filter_map(detect::title)
        .flat_map(|t| {
            [
                format!("{t} detected"),
                format!("{t} time to detect (s)"),
                format!("{t} false alarms/min"),
            ]
        })
        .collect();
    head.extend(titles.iter().map(String::as_str));
    head.extend(["missing inputs (center)", "deadline misses (agent)"]);
    md.push_str(&md_table_head(&head));
    for r in rows {
        let _ = write!(
            md,
            "| {} | {} | {} | {} |",
            r.class, r.robot, r.traditional_cell, r.proposed_cell
        );
        for n in detect::names() {
            match r.detectors.get(n) {
                Some(d) => {
                    let _ = write!(
                        md,
                        " {} | {} | {} |",
                        d.detected_cell(),
                        d.time_cell(),
                        d.false_alarm_cell()
                    );
                }
                None => md.push_str(" absent | absent | absent |"),
            }
        }
        let _ = writeln!(md, " {} | {} |", r.missing_inputs, r.deadline_misses);
    }
    md.push_str(
        "\n*detected*: onsets (rising edges of \"attack in force\", on the measurement or the \
         torque path) found by an alarm of the detector's own, of those it watched; `already on`: \
         the alarm was on at the tick before the onset (left out: no detection of its own); \
         `not watched`: the attack ended before the detector started watching (left out). \
         *time to detect*: the mean over the detected onsets; `missed`: none detected; \
         `no onset`: the attack was never in force in the run (no value, not 0); `—`: no value. \
         *false alarms/min*: alarm rising edges while no attack was in force, per minute of the \
         attack-free time watched (`—`: none watched). *missing inputs*: ticks whose measurement \
         the control center found missing (dropped, forged, replayed, not yet delivered) and \
         replaced by its last one; *deadline misses*: steps the robot held its last torque for \
         want of the command due. Detection and the two counts are of the proposed run.\n\n",
    );
    for c in CLASSES {
        let _ = writeln!(
            md,
            "* `{}` ({}, {} {}): {}.",
            c.name,
            c.source.file(),
            if c.robots.len() == 1 {
                "robot"
            } else {
                "robots"
            },
            c.robots
                .iter()
                .map(u32::to_string)
                .collect::<Vec<_>>()
                .join(", "),
            c.what
        );
    }
    md
}

/// An optional value as a CSV field: empty when it has none.
fn opt(x: Option<f64>) -> String {
    x.map_or(String::new(), |v| v.to_string())
}

/// The RMSE of a robot as a result: `None` when it diverged (its RMSE is no result then).
fn rmse_result(rmse: f64, diverged_at_s: Option<f64>) -> Option<f64> {
    diverged_at_s.is_none().then_some(rmse)
}

/// [`rmse_result`] as a CSV field.
fn result_rmse(rmse: f64, diverged_at_s: Option<f64>) -> String {
    opt(rmse_result(rmse, diverged_at_s))
}

/// `attacks.csv`: one row per class and robot; a field without a value is empty (an RMSE too,
/// when the robot diverged: its `diverged_at_s` says when).
fn csv(rows: &[Row]) -> Result<Vec<u8>> {
    let mut header: Vec<String> = [
        "class",
        "robot",
        "traditional_rmse_rad",
        "proposed_rmse_rad",
        "traditional_diverged_at_s",
        "proposed_diverged_at_s",
    ]
    .map(String::from)
    .to_vec();
    for n in detect::names() {
        for f in [
            "onsets",
            "detected",
            "already_on",
            "not_watched",
            "mean_time_to_detect_s",
            "false_alarms_per_min",
        ] {
            header.push(format!("{n}_{f}"));
        }
    }
    header.extend(["missing_inputs", "deadline_misses"].map(String::from));
    let header: Vec<&str> = header.iter().map(String::as_str).collect();
    let body = rows.iter().map(|r| {
        let mut f = vec![
            r.class.to_string(),
            r.robot.to_string(),
            result_rmse(r.traditional_rmse_rad, r.traditional_diverged_at_s),
            result_rmse(r.proposed_rmse_rad, r.proposed_diverged_at_s),
            opt(r.traditional_diverged_at_s),
            opt(r.proposed_diverged_at_s),
        ];
        for n in detect::names() {
            match r.detectors.get(n) {
                Some(d) => f.extend([
                    d.onsets.to_string(),
                    d.detected.to_string(),
                    d.already_on.to_string(),
                    d.not_watched.to_string(),
                    opt(d.mean_time_to_detect_s),
                    opt(d.false_alarms_per_min),
                ]),
                None => f.extend(std::iter::repeat_n(String::new(), 6)),
            }
        }
        f.extend([r.missing_inputs.to_string(), r.deadline_misses.to_string()]);
        f
    });
    csv_bytes(&header, body).context("writing attacks.csv")
}

/// Phase of an interrupt that stops the table.
const DURING_THE_TABLE: &str =
    "during the attack table: the runs already done are discarded, nothing is written";

/// The table's folder, its base scenario (`--scenario`, the numerics flags and `--set`
/// applied) and how it was made. `--set` of what the table sets itself is refused.
fn base(args: &AttacksOptions) -> Result<(PathBuf, Resolved, MadeWith)> {
    let dir = args.out.clone().unwrap_or_else(|| {
        PathBuf::from("runs").join(format!(
            "{}-{}",
            fdi_orchestrator::run_dirs::timestamp(),
            crate::tables::edited_name("attacks", &args.set)
        ))
    });
    let mut owned = vec![
        Owned {
            keys: &["attack"],
            why: "every class brings its attack",
        },
        Owned {
            keys: &["controller", "mode"],
            why: "it runs both controllers",
        },
    ];
    if args.duration_s.is_some() {
        owned.push(Owned {
            keys: &["duration_s"],
            why: "--duration-s gives every run's duration",
        });
    }
    let (base, made) = MadeWith::load(args.scenario.as_deref(), &args.numerics, &args.set, &owned)?;
    Ok((dir, base, made))
}

/// The attack-class table: every shipped class under both controllers, in-process; written
/// into its folder, returned.
pub fn attacks(args: &AttacksOptions, stop: &Stop) -> Result<Table> {
    stop.check(fdi_common::stop::BEFORE_THE_START)?;
    let (dir, base, made) = base(args)?;
    // Every class's scenario is made and checked before anything runs: one that cannot run
    // (a `--duration-s` shorter than its detectors' calibration) stops the table at once.
    for c in CLASSES {
        class_scenario(c, &base, ControllerMode::Proposed, args.duration_s)
            .with_context(|| format!("attack class `{}`", c.name))?;
    }
    let jobs: Vec<(usize, ControllerMode)> = (0..CLASSES.len())
        .flat_map(|i| {
            [
                (i, ControllerMode::Traditional),
                (i, ControllerMode::Proposed),
            ]
        })
        .collect();
    let results = run_all(&jobs, &base, args, stop, &*args.progress)?;
    let mut rows = Vec::new();
    for (i, c) in CLASSES.iter().enumerate() {
        let [t, p] = [ControllerMode::Traditional, ControllerMode::Proposed].map(|m| {
            jobs.iter()
                .position(|&j| j == (i, m))
                .and_then(|k| results[k].as_ref())
        });
        let (Some(t), Some(p)) = (t, p) else {
            return Err(anyhow!("attack class `{}`: a run is missing", c.name));
        };
        rows.extend(rows_of(c, &base, t, p)?);
    }
    let table = Table {
        name: "attacks",
        md: markdown(&rows, args.duration_s, &made),
        csv: csv(&rows)?,
        json: serde_json::json!({
            "engine": "inproc",
            "made_with": made,
            "duration_s": args.duration_s,
            "classes": CLASSES.iter().map(|c| serde_json::json!({
                "name": c.name, "file": c.source.file(), "robots": c.robots, "what": c.what,
            })).collect::<Vec<_>>(),
            "rows": rows,
        }),
        chart: rmse_chart(
            "Attack classes: RMSE of the attacked robots, traditional vs proposed (a robot that diverged: an outline marked \"diverged\")".into(),
            rows.iter()
                .map(|r| format!("{} r{}", r.class, r.robot))
                .collect(),
            vec![
                (
                    "traditional".into(),
                    PALETTE[1],
                    rows.iter()
                        .map(|r| {
                            rmse_result(r.traditional_rmse_rad, r.traditional_diverged_at_s)
                                .unwrap_or(f64::NAN)
                        })
                        .collect(),
                ),
                (
                    "proposed".into(),
                    PALETTE[0],
                    rows.iter()
                        .map(|r| {
                            rmse_result(r.proposed_rmse_rad, r.proposed_diverged_at_s)
                                .unwrap_or(f64::NAN)
                        })
                        .collect(),
                ),
            ],
        ),
        made,
        dir,
    };
    table.write()?;
    Ok(table)
}

/// Runs every job on up to two threads, telling `bar` each run done. Stops at the first error
/// or interrupt.
fn run_all(
    jobs: &[(usize, ControllerMode)],
    base: &Resolved,
    args: &AttacksOptions,
    stop: &Stop,
    bar: &dyn Progress,
) -> Result<Vec<Option<Outcome>>> {
    bar.begin(Work::Runs {
        total: jobs.len() as u64,
        what: "attack table".into(),
    });
    let threads = std::thread::available_parallelism()
        .map_or(1, std::num::NonZeroUsize::get)
        .clamp(1, 2);
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<Outcome>>> = Mutex::new((0..jobs.len()).map(|_| None).collect());
    let failure: Mutex<Option<anyhow::Error>> = Mutex::new(None);
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| loop {
                let k = next.fetch_add(1, Ordering::SeqCst);
                let Some(&(i, mode)) = jobs.get(k) else { break };
                let failed = failure.lock().map_or(true, |f| f.is_some());
                if failed {
                    break;
                }
                let class = &CLASSES[i];
                let outcome = stop
                    .check(DURING_THE_TABLE)
                    .map_err(anyhow::Error::from)
                    .and_then(|()| run_one(class, base, mode, args.duration_s))
                    .with_context(|| format!("attack class `{}`, {}", class.name, mode.as_str()));
                match outcome {
                    Ok(o) => {
                        if let Ok(mut r) = results.lock() {
                            r[k] = Some(o);
                        }
                        bar.step(&format!("{} ({})", class.name, mode.as_str()));
                    }
                    Err(e) => {
                        if let Ok(mut f) = failure.lock() {
                            f.get_or_insert(e);
                        }
                        break;
                    }
                }
            });
        }
    });
    if let Some(e) = failure
        .into_inner()
        .map_err(|_| anyhow!("a run thread panicked"))?
    {
        bar.finish(Finish::Stopped);
        return Err(e);
    }
    bar.finish(Finish::Done);
    stop.check(DURING_THE_TABLE)?;
    results
        .into_inner()
        .map_err(|_| anyhow!("a run thread panicked"))
}
