//! The scored benchmark (`fdi-launch score`, docs/score.md): a fixed, versioned suite — the
//! paper's team under every shipped attack class of the attack table ([`CLASSES`]), each at
//! the held-out [`SEEDS`], beside the attack-free run of the same seed — run with one controller
//! and judged by one detector, scored into one row that two labs running the same code get bit
//! for bit.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{anyhow, bail, Context, Result};
use fdi_common::control::ControllerMode;
use fdi_common::detect;
use fdi_common::engine::{run_inproc_any, RunSummary};
use fdi_common::metrics::DetectorMetrics;
use fdi_common::scenario::{self, Resolved};
use fdi_common::stop::Stop;
use serde::{Deserialize, Serialize};

use crate::attacks::{Class, Detection, CLASSES};

/// The suite's version: a change of its classes, seeds, scenario, duration or formula is a new
/// version, and rows of two versions are not compared.
pub const SUITE: &str = "fdi-mas-score-1";
/// The held-out seeds (the paper's scenario runs at seed 1).
pub const SEEDS: [u64; 3] = [11, 12, 13];
/// The tracking ratio a cell whose robot diverged counts as.
pub const DIVERGED_RATIO: f64 = 100.0;

/// How to score (`fdi-launch score`).
#[derive(Debug, Clone)]
pub struct ScoreOptions {
    pub controller: ControllerMode,
    /// The detector whose alarms are judged ([`detect::names`]); `s_hat_norm` is the control
    /// center's own alarm (the `gated` controller's gate).
    pub detector: String,
    /// Folder that receives `score.json` and `score.md`; `None`: `runs/<timestamp>-score-<controller>`.
    pub out: Option<PathBuf>,
}

/// One cell: an attack class at one seed, over the class's attacked robots.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Cell {
    pub class: String,
    pub seed: u64,
    /// The mean over the robots of RMSE under attack over RMSE of the attack-free run of the
    /// same seed; [`DIVERGED_RATIO`] for a robot that diverged.
    #[serde(with = "fdi_common::json_float")]
    pub rmse_ratio: f64,
    /// The largest `|q_d − q|` of the robots under attack that stayed bounded, rad.
    #[serde(with = "fdi_common::json_float")]
    pub worst_error_rad: f64,
    /// The robots under attack that diverged.
    pub diverged: usize,
    /// Onsets of the attack the detector watched, and those it detected after the onset.
    pub onsets: usize,
    pub detected: usize,
    /// The mean time to detect over the detected onsets, s.
    pub mean_delay_s: Option<f64>,
}

/// The overall figures of a row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Score {
    /// The geometric mean of the cells' `rmse_ratio`.
    pub tracking: f64,
    /// Detected onsets over watched onsets, all cells.
    pub detected_share: f64,
    /// The mean time to detect over every detected onset, s.
    pub mean_delay_s: Option<f64>,
    /// False alarms per minute of the attack-free runs, mean over robots and seeds.
    pub false_alarms_per_min: f64,
    /// `100 / (tracking × (2 − detected_share) × (1 + false_alarms_per_min))`: 100 when an
    /// attack costs nothing, every onset is detected and nothing else raises an alarm.
    pub overall: f64,
}

/// One leaderboard row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    pub suite: String,
    pub controller: String,
    pub detector: String,
    pub seeds: Vec<u64>,
    pub cells: Vec<Cell>,
    pub score: Score,
}

/// The folder a row was written into, and the row.
#[derive(Debug)]
pub struct Scored {
    pub dir: PathBuf,
    pub row: Row,
    pub md: String,
}

/// Runs the suite with `options`' controller, writes its row, returns it.
pub fn score(options: &ScoreOptions, stop: &Stop) -> Result<Scored> {
    stop.check(fdi_common::stop::BEFORE_THE_START)?;
    if !detect::names().contains(&options.detector.as_str()) {
        bail!(
            "unknown detector `{}` (known: {})",
            options.detector,
            detect::names().join(", ")
        );
    }
    let base = scenario::paper().map_err(|e| anyhow!("{e}"))?;
    let mut cells = Vec::new();
    let mut false_alarms = Vec::new();
    let (none, attacks): (Vec<&Class>, Vec<&Class>) =
        CLASSES.iter().partition(|c| c.name == "none");
    let none = none
        .first()
        .ok_or_else(|| anyhow!("no attack-free class"))?;
    for seed in SEEDS {
        let reference = run(&base, none, options.controller, seed, stop)?;
        for (robot, m) in &reference.metrics {
            let d = detector(m, &options.detector).ok_or_else(|| {
                anyhow!(
                    "the attack-free run has no detector `{}` on robot {robot}",
                    options.detector
                )
            })?;
            false_alarms.extend(d.false_alarms_per_min);
        }
        for &class in &attacks {
            let attacked = run(&base, class, options.controller, seed, stop)?;
            cells.push(cell(class, seed, &reference, &attacked, &options.detector)?);
        }
    }
    let row = Row {
        suite: SUITE.into(),
        controller: options.controller.as_str().into(),
        detector: options.detector.clone(),
        seeds: SEEDS.to_vec(),
        score: overall(
            &cells,
            false_alarms.iter().sum::<f64>() / false_alarms.len().max(1) as f64,
        ),
        cells,
    };
    let dir = options.out.clone().unwrap_or_else(|| {
        PathBuf::from("runs").join(format!(
            "{}-score-{}",
            fdi_orchestrator::run_dirs::timestamp(),
            row.controller
        ))
    });
    let md = markdown(&row);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let json = serde_json::to_string_pretty(&row)?;
    for (file, text) in [("score.json", &json), ("score.md", &md)] {
        let path = dir.join(file);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(Scored { dir, row, md })
}

/// One run of the suite: the paper's scenario under `class`'s attack at `seed`.
fn run(
    base: &Resolved,
    class: &Class,
    controller: ControllerMode,
    seed: u64,
    stop: &Stop,
) -> Result<RunSummary> {
    stop.check("during the score: nothing is written")?;
    let mut r = class.source.resolve(base)?;
    r.scenario.controller.mode = controller;
    r.scenario.seed = seed;
    run_inproc_any(&r, |_| {}).with_context(|| format!("class `{}`, seed {seed}", class.name))
}

fn detector<'a>(
    m: &'a fdi_common::metrics::AgentMetrics,
    name: &str,
) -> Option<&'a DetectorMetrics> {
    m.detectors.get(name)
}

/// The cell of `class` at `seed` from its run and the attack-free run of the same seed.
fn cell(
    class: &Class,
    seed: u64,
    reference: &RunSummary,
    attacked: &RunSummary,
    detector_name: &str,
) -> Result<Cell> {
    let (mut ratio, mut worst, mut onsets, mut detected, mut delay) = (0.0, 0.0f64, 0, 0, 0.0);
    let mut diverged = 0;
    for robot in class.robots {
        let key = robot.to_string();
        let (Some(clean), Some(m)) = (reference.metrics.get(&key), attacked.metrics.get(&key))
        else {
            bail!(
                "class `{}`, seed {seed}: no metrics of robot {robot}",
                class.name
            );
        };
        match m.diverged_at_s {
            Some(_) => {
                ratio += DIVERGED_RATIO;
                diverged += 1;
            }
            None => {
                ratio += m.rmse_rad / clean.rmse_rad;
                worst = worst.max(m.max_abs_error_rad);
            }
        }
        let d = detector(m, detector_name).ok_or_else(|| {
            anyhow!(
                "class `{}`: the run has no detector `{detector_name}`",
                class.name
            )
        })?;
        let d = Detection::of(d);
        onsets += d.judged();
        detected += d.detected;
        delay += d
            .mean_time_to_detect_s
            .map_or(0.0, |m| m * d.detected as f64);
    }
    Ok(Cell {
        class: class.name.into(),
        seed,
        rmse_ratio: ratio / class.robots.len() as f64,
        worst_error_rad: worst,
        diverged,
        onsets,
        detected,
        mean_delay_s: (detected > 0).then(|| delay / detected as f64),
    })
}

/// The row's overall figures from its cells and the attack-free false alarms per minute.
fn overall(cells: &[Cell], false_alarms_per_min: f64) -> Score {
    let n = cells.len().max(1) as f64;
    let tracking = (cells.iter().map(|c| c.rmse_ratio.ln()).sum::<f64>() / n).exp();
    let onsets: usize = cells.iter().map(|c| c.onsets).sum();
    let detected: usize = cells.iter().map(|c| c.detected).sum();
    let delay: f64 = (cells.iter())
        .filter_map(|c| c.mean_delay_s.map(|d| d * c.detected as f64))
        .sum();
    let detected_share = if onsets == 0 {
        0.0
    } else {
        detected as f64 / onsets as f64
    };
    Score {
        tracking,
        detected_share,
        mean_delay_s: (detected > 0).then(|| delay / detected as f64),
        false_alarms_per_min,
        overall: 100.0 / (tracking * (2.0 - detected_share) * (1.0 + false_alarms_per_min)),
    }
}

/// The row as markdown: the overall figures, then a line per class (its seeds' mean ratio).
fn markdown(row: &Row) -> String {
    let s = &row.score;
    let mut md = format!(
        "# Score: `{}` judged by `{}` ({}, seeds {:?})\n\n| overall | tracking (RMSE ratio, geometric mean) | onsets detected | mean delay (s) | false alarms/min |\n|---|---|---|---|---|\n| {:.2} | {:.3} | {:.1} % | {} | {:.2} |\n\n| class | RMSE ratio (mean of seeds) | worst error (rad) | detected |\n|---|---|---|---|\n",
        row.controller,
        row.detector,
        row.suite,
        row.seeds,
        s.overall,
        s.tracking,
        100.0 * s.detected_share,
        s.mean_delay_s.map_or_else(|| "—".into(), |d| format!("{d:.3}")),
        s.false_alarms_per_min,
    );
    for class in CLASSES.iter().filter(|c| c.name != "none") {
        let of: Vec<&Cell> = row.cells.iter().filter(|c| c.class == class.name).collect();
        let ratio = class_ratio(row, class.name);
        let worst = of.iter().map(|c| c.worst_error_rad).fold(0.0, f64::max);
        let diverged: usize = of.iter().map(|c| c.diverged).sum();
        let worst = match diverged {
            0 => format!("{worst:.4}"),
            n => format!("{worst:.4} ({n} robot-runs diverged)"),
        };
        let (d, o) = (of.iter()).fold((0, 0), |(d, o), c| (d + c.detected, o + c.onsets));
        let _ = writeln!(md, "| {} | {ratio:.3} | {worst} | {d}/{o} |", class.name);
    }
    md
}

/// Two rows side by side (`fdi-launch score --compare`): their overall figures and each
/// class's mean ratio; an error when they are of different suites.
pub fn compare(a: &Row, b: &Row) -> Result<String> {
    if a.suite != b.suite {
        bail!(
            "rows of two suites (`{}` and `{}`) are not compared",
            a.suite,
            b.suite
        );
    }
    let name = |r: &Row| format!("{} / {}", r.controller, r.detector);
    let mut md = format!(
        "| | {} | {} |\n|---|---|---|\n| overall | {:.2} | {:.2} |\n| tracking | {:.3} | {:.3} |\n| onsets detected | {:.1} % | {:.1} % |\n| false alarms/min | {:.2} | {:.2} |\n",
        name(a),
        name(b),
        a.score.overall,
        b.score.overall,
        a.score.tracking,
        b.score.tracking,
        100.0 * a.score.detected_share,
        100.0 * b.score.detected_share,
        a.score.false_alarms_per_min,
        b.score.false_alarms_per_min,
    );
    for class in CLASSES.iter().filter(|c| c.name != "none") {
        let (x, y) = (class_ratio(a, class.name), class_ratio(b, class.name));
        let _ = writeln!(md, "| {} | {x:.3} | {y:.3} |", class.name);
    }
    Ok(md)
}

/// The RMSE ratio of `class` in `row`: the mean over its seeds' cells.
fn class_ratio(row: &Row, class: &str) -> f64 {
    let of: Vec<f64> = (row.cells.iter())
        .filter(|c| c.class == class)
        .map(|c| c.rmse_ratio)
        .collect();
    of.iter().sum::<f64>() / of.len().max(1) as f64
}
