//! Trace export (`fdi-launch trace export RUN_DIR --format csv|mcap`): the binary traces of a run
//! as files that other tools open. Every column, topic and field is listed with its unit and
//! meaning in docs/traces.md.
//!
//! * CSV ([`csv`]): every `RUN_DIR/traces/<process>.trace` becomes `RUN_DIR/export/<process>.csv`
//!   (latency records `<process>-latency.csv`, the attacker's torque records
//!   `attacker-actuation.csv`, the events of every trace `events.csv`).
//! * MCAP ([`mcap`]): the whole run as `RUN_DIR/export/run.mcap`, one JSON topic per agent and
//!   stream, with a JSON schema per topic, for Foxglove and PlotJuggler.
//!
//! Both write the records of each kind in (tick, agent) order, with the tick time of
//! [`fdi_common::engine::tick_time`], and derive what the records do not hold (the desired
//! trajectory, the true attack term `S`) from the scenario in each trace's header. A damaged
//! trace is exported up to its last whole record, then the export fails naming the file and
//! the byte offset.

mod csv;
mod mcap;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use fdi_common::engine::tick_time;
use fdi_common::scenario::{self, Resolved, MAX_DOF};
use fdi_common::trace::{TraceHeader, TraceReader, TraceRecord};
use fdi_common::trajectory::TrajectoryConfig;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// One CSV per process trace and record kind (pandas, MATLAB, a spreadsheet).
    Csv,
    /// One MCAP file per run, JSON messages with JSON schemas (Foxglove, PlotJuggler).
    Mcap,
}

/// `fdi-launch trace export RUN_DIR`.
pub fn export(run_dir: &Path, format: Format) -> Result<()> {
    match format {
        Format::Csv => csv::export(run_dir),
        Format::Mcap => mcap::export(run_dir),
    }
}

/// The `*.trace` files of `RUN_DIR/traces`, sorted; an error when there are none.
fn trace_files(run_dir: &Path) -> Result<Vec<PathBuf>> {
    let traces = run_dir.join("traces");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&traces)
        .with_context(|| format!("reading {}", traces.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "trace"))
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("{}: no trace files", traces.display());
    }
    Ok(files)
}

/// The export folder `RUN_DIR/export`, made if need be.
fn out_dir(run_dir: &Path) -> Result<PathBuf> {
    let out = run_dir.join("export");
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    Ok(out)
}

/// The file stem of a trace (`agent-1`, `attacker`, …).
fn stem(path: &Path) -> String {
    path.file_stem()
        .map_or_else(|| "trace".into(), |s| s.to_string_lossy().into_owned())
}

/// The failures of an export, as one error.
fn failed(failures: Vec<String>) -> Result<()> {
    match failures.len() {
        0 => Ok(()),
        1 => bail!("{}", failures[0]),
        n => bail!(
            "{n} traces could not be exported whole:\n{}",
            failures.join("\n")
        ),
    }
}

/// `(q_d, q̇_d, q̈_d)` of one tick, rad, rad/s, rad/s², and how many of their entries are links.
type Desired = ([f64; MAX_DOF], [f64; MAX_DOF], [f64; MAX_DOF], usize);

/// One agent as the scenario of a trace describes it.
#[derive(Debug, Clone)]
struct AgentInfo {
    dof: usize,
    trajectory: TrajectoryConfig,
}

/// What the scenario in a trace's header says that the exported columns need.
#[derive(Debug, Clone)]
struct RunInfo {
    resolved: Resolved,
    /// Δ, s.
    dt: f64,
    beta: f64,
    agents: BTreeMap<u32, AgentInfo>,
    /// The largest number of links of an agent: the vector columns of a CSV.
    dof: usize,
}

impl RunInfo {
    /// From the header of the trace at `path`; an error naming the file when its scenario
    /// does not parse (the tick times, the desired trajectory and `S` come from it).
    fn from_header(path: &Path, header: &TraceHeader) -> Result<Self> {
        let resolved = scenario::load_str(&header.scenario_toml, &path.display().to_string(), None)
            .map_err(|e| anyhow::anyhow!("{e}"))
            .with_context(|| {
                format!(
                    "{}: the scenario in the trace header does not parse: the tick times, the desired trajectory and S cannot be derived",
                    path.display()
                )
            })?;
        let s = &resolved.scenario;
        let agents: BTreeMap<u32, AgentInfo> = s
            .agents
            .iter()
            .map(|a| {
                (
                    a.id,
                    AgentInfo {
                        dof: a.model.dof().min(MAX_DOF),
                        trajectory: a.trajectory.clone(),
                    },
                )
            })
            .collect();
        let dof = agents.values().map(|a| a.dof).max().unwrap_or(0);
        Ok(Self {
            dt: s.control_period_s,
            beta: s.controller.beta,
            agents,
            dof,
            resolved,
        })
    }

    /// `t_k`, s: the engine's own function of the tick.
    fn t(&self, k: u64) -> f64 {
        tick_time(k, self.dt)
    }

    /// The agent `id`; an error naming the trace when its scenario has no such agent.
    fn agent(&self, path: &Path, id: u32) -> Result<&AgentInfo> {
        self.agents.get(&id).with_context(|| {
            format!(
                "{}: a record of agent {id}, which the scenario in its header does not have",
                path.display()
            )
        })
    }

    /// `(q_d, q̇_d, q̈_d)` of agent `id` at tick `k`, rad, rad/s, rad/s².
    fn desired(&self, path: &Path, id: u32, k: u64) -> Result<Desired> {
        let a = self.agent(path, id)?;
        let r = a.trajectory.reference::<MAX_DOF>(self.t(k));
        let arr = |v: &fdi_common::model::Vector<MAX_DOF>| {
            let mut out = [0.0; MAX_DOF];
            out.copy_from_slice(v.as_slice());
            out
        };
        Ok((arr(&r.q), arr(&r.qd), arr(&r.qdd), a.dof))
    }
}

/// The kinds of per-tick records.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    Agent,
    Attack,
    Center,
    Latency,
    Actuation,
}

impl Kind {
    /// The kind, tick and agent of a record; `None` for an event.
    fn of(rec: &TraceRecord) -> Option<(Self, u64, u32)> {
        Some(match rec {
            TraceRecord::Agent(a) => (Self::Agent, a.k, a.agent),
            TraceRecord::Attack(a) => (Self::Attack, a.k, a.agent),
            TraceRecord::Center(c) => (Self::Center, c.k, c.agent),
            TraceRecord::Latency { k, agent, .. } => (Self::Latency, *k, *agent),
            TraceRecord::Actuation(a) => (Self::Actuation, a.k, a.agent),
            TraceRecord::Event { .. } => return None,
        })
    }
}

/// How far (in ticks) the records of one kind may stray from (tick, agent) order in a trace
/// and still be put back in order: a record of tick `k` is written once a record of tick
/// `k + REORDER_TICKS` has been read, or at the end of the trace.
const REORDER_TICKS: u64 = 4096;

/// Puts records back in (tick, agent) order within a window of [`REORDER_TICKS`]; records of
/// the same tick and agent keep their order in the file. A record that arrives after a later
/// one has been released is an error, never a silent misorder.
#[derive(Debug)]
struct Reorder<T> {
    buf: BTreeMap<(u64, u32, u64), T>,
    seq: u64,
    newest: u64,
    released: Option<(u64, u32)>,
}

impl<T> Default for Reorder<T> {
    fn default() -> Self {
        Self {
            buf: BTreeMap::new(),
            seq: 0,
            newest: 0,
            released: None,
        }
    }
}

impl<T> Reorder<T> {
    fn push(&mut self, k: u64, agent: u32, v: T) -> Result<()> {
        if let Some((rk, ra)) = self.released {
            if (k, agent) < (rk, ra) {
                bail!(
                    "the record of tick {k} of agent {agent} comes after that of tick {rk} of agent {ra} was written: more than {REORDER_TICKS} ticks out of order"
                );
            }
        }
        self.buf.insert((k, agent, self.seq), v);
        self.seq += 1;
        self.newest = self.newest.max(k);
        Ok(())
    }

    /// The (tick, agent) of the first record held.
    fn first(&self) -> Option<(u64, u32)> {
        self.buf.first_key_value().map(|((k, a, _), _)| (*k, *a))
    }

    /// The first record, if no record read later can come before it.
    fn pop_ready(&mut self) -> Option<T> {
        let (k, _) = self.first()?;
        (self.newest - k > REORDER_TICKS)
            .then(|| self.pop())
            .flatten()
    }

    /// The first record held (at the end of the trace).
    fn pop(&mut self) -> Option<T> {
        let ((k, a, _), v) = self.buf.pop_first()?;
        self.released = Some((k, a));
        Some(v)
    }
}

/// Reads the trace `reader` of `path` to its end, handing the records of each kind to `out` in
/// (tick, agent) order and the events in file order, each with its byte offset; `n` counts the
/// records read. The records before a damage are handed out, then the damage is the error.
fn read_sorted(
    path: &Path,
    reader: &mut TraceReader,
    n: &mut u64,
    mut out: impl FnMut(&TraceRecord, u64) -> Result<()>,
) -> Result<()> {
    let mut held: BTreeMap<Kind, Reorder<(TraceRecord, u64)>> = BTreeMap::new();
    let mut failure = None;
    while let Some(rec) = reader.next() {
        let rec = match rec {
            Ok(r) => r,
            Err(e) => {
                failure = Some(anyhow::Error::from(e));
                break;
            }
        };
        *n += 1;
        let at = reader.last_offset();
        let Some((kind, k, agent)) = Kind::of(&rec) else {
            out(&rec, at)?;
            continue;
        };
        let r = held.entry(kind).or_default();
        r.push(k, agent, (rec, at))
            .with_context(|| format!("{}: record {n} (byte offset {at})", path.display()))?;
        while let Some((rec, at)) = r.pop_ready() {
            out(&rec, at)?;
        }
    }
    for r in held.values_mut() {
        while let Some((rec, at)) = r.pop() {
            out(&rec, at)?;
        }
    }
    match failure {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reorder_sorts_by_tick_then_agent_keeping_duplicates_in_file_order() {
        let mut r = Reorder::default();
        for (k, a, v) in [
            (1, 2, "a"),
            (0, 3, "b"),
            (1, 1, "c"),
            (0, 1, "d"),
            (1, 1, "e"),
        ] {
            r.push(k, a, v).expect("in the window");
        }
        assert_eq!(
            r.pop_ready(),
            None,
            "nothing is final before the window has passed"
        );
        let mut out = Vec::new();
        while let Some(v) = r.pop() {
            out.push(v);
        }
        assert_eq!(out, ["d", "b", "c", "e", "a"]);
    }

    #[test]
    fn reorder_releases_records_past_the_window_and_refuses_one_behind_them() {
        let mut r = Reorder::default();
        r.push(0, 1, 0).expect("first");
        r.push(REORDER_TICKS, 1, 1).expect("second");
        assert_eq!(r.pop_ready(), None);
        r.push(REORDER_TICKS + 1, 1, 2).expect("third");
        assert_eq!(r.pop_ready(), Some(0));
        assert_eq!(r.pop_ready(), None);
        // Tick 0 of agent 0 would now have to come before what was written.
        r.push(0, 1, 3)
            .expect("a duplicate of the last written key keeps the order");
        let e = r.push(0, 0, 4).expect_err("behind the written records");
        assert!(e.to_string().contains("tick 0 of agent 0"), "{e}");
    }
}
