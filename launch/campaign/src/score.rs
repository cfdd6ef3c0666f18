//! The scored benchmark (`fdi-launch score`, docs/score.md) as a campaign: a fixed, versioned
//! suite — the shipped teams ([`TEAMS`]) under every attack class ([`CLASSES`]), each at the
//! held-out [`SEEDS`], beside the attack-free run of the same team and seed — run with one
//! controller, and its row: what one detector made of the attacks and how the robots tracked
//! under them, which two labs running the same code get bit for bit.
//!
//! A campaign file with a `[suite]` table instead of axes is the suite
//! ([`SuiteFile`]): `fdi-launch sweep` runs it whole or in shards like any campaign, and its
//! tables (whole, or `--aggregate`d from the shards) end with the row (`score.json`,
//! `score.md`).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use fdi_common::engine::RunSummary;
use fdi_common::field_path::FieldPath;
use fdi_common::metrics::{AgentMetrics, DetectorMetrics};
use fdi_orchestrator::run::Engine;
use serde::{Deserialize, Serialize};

use crate::classes::{Class, Detection, CLASSES};
use crate::plan::{run_key, Axis, Job, Plan, Point};
use crate::store::write_atomic;
use crate::suite::{SuiteFile, SuitePlan, SuiteRun, SEEDS, SUITE};

/// The tracking ratio of a robot that diverged, under the attack or without it.
pub const DIVERGED_RATIO: f64 = 100.0;

/// The plan of the campaign `name` whose `[suite]` is `file`: a point per team and class (the
/// attack-free one included), a run per seed.
pub(crate) fn plan(
    name: &str,
    file: &SuiteFile,
    engine: Engine,
    at: &dyn Fn(&str) -> String,
) -> Result<Plan> {
    let teams = file.check(at)?;
    let text = |v: &str| toml::Value::String(v.into());
    let axes = vec![
        Axis {
            label: "team".into(),
            paths: Vec::new(),
            fields: Vec::new(),
            values: teams.iter().map(|t| text(t.name)).collect(),
            factors: false,
        },
        Axis {
            label: "class".into(),
            paths: Vec::new(),
            fields: Vec::new(),
            values: CLASSES.iter().map(|c| text(c.name)).collect(),
            factors: false,
        },
        Axis {
            label: "seed".into(),
            paths: vec![FieldPath::parse("seed")?],
            fields: vec!["suite".into()],
            values: SEEDS
                .iter()
                .map(|&s| toml::Value::Integer(s as i64))
                .collect(),
            factors: false,
        },
    ];
    let (mut points, mut jobs, mut runs) = (Vec::new(), Vec::new(), Vec::new());
    for team in &teams {
        let base = team.resolve()?;
        for class in CLASSES {
            let point = points.len();
            points.push(Point {
                values: vec![
                    ("team".into(), text(team.name)),
                    ("class".into(), text(class.name)),
                ],
            });
            let with_class = class
                .source
                .resolve(&base)
                .with_context(|| format!("team `{}`, class `{}`", team.name, class.name))?;
            for seed in SEEDS {
                let mut resolved = with_class.clone();
                resolved.scenario.controller.mode = file.controller;
                resolved.scenario.seed = seed;
                let key = run_key(&resolved, engine);
                jobs.push(Job {
                    point,
                    label: format!(
                        "team = {}, class = {}, seed = {seed}",
                        team.name, class.name
                    ),
                    resolved,
                    key,
                });
                runs.push(SuiteRun {
                    team: team.name,
                    class: class.name,
                    seed,
                });
            }
        }
    }
    Ok(Plan {
        name: name.into(),
        axes,
        points,
        jobs,
        seeds: SEEDS.len(),
        plots: Some(Vec::new()),
        suite: Some(SuitePlan {
            file: file.clone(),
            teams,
            runs,
        }),
    })
}

/// One cell: an attack class at one seed on one team, over the class's attacked robots.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Cell {
    pub team: String,
    pub class: String,
    pub seed: u64,
    /// The mean over the robots of RMSE under attack over RMSE of the attack-free run of the
    /// same team and seed; [`DIVERGED_RATIO`] for a robot that diverged in either.
    #[serde(with = "fdi_common::json_float")]
    pub rmse_ratio: f64,
    /// The largest `|q_d − q|` of the robots under attack that stayed bounded, rad.
    #[serde(with = "fdi_common::json_float")]
    pub worst_error_rad: f64,
    /// The robots under attack that diverged, in the attacked run or in the attack-free one.
    pub diverged: usize,
    /// Onsets of the attack the detector watched, and those it detected after the onset.
    pub onsets: usize,
    pub detected: usize,
    /// The mean time to detect over the detected onsets, s.
    pub mean_delay_s: Option<f64>,
}

/// The overall figures of a row, or of one team's cells.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Score {
    /// The geometric mean of the cells' `rmse_ratio`.
    pub tracking: f64,
    /// Detected onsets over watched onsets.
    pub detected_share: f64,
    /// The mean time to detect over every detected onset, s.
    pub mean_delay_s: Option<f64>,
    /// False alarms per minute of the attack-free runs, mean over robots and seeds.
    pub false_alarms_per_min: f64,
    /// `100 / (tracking × (2 − detected_share) × (1 + false_alarms_per_min))`: 100 when an
    /// attack costs nothing, every onset is detected and nothing else raises an alarm.
    pub overall: f64,
}

/// One team's figures in a row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TeamScore {
    pub team: String,
    pub score: Score,
    /// The attack-free runs' RMSE, mean over the robots and seeds that did not diverge, rad
    /// (NaN when every one diverged):
    /// what the ratios are relative to (a controller that does not track without attack loses
    /// little more under one).
    #[serde(with = "fdi_common::json_float")]
    pub attack_free_rmse_rad: f64,
    /// The robots of the attack-free runs that diverged (robot-runs, over the seeds).
    pub attack_free_diverged: usize,
}

/// One leaderboard row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    pub suite: String,
    pub controller: String,
    pub detector: String,
    pub teams: Vec<String>,
    pub seeds: Vec<u64>,
    pub cells: Vec<Cell>,
    /// Over every cell of every team.
    pub score: Score,
    /// Per team, in the suite's order.
    pub by_team: Vec<TeamScore>,
}

/// The row of a suite's plan from its results (one per job, in order), written as
/// `score.json` and `score.md` into `out`; `None` (said) when some run has no result.
pub(crate) fn write_row(
    suite: &SuitePlan,
    results: &[Option<RunSummary>],
    out: &Path,
    said: &mut dyn FnMut(&str),
) -> Result<Option<PathBuf>> {
    let missing = results.iter().filter(|r| r.is_none()).count();
    if missing > 0 {
        // A row of an earlier, whole suite in this folder is not this one's.
        for stale in ["score.json", "score.md"] {
            match std::fs::remove_file(out.join(stale)) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(e)
                        .with_context(|| format!("removing {}", out.join(stale).display()))
                }
                _ => {}
            }
        }
        said(&format!(
            "no score row: {missing} of the suite's {} runs have no result",
            results.len()
        ));
        return Ok(None);
    }
    let row = row(suite, results)?;
    let json = serde_json::to_string_pretty(&row)? + "\n";
    write_atomic(&out.join("score.json"), json.as_bytes())?;
    write_atomic(&out.join("score.md"), markdown(&row).as_bytes())?;
    said(&format!(
        "score of `{}` judged by `{}`: {:.2} (tracking {:.3}, onsets detected {:.1} %, false alarms/min {:.2})",
        row.controller,
        row.detector,
        row.score.overall,
        row.score.tracking,
        100.0 * row.score.detected_share,
        row.score.false_alarms_per_min
    ));
    Ok(Some(out.join("score.json")))
}

/// The row of the suite from its results.
fn row(suite: &SuitePlan, results: &[Option<RunSummary>]) -> Result<Row> {
    let detector = suite.file.detector.as_str();
    let result = |team: &str, class: &str, seed: u64| -> Result<&RunSummary> {
        (suite.runs.iter())
            .position(|r| r.team == team && r.class == class && r.seed == seed)
            .and_then(|i| results.get(i)?.as_ref())
            .ok_or_else(|| anyhow!("no result of team `{team}`, class `{class}`, seed {seed}"))
    };
    let (mut cells, mut by_team, mut all_alarms) = (Vec::new(), Vec::new(), Vec::new());
    for team in &suite.teams {
        let (mut team_cells, mut alarms) = (Vec::new(), Vec::new());
        let (mut clean_rmse, mut clean_diverged) = (Vec::new(), 0);
        for seed in SEEDS {
            let reference = result(team.name, "none", seed)?;
            for (robot, m) in &reference.metrics {
                let at = || {
                    format!(
                        "team `{}`, seed {seed}, robot {robot} without attack",
                        team.name
                    )
                };
                let (rmse, rate) = attack_free(m, detector).with_context(at)?;
                match rmse {
                    Some(r) => clean_rmse.push(r),
                    None => clean_diverged += 1,
                }
                alarms.push(rate);
            }
            for class in CLASSES.iter().filter(|c| c.name != "none") {
                let attacked = result(team.name, class.name, seed)?;
                team_cells.push(
                    cell(class, seed, reference, attacked, detector)
                        .with_context(|| format!("team `{}`", team.name))?
                        .of_team(team.name),
                );
            }
        }
        by_team.push(TeamScore {
            team: team.name.into(),
            score: overall(&team_cells, mean(&alarms)),
            // No robot left to measure: no number, not a zero.
            attack_free_rmse_rad: if clean_rmse.is_empty() {
                f64::NAN
            } else {
                mean(&clean_rmse)
            },
            attack_free_diverged: clean_diverged,
        });
        cells.extend(team_cells);
        all_alarms.extend(alarms);
    }
    let score = overall(&cells, mean(&all_alarms));
    all_finite(&score, &by_team)?;
    Ok(Row {
        suite: SUITE.into(),
        controller: suite.file.controller.as_str().into(),
        detector: detector.into(),
        teams: suite.teams.iter().map(|t| t.name.to_string()).collect(),
        seeds: SEEDS.to_vec(),
        score,
        cells,
        by_team,
    })
}

/// What a robot's attack-free run gives the row: its RMSE (`None`: it diverged) and its
/// detector's false alarms per minute (a detector that watched no attack-free time has no rate:
/// an error, not 0).
fn attack_free(m: &AgentMetrics, detector: &str) -> Result<(Option<f64>, f64)> {
    let rmse = match m.diverged_at_s {
        Some(_) => None,
        None if m.rmse_rad.is_finite() => Some(m.rmse_rad),
        None => bail!("an RMSE of {} rad, and it did not diverge", m.rmse_rad),
    };
    let d =
        detector_of(m, detector).ok_or_else(|| anyhow!("the run has no detector `{detector}`"))?;
    let rate = (d.false_alarms_per_min)
        .ok_or_else(|| anyhow!("the detector `{detector}` watched no attack-free time"))?;
    Ok((rmse, rate))
}

/// Refuses a row whose overall figures (or a team's) are not numbers: a cell's are then no
/// results, and a row of them would read as one.
fn all_finite(score: &Score, by_team: &[TeamScore]) -> Result<()> {
    for (what, s) in
        std::iter::once(("all", score)).chain(by_team.iter().map(|t| (t.team.as_str(), &t.score)))
    {
        for (field, v) in [
            ("tracking", s.tracking),
            ("false_alarms_per_min", s.false_alarms_per_min),
            ("overall", s.overall),
        ] {
            if !v.is_finite() {
                bail!("the row's {field} of {what} is {v}: a cell's numbers are not results");
            }
        }
    }
    Ok(())
}

fn mean(xs: &[f64]) -> f64 {
    xs.iter().sum::<f64>() / xs.len().max(1) as f64
}

fn detector_of<'a>(m: &'a AgentMetrics, name: &str) -> Option<&'a DetectorMetrics> {
    m.detectors.get(name)
}

impl Cell {
    fn of_team(self, team: &str) -> Self {
        Self {
            team: team.into(),
            ..self
        }
    }
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
    let at = || format!("class `{}`, seed {seed}", class.name);
    for robot in class.robots {
        let key = robot.to_string();
        let (Some(clean), Some(m)) = (reference.metrics.get(&key), attacked.metrics.get(&key))
        else {
            bail!("{}: no metrics of robot {robot}", at());
        };
        if m.diverged_at_s.is_some() || clean.diverged_at_s.is_some() {
            ratio += DIVERGED_RATIO;
            diverged += 1;
        } else {
            let (a, b, e) = (m.rmse_rad, clean.rmse_rad, m.max_abs_error_rad);
            if !(a.is_finite() && a > 0.0 && b.is_finite() && b > 0.0 && e.is_finite()) {
                bail!("{}: robot {robot} has an RMSE of {a} rad (worst error {e} rad) under the attack and {b} rad without it, and diverged in neither", at());
            }
            ratio += a / b;
            worst = worst.max(e);
        }
        let d = detector_of(m, detector_name)
            .ok_or_else(|| anyhow!("{}: the run has no detector `{detector_name}`", at()))?;
        let d = Detection::of(d);
        onsets += d.judged();
        detected += d.detected;
        delay += d
            .mean_time_to_detect_s
            .map_or(0.0, |m| m * d.detected as f64);
    }
    Ok(Cell {
        team: String::new(),
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

/// The overall figures of `cells`, with the attack-free false alarms per minute.
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

/// `0.321` or `—`.
fn delay_cell(d: Option<f64>) -> String {
    d.map_or_else(|| "—".into(), |d| format!("{d:.3}"))
}

/// The row as markdown: the overall figures and each team's, then a line per class (each
/// team's mean ratio over the seeds, the worst error, the onsets detected).
pub fn markdown(row: &Row) -> String {
    let mut md = format!(
        "# Score: `{}` judged by `{}` ({}, teams {}, seeds {:?})\n\n| | overall | tracking (RMSE ratio, geometric mean) | onsets detected | mean delay (s) | false alarms/min |\n|---|---|---|---|---|---|\n",
        row.controller,
        row.detector,
        row.suite,
        row.teams.join(", "),
        row.seeds,
    );
    let line = |md: &mut String, what: &str, s: &Score| {
        let _ = writeln!(
            md,
            "| {what} | {:.2} | {:.3} | {:.1} % | {} | {:.2} |",
            s.overall,
            s.tracking,
            100.0 * s.detected_share,
            delay_cell(s.mean_delay_s),
            s.false_alarms_per_min,
        );
    };
    line(&mut md, "**all**", &row.score);
    for t in &row.by_team {
        line(&mut md, &format!("team `{}`", t.team), &t.score);
    }
    let _ = write!(
        md,
        "\nWithout attack (what the ratios are relative to):\n\n| team | RMSE (rad), robots that did not diverge | robot-runs diverged |\n|---|---|---|\n"
    );
    for t in &row.by_team {
        let _ = writeln!(
            md,
            "| `{}` | {:.4} | {} |",
            t.team, t.attack_free_rmse_rad, t.attack_free_diverged
        );
    }
    let _ = write!(
        md,
        "\nRMSE ratio per class (mean of the seeds; {DIVERGED_RATIO} counts a robot that diverged):\n\n| class | {} | worst error (rad) | detected |\n|---|{}---|---|\n",
        row.teams.join(" | "),
        "---|".repeat(row.teams.len())
    );
    for class in CLASSES.iter().filter(|c| c.name != "none") {
        let of: Vec<&Cell> = row.cells.iter().filter(|c| c.class == class.name).collect();
        let ratios: Vec<String> = (row.teams.iter())
            .map(|t| format!("{:.3}", class_ratio(row, t, class.name)))
            .collect();
        let worst = of.iter().map(|c| c.worst_error_rad).fold(0.0, f64::max);
        let diverged: usize = of.iter().map(|c| c.diverged).sum();
        let worst = match diverged {
            0 => format!("{worst:.4}"),
            n => format!("{worst:.4} ({n} robot-runs diverged)"),
        };
        let (d, o) = (of.iter()).fold((0, 0), |(d, o), c| (d + c.detected, o + c.onsets));
        let _ = writeln!(
            md,
            "| {} | {} | {worst} | {d}/{o} |",
            class.name,
            ratios.join(" | ")
        );
    }
    md
}

/// Two rows side by side (`fdi-launch score --compare`): their overall figures, each team's,
/// and each class's mean ratio per team; an error when they are of different suites or teams.
pub fn compare(a: &Row, b: &Row) -> Result<String> {
    if a.suite != b.suite {
        bail!(
            "rows of two suites (`{}` and `{}`) are not compared",
            a.suite,
            b.suite
        );
    }
    if a.teams != b.teams {
        bail!(
            "rows of different teams ({} and {}) are not compared",
            a.teams.join(", "),
            b.teams.join(", ")
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
    for (x, y) in a.by_team.iter().zip(&b.by_team) {
        let _ = writeln!(
            md,
            "| overall, team `{}` | {:.2} | {:.2} |",
            x.team, x.score.overall, y.score.overall
        );
    }
    for team in &a.teams {
        for class in CLASSES.iter().filter(|c| c.name != "none") {
            let (x, y) = (
                class_ratio(a, team, class.name),
                class_ratio(b, team, class.name),
            );
            let _ = writeln!(md, "| {} ({team}) | {x:.3} | {y:.3} |", class.name);
        }
    }
    Ok(md)
}

/// The RMSE ratio of `class` on `team` in `row`: the mean over its seeds' cells.
fn class_ratio(row: &Row, team: &str, class: &str) -> f64 {
    let of: Vec<f64> = (row.cells.iter())
        .filter(|c| c.team == team && c.class == class)
        .map(|c| c.rmse_ratio)
        .collect();
    mean(&of)
}

/// The row stored in a campaign folder (`score.json`).
pub fn read_row(path: &Path) -> Result<Row> {
    let text =
        fdi_common::files::read_limited(path).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: not a score row", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::suite::{DEFAULT_DETECTOR, TEAMS};
    use fdi_common::control::ControllerMode;
    use fdi_common::scenario;

    #[test]
    fn every_class_resolves_on_every_team_and_names_robots_of_it() {
        for team in TEAMS {
            let base = team
                .resolve()
                .unwrap_or_else(|e| panic!("{}: {e:#}", team.name));
            for c in CLASSES {
                let r = (c.source.resolve(&base))
                    .unwrap_or_else(|e| panic!("{} on {}: {e:#}", c.name, team.name));
                for id in c.robots {
                    assert!(
                        r.scenario.agents.iter().any(|a| a.id == *id),
                        "{} on {}: robot {id}",
                        c.name,
                        team.name
                    );
                }
            }
        }
    }

    #[test]
    fn the_suite_as_a_campaign_file_plans_every_team_class_and_seed() {
        let file = SuiteFile::new(ControllerMode::Traditional, DEFAULT_DETECTOR, None);
        let text = file.campaign_text("score-traditional").expect("text");
        let read: toml::Table = toml::from_str(&text).expect("TOML");
        let back: SuiteFile = read["suite"].clone().try_into().expect("a suite");
        assert_eq!(back, file);
        let at = |f: &str| f.to_string();
        let plan = plan("s", &file, Engine::Inproc, &at).expect("plan");
        assert_eq!(plan.jobs.len(), TEAMS.len() * CLASSES.len() * SEEDS.len());
        let keys: std::collections::BTreeSet<&str> =
            plan.jobs.iter().map(|j| j.key.as_str()).collect();
        assert_eq!(keys.len(), plan.jobs.len(), "every run is its own");
        assert!(plan
            .jobs
            .iter()
            .all(|j| j.resolved.scenario.controller.mode == ControllerMode::Traditional));
    }

    #[test]
    fn a_row_is_not_left_from_an_earlier_suite_when_runs_are_missing_and_teams_keep_their_order() {
        let file = SuiteFile::new(
            ControllerMode::Pd,
            DEFAULT_DETECTOR,
            Some(&["panda".to_string(), "paper".to_string()]),
        );
        assert_eq!(file.teams, ["paper", "panda"], "the suite's order");
        let at = |f: &str| f.to_string();
        let plan = plan("s", &file, Engine::Inproc, &at).expect("plan");
        let suite = plan.suite.as_ref().expect("a suite");
        let dir = tempfile::tempdir().expect("a folder");
        for stale in ["score.json", "score.md"] {
            std::fs::write(dir.path().join(stale), "an earlier row").expect("writing");
        }
        let mut said = Vec::new();
        let results: Vec<Option<RunSummary>> = vec![None; plan.jobs.len()];
        let row = write_row(suite, &results, dir.path(), &mut |l| {
            said.push(l.to_string())
        });
        assert!(matches!(row, Ok(None)), "{row:?}");
        assert!(
            said[0].starts_with("no score row: 96 of the suite's 96 runs"),
            "{said:?}"
        );
        assert!(!dir.path().join("score.json").exists() && !dir.path().join("score.md").exists());
    }

    #[test]
    fn a_suite_that_is_not_this_one_is_refused_naming_the_field() {
        let at = |f: &str| format!("c.toml: {f}");
        let ok = SuiteFile::new(ControllerMode::Gated, DEFAULT_DETECTOR, None);
        let refused = |f: SuiteFile| {
            plan("s", &f, Engine::Inproc, &at)
                .expect_err("refused")
                .to_string()
        };
        let e = refused(SuiteFile {
            version: "fdi-mas-score-1".into(),
            ..ok.clone()
        });
        assert!(e.contains("suite.version") && e.contains(SUITE), "{e}");
        let e = refused(SuiteFile {
            detector: "psychic".into(),
            ..ok.clone()
        });
        assert!(
            e.contains("unknown detector `psychic`") && e.contains("chi2"),
            "{e}"
        );
        let e = format!(
            "{:#}",
            plan(
                "s",
                &SuiteFile {
                    teams: vec!["ur5".into()],
                    ..ok.clone()
                },
                Engine::Inproc,
                &at
            )
            .expect_err("refused")
        );
        assert!(e.contains("suite.teams[0]") && e.contains("panda"), "{e}");
        let e = refused(SuiteFile {
            teams: vec!["paper".into(), "paper".into()],
            ..ok.clone()
        });
        assert!(e.contains("suite.teams[1]"), "{e}");
        let e = refused(SuiteFile {
            controller: ControllerMode::External,
            ..ok
        });
        assert!(e.contains("in-process engine cannot run it"), "{e}");
    }

    #[test]
    fn a_robot_that_diverged_without_attack_counts_as_diverged_and_a_bad_rmse_is_named() {
        let mut r = scenario::paper().expect("paper");
        r.scenario.duration_s = 0.2;
        let clean = fdi_common::engine::run_inproc_any(&r, |_| {}).expect("a run");
        let class = CLASSES.iter().find(|c| c.name == "scale").expect("scale");
        let same = cell(class, 1, &clean, &clean, DEFAULT_DETECTOR).expect("a cell");
        assert_eq!((same.rmse_ratio, same.diverged), (1.0, 0));
        let mut lost = clean.clone();
        lost.metrics.get_mut("1").expect("robot 1").diverged_at_s = Some(0.1);
        let c = cell(class, 1, &lost, &clean, DEFAULT_DETECTOR).expect("a cell");
        assert_eq!((c.rmse_ratio, c.diverged), (DIVERGED_RATIO, 1));
        let mut bad = clean.clone();
        bad.metrics.get_mut("1").expect("robot 1").rmse_rad = f64::NAN;
        let e = cell(class, 1, &clean, &bad, DEFAULT_DETECTOR).expect_err("refused");
        assert!(e.to_string().contains("robot 1 has an RMSE of NaN"), "{e}");
    }
}
