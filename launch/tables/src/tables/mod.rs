//! The paper's Tables I and II.

use fdi_common::stop::Stop;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use fdi_common::delay::DelayProfile;
use fdi_common::engine::RunSummary;
use fdi_common::observe::Observer;
use fdi_common::scenario::{self, ControllerMode, Resolved};
use serde::Serialize;

use fdi_orchestrator::run::{execute, Engine};
use fdi_report::output::{csv_bytes, md_table_head};
use fdi_report::plot::{BarChart, PALETTE};
use plotters::style::RGBColor;

mod verdict;
use verdict::{Cell, Verdict};

/// How to make Table I or II (`fdi-launch table1`, `table2`).
#[derive(Debug, Clone)]
pub struct TableOptions {
    pub engine: Engine,
    /// Base scenario (`None`: the embedded paper scenario): its robots, gains and numerics. Its
    /// attack and duration are replaced by the table's (the paper's attack, 40 s), and the
    /// header names what differs from the paper's calibration.
    pub scenario: Option<PathBuf>,
    pub numerics: fdi_orchestrator::request::NumericsArgs,
    pub set: fdi_orchestrator::request::SetArgs,
    /// Shorten every run to this many seconds (the paper's tables use 40 s).
    pub duration_s: Option<f64>,
    /// Folder that receives the table's run directories.
    pub out: PathBuf,
    /// Run every entry with N seeds (the scenario's seed, seed + 1, …, seed + N − 1) and give
    /// each cell as mean ± 95 % confidence interval (Student t) over them.
    pub seeds: Option<u32>,
    /// With `seeds`: runs at a time (default: the number of CPUs).
    pub jobs: Option<std::num::NonZeroUsize>,
    /// Told the runs' progress.
    pub progress: Observer,
}

/// Table I of the paper: (robot, traditional, proposed) RMSE in rad.
const PAPER_TABLE1: [(u32, f64, f64); 4] = [
    (1, 0.028, 0.008),
    (2, 0.041, 0.013),
    (3, 0.026, 0.009),
    (4, 0.015, 0.010),
];

/// Table II of the paper: (case, delay, RMSE of robot 1 in rad).
fn paper_table2() -> [(&'static str, DelayProfile, f64); 4] {
    let sine = |a_ms: f64, rate: f64, off_ms: f64| DelayProfile::Sine {
        amplitude_s: a_ms * 1e-3,
        offset_s: off_ms * 1e-3,
        rate_rad_s: rate,
    };
    [
        ("small-fast", sine(2.0, 0.5, 3.0), 0.0084),
        ("large-fast", sine(20.0, 0.5, 30.0), 0.0101),
        ("small-slow", sine(2.0, 0.05, 3.0), 0.0085),
        ("large-slow", sine(20.0, 0.05, 30.0), 0.0113),
    ]
}

#[derive(Debug, Serialize)]
struct Table1Row {
    robot: u32,
    traditional_rmse_rad: f64,
    proposed_rmse_rad: f64,
    /// The paper's values, for a robot that is the paper's (same model, trajectory and delay);
    /// `null` for any other robot.
    paper_traditional: Option<f64>,
    paper_proposed: Option<f64>,
}

#[derive(Debug, Serialize)]
struct Table2Row {
    case: &'static str,
    tau_ms: String,
    rmse_rad: f64,
    /// The paper's value, when robot 1 is the paper's robot 1 (model and trajectory).
    paper_rmse_rad: Option<f64>,
}

/// How a table was made: its base scenario, what the table replaced in it, and its controller
/// and numerics options that differ from the paper's calibration. Every table shows it in its
/// header (markdown), a leading `#` comment (CSV) and a `made_with` field (JSON).
#[derive(Debug, Clone, Serialize)]
pub struct MadeWith {
    /// `the embedded paper scenario` or the file given.
    pub scenario: String,
    /// What the table replaced in the base scenario, e.g. `attack `none` → `paper``.
    pub replaced: Vec<String>,
    /// The options that differ from the paper's calibration (empty: the paper's).
    pub numerics: Vec<fdi_common::numerics::Difference>,
    /// The edits of `--set`, as given (`controller.beta=10`).
    pub set: Vec<String>,
}

/// A field that a table sets itself in every run (its keys, the indices left out:
/// `agents.delay` is every agent's delay), and what the table does with it: `--set` there is
/// refused, as the table would silently undo it.
pub struct Owned {
    pub keys: &'static [&'static str],
    pub why: &'static str,
}

/// The field paths of `set` that reach a field of `owned` (or a table holding one).
fn refuse_owned(set: &fdi_orchestrator::request::SetArgs, owned: &[Owned]) -> Result<()> {
    let mut problems = Vec::new();
    for e in &set.set {
        let target = e.path.target();
        let keys: Vec<&str> = target
            .iter()
            .filter_map(|s| match s {
                fdi_common::field_path::Seg::Key(k) => Some(k.as_str()),
                fdi_common::field_path::Seg::Index(_) => None,
            })
            .collect();
        for o in owned {
            if keys.starts_with(o.keys) || o.keys.starts_with(&keys) {
                problems.push(fdi_common::problem::Problem {
                    path: format!("--set {e}"),
                    message: format!("this table sets `{}` itself: {}", o.keys.join("."), o.why),
                });
            }
        }
    }
    if problems.is_empty() {
        return Ok(());
    }
    Err(scenario::ScenarioError {
        source_name: fdi_common::overrides::SOURCE_NAME.into(),
        problems,
    }
    .into())
}

/// The fields Tables I and II set themselves.
fn owned_by_tables(args: &TableOptions) -> Vec<Owned> {
    let mut owned = vec![
        Owned {
            keys: &["attack"],
            why: "it runs the paper's attack",
        },
        Owned {
            keys: &["duration_s"],
            why: "its runs last 40 s, or --duration-s",
        },
    ];
    if args.seeds.is_some() {
        owned.push(Owned {
            keys: &["seed"],
            why: "--seeds runs the scenario's seed and the ones after it",
        });
    }
    owned
}

impl MadeWith {
    /// The table was made with options other than the paper's calibration (numerics options
    /// or `--set` edits).
    pub fn is_other_calibration(&self) -> bool {
        !self.numerics.is_empty() || !self.set.is_empty()
    }

    /// The base scenario of `args` (file or embedded), with the numerics options applied, and
    /// how it differs from the paper's.
    pub fn load(
        scenario: Option<&Path>,
        numerics: &fdi_orchestrator::request::NumericsArgs,
        set: &fdi_orchestrator::request::SetArgs,
        owned: &[Owned],
    ) -> Result<(Resolved, Self)> {
        refuse_owned(set, owned)?;
        let mut r = fdi_orchestrator::request::load(scenario)?;
        numerics.apply(&mut r.scenario);
        let r = set.apply(r, &numerics.fields())?;
        let r = fdi_orchestrator::run::check_overrides(r)?;
        let made = Self {
            scenario: scenario.map_or_else(
                || "the embedded paper scenario".into(),
                |p| p.display().to_string(),
            ),
            replaced: Vec::new(),
            numerics: fdi_common::numerics::differences_from_paper(
                &r.scenario,
                fdi_common::numerics::Compare::WithoutMode,
            ),
            set: set.name_parts(),
        };
        Ok((r, made))
    }

    /// One line: `scenario X (…replaced…); numerics: …`.
    pub fn line(&self) -> String {
        let mut out = format!("scenario: {}", self.scenario);
        if !self.set.is_empty() {
            let edits: Vec<String> = self.set.iter().map(|e| format!("`--set {e}`")).collect();
            let _ = write!(out, " with {}", edits.join(", "));
        }
        if !self.replaced.is_empty() {
            let _ = write!(
                out,
                " (replaced for this table: {})",
                self.replaced.join(", ")
            );
        }
        let _ = write!(
            out,
            "; numerics: {}",
            fdi_common::numerics::describe(&self.numerics)
        );
        out
    }

    /// The markdown paragraph under a table's title.
    pub fn md(&self) -> String {
        let mut out = format!("Made with {}", self.line());
        if !self.numerics.is_empty() {
            out.push_str(
                ". **These numerics differ from the paper's calibration**: the paper's values are shown for comparison only",
            );
        }
        out.push_str(".\n\n");
        out
    }

    /// The CSV's leading comment line (read with `comment='#'` in pandas).
    pub fn csv_comment(&self) -> Vec<u8> {
        format!("# made with {}\n", self.line().replace('\n', " ")).into_bytes()
    }
}

/// The base scenario of Tables I and II: the given one (or the paper's), under the paper's
/// attack, for the paper's 40 s unless `--duration-s` says otherwise.
fn base(args: &TableOptions, owned: &[Owned]) -> Result<(Resolved, MadeWith)> {
    let (mut r, mut made) =
        MadeWith::load(args.scenario.as_deref(), &args.numerics, &args.set, owned)?;
    let paper = scenario::paper()?;
    if r.attack.name != paper.attack.name {
        let profile = scenario::attack_from_arg(&paper.attack.name, &r.scenario)?;
        made.replaced.push(format!(
            "attack `{}` → `{}`",
            r.attack.name, paper.attack.name
        ));
        r = r.with_attack(profile)?;
    }
    let duration = args.duration_s.unwrap_or(paper.scenario.duration_s);
    if r.scenario.duration_s != duration {
        made.replaced.push(format!(
            "duration {} s → {duration} s",
            r.scenario.duration_s
        ));
        r.scenario.duration_s = duration;
    }
    Ok((fdi_orchestrator::run::check_overrides(r)?, made))
}

/// True when robot `id` of `r` is the paper's robot `id`: same model and trajectory, and the
/// same delay where `same_delay` (gains and numerics may differ: the table names them).
fn is_papers_robot(r: &Resolved, id: u32, same_delay: bool) -> bool {
    static PAPER: std::sync::OnceLock<Option<Resolved>> = std::sync::OnceLock::new();
    let Some(paper) = PAPER.get_or_init(|| scenario::paper().ok()) else {
        return false;
    };
    let find = |r: &Resolved| r.scenario.agents.iter().find(|a| a.id == id).cloned();
    match (find(r), find(paper)) {
        (Some(a), Some(b)) => {
            a.model == b.model
                && a.trajectory == b.trajectory
                && (!same_delay || a.delay == b.delay)
        }
        _ => false,
    }
}

/// The paper's Table I values (traditional, proposed) of robot `id` of `r`, when it is the
/// paper's robot.
fn paper_table1(r: &Resolved, id: u32) -> Option<(f64, f64)> {
    PAPER_TABLE1
        .iter()
        .find(|(robot, _, _)| *robot == id)
        .filter(|_| is_papers_robot(r, id, true))
        .map(|&(_, t, p)| (t, p))
}

/// `{:.prec$}` of a paper value, `—` where the table has none.
fn or_dash(v: Option<f64>, prec: usize) -> String {
    v.map_or_else(|| "—".into(), |v| format!("{v:.prec$}"))
}

/// A CSV cell of an optional value: empty where there is none.
fn or_empty(v: Option<f64>) -> String {
    v.map_or_else(String::new, |v| v.to_string())
}

/// The robots of a Table I: the base scenario's, in id order.
fn robots(r: &Resolved) -> Vec<u32> {
    let mut ids: Vec<u32> = r.scenario.agents.iter().map(|a| a.id).collect();
    ids.sort_unstable();
    ids
}

/// Runs one table entry; ipc runs keep their run directory under the table's folder.
fn run_case(
    r: &Resolved,
    args: &TableOptions,
    dir: &std::path::Path,
    case: &str,
    progress: bool,
    stop: &Stop,
) -> Result<RunSummary> {
    let quiet = fdi_orchestrator::run::Options::quiet(fdi_orchestrator::run::Traces::Full, stop);
    match args.engine {
        Engine::Inproc => Ok(execute(r, args.engine, None, &quiet)?),
        Engine::Ipc => {
            let mut named = r.clone();
            named.scenario.name = case.into();
            let d = fdi_orchestrator::run_dirs::create_run_dir(dir, &named)?;
            let summary = fdi_orchestrator::run_dirs::discard_if_not_started(
                &d,
                execute(
                    r,
                    args.engine,
                    Some(&d),
                    &fdi_orchestrator::run::Options {
                        progress: if progress {
                            args.progress.clone()
                        } else {
                            Observer::quiet()
                        },
                        ..quiet
                    },
                ),
            )
            .and_then(fdi_orchestrator::run::require_whole)?;
            if let Err(e) = fdi_report::report::write_report(
                &fdi_common::run_dir::RunDir::new(&d),
                r,
                &summary,
                stop,
            ) {
                // Stopped by the signal: the table stops too.
                if stop.pending().is_some() {
                    return Err(e);
                }
                log::warn!(
                    "the report of {} could not be made: {}",
                    d.display(),
                    fdi_report::output::describe_error(&e)
                );
            }
            Ok(summary)
        }
    }
}

/// The folder of one table: `<out>/<timestamp>-<name>`, then the `--set` edits
/// (`-controller_beta_10`).
fn table_dir(args: &TableOptions, name: &str) -> PathBuf {
    args.out.join(format!(
        "{}-{}",
        fdi_orchestrator::run_dirs::timestamp(),
        edited_name(name, &args.set)
    ))
}

/// `name`, then each `--set` edit, as one component of a path ([`fdi_orchestrator::run_dirs::safe_name`]).
pub(crate) fn edited_name(name: &str, set: &fdi_orchestrator::request::SetArgs) -> String {
    let parts: Vec<String> = std::iter::once(name.to_string())
        .chain(set.name_parts())
        .collect();
    fdi_orchestrator::run_dirs::safe_name(&parts.join("-"))
}

/// The RMSE of `robot` in a run, NaN when the run has none.
fn robot_rmse(s: &RunSummary, robot: u32) -> f64 {
    s.rmse_rad
        .get(&robot.to_string())
        .copied()
        .unwrap_or(f64::NAN)
}

/// Table I: every robot's RMSE under the traditional and the proposed controller, beside the
/// paper's; written into its folder, returned.
pub fn table1(args: &TableOptions, stop: &Stop) -> Result<Table> {
    let mut owned = owned_by_tables(args);
    owned.push(Owned {
        keys: &["controller", "mode"],
        why: "it runs both controllers",
    });
    let (base, made) = base(args, &owned)?;
    let dir = table_dir(args, "table1");
    if let Some(n) = args.seeds {
        return seeded::table1(args, &base, &made, &dir, n, stop);
    }
    let run_mode = |mode: ControllerMode| {
        let mut r = base.clone();
        r.scenario.controller.mode = mode;
        run_case(&r, args, &dir, mode.as_str(), true, stop)
    };
    let traditional = run_mode(ControllerMode::Traditional)?;
    let proposed = run_mode(ControllerMode::Proposed)?;
    let rows = table1_rows(&base, &traditional, &proposed);
    let verdict = table1_verdict(&rows, &made);
    let table = Table {
        name: "table1",
        md: table1_markdown(args.engine, &made, &rows, &verdict),
        csv: table1_csv(&rows)?,
        json: serde_json::json!({ "engine": args.engine.as_str(), "made_with": made, "rows": rows, "verdict": verdict }),
        chart: table1_chart(args.engine, &rows),
        made,
        dir,
    };
    table.write()?;
    Ok(table)
}

/// Table I's rows: the base scenario's robots, their RMSE in the two runs beside the paper's.
fn table1_rows(base: &Resolved, traditional: &RunSummary, proposed: &RunSummary) -> Vec<Table1Row> {
    robots(base)
        .into_iter()
        .map(|robot| {
            let paper = paper_table1(base, robot);
            Table1Row {
                robot,
                traditional_rmse_rad: robot_rmse(traditional, robot),
                proposed_rmse_rad: robot_rmse(proposed, robot),
                paper_traditional: paper.map(|p| p.0),
                paper_proposed: paper.map(|p| p.1),
            }
        })
        .collect()
}

/// The title of a Table I.
fn table1_title(engine: Engine) -> String {
    format!(
        "Table I: RMSE of the position tracking error (rad) under the paper's FDI attack, engine {}",
        engine.as_str()
    )
}

/// Table I's cells beside the paper's: each robot's traditional, then proposed RMSE; `made`
/// says whether the table's options are the paper's calibration.
fn table1_verdict(rows: &[Table1Row], made: &MadeWith) -> Verdict {
    let column = |name: &str, this: fn(&Table1Row) -> f64, paper: fn(&Table1Row) -> Option<f64>| {
        rows.iter()
            .filter_map(|r| Cell::new(name, format!("robot {}", r.robot), this(r), paper(r)))
            .collect::<Vec<_>>()
    };
    let mut cells = column(
        "traditional",
        |r| r.traditional_rmse_rad,
        |r| r.paper_traditional,
    );
    cells.extend(column(
        "proposed",
        |r| r.proposed_rmse_rad,
        |r| r.paper_proposed,
    ));
    Verdict::of(
        cells,
        "no robot is the paper's (its model, trajectory and delay)",
    )
    .other_calibration(made.is_other_calibration())
}

/// The columns of a Table I in markdown, plain or over seeds.
const TABLE1_HEAD: [&str; 9] = [
    "robot",
    "traditional",
    "proposed",
    "ratio",
    "paper traditional",
    "paper proposed",
    "paper ratio",
    "traditional / paper",
    "proposed / paper",
];

/// The last four cells of a Table I row in markdown: the paper's values, its ratio, and this
/// table's values over the paper's (`trad` and `prop`, means over seeds).
fn table1_paper_cells(r: &Table1Row) -> String {
    format!(
        "{} | {} | {} | {} | {}",
        or_dash(r.paper_traditional, 3),
        or_dash(r.paper_proposed, 3),
        or_dash(ratio(r.paper_traditional, r.paper_proposed), 2),
        or_dash(over_paper(r.traditional_rmse_rad, r.paper_traditional), 2),
        or_dash(over_paper(r.proposed_rmse_rad, r.paper_proposed), 2),
    )
}

/// `table1.md` (without its leading `# `), as printed.
fn table1_markdown(engine: Engine, made: &MadeWith, rows: &[Table1Row], v: &Verdict) -> String {
    let mut md = format!("{}\n\n{}", table1_title(engine), made.md());
    md.push_str(&md_table_head(&TABLE1_HEAD));
    for r in rows {
        let _ = writeln!(
            md,
            "| {} | {:.4} | {:.4} | {:.2} | {} |",
            r.robot,
            r.traditional_rmse_rad,
            r.proposed_rmse_rad,
            r.traditional_rmse_rad / r.proposed_rmse_rad,
            table1_paper_cells(r),
        );
    }
    let _ = writeln!(md, "\n{}", v.line());
    md
}

/// `this / paper`, where the paper has a value.
fn over_paper(this: f64, paper: Option<f64>) -> Option<f64> {
    Some(this / paper?)
}

/// `a / b` of two values that may be missing.
fn ratio(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    Some(a? / b?)
}

/// Table I's bar chart: per robot, each controller's RMSE beside the paper's (the paper's bars
/// only where every robot has a paper value).
fn table1_chart(engine: Engine, rows: &[Table1Row]) -> BarChart {
    let values = |f: fn(&Table1Row) -> f64| -> Vec<f64> { rows.iter().map(f).collect() };
    let paper =
        |f: fn(&Table1Row) -> Option<f64>| -> Option<Vec<f64>> { rows.iter().map(f).collect() };
    let mut series = vec![(
        "traditional".into(),
        PALETTE[1],
        values(|r| r.traditional_rmse_rad),
    )];
    if let Some(v) = paper(|r| r.paper_traditional) {
        series.push(("paper traditional".into(), PAPER_SHADE[1], v));
    }
    series.push((
        "proposed".into(),
        PALETTE[0],
        values(|r| r.proposed_rmse_rad),
    ));
    if let Some(v) = paper(|r| r.paper_proposed) {
        series.push(("paper proposed".into(), PAPER_SHADE[0], v));
    }
    rmse_chart(
        format!(
            "Table I: RMSE per robot, this run ({} engine) beside the paper",
            engine.as_str()
        ),
        rows.iter().map(|r| format!("robot {}", r.robot)).collect(),
        series,
    )
}

/// `table1.csv`: one row per robot.
fn table1_csv(rows: &[Table1Row]) -> Result<Vec<u8>> {
    const HEADER: [&str; 5] = [
        "robot",
        "traditional_rmse_rad",
        "proposed_rmse_rad",
        "paper_traditional_rmse_rad",
        "paper_proposed_rmse_rad",
    ];
    let rows = rows.iter().map(|r| {
        [
            r.robot.to_string(),
            r.traditional_rmse_rad.to_string(),
            r.proposed_rmse_rad.to_string(),
            or_empty(r.paper_traditional),
            or_empty(r.paper_proposed),
        ]
    });
    csv_bytes(&HEADER, rows).context("writing table1.csv")
}

/// `table2.csv`: one row per delay case.
fn table2_csv(rows: &[Table2Row]) -> Result<Vec<u8>> {
    const HEADER: [&str; 4] = ["case", "tau_ms", "rmse_rad", "paper_rmse_rad"];
    let rows = rows.iter().map(|r| {
        [
            r.case.to_string(),
            r.tau_ms.clone(),
            r.rmse_rad.to_string(),
            or_empty(r.paper_rmse_rad),
        ]
    });
    csv_bytes(&HEADER, rows).context("writing table2.csv")
}

/// Lighter shades of the palette's first two colours, for the paper's values.
const PAPER_SHADE: [RGBColor; 2] = [RGBColor(140, 190, 225), RGBColor(240, 175, 135)];

/// A bar chart of RMSE values, one group per category.
pub(crate) fn rmse_chart(
    title: String,
    categories: Vec<String>,
    series: Vec<(String, RGBColor, Vec<f64>)>,
) -> BarChart {
    BarChart {
        title,
        y_label: "RMSE (rad)".into(),
        log_y: false,
        categories,
        series,
    }
}

/// One table: what is written into its folder, and what the command line prints.
pub struct Table {
    /// File stem: `table1`, `table2`, `attacks`.
    pub name: &'static str,
    /// The markdown, without the leading `# ` of its file.
    pub md: String,
    /// The CSV's header and rows; the file starts with the [`MadeWith`] comment of `made`.
    pub csv: Vec<u8>,
    pub json: serde_json::Value,
    pub chart: BarChart,
    /// How the table was made.
    pub made: MadeWith,
    /// The folder it is written into.
    pub dir: PathBuf,
}

impl Table {
    /// Writes `<name>.md`, `.csv`, `.json` and the bar chart (`.png`, `.svg`) into its folder.
    pub(crate) fn write(&self) -> Result<()> {
        let dir = &self.dir;
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let write = |ext: &str, bytes: &[u8]| -> Result<()> {
            let p = dir.join(format!("{}.{ext}", self.name));
            std::fs::write(&p, bytes).with_context(|| format!("writing {}", p.display()))
        };
        write("md", format!("# {}", self.md).as_bytes())?;
        let mut csv = self.made.csv_comment();
        csv.extend_from_slice(&self.csv);
        write("csv", &csv)?;
        write(
            "json",
            (serde_json::to_string_pretty(&self.json)? + "\n").as_bytes(),
        )?;
        // Wider for many categories, so that their labels stay apart.
        let width =
            900.max(90 * u32::try_from(self.chart.categories.len()).unwrap_or(u32::MAX / 90));
        fdi_report::plot::save_bars(&self.chart, &dir.join(self.name), (width, 520))?;
        Ok(())
    }
}

/// Table II: robot 1's RMSE under the paper's four delays, beside the paper's; written into
/// its folder, returned.
pub fn table2(args: &TableOptions, stop: &Stop) -> Result<Table> {
    let mut owned = owned_by_tables(args);
    for keys in [&["agents", "delay"][..], &["defaults", "delay"]] {
        owned.push(Owned {
            keys,
            why: "it runs robot 1 under the four delays of the paper's Table II",
        });
    }
    let (base, made) = base(args, &owned)?;
    table2_robot(&base, args.scenario.as_deref())?;
    let dir = table_dir(args, "table2");
    if let Some(n) = args.seeds {
        return seeded::table2(args, &base, &made, &dir, n, stop);
    }
    let compare = is_papers_robot(&base, 1, false);
    let mut rows = Vec::new();
    for (case, delay, paper_rmse) in paper_table2() {
        let r = table2_case(&base, delay);
        let summary = run_case(&r, args, &dir, case, true, stop)?;
        rows.push(Table2Row {
            case,
            tau_ms: delay.describe_ms(),
            rmse_rad: robot_rmse(&summary, 1),
            paper_rmse_rad: compare.then_some(paper_rmse),
        });
    }
    let verdict = table2_verdict(&rows, &made);
    let table = Table {
        name: "table2",
        md: table2_markdown(args.engine, &made, &rows, &verdict),
        csv: table2_csv(&rows)?,
        json: serde_json::json!({ "engine": args.engine.as_str(), "made_with": made, "rows": rows, "verdict": verdict }),
        chart: table2_chart(args.engine, &rows),
        made,
        dir,
    };
    table.write()?;
    Ok(table)
}

/// Table II is robot 1's: a base scenario without an agent 1 is refused, naming the file.
fn table2_robot(base: &Resolved, file: Option<&Path>) -> Result<()> {
    if base.scenario.agents.iter().any(|a| a.id == 1) {
        return Ok(());
    }
    anyhow::bail!(
        "{}: Table II runs robot 1 under four delays, and this scenario has no agent with id 1 (its agents: {:?})",
        file.map_or_else(|| "the scenario".into(), |p| p.display().to_string()),
        robots(base)
    )
}

/// The scenario of one Table II case: robot 1 alone under `delay`.
fn table2_case(base: &Resolved, delay: DelayProfile) -> Resolved {
    let mut r = base.clone().retain_agents(|a| a.id == 1);
    for a in &mut r.scenario.agents {
        a.delay = delay;
    }
    r
}

/// The title of a Table II.
fn table2_title(engine: Engine) -> String {
    format!(
        "Table II: RMSE of robot 1 (rad) under time-varying delays, proposed controller, engine {}",
        engine.as_str()
    )
}

/// Table II's cells beside the paper's: robot 1's RMSE per delay case; `made` says whether the
/// table's options are the paper's calibration.
fn table2_verdict(rows: &[Table2Row], made: &MadeWith) -> Verdict {
    Verdict::of(
        rows.iter()
            .filter_map(|r| Cell::new("robot 1", r.case.to_string(), r.rmse_rad, r.paper_rmse_rad))
            .collect(),
        "robot 1 is not the paper's (its model and trajectory)",
    )
    .other_calibration(made.is_other_calibration())
}

/// The columns of a Table II in markdown, plain or over seeds.
const TABLE2_HEAD: [&str; 5] = ["case", "tau(t) (ms)", "RMSE", "paper RMSE", "RMSE / paper"];

/// `table2.md` (without its leading `# `), as printed.
fn table2_markdown(engine: Engine, made: &MadeWith, rows: &[Table2Row], v: &Verdict) -> String {
    let mut md = format!("{}\n\n{}", table2_title(engine), made.md());
    md.push_str(&md_table_head(&TABLE2_HEAD));
    for r in rows {
        let _ = writeln!(
            md,
            "| {} | {} | {:.4} | {} | {} |",
            r.case,
            r.tau_ms,
            r.rmse_rad,
            or_dash(r.paper_rmse_rad, 4),
            or_dash(over_paper(r.rmse_rad, r.paper_rmse_rad), 2),
        );
    }
    let _ = writeln!(md, "\n{}", v.line());
    md
}

/// Table II's bar chart: per delay case, this run's RMSE beside the paper's.
fn table2_chart(engine: Engine, rows: &[Table2Row]) -> BarChart {
    rmse_chart(
        format!(
            "Table II: RMSE of robot 1 per delay, this run ({} engine) beside the paper",
            engine.as_str()
        ),
        rows.iter().map(|r| r.case.to_string()).collect(),
        std::iter::once((
            "this run".into(),
            PALETTE[0],
            rows.iter().map(|r| r.rmse_rad).collect(),
        ))
        .chain(
            rows.iter()
                .map(|r| r.paper_rmse_rad)
                .collect::<Option<Vec<f64>>>()
                .map(|v| ("paper".into(), PAPER_SHADE[0], v)),
        )
        .collect(),
    )
}

/// Tables I and II over seeds (`--seeds N`): each cell the mean ± 95 % confidence interval
/// over N runs, on the campaigns' parallel runner.
mod seeded {
    use super::*;
    use fdi_campaign::runner;
    use fdi_campaign::stats::{self, Stats};

    /// A cell of a seeded table, as its JSON holds it.
    #[derive(Debug, Serialize)]
    struct CellStats {
        mean: f64,
        sd: Option<f64>,
        ci_low: Option<f64>,
        ci_high: Option<f64>,
        n: usize,
    }

    impl CellStats {
        fn of(values: &[f64], what: &str) -> Result<Self> {
            let Some(Stats {
                n,
                mean,
                sd,
                ci_low,
                ci_high,
            }) = stats::describe(values)
            else {
                anyhow::bail!("{what}: no run gave a finite RMSE");
            };
            if n != values.len() {
                anyhow::bail!(
                    "{what}: {} of {} runs gave no finite RMSE (a robot diverged?)",
                    values.len() - n,
                    values.len()
                );
            }
            Ok(Self {
                mean,
                sd,
                ci_low,
                ci_high,
                n,
            })
        }

        /// `0.0084 ± 0.0001`, or the mean alone for one seed.
        fn md(&self) -> String {
            match (self.ci_low, self.ci_high) {
                (Some(lo), Some(hi)) => {
                    format!("{:.4} ± {}", self.mean, fdi_campaign::sig((hi - lo) / 2.0))
                }
                _ => format!("{:.4}", self.mean),
            }
        }

        fn csv(&self) -> [String; 5] {
            let o = |x: Option<f64>| x.map_or(String::new(), |x| x.to_string());
            [
                self.mean.to_string(),
                o(self.sd),
                o(self.ci_low),
                o(self.ci_high),
                self.n.to_string(),
            ]
        }
    }

    const STAT_COLUMNS: [&str; 5] = ["mean", "sd", "ci_low", "ci_high", "n"];

    /// Runs every (scenario, case name) in parallel; every run must be whole.
    fn run_all(
        args: &TableOptions,
        dir: &Path,
        cases: &[(Resolved, String)],
        stop: &Stop,
    ) -> Result<Vec<RunSummary>> {
        let workers = args.jobs.unwrap_or_else(runner::default_jobs);
        let mut out: Vec<Option<RunSummary>> = cases.iter().map(|_| None).collect();
        let mut first_error = None;
        let outcome = runner::run_parallel(
            cases,
            workers,
            "runs",
            &*args.progress,
            stop,
            |(r, case)| {
                run_case(r, args, dir, case, false, stop).with_context(|| format!("the run {case}"))
            },
            |i, result| {
                match result {
                    Ok(s) => out[i] = Some(s),
                    Err(e) => {
                        first_error.get_or_insert(e);
                    }
                }
                Ok(())
            },
        )?;
        if let Some(e) = first_error {
            return Err(e);
        }
        if let Some(signal) = outcome.interrupted {
            return Err(fdi_common::stop::Interrupted {
                signal,
                phase: fdi_common::stop::DURING_THE_RUN,
            }
            .into());
        }
        out.into_iter()
            .zip(cases)
            .map(|(s, (_, case))| s.ok_or_else(|| anyhow::anyhow!("the run {case} did not run")))
            .collect()
    }

    fn seeds(base: u64, n: u32) -> Result<Vec<u64>> {
        (0..u64::from(n))
            .map(|i| {
                base.checked_add(i)
                    .ok_or_else(|| anyhow::anyhow!("--seeds {n}: the seed {base} + {i} overflows"))
            })
            .collect()
    }

    fn describe_seeds(seeds: &[u64]) -> String {
        match seeds {
            [one] => format!("seed {one}"),
            [first, .., last] => format!("seeds {first}–{last}"),
            [] => "no seed".into(),
        }
    }

    fn with_seed(r: &Resolved, seed: u64) -> Resolved {
        let mut r = r.clone();
        r.scenario.seed = seed;
        r
    }

    #[derive(Debug, Serialize)]
    struct Row1 {
        robot: u32,
        traditional_rmse_rad: CellStats,
        proposed_rmse_rad: CellStats,
        paper_traditional: Option<f64>,
        paper_proposed: Option<f64>,
    }

    /// Table I over seeds: each robot's RMSE, traditional and proposed, over `n` seeds.
    pub fn table1(
        args: &TableOptions,
        paper: &Resolved,
        made: &MadeWith,
        dir: &Path,
        n: u32,
        stop: &Stop,
    ) -> Result<Table> {
        let seeds = seeds(paper.scenario.seed, n)?;
        let cases = cases1(paper, &seeds);
        let summaries = run_all(args, dir, &cases, stop)?;
        let (trad, prop) = summaries.split_at(seeds.len());
        let rows = rows1(paper, trad, prop)?;
        let over = describe_seeds(&seeds);
        let csv = csv1(&rows)?;
        let plain: Vec<Table1Row> = rows
            .iter()
            .map(|r| Table1Row {
                robot: r.robot,
                traditional_rmse_rad: r.traditional_rmse_rad.mean,
                proposed_rmse_rad: r.proposed_rmse_rad.mean,
                paper_traditional: r.paper_traditional,
                paper_proposed: r.paper_proposed,
            })
            .collect();
        let verdict = table1_verdict(&plain, made).on_means();
        let md = markdown1(args.engine, made, (&over, n), (&rows, &plain), &verdict);
        let chart = table1_chart(args.engine, &plain);
        publish(
            args,
            dir,
            "table1",
            (md, csv, chart),
            made,
            (&over, &seeds),
            (&rows, &verdict),
        )
    }

    /// The runs of Table I: every seed in traditional mode, then every seed in proposed mode.
    fn cases1(paper: &Resolved, seeds: &[u64]) -> Vec<(Resolved, String)> {
        let modes = [ControllerMode::Traditional, ControllerMode::Proposed];
        let mut cases = Vec::new();
        for mode in modes {
            for &seed in seeds {
                let mut r = with_seed(paper, seed);
                r.scenario.controller.mode = mode;
                cases.push((r, format!("{}-seed{seed}", mode.as_str())));
            }
        }
        cases
    }

    /// A row of Table I per robot: its RMSE over the traditional and the proposed runs.
    fn rows1(paper: &Resolved, trad: &[RunSummary], prop: &[RunSummary]) -> Result<Vec<Row1>> {
        let mut rows = Vec::new();
        for robot in robots(paper) {
            let rmse = |runs: &[RunSummary]| -> Vec<f64> {
                runs.iter().map(|s| robot_rmse(s, robot)).collect()
            };
            let values = paper_table1(paper, robot);
            let (pt, pp) = (values.map(|v| v.0), values.map(|v| v.1));
            rows.push(Row1 {
                robot,
                traditional_rmse_rad: CellStats::of(
                    &rmse(trad),
                    &format!("robot {robot}, traditional"),
                )?,
                proposed_rmse_rad: CellStats::of(&rmse(prop), &format!("robot {robot}, proposed"))?,
                paper_traditional: pt,
                paper_proposed: pp,
            });
        }
        Ok(rows)
    }

    /// `table1.md` over seeds (`over`, as words; `n` of them); `plain` are the rows' means.
    fn markdown1(
        engine: Engine,
        made: &MadeWith,
        (over, n): (&str, u32),
        (rows, plain): (&[Row1], &[Table1Row]),
        v: &Verdict,
    ) -> String {
        let mut md = format!(
            "{}, mean ± half-width of the 95 % confidence interval (Student t) over {over} (n = {n})\n\n{}",
            table1_title(engine),
            made.md()
        );
        let mut head = TABLE1_HEAD;
        head[3] = "ratio of means";
        md.push_str(&md_table_head(&head));
        for (r, p) in rows.iter().zip(plain) {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {:.2} | {} |",
                r.robot,
                r.traditional_rmse_rad.md(),
                r.proposed_rmse_rad.md(),
                r.traditional_rmse_rad.mean / r.proposed_rmse_rad.mean,
                table1_paper_cells(p),
            );
        }
        let _ = writeln!(md, "\n{}", v.line());
        md
    }

    /// `table1.csv` over seeds: the statistics of each cell in columns of their own.
    fn csv1(rows: &[Row1]) -> Result<Vec<u8>> {
        let mut header = vec!["robot".to_string()];
        for what in ["traditional_rmse_rad", "proposed_rmse_rad"] {
            header.extend(STAT_COLUMNS.iter().map(|c| format!("{what}_{c}")));
        }
        header.extend([
            "paper_traditional_rmse_rad".into(),
            "paper_proposed_rmse_rad".into(),
        ]);
        let header: Vec<&str> = header.iter().map(String::as_str).collect();
        csv_bytes(
            &header,
            rows.iter().map(|r| {
                let mut rec = vec![r.robot.to_string()];
                rec.extend(r.traditional_rmse_rad.csv());
                rec.extend(r.proposed_rmse_rad.csv());
                rec.push(or_empty(r.paper_traditional));
                rec.push(or_empty(r.paper_proposed));
                rec
            }),
        )
        .context("writing table1.csv")
    }

    #[derive(Debug, Serialize)]
    struct Row2 {
        case: &'static str,
        tau_ms: String,
        rmse_rad: CellStats,
        paper_rmse_rad: Option<f64>,
    }

    /// Table II over seeds: robot 1's RMSE under each of the paper's delay cases, over `n`
    /// seeds.
    pub fn table2(
        args: &TableOptions,
        paper: &Resolved,
        made: &MadeWith,
        dir: &Path,
        n: u32,
        stop: &Stop,
    ) -> Result<Table> {
        let seeds = seeds(paper.scenario.seed, n)?;
        let compare = is_papers_robot(paper, 1, false);
        let mut cases = Vec::new();
        for (case, delay, _) in paper_table2() {
            let r = table2_case(paper, delay);
            for &seed in &seeds {
                cases.push((with_seed(&r, seed), format!("{case}-seed{seed}")));
            }
        }
        let summaries = run_all(args, dir, &cases, stop)?;
        let rows = rows2(&summaries, seeds.len(), compare)?;
        let over = describe_seeds(&seeds);
        let csv = csv2(&rows)?;
        let plain: Vec<Table2Row> = rows
            .iter()
            .map(|r| Table2Row {
                case: r.case,
                tau_ms: r.tau_ms.clone(),
                rmse_rad: r.rmse_rad.mean,
                paper_rmse_rad: r.paper_rmse_rad,
            })
            .collect();
        let verdict = table2_verdict(&plain, made).on_means();
        let md = markdown2(args.engine, made, (&over, n), &rows, &verdict);
        let chart = table2_chart(args.engine, &plain);
        publish(
            args,
            dir,
            "table2",
            (md, csv, chart),
            made,
            (&over, &seeds),
            (&rows, &verdict),
        )
    }

    /// A row of Table II per delay case: robot 1's RMSE over the case's runs (`per_case` of
    /// them, in the order of the cases), with the paper's value when `compare`.
    fn rows2(summaries: &[RunSummary], per_case: usize, compare: bool) -> Result<Vec<Row2>> {
        let mut rows = Vec::new();
        for ((case, delay, paper_rmse), runs) in
            paper_table2().into_iter().zip(summaries.chunks(per_case))
        {
            let rmse: Vec<f64> = runs.iter().map(|s| robot_rmse(s, 1)).collect();
            rows.push(Row2 {
                case,
                tau_ms: delay.describe_ms(),
                rmse_rad: CellStats::of(&rmse, case)?,
                paper_rmse_rad: compare.then_some(paper_rmse),
            });
        }
        Ok(rows)
    }

    /// `table2.md` over seeds (`over`, as words; `n` of them).
    fn markdown2(
        engine: Engine,
        made: &MadeWith,
        (over, n): (&str, u32),
        rows: &[Row2],
        v: &Verdict,
    ) -> String {
        let mut md = format!(
            "{}, mean ± half-width of the 95 % confidence interval (Student t) over {over} (n = {n})\n\n{}",
            table2_title(engine),
            made.md()
        );
        md.push_str(&md_table_head(&TABLE2_HEAD));
        for r in rows {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {} |",
                r.case,
                r.tau_ms,
                r.rmse_rad.md(),
                or_dash(r.paper_rmse_rad, 4),
                or_dash(over_paper(r.rmse_rad.mean, r.paper_rmse_rad), 2),
            );
        }
        let _ = writeln!(md, "\n{}", v.line());
        md
    }

    /// `table2.csv` over seeds: the statistics of each cell in columns of their own.
    fn csv2(rows: &[Row2]) -> Result<Vec<u8>> {
        let mut header = vec!["case".to_string(), "tau_ms".into()];
        header.extend(STAT_COLUMNS.iter().map(|c| format!("rmse_rad_{c}")));
        header.push("paper_rmse_rad".into());
        let header: Vec<&str> = header.iter().map(String::as_str).collect();
        csv_bytes(
            &header,
            rows.iter().map(|r| {
                let mut rec = vec![r.case.to_string(), r.tau_ms.clone()];
                rec.extend(r.rmse_rad.csv());
                rec.push(or_empty(r.paper_rmse_rad));
                rec
            }),
        )
        .context("writing table2.csv")
    }

    /// Writes a seeded table and returns it: its chart titled with the seeds (`over`, as words),
    /// its JSON with the engine, the seeds, the confidence level and the rows.
    fn publish<R: Serialize>(
        args: &TableOptions,
        dir: &Path,
        name: &'static str,
        (md, csv, mut chart): (String, Vec<u8>, BarChart),
        made: &MadeWith,
        (over, seeds): (&str, &[u64]),
        (rows, verdict): (&R, &Verdict),
    ) -> Result<Table> {
        chart.title = format!("{} (mean over {over})", chart.title);
        let table = Table {
            name,
            md,
            csv,
            json: serde_json::json!({
                "engine": args.engine.as_str(),
                "made_with": made,
                "seeds": seeds,
                "confidence": stats::LEVEL,
                "rows": rows,
                "verdict": verdict
            }),
            chart,
            made: made.clone(),
            dir: dir.to_path_buf(),
        };
        table.write()?;
        Ok(table)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table1s_verdict_judges_both_columns_against_the_paper() {
        // docs/model.md, "Reproduction": the default calibration's Table I.
        let ours = [
            (0.0187, 0.0086),
            (0.0494, 0.0107),
            (0.0204, 0.0086),
            (0.0092, 0.0087),
        ];
        let rows: Vec<Table1Row> = PAPER_TABLE1
            .iter()
            .zip(ours)
            .map(|(&(robot, pt, pp), (t, p))| Table1Row {
                robot,
                traditional_rmse_rad: t,
                proposed_rmse_rad: p,
                paper_traditional: Some(pt),
                paper_proposed: Some(pp),
            })
            .collect();
        let made = MadeWith {
            scenario: "the embedded paper scenario".into(),
            replaced: Vec::new(),
            numerics: Vec::new(),
            set: Vec::new(),
        };
        let v = table1_verdict(&rows, &made);
        let outside: Vec<String> = v
            .cells
            .iter()
            .filter(|c| !c.within)
            .map(|c| format!("{} {}", c.column, c.row))
            .collect();
        assert_eq!(outside, ["traditional robot 1", "traditional robot 4"]);
        let md = table1_markdown(Engine::Ipc, &made, &rows, &v);
        assert!(
            md.contains("| 3 | 0.0204 | 0.0086 | 2.37 | 0.026 | 0.009 | 2.89 | 0.78 | 0.96 |")
                && md.contains("Verdict: 6 of 8 cells within ±25 % of the paper."),
            "{md}"
        );
    }

    #[test]
    fn table_csvs_have_a_header_and_a_row_per_entry() {
        let t1 = table1_csv(&[Table1Row {
            robot: 2,
            traditional_rmse_rad: 0.041,
            proposed_rmse_rad: 1.0 / 3.0,
            paper_traditional: Some(0.041),
            paper_proposed: Some(0.013),
        }])
        .expect("csv");
        let mut r = csv::Reader::from_reader(t1.as_slice());
        assert_eq!(
            r.headers().expect("header"),
            vec![
                "robot",
                "traditional_rmse_rad",
                "proposed_rmse_rad",
                "paper_traditional_rmse_rad",
                "paper_proposed_rmse_rad"
            ]
        );
        let rows: Vec<csv::StringRecord> = r.records().map(|x| x.expect("row")).collect();
        assert_eq!(rows.len(), 1);
        assert_eq!(&rows[0][0], "2");
        assert_eq!(
            rows[0][2].parse::<f64>().expect("rmse").to_bits(),
            (1.0_f64 / 3.0).to_bits()
        );

        let (case, delay, paper) = paper_table2()[1];
        let t2 = table2_csv(&[Table2Row {
            case,
            tau_ms: delay.describe_ms(),
            rmse_rad: 0.01,
            paper_rmse_rad: Some(paper),
        }])
        .expect("csv");
        assert_eq!(
            std::str::from_utf8(&t2).expect("utf-8"),
            "case,tau_ms,rmse_rad,paper_rmse_rad\nlarge-fast,20 sin(0.5t) + 30,0.01,0.0101\n"
        );
        let mut r = csv::Reader::from_reader(t2.as_slice());
        assert_eq!(
            r.headers().expect("header"),
            vec!["case", "tau_ms", "rmse_rad", "paper_rmse_rad"]
        );
        let row = r.records().next().expect("a row").expect("row");
        assert_eq!(&row[1], "20 sin(0.5t) + 30");
    }
}
