//! The paper's Tables I and II.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::Args;
use fdi_common::delay::DelayProfile;
use fdi_common::engine::RunSummary;
use fdi_common::scenario::{self, ControllerMode, Resolved};
use serde::Serialize;

use crate::output::{csv_bytes, md_table_head};
use crate::plot::{BarChart, PALETTE};
use crate::run::{execute, Engine};
use plotters::style::RGBColor;

#[derive(Debug, Args)]
pub struct TableArgs {
    #[arg(long, value_enum, default_value_t = Engine::Ipc)]
    pub engine: Engine,
    /// Print JSON instead of markdown.
    #[arg(long)]
    pub json: bool,
    /// Shorten every run to this many seconds (the paper's tables use 40 s).
    #[arg(long, allow_negative_numbers = true)]
    pub duration_s: Option<f64>,
    /// Folder that receives the table's run directories.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
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
    paper_traditional: f64,
    paper_proposed: f64,
}

#[derive(Debug, Serialize)]
struct Table2Row {
    case: &'static str,
    tau_ms: String,
    rmse_rad: f64,
    paper_rmse_rad: f64,
}

/// Runs one table entry; ipc runs keep their run directory under the table's folder.
fn run_case(
    r: &Resolved,
    args: &TableArgs,
    dir: &std::path::Path,
    case: &str,
) -> Result<RunSummary> {
    match args.engine {
        Engine::Inproc => execute(
            r,
            args.engine,
            None,
            false,
            &Default::default(),
            crate::run::Traces::Full,
        ),
        Engine::Ipc => {
            let mut named = r.clone();
            named.scenario.name = case.into();
            let d = crate::output::create_run_dir(dir, &named)?;
            let summary = crate::output::discard_if_not_started(
                &d,
                execute(
                    r,
                    args.engine,
                    Some(&d),
                    !args.json,
                    &Default::default(),
                    crate::run::Traces::Full,
                ),
            )
            .and_then(crate::run::require_whole)?;
            if let Err(e) = crate::report::write_report(&d, r, &summary) {
                if e.downcast_ref::<crate::runtime::Interrupted>().is_some() {
                    return Err(e);
                }
                eprintln!(
                    "fdi-launch: warning: the report of {} could not be made: {}",
                    d.display(),
                    crate::reporting::output::describe_error(&e)
                );
            }
            Ok(summary)
        }
    }
}

fn base(args: &TableArgs) -> Result<Resolved> {
    let mut r = scenario::paper()?;
    if let Some(d) = args.duration_s {
        r.scenario.duration_s = d;
    }
    crate::run::check_overrides(r)
}

/// The folder of one table: `<out>/<timestamp>-<name>`.
fn table_dir(args: &TableArgs, name: &str) -> PathBuf {
    args.out
        .join(format!("{}-{name}", crate::output::timestamp()))
}

/// The RMSE of `robot` in a run, NaN when the run has none.
fn robot_rmse(s: &RunSummary, robot: u32) -> f64 {
    s.rmse_rad
        .get(&robot.to_string())
        .copied()
        .unwrap_or(f64::NAN)
}

pub fn table1(args: &TableArgs) -> Result<ExitCode> {
    let paper = base(args)?;
    let dir = table_dir(args, "table1");
    let run_mode = |mode: ControllerMode| {
        let mut r = paper.clone();
        r.scenario.controller.mode = mode;
        run_case(&r, args, &dir, mode.as_str())
    };
    let traditional = run_mode(ControllerMode::Traditional)?;
    let proposed = run_mode(ControllerMode::Proposed)?;
    let rows = table1_rows(&traditional, &proposed);
    let table = Table {
        name: "table1",
        md: table1_markdown(args.engine, &rows),
        csv: table1_csv(&rows)?,
        json: serde_json::json!({ "engine": args.engine.as_str(), "rows": rows }),
        chart: table1_chart(args.engine, &rows),
    };
    table.publish(args.json, &dir)
}

/// Table I's rows: the paper's robots, their RMSE in the two runs beside the paper's.
fn table1_rows(traditional: &RunSummary, proposed: &RunSummary) -> Vec<Table1Row> {
    PAPER_TABLE1
        .iter()
        .map(|&(robot, pt, pp)| Table1Row {
            robot,
            traditional_rmse_rad: robot_rmse(traditional, robot),
            proposed_rmse_rad: robot_rmse(proposed, robot),
            paper_traditional: pt,
            paper_proposed: pp,
        })
        .collect()
}

/// `table1.md` (without its leading `# `), as printed.
fn table1_markdown(engine: Engine, rows: &[Table1Row]) -> String {
    let mut md = format!(
        "Table I: RMSE of the position tracking error (rad) under the paper's FDI attack, engine {}\n\n",
        engine.as_str()
    );
    md.push_str(&md_table_head(&[
        "robot",
        "traditional",
        "proposed",
        "ratio",
        "paper traditional",
        "paper proposed",
        "paper ratio",
    ]));
    for r in rows {
        let _ = writeln!(
            md,
            "| {} | {:.4} | {:.4} | {:.2} | {:.3} | {:.3} | {:.2} |",
            r.robot,
            r.traditional_rmse_rad,
            r.proposed_rmse_rad,
            r.traditional_rmse_rad / r.proposed_rmse_rad,
            r.paper_traditional,
            r.paper_proposed,
            r.paper_traditional / r.paper_proposed
        );
    }
    md
}

/// Table I's bar chart: per robot, each controller's RMSE beside the paper's.
fn table1_chart(engine: Engine, rows: &[Table1Row]) -> BarChart {
    let values = |f: fn(&Table1Row) -> f64| -> Vec<f64> { rows.iter().map(f).collect() };
    rmse_chart(
        format!(
            "Table I: RMSE per robot, this run ({} engine) beside the paper",
            engine.as_str()
        ),
        rows.iter().map(|r| format!("robot {}", r.robot)).collect(),
        vec![
            (
                "traditional".into(),
                PALETTE[1],
                values(|r| r.traditional_rmse_rad),
            ),
            (
                "paper traditional".into(),
                PAPER_SHADE[1],
                values(|r| r.paper_traditional),
            ),
            (
                "proposed".into(),
                PALETTE[0],
                values(|r| r.proposed_rmse_rad),
            ),
            (
                "paper proposed".into(),
                PAPER_SHADE[0],
                values(|r| r.paper_proposed),
            ),
        ],
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
            r.paper_traditional.to_string(),
            r.paper_proposed.to_string(),
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
            r.paper_rmse_rad.to_string(),
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

/// One table as written and printed.
pub(crate) struct Table {
    /// File stem: `table1`, `table2`, `attacks`.
    pub name: &'static str,
    /// The markdown, without the leading `# ` of its file.
    pub md: String,
    pub csv: Vec<u8>,
    pub json: serde_json::Value,
    pub chart: BarChart,
}

impl Table {
    /// Writes the table into `dir` and prints it: its JSON with `--json`, else its markdown
    /// and where it was written.
    pub fn publish(&self, json: bool, dir: &Path) -> Result<ExitCode> {
        self.write(dir)?;
        if json {
            println!("{}", self.json);
        } else {
            print!("{}", self.md);
            println!("\ntable written to {}", dir.display());
        }
        Ok(ExitCode::SUCCESS)
    }

    /// Writes `<name>.md`, `.csv`, `.json` and the bar chart (`.png`, `.svg`) into `dir`.
    fn write(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let write = |ext: &str, bytes: &[u8]| -> Result<()> {
            let p = dir.join(format!("{}.{ext}", self.name));
            std::fs::write(&p, bytes).with_context(|| format!("writing {}", p.display()))
        };
        write("md", format!("# {}", self.md).as_bytes())?;
        write("csv", &self.csv)?;
        write(
            "json",
            (serde_json::to_string_pretty(&self.json)? + "\n").as_bytes(),
        )?;
        // Wider for many categories, so that their labels stay apart.
        let width =
            900.max(90 * u32::try_from(self.chart.categories.len()).unwrap_or(u32::MAX / 90));
        crate::plot::save_bars(&self.chart, &dir.join(self.name), (width, 520))?;
        Ok(())
    }
}

pub fn table2(args: &TableArgs) -> Result<ExitCode> {
    let paper = base(args)?;
    let dir = table_dir(args, "table2");
    let mut rows = Vec::new();
    for (case, delay, paper_rmse) in paper_table2() {
        let mut r = paper.clone().retain_agents(|a| a.id == 1);
        for a in &mut r.scenario.agents {
            a.delay = delay;
        }
        let summary = run_case(&r, args, &dir, case)?;
        rows.push(Table2Row {
            case,
            tau_ms: delay.describe_ms(),
            rmse_rad: robot_rmse(&summary, 1),
            paper_rmse_rad: paper_rmse,
        });
    }
    let table = Table {
        name: "table2",
        md: table2_markdown(args.engine, &rows),
        csv: table2_csv(&rows)?,
        json: serde_json::json!({ "engine": args.engine.as_str(), "rows": rows }),
        chart: table2_chart(args.engine, &rows),
    };
    table.publish(args.json, &dir)
}

/// `table2.md` (without its leading `# `), as printed.
fn table2_markdown(engine: Engine, rows: &[Table2Row]) -> String {
    let mut md = format!(
        "Table II: RMSE of robot 1 (rad) under time-varying delays, proposed controller, engine {}\n\n",
        engine.as_str()
    );
    md.push_str(&md_table_head(&[
        "case",
        "tau(t) (ms)",
        "RMSE",
        "paper RMSE",
    ]));
    for r in rows {
        let _ = writeln!(
            md,
            "| {} | {} | {:.4} | {:.4} |",
            r.case, r.tau_ms, r.rmse_rad, r.paper_rmse_rad
        );
    }
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
        vec![
            (
                "this run".into(),
                PALETTE[0],
                rows.iter().map(|r| r.rmse_rad).collect(),
            ),
            (
                "paper".into(),
                PAPER_SHADE[0],
                rows.iter().map(|r| r.paper_rmse_rad).collect(),
            ),
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_csvs_have_a_header_and_a_row_per_entry() {
        let t1 = table1_csv(&[Table1Row {
            robot: 2,
            traditional_rmse_rad: 0.041,
            proposed_rmse_rad: 1.0 / 3.0,
            paper_traditional: 0.041,
            paper_proposed: 0.013,
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
            paper_rmse_rad: paper,
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
