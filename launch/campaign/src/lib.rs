//! Campaigns (`fdi-launch sweep CAMPAIGN.toml`): a base scenario, axes of values for fields of
//! it, every combination run (in parallel, resumably), and the statistics over seeds.
//!
//! A campaign file:
//!
//! ```toml
//! name = "beta-sweep"
//! scenario = "../paper.toml"   # relative to this file; absent: the embedded paper scenario
//! mode = "product"             # or "zip": the axes other than `seed` in lockstep
//! [set]                        # edits made to every run (optional)
//! duration_s = 20.0
//! [[axes]]
//! path = "controller.beta"     # a field path of the scenario
//! values = [0.0, 15.0, 30.0]   # or range = { start, stop, step } / { start, stop, count },
//!                              # or factors = [...]: multiples of the base value
//! [[axes]]
//! path = "seed"                # the replicates: always crossed with the other axes
//! range = { start = 1, stop = 5, step = 1 }
//! ```
//!
//! `paths = [...]` (with a `label`) sets one value at several paths (e.g. every amplitude of an
//! attack scaled by one factor). Every run's scenario is the base document edited at those
//! paths and then validated as a scenario file is; a path that is not in the document is an
//! error naming it and the keys that are there. Each result is stored under the SHA-256 of
//! the run's fully resolved scenario and engine (`points/<key>.json`, written atomically), so
//! a rerun skips what is done and an edited campaign never reuses a stale result.

pub mod classes;
pub mod figures;
pub mod flatten;
pub mod plan;
pub mod runner;
pub mod score;
pub mod shard;
pub mod stats;
pub mod status;
pub mod store;
pub mod suite;
pub mod tables;

pub use tables::sig;

use std::collections::BTreeSet;
use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use fdi_common::engine::RunSummary;
use fdi_common::observe::{Observer, Progress};
use fdi_common::scenario::{self, ClockMode, Resolved};
use fdi_common::stop::Stop;
use serde::{Deserialize, Serialize};

use fdi_common::field_path::{show, FieldPath, PathError};
use fdi_orchestrator::run::{execute, Engine, Traces};
use plan::{run_key, Axis, Job, Plan, Point, MAX_RUNS};
use store::{load_stored, stored_path, write_atomic, Stored};

/// What an interrupted campaign kept.
pub const DURING_THE_CAMPAIGN: &str =
    "during the campaign: the finished runs are stored, a rerun runs only the others";

/// A campaign to run (`fdi-launch sweep`): its file, how, and where.
#[derive(Debug, Clone)]
pub struct SweepOptions {
    /// Campaign TOML file: a base scenario and axes (see `scenarios/campaigns/`).
    pub campaign: PathBuf,
    /// Runs at a time (`None`: the number of CPUs).
    pub jobs: Option<NonZeroUsize>,
    /// The engine of every run.
    pub engine: Engine,
    /// The campaign folder (`None`: `runs/campaigns/<name>`).
    pub out: Option<PathBuf>,
    /// What each run keeps: [`Traces::None`] (the summary only; no run directory), `Full` (a
    /// run directory per run under `<out>/runs/`), `Decimate(K)`.
    pub traces: Traces,
    /// Run only this shard of the campaign ([`shard::ShardArg`]).
    pub shard: Option<shard::ShardArg>,
    /// Run nothing: make the tables and figures from the results in `out`, and name the runs
    /// missing with the shard that owns each.
    pub aggregate: bool,
    /// Run nothing: per shard, its runs done of its total, its failures, the time left.
    pub status: bool,
    /// Told the runs' progress.
    pub progress: Observer,
}

/// How a campaign (or its shard, or its aggregation) ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    /// Every run it was to make is there.
    Whole,
    /// Some runs failed or are missing (said, with their causes).
    Incomplete,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CampaignFile {
    name: String,
    #[serde(default)]
    scenario: Option<PathBuf>,
    #[serde(default)]
    mode: Mode,
    #[serde(default)]
    set: toml::Table,
    #[serde(default)]
    axes: Vec<AxisFile>,
    /// The scored benchmark in place of a base scenario and axes (docs/score.md).
    #[serde(default)]
    suite: Option<suite::SuiteFile>,
    /// Metrics (per robot, without `robot<id>.`) drawn against each axis; default: RMSE, max
    /// error, deadline misses and each detector's mean time to detect, false alarms, coverage.
    #[serde(default)]
    plots: Option<Vec<String>>,
}

#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
enum Mode {
    #[default]
    Product,
    Zip,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct AxisFile {
    path: Option<String>,
    paths: Option<Vec<String>>,
    label: Option<String>,
    values: Option<Vec<toml::Value>>,
    range: Option<RangeFile>,
    factors: Option<Vec<f64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RangeFile {
    start: toml::Value,
    stop: toml::Value,
    step: Option<toml::Value>,
    count: Option<usize>,
}

fn number(v: &toml::Value, what: &str) -> Result<f64> {
    match v {
        toml::Value::Integer(i) => Ok(*i as f64),
        toml::Value::Float(f) if f.is_finite() => Ok(*f),
        other => bail!("{what} must be a finite number, not {other}"),
    }
}

/// The values of a range; `at` names a field of the range (`start`, `step`, …) with its place
/// in the campaign file. A range of integers (`start`, `stop` and `step` or the steps of a
/// `count` all whole) gives integers, computed exactly (a seed near 2⁶³ stays itself); a range
/// of more values than a campaign may run is refused before any is made, whatever the count
/// (a step of 1e-300, a span beyond the largest float).
fn range_values(r: &RangeFile, at: &dyn Fn(&str) -> String) -> Result<Vec<toml::Value>> {
    match (&r.step, r.count) {
        (Some(step), None) => range_by_step(r, step, at),
        (None, Some(count)) => range_by_count(r, count, at),
        _ => bail!(
            "{}: takes exactly one of `step` and `count` beside `start` and `stop`",
            at("")
        ),
    }
}

/// The refusal of a range of `n` values, more than a campaign may run.
fn too_many(at: &dyn Fn(&str) -> String, n: String) -> anyhow::Error {
    anyhow::anyhow!(
        "{}: {n} values, more than the {MAX_RUNS} runs a campaign may hold",
        at("")
    )
}

/// The values of a range given by `step`: integers when `start`, `stop` and `step` are all
/// integers, floats otherwise.
fn range_by_step(
    r: &RangeFile,
    step: &toml::Value,
    at: &dyn Fn(&str) -> String,
) -> Result<Vec<toml::Value>> {
    if let (toml::Value::Integer(a), toml::Value::Integer(b), toml::Value::Integer(d)) =
        (&r.start, &r.stop, step)
    {
        let (a, b, d) = (i128::from(*a), i128::from(*b), i128::from(*d));
        if d == 0 || (b - a) * d.signum() < 0 {
            bail!("{}: step {d} never goes from {a} to {b}", at("step"));
        }
        let n = (b - a) / d + 1;
        if n > MAX_RUNS as i128 {
            return Err(too_many(at, n.to_string()));
        }
        return integer_values((0..n).map(|i| a + i * d), at(""));
    }
    float_range_by_step(r, step, at)
}

/// The values of a range of floats given by `step`; a span beyond the largest float is
/// stepped through piecewise.
fn float_range_by_step(
    r: &RangeFile,
    step: &toml::Value,
    at: &dyn Fn(&str) -> String,
) -> Result<Vec<toml::Value>> {
    let start = number(&r.start, &at("start"))?;
    let stop = number(&r.stop, &at("stop"))?;
    let step = number(step, &at("step"))?;
    if step == 0.0 || (stop - start) * step < 0.0 {
        bail!(
            "{}: step {step} never goes from {start} to {stop}",
            at("step")
        );
    }
    // The number of steps; beyond the largest float the span is divided piecewise.
    let span = stop - start;
    let steps = if span.is_finite() {
        span / step
    } else {
        stop / step - start / step
    };
    let n = (steps + 1e-9).floor() + 1.0;
    if n.is_nan() || n > MAX_RUNS as f64 {
        return Err(too_many(
            at,
            if n.is_finite() {
                format!("about {n:.1e}")
            } else {
                "more than 10^308".into()
            },
        ));
    }
    // n ≤ MAX_RUNS: exact as an integer.
    let n = n as usize;
    finite_values(
        (0..n).map(|i| {
            if span.is_finite() {
                start + i as f64 * step
            } else {
                // i · step may pass the largest float where the value does not.
                2.0 * (start / 2.0 + i as f64 * (step / 2.0))
            }
        }),
        at(""),
    )
}

/// The `count` values of a range from `start` to `stop`: integers when the ends are integers
/// an integer step apart, floats otherwise.
fn range_by_count(
    r: &RangeFile,
    count: usize,
    at: &dyn Fn(&str) -> String,
) -> Result<Vec<toml::Value>> {
    if count == 0 || count > MAX_RUNS {
        bail!(
            "{}: must be between 1 and {MAX_RUNS}, not {count}",
            at("count")
        );
    }
    if let (toml::Value::Integer(a), toml::Value::Integer(b)) = (&r.start, &r.stop) {
        let (a, b) = (i128::from(*a), i128::from(*b));
        let gaps = count as i128 - 1;
        if gaps == 0 || (b - a) % gaps == 0 {
            let d = if gaps == 0 { 0 } else { (b - a) / gaps };
            return integer_values((0..count as i128).map(|i| a + i * d), at(""));
        }
    }
    let start = number(&r.start, &at("start"))?;
    let stop = number(&r.stop, &at("stop"))?;
    let span = stop - start;
    finite_values(
        (0..count).map(|i| {
            let t = i as f64 / (count.max(2) - 1) as f64;
            if count == 1 {
                start
            } else if i + 1 == count {
                stop
            } else if span.is_finite() {
                start + span * t
            } else {
                // The span is beyond the largest float: weigh the ends instead.
                start * (1.0 - t) + stop * t
            }
        }),
        at(""),
    )
}

/// The values as integers of TOML (64-bit), or an error naming `at`.
fn integer_values(xs: impl Iterator<Item = i128>, at: String) -> Result<Vec<toml::Value>> {
    xs.map(|x| {
        i64::try_from(x)
            .map(toml::Value::Integer)
            .map_err(|_| anyhow::anyhow!("{at}: gives {x}, beyond the integers of TOML"))
    })
    .collect()
}

/// The values as floats, each finite, or an error naming `at`.
fn finite_values(xs: impl Iterator<Item = f64>, at: String) -> Result<Vec<toml::Value>> {
    xs.map(|x| {
        if x.is_finite() {
            Ok(toml::Value::Float(x))
        } else {
            Err(anyhow::anyhow!(
                "{at}: gives the value {x}, not a finite number"
            ))
        }
    })
    .collect()
}

/// The campaign file's text, to say where in it a field is.
struct Source<'a> {
    name: &'a str,
    text: &'a str,
}

impl Source<'_> {
    /// `FILE: FIELD (line L, column C)` of a field path of the campaign file (`axes[1].path`);
    /// a field the text does not hold is placed at the nearest table above it that it holds,
    /// and named without a place when it holds nothing of it.
    fn at(&self, field: &str) -> String {
        format!("{}: {}", self.name, self.place(field))
    }

    /// `FIELD (line L, column C)`, as [`Source::at`] without the file.
    fn place(&self, field: &str) -> String {
        match scenario::locate(self.text, field) {
            Some(offset) => {
                let (line, column) = scenario::line_column(self.text, offset);
                format!("{field} (line {line}, column {column})")
            }
            None => field.to_string(),
        }
    }
}

/// An edit of the base document that failed: a key missing below the top level may be one the
/// base scenario leaves at its default, which a campaign edits only once it is written there.
fn swept(e: PathError) -> anyhow::Error {
    match e {
        PathError::NoKey { ref at, .. } if at.starts_with('`') => anyhow::anyhow!(
            "{e} (a key the base scenario leaves at its default must be written into it to be swept)"
        ),
        e => e.into(),
    }
}

fn resolve_axes(file: &CampaignFile, src: &Source) -> Result<Vec<Axis>> {
    if file.axes.is_empty() {
        bail!(
            "{}: a campaign needs at least one [[axes]] (or a `[suite]`: docs/score.md)",
            src.name
        );
    }
    let mut axes = Vec::new();
    for (i, a) in file.axes.iter().enumerate() {
        let field = format!("axes[{i}]");
        let at = src.at(&field);
        let (paths, fields): (Vec<String>, Vec<String>) = match (&a.path, &a.paths) {
            (Some(p), None) => (vec![p.clone()], vec![format!("{field}.path")]),
            (None, Some(ps)) if !ps.is_empty() => (
                ps.clone(),
                (0..ps.len())
                    .map(|j| format!("{field}.paths[{j}]"))
                    .collect(),
            ),
            _ => bail!("{at}: takes exactly one of `path` and `paths` (a non-empty list)"),
        };
        let label = match (&a.label, paths.as_slice()) {
            (Some(l), _) => l.clone(),
            (None, [one]) => one.clone(),
            (None, _) => bail!("{at}: an axis over several `paths` needs a `label`"),
        };
        let paths = paths
            .iter()
            .zip(&fields)
            .map(|(p, f)| FieldPath::parse(p).with_context(|| src.at(f)))
            .collect::<Result<Vec<_>>>()?;
        let range_at = |sub: &str| {
            if sub.is_empty() {
                src.at(&format!("{field}.range"))
            } else {
                src.at(&format!("{field}.range.{sub}"))
            }
        };
        let (values, factors) = match (&a.values, &a.range, &a.factors) {
            (Some(v), None, None) => (v.clone(), false),
            (None, Some(r), None) => (range_values(r, &range_at)?, false),
            (None, None, Some(f)) => {
                if let Some(bad) = f.iter().find(|x| !x.is_finite()) {
                    bail!(
                        "{}: {bad} is not a finite number",
                        src.at(&format!("{field}.factors"))
                    );
                }
                (f.iter().map(|x| toml::Value::Float(*x)).collect(), true)
            }
            _ => bail!("{at}: takes exactly one of `values`, `range` and `factors`"),
        };
        if values.is_empty() {
            bail!("{at} ({label}) has no values");
        }
        axes.push(Axis {
            label,
            paths,
            fields,
            values,
            factors,
        });
    }
    let mut labels = BTreeSet::new();
    for (i, a) in axes.iter().enumerate() {
        if !labels.insert(a.label.as_str()) {
            bail!(
                "{}: two axes are labelled `{}`: give one a `label`",
                src.at(&format!("axes[{i}]")),
                a.label
            );
        }
        if a.is_seed() && a.factors {
            bail!(
                "{}: the seed axis takes `values` or a `range`, not `factors`",
                src.at(&format!("axes[{i}]"))
            );
        }
    }
    refuse_overlaps(&axes, src)?;
    Ok(axes)
}

/// The campaign file from its text: a syntax error, an unknown key or a value of the wrong type
/// is named with its line and column.
fn parse_campaign(text: &str, name: &str) -> Result<CampaignFile> {
    // Syntax first, as scenario files are checked.
    toml::from_str::<toml::Table>(text)
        .map_err(|e| anyhow::anyhow!("{name}: {}", scenario::toml_syntax_error(text, &e)))?;
    toml::from_str(text).map_err(|e| {
        let at = e.span().map_or(String::new(), |span| {
            let (line, column) = scenario::line_column(text, span.start);
            format!(" (line {line}, column {column})")
        });
        anyhow::anyhow!("{name}{at}: {}", e.message().trim_end())
    })
}

/// Refuses a `[set]` edit that an axis overwrites in every run (the axis's path is the edit's
/// or a table holding it); an axis of `factors` scales the value `[set]` gives, so an edit
/// under it is meant.
fn refuse_set_under_axes(
    set: &[(FieldPath, toml::Value)],
    axes: &[Axis],
    src: &Source,
) -> Result<()> {
    for (p, _) in set {
        for a in axes.iter().filter(|a| !a.factors) {
            for (q, f) in a.paths.iter().zip(&a.fields) {
                if q.holds(p) {
                    bail!(
                        "{}: `{p}` in [set] ({}) is overwritten in every run by axis `{}` ({}): set it in one place",
                        src.name,
                        src.place("set"),
                        a.label,
                        src.place(f)
                    );
                }
            }
        }
    }
    Ok(())
}

/// Refuses two paths of the axes that reach one value (the same path, `attack.x` and
/// `attack.profile.x`, or a table and a value inside it): the later one would overwrite the
/// earlier in every run, which would run one value and report another. Names both axes, the
/// paths and their places in the campaign file.
fn refuse_overlaps(axes: &[Axis], src: &Source) -> Result<()> {
    let all: Vec<(&Axis, &FieldPath, &String)> = axes
        .iter()
        .flat_map(|a| a.paths.iter().zip(&a.fields).map(move |(p, f)| (a, p, f)))
        .collect();
    for (n, (a, p, f)) in all.iter().enumerate() {
        for (b, q, g) in &all[n + 1..] {
            if !p.overlaps(q) {
                continue;
            }
            let what = if p.text == q.text {
                format!("`{p}`")
            } else {
                format!("`{p}` and `{q}`, which reach one value")
            };
            if std::ptr::eq(*a, *b) {
                bail!(
                    "{}: axis `{}` sets {what} twice, at {} and at {}: each path of an axis must reach a value of its own",
                    src.name,
                    a.label,
                    src.place(f),
                    src.place(g)
                );
            }
            bail!(
                "{}: axes `{}` ({}) and `{}` ({}) both set {what}: every run would hold the later axis's value whatever the earlier one's column says; sweep the path on one axis (several values in lockstep: mode = \"zip\"; one value at several paths: `paths`)",
                src.name,
                a.label,
                src.place(f),
                b.label,
                src.place(g)
            );
        }
    }
    Ok(())
}

/// The combinations of the non-seed axes (indices into each one's values).
fn combinations(axes: &[&Axis], mode: Mode) -> Result<Vec<Vec<usize>>> {
    if axes.is_empty() {
        return Ok(vec![vec![]]);
    }
    match mode {
        Mode::Zip => {
            let n = axes[0].values.len();
            if let Some(other) = axes.iter().find(|a| a.values.len() != n) {
                bail!(
                    "mode = \"zip\" needs axes of one length: `{}` has {n} values, `{}` has {}",
                    axes[0].label,
                    other.label,
                    other.values.len()
                );
            }
            Ok((0..n).map(|i| vec![i; axes.len()]).collect())
        }
        Mode::Product => {
            let mut out: Vec<Vec<usize>> = vec![vec![]];
            for a in axes {
                out = out
                    .into_iter()
                    .flat_map(|c| {
                        (0..a.values.len()).map(move |i| {
                            let mut c = c.clone();
                            c.push(i);
                            c
                        })
                    })
                    .collect();
                if out.len() > MAX_RUNS {
                    bail!("more than {MAX_RUNS} points");
                }
            }
            Ok(out)
        }
    }
}

/// The value an axis writes at `path` of `doc`.
fn axis_value(
    a: &Axis,
    p: &FieldPath,
    v: &toml::Value,
    doc: &mut toml::Table,
) -> Result<toml::Value> {
    if !a.factors {
        return Ok(v.clone());
    }
    let f = number(v, &a.label)?;
    let base = p.number(doc).map_err(swept)?;
    Ok(toml::Value::Float(base * f))
}

/// Reads the campaign file and expands it into its points and runs, each run's scenario
/// resolved and keyed.
fn plan(campaign: &Path, engine: Engine) -> Result<Plan> {
    let name_of = campaign.display().to_string();
    let text = scenario::read_limited(campaign).map_err(anyhow::Error::msg)?;
    let file = parse_campaign(&text, &name_of)?;
    let src = Source {
        name: &name_of,
        text: &text,
    };
    if fdi_orchestrator::run_dirs::safe_name(&file.name).is_empty() {
        bail!(
            "{}: is empty: the campaign's folder is runs/campaigns/<name>",
            src.at("name")
        );
    }
    if let Some(why) = fdi_common::files::unprintable(&file.name) {
        bail!("{}: {why}", src.at("name"));
    }
    if let Some(suite) = &file.suite {
        refuse_beside_suite(&file, &src)?;
        return score::plan(&file.name, suite, engine, &|f| src.at(f));
    }
    let (base_text, base_name, base_dir) = read_base(campaign, &file)?;
    let base = scenario::load_str(&base_text, &base_name, base_dir.as_deref())?;
    let mut doc: toml::Table =
        toml::from_str(&base_text).with_context(|| format!("{base_name}: not a TOML document"))?;
    let axes = resolve_axes(&file, &src)?;
    let set = parse_set(&file, &src)?;
    refuse_set_under_axes(&set, &axes, &src)?;
    apply_set(&mut doc, &set, &axes, &base, &src)?;
    let seed_axis = axes.iter().find(|a| a.is_seed()).cloned();
    let others: Vec<&Axis> = axes.iter().filter(|a| !a.is_seed()).collect();
    let combos = combinations(&others, file.mode)?;
    let seeds = seed_axis.as_ref().map_or(1, |a| a.values.len());
    if combos.len().saturating_mul(seeds) > MAX_RUNS {
        bail!("{} runs, more than {MAX_RUNS}", combos.len() * seeds);
    }
    let expansion = Expansion {
        doc: &doc,
        others: &others,
        seed_axis: seed_axis.as_ref(),
        name: &name_of,
        base_dir: base_dir.as_deref(),
        engine,
    };
    let mut points = Vec::new();
    let mut jobs = Vec::new();
    for (pi, combo) in combos.iter().enumerate() {
        points.push(expansion.point(pi, combo, &mut jobs)?);
    }
    Ok(Plan {
        name: file.name,
        axes,
        points,
        jobs,
        seeds,
        plots: file.plots,
        suite: None,
    })
}

/// Refuses what a campaign of the suite cannot have beside its `[suite]`: the suite's runs
/// are fixed, and a row is of the suite as it is.
fn refuse_beside_suite(file: &CampaignFile, src: &Source) -> Result<()> {
    let beside = [
        ("scenario", file.scenario.is_some()),
        ("set", !file.set.is_empty()),
        ("axes", !file.axes.is_empty()),
        ("plots", file.plots.is_some()),
        ("mode", file.mode != Mode::Product),
    ];
    if let Some((key, _)) = beside.iter().find(|(_, there)| *there) {
        bail!(
            "{}: a campaign of the suite (`[suite]`) has no `{key}`: its teams, attacks and seeds are the suite's",
            src.at(key)
        );
    }
    Ok(())
}

/// The base scenario of a campaign: its text, its name for messages and its folder (the
/// embedded paper scenario when the campaign names none).
fn read_base(campaign: &Path, file: &CampaignFile) -> Result<(String, String, Option<PathBuf>)> {
    let file_dir = campaign.parent().unwrap_or(Path::new(""));
    Ok(match &file.scenario {
        Some(p) => {
            let path = file_dir.join(p);
            (
                scenario::read_limited(&path).map_err(anyhow::Error::msg)?,
                path.display().to_string(),
                path.parent().map(Path::to_path_buf),
            )
        }
        None => (
            scenario::PAPER_SCENARIO.to_string(),
            "<embedded paper scenario>".to_string(),
            None,
        ),
    })
}

/// The edits of the campaign's `[set]`, each path parsed.
fn parse_set(file: &CampaignFile, src: &Source) -> Result<Vec<(FieldPath, toml::Value)>> {
    file.set
        .iter()
        .map(|(k, v)| {
            Ok((
                FieldPath::parse(k).with_context(|| src.at("set"))?,
                v.clone(),
            ))
        })
        .collect::<Result<_>>()
}

/// Applies `[set]` to the base document, with the base attack written inline first when `[set]`
/// or an axis edits the attack's profile.
fn apply_set(
    doc: &mut toml::Table,
    set: &[(FieldPath, toml::Value)],
    axes: &[Axis],
    base: &Resolved,
    src: &Source,
) -> Result<()> {
    let touches_attack = set.iter().any(|(p, _)| p.is_in_attack_profile())
        || axes
            .iter()
            .flat_map(|a| &a.paths)
            .any(FieldPath::is_in_attack_profile);
    if touches_attack {
        // Paths into the attack edit its profile, written inline.
        let mut attack = toml::Table::new();
        attack.insert(
            "profile".into(),
            toml::Value::try_from(&base.attack).context("the base scenario's attack as TOML")?,
        );
        doc.insert("attack".into(), toml::Value::Table(attack));
    }
    for (p, v) in set {
        p.set(doc, v)
            .map_err(swept)
            .with_context(|| src.at("set"))?;
    }
    Ok(())
}

/// What the points and runs of a campaign are made from: the base document (`[set]` applied),
/// the axes other than the seed, the seed axis, and what each run's scenario is loaded with.
struct Expansion<'a> {
    doc: &'a toml::Table,
    others: &'a [&'a Axis],
    seed_axis: Option<&'a Axis>,
    /// The campaign file's name, for messages.
    name: &'a str,
    base_dir: Option<&'a Path>,
    engine: Engine,
}

impl Expansion<'_> {
    /// Point `pi` (the combination `combo` of the other axes); its runs, one per seed, are
    /// pushed onto `jobs`.
    fn point(&self, pi: usize, combo: &[usize], jobs: &mut Vec<Job>) -> Result<Point> {
        let mut point_doc = self.doc.clone();
        let mut values = Vec::new();
        for (a, &i) in self.others.iter().zip(combo) {
            let v = &a.values[i];
            for p in &a.paths {
                let x = axis_value(a, p, v, &mut point_doc)
                    .with_context(|| format!("axis `{}`", a.label))?;
                p.set(&mut point_doc, &x)
                    .map_err(swept)
                    .with_context(|| format!("axis `{}` = {}", a.label, show(v)))?;
            }
            values.push((a.label.clone(), v.clone()));
        }
        let seed_values: Vec<Option<&toml::Value>> = match self.seed_axis {
            Some(a) => a.values.iter().map(Some).collect(),
            None => vec![None],
        };
        for sv in seed_values {
            jobs.push(self.job(pi, &point_doc, &values, sv)?);
        }
        Ok(Point { values })
    }

    /// The run of point `pi` (its document and axis values) with seed `sv`: its label, its
    /// resolved scenario and its key.
    fn job(
        &self,
        pi: usize,
        point_doc: &toml::Table,
        values: &[(String, toml::Value)],
        sv: Option<&toml::Value>,
    ) -> Result<Job> {
        let mut run_doc = point_doc.clone();
        let mut label: Vec<String> = values
            .iter()
            .map(|(l, v)| format!("{l} = {}", show(v)))
            .collect();
        if let (Some(a), Some(v)) = (self.seed_axis, sv) {
            a.paths[0]
                .set(&mut run_doc, v)
                .map_err(swept)
                .with_context(|| format!("axis `seed` = {}", show(v)))?;
            label.push(format!("seed = {}", show(v)));
        }
        let label = label.join(", ");
        let text = toml::to_string(&run_doc).context("a run's scenario as TOML")?;
        let resolved = scenario::load_str(
            &text,
            &format!("{}: the run {label}", self.name),
            self.base_dir,
        )?;
        if resolved.scenario.clock == ClockMode::Realtime && self.engine == Engine::Inproc {
            bail!("the run {label}: the realtime clock needs --engine ipc");
        }
        let key = run_key(&resolved, self.engine);
        Ok(Job {
            point: pi,
            label,
            resolved,
            key,
        })
    }
}

/// The folder of a campaign without `--out`: `runs/campaigns/<name>`, the name made one
/// component of the path by the rule of run folders ([`fdi_orchestrator::run_dirs::safe_name`]), so that
/// `../x` or `/x` stays under `runs/campaigns/` (an empty name is refused by [`plan`]).
fn default_out(name: &str) -> PathBuf {
    PathBuf::from("runs")
        .join("campaigns")
        .join(fdi_orchestrator::run_dirs::safe_name(name))
}

/// Runs a campaign (`fdi-launch sweep`): the runs not stored yet, then its tables and figures.
/// With `--shard`, only the shard's runs and no tables; with `--aggregate` or `--status`, no
/// runs.
pub fn sweep(args: &SweepOptions, stop: &Stop, said: &mut dyn FnMut(&str)) -> Result<Ended> {
    let progress = &*args.progress;
    let plan = plan(&args.campaign, args.engine)?;
    let out = args.out.clone().unwrap_or_else(|| default_out(&plan.name));
    if args.status {
        status::print(&plan, &out, args.engine, said)?;
        return Ok(Ended::Whole);
    }
    if args.aggregate {
        return aggregate(args, &plan, &out, said);
    }
    if let Some(shard) = args.shard {
        return run_shard(args, &plan, &out, shard.resolve()?, (stop, progress), said);
    }
    prepare_out(&out)?;
    copy_campaign(args, &out)?;
    let all = plan.unique_jobs(|_| true);
    said(&format!(
        "campaign {}: {} runs ({} points × {} seeds), engine {}, {}",
        plan.name,
        plan.jobs.len(),
        plan.points.len(),
        plan.seeds,
        args.engine.as_str(),
        plural(args.jobs.unwrap_or_else(runner::default_jobs).get(), "job")
    ));
    let tally = run_batch(args, &plan, &out, &all, None, (stop, progress), said)?;
    let results: Vec<Option<RunSummary>> = plan
        .jobs
        .iter()
        .map(|j| load_stored(&out, &j.key))
        .collect();
    let mut tables = tables::write_outputs(&plan, &results, &out)?;
    said(&format!(
        "{}; {} of {} runs in the tables",
        tally.said(),
        results.iter().filter(|r| r.is_some()).count(),
        plan.jobs.len()
    ));
    if let Some(suite) = &plan.suite {
        tables.extend(score::write_row(suite, &results, &out, said)?);
    }
    said(&format!("campaign folder {}", out.display()));
    for t in tables {
        said(&format!("  {}", t.display()));
    }
    campaign_end(tally.signal, &tally.failed)
}

/// `1 job`, `2 jobs`.
fn plural(n: usize, what: &str) -> String {
    format!("{n} {what}{}", if n == 1 { "" } else { "s" })
}

/// Shard `shard` of the campaign: its runs not stored yet, its record kept in
/// `shards/K-of-N.json` as they end, under its lease; no table (`--aggregate` makes them).
fn run_shard(
    args: &SweepOptions,
    plan: &Plan,
    out: &Path,
    shard: shard::Shard,
    (stop, progress): (&Stop, &dyn Progress),
    said: &mut dyn FnMut(&str),
) -> Result<Ended> {
    prepare_out(out)?;
    let hash = shard::campaign_hash(plan);
    let expected = shard::Expected {
        hash: &hash,
        engine: args.engine.as_str(),
        count: Some(shard.count),
    };
    shard::check_records(&shard::records(out)?, &expected, out)?;
    let auto = matches!(args.shard, Some(shard::ShardArg::Auto));
    let lease = shard::Lease::take(out, shard, auto)?;
    let owners = shard::owners(plan, shard.count);
    let owned = plan.unique_jobs(|i| owners[i] == shard.index);
    let jobs = args.jobs.unwrap_or_else(runner::default_jobs).get();
    said(&format!(
        "campaign {}, shard {shard}: {} of the campaign's {} runs, engine {}, {}",
        plan.name,
        owned.len(),
        plan.unique_jobs(|_| true).len(),
        args.engine.as_str(),
        plural(jobs, "job")
    ));
    let now = shard::unix_now();
    let record = shard::Record {
        campaign: plan.name.clone(),
        campaign_hash: hash.clone(),
        engine: args.engine.as_str().into(),
        launcher: shard::launcher_version(),
        shard,
        runs: owned.len(),
        jobs,
        host: shard::host_name(),
        pid: std::process::id(),
        started_unix_s: now,
        updated_unix_s: now,
        state: shard::State::Running,
        ran: 0,
        skipped: 0,
        failures: Vec::new(),
    };
    let tally = run_batch(
        args,
        plan,
        out,
        &owned,
        Some((record, lease.lost())),
        (stop, progress),
        said,
    )?;
    said(&tally.said());
    said(&format!(
        "shard {shard} of campaign folder {}: once every shard is done, `fdi-launch sweep {} --aggregate --out {}` makes the tables",
        out.display(),
        args.campaign.display(),
        out.display()
    ));
    campaign_end(tally.signal, &tally.failed)
}

/// `fdi-launch sweep CAMPAIGN --aggregate`: the tables and figures from the results in the
/// folder, and the runs missing, each with the shard that owns it. Fails (after writing the
/// tables of what is there) when a run is missing.
fn aggregate(
    args: &SweepOptions,
    plan: &Plan,
    out: &Path,
    said: &mut dyn FnMut(&str),
) -> Result<Ended> {
    if !out.join("points").is_dir() {
        bail!(
            "--aggregate: {} holds no results (no points/ folder): run the campaign or its shards into it first",
            out.display()
        );
    }
    let records = shard::records(out)?;
    let hash = shard::campaign_hash(plan);
    let expected = shard::Expected {
        hash: &hash,
        engine: args.engine.as_str(),
        count: None,
    };
    shard::check_records(&records, &expected, out)?;
    let count = shard::count_of(&records, out)?;
    let results: Vec<Option<RunSummary>> =
        plan.jobs.iter().map(|j| load_stored(out, &j.key)).collect();
    let done = results.iter().filter(|r| r.is_some()).count();
    // The missing runs first: the tables of what is there may fail (no result at all).
    if done < plan.jobs.len() {
        log::info!(
            "{} of {} runs are missing:\n{}",
            plan.jobs.len() - done,
            plan.jobs.len(),
            status::missing(plan, &results, count, &records, out)
        );
    }
    copy_campaign(args, out)?;
    let mut tables = tables::write_outputs(plan, &results, out)?;
    if let Some(suite) = &plan.suite {
        tables.extend(score::write_row(suite, &results, out, said)?);
    }
    said(&format!(
        "campaign {}: {done} of {} runs in the tables{}",
        plan.name,
        plan.jobs.len(),
        count.map_or(String::new(), |n| format!(" (from {} shards)", n))
    ));
    said(&format!("campaign folder {}", out.display()));
    for t in tables {
        said(&format!("  {}", t.display()));
    }
    Ok(if done == plan.jobs.len() {
        Ended::Whole
    } else {
        Ended::Incomplete
    })
}

/// The campaign folder `out`, made.
fn prepare_out(out: &Path) -> Result<()> {
    if out.exists() && !out.is_dir() {
        bail!("--out {} is not a folder", out.display());
    }
    std::fs::create_dir_all(out.join("points"))
        .with_context(|| format!("creating {}", out.join("points").display()))
}

/// A copy of the campaign file in its folder (`campaign.toml`), written whole.
fn copy_campaign(args: &SweepOptions, out: &Path) -> Result<()> {
    let text = std::fs::read(&args.campaign)
        .with_context(|| format!("reading {}", args.campaign.display()))?;
    write_atomic(&out.join("campaign.toml"), &text)
        .with_context(|| format!("copying the campaign into {}", out.display()))
}

/// Runs the jobs `owned` (indices into the plan's jobs, one per key) whose result is not
/// stored yet; stores each result as it ends, and keeps a shard's record up to date (with the
/// flag its lease raises when it is lost: the batch then starts no more runs).
fn run_batch(
    args: &SweepOptions,
    plan: &Plan,
    out: &Path,
    owned: &[usize],
    shard: Option<(shard::Record, Arc<AtomicBool>)>,
    (stop, progress): (&Stop, &dyn Progress),
    said: &mut dyn FnMut(&str),
) -> Result<Tally> {
    let todo: Vec<usize> = owned
        .iter()
        .copied()
        .filter(|&i| load_stored(out, &plan.jobs[i].key).is_none())
        .collect();
    let skipped = owned.len() - todo.len();
    said(&format!(
        "{skipped} already done (skipped), {} to run",
        todo.len()
    ));
    let (record, lost) = shard.unzip();
    let mut tally = Tally {
        out: out.to_path_buf(),
        engine: args.engine,
        failed: Vec::new(),
        ran: 0,
        skipped,
        not_started: 0,
        signal: None,
        record,
        lost,
    };
    tally.save_record(None);
    let runs_root = out.join("runs");
    let outcome = runner::run_parallel(
        &todo,
        args.jobs.unwrap_or_else(runner::default_jobs),
        &plan.name,
        progress,
        stop,
        |&i| run_one(&plan.jobs[i], &plan.name, args, &runs_root, stop),
        |n, end| tally.record(&plan.jobs[todo[n]], end),
    );
    let outcome = match outcome {
        Ok(o) => o,
        Err(e) => {
            tally.save_record(Some(shard::State::Failed));
            return Err(e);
        }
    };
    tally.signal = tally.signal.or(outcome.interrupted);
    tally.not_started = outcome.not_started;
    let end = if tally.signal.is_some() {
        shard::State::Interrupted
    } else if tally.failed.is_empty() {
        shard::State::Finished
    } else {
        shard::State::Failed
    };
    tally.save_record(Some(end));
    Ok(tally)
}

/// What the runs of a batch gave: the runs that failed, how many ran, and the signal that
/// interrupted one; with the record of the shard they are of, and its lease's flag.
struct Tally {
    out: PathBuf,
    engine: Engine,
    failed: Vec<shard::Failure>,
    ran: usize,
    skipped: usize,
    not_started: usize,
    signal: Option<i32>,
    record: Option<shard::Record>,
    lost: Option<Arc<AtomicBool>>,
}

impl Tally {
    /// Records the end of `job`: a summary is stored in `points/`, a failure named. An error
    /// (a result that cannot be stored, a shard's lease lost) stops the batch.
    /// Stores a run's result, or counts its failure; an interrupted run is neither: the next
    /// attempt runs it again.
    fn record(&mut self, job: &Job, end: RunEnd) -> Result<()> {
        match end {
            RunEnd::Whole(summary) => {
                let stored = Stored {
                    key: job.key.clone(),
                    engine: self.engine.as_str().into(),
                    run: job.label.clone(),
                    summary: *summary,
                };
                write_atomic(
                    &stored_path(&self.out, &job.key),
                    (serde_json::to_string_pretty(&stored)? + "\n").as_bytes(),
                )?;
                self.ran += 1;
            }
            RunEnd::Interrupted(signal) => self.signal = Some(signal),
            RunEnd::Failed(e) => {
                let error = fdi_report::output::describe_error(&e);
                log::info!("the run {} failed: {error}", job.label);
                self.failed.push(shard::Failure {
                    run: job.label.clone(),
                    key: job.key[..16].to_string(),
                    error,
                });
            }
        }
        self.save_record(None);
        if self.lost.as_ref().is_some_and(|l| l.load(Ordering::SeqCst)) {
            bail!("the shard's lease was lost (another copy took it over, or it was removed): this copy stopped; the results it stored are kept");
        }
        Ok(())
    }

    /// Writes the shard's record (if this batch is a shard's), its state set to `end`; a
    /// record that cannot be written is a warning (the results are what counts, and they are
    /// stored on their own).
    fn save_record(&mut self, end: Option<shard::State>) {
        let Some(r) = self.record.as_mut() else {
            return;
        };
        r.ran = self.ran;
        r.skipped = self.skipped;
        r.failures.clone_from(&self.failed);
        if let Some(end) = end {
            r.state = end;
        }
        if let Err(e) = r.save(&self.out) {
            log::warn!("the shard's record: {e:#}");
        }
    }

    /// `skipped 3, ran 9, failed 0`.
    fn said(&self) -> String {
        format!(
            "skipped {}, ran {}, failed {}{}",
            self.skipped,
            self.ran,
            self.failed.len(),
            if self.not_started > 0 {
                format!(", not started {}", self.not_started)
            } else {
                String::new()
            }
        )
    }
}

/// How a campaign ends: interrupted by `signal`, failed when some runs did, else success.
fn campaign_end(signal: Option<i32>, failed: &[shard::Failure]) -> Result<Ended> {
    if let Some(signal) = signal {
        return Err(fdi_common::stop::Interrupted {
            signal,
            phase: DURING_THE_CAMPAIGN,
        }
        .into());
    }
    if !failed.is_empty() {
        let runs: Vec<&str> = failed.iter().map(|f| f.run.as_str()).collect();
        log::info!(
            "{} runs failed ({}); a rerun runs them again",
            failed.len(),
            runs.join("; ")
        );
        return Ok(Ended::Incomplete);
    }
    Ok(Ended::Whole)
}

/// How one run of the campaign ended.
enum RunEnd {
    Whole(Box<RunSummary>),
    /// Stopped by this signal (SIGINT, SIGTERM): not a failure of the run.
    Interrupted(i32),
    Failed(anyhow::Error),
}

/// One run of the campaign: whole, interrupted (its summary says by which signal, or the stop
/// was raised before it began), or failed.
fn run_one(job: &Job, name: &str, args: &SweepOptions, runs_root: &Path, stop: &Stop) -> RunEnd {
    let opts = fdi_orchestrator::run::Options::quiet(args.traces, stop);
    let summary = match args.traces {
        Traces::None => execute(&job.resolved, args.engine, None, &opts).map_err(Into::into),
        _ => {
            let mut named = job.resolved.clone();
            named.scenario.name = format!("{name}-{}", &job.key[..12]);
            fdi_orchestrator::run_dirs::create_run_dir(runs_root, &named).and_then(|dir| {
                fdi_orchestrator::run_dirs::discard_if_not_started(
                    &dir,
                    execute(&named, args.engine, Some(&dir), &opts),
                )
            })
        }
    };
    let failed = |e: anyhow::Error| RunEnd::Failed(e.context(format!("the run {}", job.label)));
    match summary {
        Ok(s) => match s.partial.as_ref().and_then(|p| p.signal) {
            Some(signal) => RunEnd::Interrupted(signal),
            None => fdi_orchestrator::run::require_whole(s)
                .map_or_else(failed, |s| RunEnd::Whole(Box::new(s))),
        },
        Err(e) => match stop.pending() {
            Some(signal) => RunEnd::Interrupted(signal),
            None => failed(e),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(text: &str) -> RangeFile {
        toml::from_str::<RangeFile>(text).expect("range")
    }

    fn values(text: &str) -> Result<Vec<toml::Value>> {
        range_values(&r(text), &|f: &str| format!("r.{f}"))
    }

    #[test]
    fn ranges_by_step_and_by_count() {
        let ints = values("start = 1\nstop = 4\nstep = 1").expect("values");
        assert_eq!(ints, (1..=4).map(toml::Value::Integer).collect::<Vec<_>>());
        let down = values("start = 4\nstop = 0\nstep = -2").expect("values");
        assert_eq!(down, [4, 2, 0].map(toml::Value::Integer).to_vec());
        let fl = values("start = 0.0\nstop = 0.3\nstep = 0.1").expect("values");
        assert_eq!(fl.len(), 4);
        // Integer ends and whole steps: integers.
        let c = values("start = 10\nstop = 40\ncount = 4").expect("values");
        assert_eq!(c, [10, 20, 30, 40].map(toml::Value::Integer).to_vec());
        let c = values("start = 1\nstop = 2\ncount = 3").expect("values");
        assert_eq!(c, [1.0, 1.5, 2.0].map(toml::Value::Float).to_vec());
        let c = values("start = 10.0\nstop = 40.0\ncount = 4").expect("values");
        assert_eq!(c, [10.0, 20.0, 30.0, 40.0].map(toml::Value::Float).to_vec());
        for bad in [
            "start = 1\nstop = 4",
            "start = 1\nstop = 4\nstep = 1\ncount = 2",
            "start = 1\nstop = 4\nstep = 0",
            "start = 4\nstop = 1\nstep = 1",
            "start = 1.0\nstop = 4.0\nstep = 0.0",
            "start = 4.0\nstop = 1.0\nstep = 1.0",
            "start = 1\nstop = 4\ncount = 0",
            "start = nan\nstop = 4.0\nstep = 1.0",
        ] {
            assert!(values(bad).is_err(), "{bad}");
        }
    }

    /// A range near 2⁶³ used to be computed in floats: its eight seeds were one
    /// (9223372036854775807 rounds to 9223372036854775808.0), the campaign ran once and showed
    /// the seed as 9223372036854776000.
    #[test]
    fn seeds_near_2_to_the_63_stay_exact() {
        let seeds = values("start = 9223372036854775800\nstop = 9223372036854775807\nstep = 1")
            .expect("values");
        assert_eq!(
            seeds,
            (i64::MAX - 7..=i64::MAX)
                .map(toml::Value::Integer)
                .collect::<Vec<_>>()
        );
        let by_count = values("start = 9223372036854775800\nstop = 9223372036854775807\ncount = 8")
            .expect("values");
        assert_eq!(by_count, seeds);

        let dir = tempfile::tempdir().expect("temporary folder");
        let file = dir.path().join("seeds.toml");
        std::fs::write(
            &file,
            "name = \"seeds\"\n[set]\nduration_s = 0.1\n[[axes]]\npath = \"seed\"\n\
             range = { start = 9223372036854775800, stop = 9223372036854775807, step = 1 }\n",
        )
        .expect("campaign file");
        let plan = plan(&file, Engine::Inproc).expect("plan");
        assert_eq!(plan.jobs.len(), 8);
        let ran: Vec<u64> = plan.jobs.iter().map(|j| j.resolved.scenario.seed).collect();
        let want: Vec<u64> = (i64::MAX as u64 - 7..=i64::MAX as u64).collect();
        assert_eq!(ran, want);
        let keys: BTreeSet<&str> = plan.jobs.iter().map(|j| j.key.as_str()).collect();
        assert_eq!(keys.len(), 8, "eight seeds are eight runs");
        assert_eq!(plan.jobs[7].label, "seed = 9223372036854775807");

        // The tables show each seed as it ran, to the last digit.
        let results: Vec<Option<RunSummary>> = ran
            .iter()
            .map(|&seed| {
                let mut s = fdi_report::output::sample_summary();
                s.seed = seed;
                Some(s)
            })
            .collect();
        let out = dir.path().join("out");
        tables::write_outputs(&plan, &results, &out).expect("outputs");
        let csv = std::fs::read_to_string(out.join("results.csv")).expect("results.csv");
        let mut reader = csv::Reader::from_reader(csv.as_bytes());
        let column = reader
            .headers()
            .expect("header")
            .iter()
            .position(|h| h == "seed")
            .expect("a seed column");
        let shown: Vec<String> = reader
            .records()
            .map(|r| r.expect("row")[column].to_string())
            .collect();
        let want_text: Vec<String> = want.iter().map(u64::to_string).collect();
        assert_eq!(shown, want_text);
        let json: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(out.join("results.json")).expect("results.json"),
        )
        .expect("JSON");
        let json_seeds: Vec<Option<u64>> = json
            .as_array()
            .expect("rows")
            .iter()
            .map(|r| r["seed"].as_u64())
            .collect();
        assert_eq!(
            json_seeds,
            want.iter().copied().map(Some).collect::<Vec<_>>()
        );
        let aggregate: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(out.join("aggregate.json")).expect("aggregate.json"),
        )
        .expect("JSON");
        assert_eq!(aggregate[0]["seeds"], serde_json::json!(want));
    }

    /// A step of 1e-300 (or a span beyond the largest float) made the count wrap: "has no
    /// values". It is the run limit that refuses it, saying so.
    #[test]
    fn a_step_of_1e_300_hits_the_run_limit() {
        for text in [
            "start = 0.0\nstop = 1.0\nstep = 1e-300",
            "start = -1e308\nstop = 1e308\nstep = 1.0",
            "start = -9223372036854775808\nstop = 9223372036854775807\nstep = 1",
            "start = 0\nstop = 100000\nstep = 1",
        ] {
            let e = values(text).expect_err(text).to_string();
            assert!(
                e.starts_with("r.: ")
                    && e.contains(&format!(
                        "more than the {MAX_RUNS} runs a campaign may hold"
                    )),
                "{text}: {e}"
            );
        }
        assert_eq!(
            values("start = 0\nstop = 99999\nstep = 1")
                .expect("the limit itself")
                .len(),
            MAX_RUNS
        );
        // A span beyond the largest float in few steps is a range of finite values.
        let wide = values("start = -1e308\nstop = 1e308\nstep = 1e307").expect("values");
        assert_eq!(wide.len(), 21);
        assert_eq!(wide[20], toml::Value::Float(1e308));
        let wide = values("start = -1e308\nstop = 1e308\ncount = 3").expect("values");
        assert_eq!(wide, [-1e308, 0.0, 1e308].map(toml::Value::Float).to_vec());
    }

    /// Writes `text` as a campaign file and plans it: the error, or a panic if it plans.
    fn refusal(text: &str) -> String {
        let dir = tempfile::tempdir().expect("temporary folder");
        let file = dir.path().join("c.toml");
        std::fs::write(&file, text).expect("campaign file");
        let e = match plan(&file, Engine::Inproc) {
            Ok(_) => panic!("planned:\n{text}"),
            Err(e) => format!("{e:#}"),
        };
        let name = file.display().to_string();
        assert!(e.starts_with(&name), "{e}");
        e.replacen(&name, "c.toml", 1)
    }

    /// A campaign of the suite has its runs from the suite: axes, edits or a base scenario beside
    /// `[suite]` are refused, naming the key, as is a suite of another version.
    #[test]
    fn a_suite_campaign_with_axes_or_another_version_is_refused() {
        let suite = "[suite]\nversion = \"fdi-mas-score-2\"\ncontroller = \"pd\"\n";
        let e = refusal(&format!(
            "name = \"x\"\n{suite}[[axes]]\npath = \"seed\"\nvalues = [1]\n"
        ));
        assert!(e.contains("c.toml: axes (line 5, column 3): a campaign of the suite (`[suite]`) has no `axes`"), "{e}");
        let e = refusal(&format!("name = \"x\"\n[set]\nduration_s = 1.0\n{suite}"));
        assert!(e.contains("has no `set`"), "{e}");
        let e =
            refusal("name = \"x\"\n[suite]\nversion = \"fdi-mas-score-1\"\ncontroller = \"pd\"\n");
        assert!(e.contains("c.toml: suite.version (line 3, column 1): `fdi-mas-score-1` is not this launcher's suite"), "{e}");
        let e = refusal("name = \"x\"\n");
        assert!(e.contains("at least one [[axes]] (or a `[suite]`"), "{e}");
    }

    /// `a` = controller.beta [10, 20] and `b` = controller.beta [30] ran β = 30 twice and
    /// reported rows a = 10 and a = 20.
    #[test]
    fn two_axes_on_one_path_are_refused() {
        let e = refusal(
            "name = \"x\"\n\
             [[axes]]\nlabel = \"a\"\npath = \"controller.beta\"\nvalues = [10.0, 20.0]\n\
             [[axes]]\nlabel = \"b\"\npath = \"controller.beta\"\nvalues = [30.0]\n",
        );
        assert!(
            e.starts_with(
                "c.toml: axes `a` (axes[0].path (line 4, column 1)) and `b` (axes[1].path (line 8, column 1)) both set `controller.beta`"
            ),
            "{e}"
        );
        // One value reached by two spellings, and a table holding a swept value.
        let e = refusal(
            "name = \"x\"\n\
             [[axes]]\npath = \"attack.channels[0].segments[1].waveform.value\"\nvalues = [1.0]\n\
             [[axes]]\npath = \"attack.profile.channels\"\nvalues = [[]]\n",
        );
        assert!(
            e.contains("both set `attack.channels[0].segments[1].waveform.value` and `attack.profile.channels`, which reach one value")
                && e.contains("(line 3, column 1)")
                && e.contains("(line 6, column 1)"),
            "{e}"
        );
        // One path twice in one axis (with factors, it was scaled twice).
        let e = refusal(
            "name = \"x\"\n[[axes]]\nlabel = \"k\"\n\
             paths = [\"controller.beta\", \"controller.beta\"]\nfactors = [2.0]\n",
        );
        assert!(
            e.contains("axis `k` sets `controller.beta` twice, at axes[0].paths[0] (line 4, column 10) and at axes[0].paths[1] (line 4, column 29)"),
            "{e}"
        );
        // A [set] edit that an axis overwrites in every run.
        let e = refusal(
            "name = \"x\"\n[set]\n\"controller.beta\" = 5.0\n\
             [[axes]]\npath = \"controller\"\nvalues = [{ mode = \"proposed\" }]\n",
        );
        assert!(
            e.contains("`controller.beta` in [set] (set (line 2, column 2)) is overwritten in every run by axis `controller` (axes[0].path (line 5, column 1))"),
            "{e}"
        );
        // An axis of factors scales what [set] gives: meant, and planned.
        let dir = tempfile::tempdir().expect("temporary folder");
        let file = dir.path().join("c.toml");
        std::fs::write(
            &file,
            "name = \"x\"\n[set]\n\"controller.beta\" = 5.0\n\
             [[axes]]\npath = \"controller.beta\"\nfactors = [1.0, 2.0]\n",
        )
        .expect("campaign file");
        let p = plan(&file, Engine::Inproc).expect("plan");
        let betas: Vec<f64> = p
            .jobs
            .iter()
            .map(|j| j.resolved.scenario.controller.beta)
            .collect();
        assert_eq!(betas, [5.0, 10.0]);
    }

    /// Regression (issue 51): a name holding NUL or ESC ran every run of the campaign, then
    /// failed writing its first SVG. It is refused before any run, naming the field and the
    /// character.
    #[test]
    fn a_campaign_name_with_a_control_character_is_refused_before_any_run() {
        for (name, code) in [("a\\u0000b", "U+0000"), ("a\\u001b[31mb", "U+001B")] {
            let e = refusal(&format!(
                "name = \"{name}\"\n[[axes]]\npath = \"controller.beta\"\nvalues = [1.0]\n"
            ));
            assert!(
                e.starts_with("c.toml: name (line 1, column 1): holds the control character")
                    && e.contains(&format!("{code} at byte 1")),
                "{e}"
            );
        }
    }

    #[test]
    fn campaign_toml_syntax_error_has_line_and_column() {
        let e = refusal("name = \"x\"\n[[axes]]\npath = \"controller.beta\nvalues = [1.0]\n");
        assert!(
            e.starts_with("c.toml: TOML syntax at line 3, column "),
            "{e}"
        );
        let e = refusal("name = \"x\"\n[[axes]]\npath = \"controller.beta\"\nvalue = [1.0]\n");
        assert!(
            e.starts_with("c.toml (line 4, column 1): unknown field `value`"),
            "{e}"
        );
        let e = refusal(
            "name = \"x\"\n[[axes]]\npath = \"controller.beta\"\n\
             range = { start = 1.0, stop = 2.0, step = -1.0 }\n",
        );
        assert!(
            e.starts_with("c.toml: axes[0].range.step (line 4, column 36): step -1 never goes"),
            "{e}"
        );
    }

    /// `name = "../../../x"` or `"/abs/x"` wrote the campaign outside `runs/`, `""` into
    /// `runs/campaigns/` itself.
    #[test]
    fn campaign_names_cannot_leave_the_runs_folder() {
        let campaigns = Path::new("runs").join("campaigns");
        for name in [
            "../../../x",
            "/abs/x",
            "..",
            ".",
            "a/../../b",
            "x\0y",
            "beta-sweep",
        ] {
            let out = default_out(name);
            assert_eq!(out.parent(), Some(campaigns.as_path()), "{name:?}: {out:?}");
            assert!(
                matches!(
                    out.components().next_back(),
                    Some(std::path::Component::Normal(_))
                ),
                "{name:?}: {out:?}"
            );
            // The rule of run folders, one function for both.
            assert_eq!(
                out.file_name().and_then(|n| n.to_str()),
                Some(fdi_orchestrator::run_dirs::safe_name(name).as_str())
            );
        }
        assert_eq!(default_out("beta-sweep"), campaigns.join("beta-sweep"));
        assert_eq!(default_out("../../../x"), campaigns.join("_________x"));
        let e = refusal("name = \"\"\n[[axes]]\npath = \"seed\"\nvalues = [1]\n");
        assert!(
            e.starts_with("c.toml: name (line 1, column 1): is empty"),
            "{e}"
        );
    }

    #[test]
    fn product_and_zip() {
        let axis = |n: usize| Axis {
            label: format!("a{n}"),
            paths: vec![],
            fields: vec![],
            values: (0..n as i64).map(toml::Value::Integer).collect(),
            factors: false,
        };
        let (a, b) = (axis(2), axis(3));
        assert_eq!(
            combinations(&[&a, &b], Mode::Product).expect("product"),
            vec![
                vec![0, 0],
                vec![0, 1],
                vec![0, 2],
                vec![1, 0],
                vec![1, 1],
                vec![1, 2]
            ]
        );
        assert!(combinations(&[&a, &b], Mode::Zip).is_err());
        let c = axis(3);
        assert_eq!(
            combinations(&[&b, &c], Mode::Zip).expect("zip"),
            vec![vec![0, 0], vec![1, 1], vec![2, 2]]
        );
    }
}
