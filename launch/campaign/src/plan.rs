//! A campaign as resolved — its axes, points and runs ([`Plan`]) — and the statistics of
//! its points ([`Aggregate`]): what the runner, the tables and the figures share.

use std::collections::BTreeMap;

use fdi_common::scenario::Resolved;
use fdi_orchestrator::run::Engine;
use sha2::{Digest, Sha256};

use super::flatten::Cell;
use super::stats::Stats;
use fdi_common::field_path::{show, FieldPath};

/// Most runs a campaign may hold.
pub(super) const MAX_RUNS: usize = 100_000;

/// One axis as resolved.
#[derive(Debug, Clone)]
pub(super) struct Axis {
    pub(super) label: String,
    pub(super) paths: Vec<FieldPath>,
    /// Where each path is written in the campaign file (`axes[1].path`, `axes[0].paths[2]`).
    pub(super) fields: Vec<String>,
    pub(super) values: Vec<toml::Value>,
    /// The values multiply the base value at each path.
    pub(super) factors: bool,
}

impl Plan {
    /// The jobs (indices into `jobs`) that `keep` keeps, the first of each key only: runs of
    /// one key are one run, stored once.
    pub(super) fn unique_jobs(&self, keep: impl Fn(usize) -> bool) -> Vec<usize> {
        let mut keys = std::collections::BTreeSet::new();
        (0..self.jobs.len())
            .filter(|&i| keys.insert(self.jobs[i].key.as_str()) && keep(i))
            .collect()
    }
}

impl Axis {
    pub(super) fn is_seed(&self) -> bool {
        self.paths.len() == 1 && self.paths[0].text == "seed"
    }
}

/// One run of the campaign.
#[derive(Debug)]
pub(super) struct Job {
    /// Index of its point (its combination of the axes other than `seed`).
    pub(super) point: usize,
    /// `controller.beta = 10, seed = 2`.
    pub(super) label: String,
    pub(super) resolved: Resolved,
    pub(super) key: String,
}

/// A point: the values of the non-seed axes.
#[derive(Debug, Clone)]
pub(super) struct Point {
    pub(super) values: Vec<(String, toml::Value)>,
}

/// The campaign as resolved: its axes, points and runs.
#[derive(Debug)]
pub(super) struct Plan {
    pub(super) name: String,
    pub(super) axes: Vec<Axis>,
    pub(super) points: Vec<Point>,
    pub(super) jobs: Vec<Job>,
    pub(super) seeds: usize,
    pub(super) plots: Option<Vec<String>>,
    /// The suite a campaign of the scored benchmark is ([`crate::suite`]).
    pub(super) suite: Option<crate::suite::SuitePlan>,
}

pub(super) fn toml_cell(v: &toml::Value) -> Cell {
    match v {
        toml::Value::Integer(i) => Cell::Int(i128::from(*i)),
        toml::Value::Float(f) => Cell::Num(*f),
        other => Cell::Text(show(other)),
    }
}

/// The statistics of one point.
#[derive(Debug)]
pub(super) struct Aggregate {
    pub(super) point: Point,
    pub(super) runs: usize,
    /// The seeds of its runs, exact.
    pub(super) seeds: Vec<u64>,
    /// Per column: `None` when no run of the point has a number there.
    pub(super) metrics: BTreeMap<String, Option<Stats>>,
}

/// The robots of a set of columns (`robot<id>.…`), in id order.
/// The labels of a plan's axes other than the seed, and the robots an aggregate has metrics
/// of.
pub(super) fn labels_and_robots<'p>(
    plan: &'p Plan,
    aggregate: &[Aggregate],
) -> (Vec<&'p str>, Vec<String>) {
    let labels = plan
        .axes
        .iter()
        .filter(|a| !a.is_seed())
        .map(|a| a.label.as_str())
        .collect();
    let all: Vec<String> = aggregate
        .iter()
        .flat_map(|a| a.metrics.keys().cloned())
        .collect();
    let refs: Vec<&String> = all.iter().collect();
    (labels, robots(&refs))
}

pub(super) fn robots(columns: &[&String]) -> Vec<String> {
    let mut ids: Vec<(u64, String)> = columns
        .iter()
        .filter_map(|c| {
            c.strip_prefix("robot")?
                .split_once('.')
                .map(|(id, _)| id.to_string())
        })
        .filter_map(|id| id.parse::<u64>().ok().map(|n| (n, id)))
        .collect();
    ids.sort();
    ids.dedup();
    ids.into_iter().map(|(_, id)| id).collect()
}

/// The key of a run: SHA-256 over the launcher's version, the engine and the fully resolved
/// scenario (attack inlined).
pub(super) fn run_key(r: &Resolved, engine: Engine) -> String {
    let mut h = Sha256::new();
    h.update(format!(
        "fdi-launch {}\nengine {}\n",
        env!("CARGO_PKG_VERSION"),
        engine.as_str()
    ));
    h.update(r.to_toml());
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}
