//! The tables and figures of a campaign from its stored results: `results.*` (a row per run),
//! `aggregate.*` and `aggregate.md` (statistics per point over its seeds), `timings.csv` (each
//! run's wall-clock time, kept out of the results so that they depend on the campaign alone)
//! and the figures.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use fdi_common::engine::RunSummary;
use fdi_common::field_path::show;

use super::figures;
use super::flatten::{self, Cell};
use super::plan::{labels_and_robots, toml_cell, Aggregate, Job, Plan};
use super::stats;
use super::store::write_atomic;
use std::collections::BTreeMap;
/// One row of the results table.
struct Row<'a> {
    job: &'a Job,
    seed: u64,
    cells: Vec<(String, Cell)>,
}

/// Writes the results and aggregate tables and the figures; returns the tables' paths.
pub(super) fn write_outputs(
    plan: &Plan,
    results: &[Option<RunSummary>],
    out: &Path,
) -> Result<Vec<PathBuf>> {
    let axis_labels: Vec<&str> = plan
        .axes
        .iter()
        .filter(|a| !a.is_seed())
        .map(|a| a.label.as_str())
        .collect();
    let rows = result_rows(plan, results)?;
    let columns = columns_of(&rows);
    let (results_csv, results_json) = write_results(&rows, &columns, out)?;

    // Aggregate per point over its seeds.
    let skip: BTreeSet<&str> = axis_labels.iter().copied().chain(["seed", "key"]).collect();
    let numeric: Vec<&String> = columns
        .iter()
        .filter(|c| !skip.contains(c.as_str()))
        .filter(|c| rows.iter().any(|r| lookup(r, c).num().is_some()))
        .collect();
    let aggregate = aggregate_points(plan, &rows, &numeric);
    let aggregate_csv = write_aggregate_csv(&aggregate, &numeric, &axis_labels, out)?;
    let aggregate_json = write_aggregate_json(&aggregate, out)?;

    let families = plot_families(plan.plots.as_deref(), &numeric)?;
    let md_path = out.join("aggregate.md");
    write_atomic(
        &md_path,
        aggregate_markdown(plan, &aggregate, &families).as_bytes(),
    )?;
    figures::write_all(plan, &aggregate, &families, &out.join("figures"))?;
    let timings_csv = write_timings(plan, results, out)?;
    Ok(vec![
        results_csv,
        results_json,
        aggregate_csv,
        aggregate_json,
        md_path,
        timings_csv,
        out.join("figures"),
    ])
}

/// Writes `timings.csv`: each run's wall-clock time (`run`, `key`, `engine`, `wall_s`), which
/// depends on the machine and its load and so is kept out of the results; returns its path.
fn write_timings(plan: &Plan, results: &[Option<RunSummary>], out: &Path) -> Result<PathBuf> {
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(["run", "key", "engine", "wall_s"])?;
    for (job, r) in plan.jobs.iter().zip(results) {
        if let Some(s) = r {
            w.write_record([
                job.label.clone(),
                job.key[..16].to_string(),
                s.engine.clone(),
                s.wall_s.to_string(),
            ])?;
        }
    }
    let path = out.join("timings.csv");
    write_atomic(&path, &w.into_inner().map_err(|e| e.into_error())?)?;
    Ok(path)
}

/// A row per run with a result: its point's axis values, its seed and key, and its metrics.
fn result_rows<'a>(plan: &'a Plan, results: &[Option<RunSummary>]) -> Result<Vec<Row<'a>>> {
    let mut rows = Vec::new();
    for (job, r) in plan.jobs.iter().zip(results) {
        let Some(s) = r else { continue };
        let mut cells: Vec<(String, Cell)> = plan.points[job.point]
            .values
            .iter()
            .map(|(l, v)| (l.clone(), toml_cell(v)))
            .collect();
        cells.push(("seed".into(), Cell::Int(i128::from(s.seed))));
        cells.push(("key".into(), Cell::Text(job.key[..16].to_string())));
        cells.extend(flatten::flatten(s)?);
        rows.push(Row {
            job,
            seed: s.seed,
            cells,
        });
    }
    Ok(rows)
}

/// Every column any row has, in first-seen order.
fn columns_of(rows: &[Row]) -> Vec<String> {
    let mut columns: Vec<String> = Vec::new();
    let mut seen = BTreeSet::new();
    for r in rows {
        for (c, _) in &r.cells {
            if seen.insert(c.clone()) {
                columns.push(c.clone());
            }
        }
    }
    columns
}

/// The cell of row `r` in column `c` (empty when the row has none).
fn lookup(r: &Row, c: &str) -> Cell {
    r.cells
        .iter()
        .find(|(n, _)| n == c)
        .map_or(Cell::Empty, |(_, v)| v.clone())
}

/// Writes `results.csv` and `results.json`; returns their paths.
fn write_results(rows: &[Row], columns: &[String], out: &Path) -> Result<(PathBuf, PathBuf)> {
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(columns)?;
    for r in rows {
        w.write_record(columns.iter().map(|c| lookup(r, c).csv()))?;
    }
    let results_csv = out.join("results.csv");
    write_atomic(&results_csv, &w.into_inner().map_err(|e| e.into_error())?)?;
    let json_rows: Vec<serde_json::Value> = rows
        .iter()
        .map(|r| {
            let mut m = serde_json::Map::new();
            m.insert("run".into(), r.job.label.clone().into());
            for (c, v) in &r.cells {
                m.insert(c.clone(), v.json());
            }
            serde_json::Value::Object(m)
        })
        .collect();
    let results_json = out.join("results.json");
    write_atomic(
        &results_json,
        (serde_json::to_string_pretty(&json_rows)? + "\n").as_bytes(),
    )?;
    Ok((results_csv, results_json))
}

/// Per point, the statistics of each numeric column over the point's runs.
fn aggregate_points(plan: &Plan, rows: &[Row], numeric: &[&String]) -> Vec<Aggregate> {
    let mut aggregate = Vec::new();
    for (pi, point) in plan.points.iter().enumerate() {
        let members: Vec<&Row> = rows.iter().filter(|r| r.job.point == pi).collect();
        let mut metrics = BTreeMap::new();
        for c in numeric {
            let xs: Vec<f64> = members
                .iter()
                .map(|r| lookup(r, c).num().unwrap_or(f64::NAN))
                .collect();
            metrics.insert((*c).clone(), stats::describe(&xs));
        }
        aggregate.push(Aggregate {
            point: point.clone(),
            runs: members.len(),
            seeds: members.iter().map(|r| r.seed).collect(),
            metrics,
        });
    }
    aggregate
}

/// Writes `aggregate.csv`: a line per point and metric; returns its path.
fn write_aggregate_csv(
    aggregate: &[Aggregate],
    numeric: &[&String],
    axis_labels: &[&str],
    out: &Path,
) -> Result<PathBuf> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let mut header: Vec<&str> = axis_labels.to_vec();
    header.extend(["metric", "runs", "n", "mean", "sd", "ci_low", "ci_high"]);
    w.write_record(&header)?;
    let opt = |x: Option<f64>| x.map_or(String::new(), |x| x.to_string());
    for a in aggregate {
        for c in numeric {
            let s = a.metrics.get(*c).copied().flatten();
            let mut rec: Vec<String> = a.point.values.iter().map(|(_, v)| show(v)).collect();
            rec.push((*c).clone());
            rec.push(a.runs.to_string());
            rec.push(s.map_or(0, |s| s.n).to_string());
            rec.push(opt(s.map(|s| s.mean)));
            rec.push(opt(s.and_then(|s| s.sd)));
            rec.push(opt(s.and_then(|s| s.ci_low)));
            rec.push(opt(s.and_then(|s| s.ci_high)));
            w.write_record(&rec)?;
        }
    }
    let aggregate_csv = out.join("aggregate.csv");
    write_atomic(&aggregate_csv, &w.into_inner().map_err(|e| e.into_error())?)?;
    Ok(aggregate_csv)
}

/// Writes `aggregate.json`: per point, its axis values, runs, seeds and metrics; returns its
/// path.
fn write_aggregate_json(aggregate: &[Aggregate], out: &Path) -> Result<PathBuf> {
    let aggregate_json = out.join("aggregate.json");
    let json: Vec<serde_json::Value> = aggregate
        .iter()
        .map(|a| {
            let point: serde_json::Map<String, serde_json::Value> = a
                .point
                .values
                .iter()
                .map(|(l, v)| (l.clone(), toml_cell(v).json()))
                .collect();
            serde_json::json!({
                "point": point,
                "runs": a.runs,
                "seeds": a.seeds,
                "confidence": stats::LEVEL,
                "metrics": a.metrics,
            })
        })
        .collect();
    write_atomic(
        &aggregate_json,
        (serde_json::to_string_pretty(&json)? + "\n").as_bytes(),
    )?;
    Ok(aggregate_json)
}

/// The per-robot metrics drawn and tabulated: those asked for (each must exist), or the
/// default set among those present.
fn plot_families(asked: Option<&[String]>, numeric: &[&String]) -> Result<Vec<String>> {
    let present: BTreeSet<String> = numeric
        .iter()
        .filter_map(|c| {
            c.strip_prefix("robot")?
                .split_once('.')
                .map(|(_, f)| f.to_string())
        })
        .collect();
    if let Some(asked) = asked {
        for f in asked {
            if !present.contains(f) {
                bail!(
                    "plots: no per-robot metric `{f}` in the results; the metrics are: {}",
                    present.iter().cloned().collect::<Vec<_>>().join(", ")
                );
            }
        }
        return Ok(asked.to_vec());
    }
    let mut out: Vec<String> = ["rmse_rad", "max_abs_error_rad", "deadline_misses"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let detectors: BTreeSet<&str> = present
        .iter()
        .filter_map(|f| {
            f.strip_prefix("detectors.")?
                .split_once('.')
                .map(|(d, _)| d)
        })
        .collect();
    for d in detectors {
        for m in ["onsets.mean_time_to_detect_s", "false_alarms", "coverage"] {
            out.push(format!("detectors.{d}.{m}"));
        }
    }
    Ok(out.into_iter().filter(|f| present.contains(f)).collect())
}

/// `aggregate.md`: per metric, a table of its mean ± CI half-width (n) per point and robot.
fn aggregate_markdown(plan: &Plan, aggregate: &[Aggregate], families: &[String]) -> String {
    let (labels, ids) = labels_and_robots(plan, aggregate);
    let mut md = format!(
        "# Campaign `{}`\n\nMean ± half-width of the {:.0} % confidence interval (Student t) over the seeds of each point, (n) the runs with a value.\n",
        plan.name,
        stats::LEVEL * 100.0
    );
    for f in families {
        let _ = write!(md, "\n## {f}\n\n");
        let mut cols: Vec<String> = labels.iter().map(|s| s.to_string()).collect();
        cols.extend(ids.iter().map(|id| format!("robot {id}")));
        let cols: Vec<&str> = cols.iter().map(String::as_str).collect();
        md.push_str(&fdi_report::output::md_table_head(&cols));
        for a in aggregate {
            let mut cells: Vec<String> = a.point.values.iter().map(|(_, v)| show(v)).collect();
            for id in &ids {
                let s = a.metrics.get(&format!("robot{id}.{f}")).copied().flatten();
                cells.push(match s {
                    None => "–".into(),
                    Some(s) => match s.half_width() {
                        Some(h) => format!("{} ± {} ({})", sig(s.mean), sig(h), s.n),
                        None => format!("{} ({})", sig(s.mean), s.n),
                    },
                });
            }
            let _ = writeln!(md, "| {} |", cells.join(" | "));
        }
    }
    md
}

/// Four significant digits.
pub fn sig(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    if x.abs() < 1e-3 {
        return format!("{x:.3e}");
    }
    let digits = (3 - x.abs().log10().floor() as i32).clamp(0, 12) as usize;
    format!("{x:.digits$}")
}
