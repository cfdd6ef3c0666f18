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
//!
//! An export never leaves a partial file: it is written under a temporary name in
//! `RUN_DIR/export` (`.run.mcap.*`, a folder `.csv.*` for the CSV files) and renamed into place
//! once every byte is on disk. A write that fails (a full disk, a read-only folder) abandons the
//! export: the temporary is removed, what `RUN_DIR/export` held before is left as it was, and
//! the error names the file and the cause (`no space left on device (ENOSPC)`).

mod csv;
mod mcap;

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::io;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use fdi_common::engine::tick_time;
use fdi_common::scenario::{self, Resolved, MAX_DOF};
use fdi_common::trace::{TraceError, TraceHeader, TraceReader, TraceRecord};
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
    let traces = fdi_common::run_dir::RunDir::new(run_dir).traces();
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
struct OutDir {
    path: PathBuf,
    /// This export made it: an abandoned export removes it again.
    made: bool,
}

impl OutDir {
    fn open(run_dir: &Path) -> Result<Self> {
        let path = run_dir.join("export");
        let made = !path.is_dir();
        std::fs::create_dir_all(&path).map_err(|e| WriteFailed::io(&path, e))?;
        Ok(Self { path, made })
    }

    /// After an abandoned export: removes the folder if this export made it (and it is empty).
    fn discard(&self) {
        if self.made {
            let _ = std::fs::remove_dir(&self.path);
        }
    }
}

/// A write of the export's own files that failed (a full disk, a read-only folder): it ends the
/// whole export, whose temporary files are then removed. `path` is the file the export was
/// making (its final name).
#[derive(Debug)]
struct WriteFailed {
    path: PathBuf,
    cause: String,
}

impl WriteFailed {
    fn io(path: &Path, e: io::Error) -> anyhow::Error {
        anyhow::Error::new(Self {
            path: path.to_path_buf(),
            cause: crate::io_cause::describe(&e),
        })
    }

    fn other(path: &Path, cause: impl fmt::Display) -> anyhow::Error {
        anyhow::Error::new(Self {
            path: path.to_path_buf(),
            cause: cause.to_string(),
        })
    }
}

impl fmt::Display for WriteFailed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "writing {}: {}", self.path.display(), self.cause)
    }
}

impl std::error::Error for WriteFailed {}

/// The failed write that `e` comes from, if it does.
fn write_failure(e: &anyhow::Error) -> Option<&WriteFailed> {
    e.chain().find_map(|c| c.downcast_ref::<WriteFailed>())
}

/// The error of an export abandoned on `e` (its temporary files already removed): a failed
/// write says so, naming the file and the cause; any other error is `e`.
fn abandoned(e: anyhow::Error, format: &str) -> anyhow::Error {
    match write_failure(&e) {
        Some(w) => anyhow::anyhow!(
            "{w}: the {format} export is abandoned, its temporary files removed (nothing partial is left)"
        ),
        None => e,
    }
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
    Monitor,
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
            TraceRecord::Monitor(m) => (Self::Monitor, m.k, m.agent),
            TraceRecord::Event { .. } => return None,
        })
    }
}

/// The (kind, agent) streams of a trace.
type Streams = BTreeSet<(Kind, u32)>;

/// One (kind, agent) stream of a trace: a reader of its own over the file, handing out only
/// that stream's records.
struct Stream {
    reader: TraceReader,
    kind: Kind,
    agent: u32,
}

impl Stream {
    /// The stream's next record and its byte offset; `None` at the end of the file, or at a
    /// damage (the first pass over the file reports it).
    fn next(&mut self) -> Option<(u64, TraceRecord, u64)> {
        loop {
            let rec = self.reader.next()?.ok()?;
            if let Some((kind, k, agent)) = Kind::of(&rec) {
                if kind == self.kind && agent == self.agent {
                    return Some((k, rec, self.reader.last_offset()));
                }
            }
        }
    }
}

/// The per-tick records of a trace in (tick, agent) order (records of one tick and agent in
/// kind order, then in file order), merged from one [`Stream`] per (kind, agent) found in the
/// trace. Every agent's pipeline runs on its own, so one agent's records can be written
/// seconds of ticks after another's; merging streams keeps memory at one record per stream
/// however far apart they were written (the file is read once per stream).
struct Sorted {
    streams: Vec<Stream>,
    heads: BTreeMap<(u64, u32, Kind, usize), (TraceRecord, u64)>,
}

impl Sorted {
    fn open(path: &Path, keys: &Streams) -> Result<Self, TraceError> {
        let mut sorted = Self {
            streams: Vec::new(),
            heads: BTreeMap::new(),
        };
        for &(kind, agent) in keys {
            let mut stream = Stream {
                reader: TraceReader::open(path)?,
                kind,
                agent,
            };
            let i = sorted.streams.len();
            if let Some((k, rec, at)) = stream.next() {
                sorted.heads.insert((k, agent, kind, i), (rec, at));
            }
            sorted.streams.push(stream);
        }
        Ok(sorted)
    }

    /// The (tick, agent, kind) of the next record.
    fn peek(&self) -> Option<(u64, u32, Kind)> {
        self.heads
            .first_key_value()
            .map(|(&(k, agent, kind, _), _)| (k, agent, kind))
    }

    /// The next record and its byte offset.
    fn pop(&mut self) -> Option<(TraceRecord, u64)> {
        let ((_, agent, kind, i), head) = self.heads.pop_first()?;
        if let Some((k, rec, at)) = self.streams[i].next() {
            self.heads.insert((k, agent, kind, i), (rec, at));
        }
        Some(head)
    }
}

/// The first pass over a trace: the (kind, agent) streams it holds, each checked to be in
/// tick order; events go to `event` in file order; `n` counts the records read. Returns the
/// streams and the damage that ended the file early, if any.
fn scan(
    path: &Path,
    reader: &mut TraceReader,
    n: &mut u64,
    mut event: impl FnMut(&TraceRecord, u64) -> Result<()>,
) -> Result<(Streams, Option<anyhow::Error>)> {
    let mut last: BTreeMap<(Kind, u32), u64> = BTreeMap::new();
    while let Some(rec) = reader.next() {
        let rec = match rec {
            Ok(r) => r,
            Err(e) => return Ok((last.into_keys().collect(), Some(e.into()))),
        };
        *n += 1;
        let at = reader.last_offset();
        let Some((kind, k, agent)) = Kind::of(&rec) else {
            event(&rec, at)?;
            continue;
        };
        let prev = last.insert((kind, agent), k);
        if let Some(prev) = prev.filter(|&prev| k < prev) {
            bail!(
                "{}: record {n} (byte offset {at}): tick {k} of agent {agent} comes after tick {prev} of the same agent: the trace is not in tick order",
                path.display()
            );
        }
    }
    Ok((last.into_keys().collect(), None))
}

/// Reads the trace `reader` of `path` to its end, handing the events to `out` in file order,
/// then the per-tick records in (tick, agent) order ([`Sorted`]), each with its byte offset;
/// `n` counts the records read. The records before a damage are handed out, then the damage
/// is the error.
fn read_sorted(
    path: &Path,
    reader: &mut TraceReader,
    n: &mut u64,
    mut out: impl FnMut(&TraceRecord, u64) -> Result<()>,
) -> Result<()> {
    let (keys, failure) = scan(path, reader, n, &mut out)?;
    let mut sorted = Sorted::open(path, &keys)?;
    while let Some((rec, at)) = sorted.pop() {
        out(&rec, at)?;
    }
    match failure {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use fdi_common::records::AttackRecord;
    use fdi_common::trace::{TraceHeader, TraceWriter, FORMAT_VERSION};

    use super::*;

    /// A scratch run directory holding the fixture `testdata/short-run` (scenario and traces).
    pub(super) fn fixture_copy() -> tempfile::TempDir {
        let from = Path::new(env!("CARGO_MANIFEST_DIR")).join("testdata/short-run");
        let tmp = tempfile::tempdir().expect("a scratch folder");
        std::fs::create_dir(fdi_common::run_dir::RunDir::new(tmp.path()).traces())
            .expect("traces/");
        std::fs::copy(
            fdi_common::run_dir::RunDir::new(&from).scenario(),
            fdi_common::run_dir::RunDir::new(tmp.path()).scenario(),
        )
        .expect("copy");
        for e in std::fs::read_dir(fdi_common::run_dir::RunDir::new(&from).traces())
            .expect("the fixture's traces")
        {
            let p = e.expect("an entry").path();
            std::fs::copy(
                &p,
                fdi_common::run_dir::RunDir::new(tmp.path())
                    .traces()
                    .join(p.file_name().expect("name")),
            )
            .expect("copy");
        }
        tmp
    }

    fn attack(k: u64, agent: u32, tag: f64) -> TraceRecord {
        TraceRecord::Attack(AttackRecord {
            k,
            agent,
            alpha_position: Default::default(),
            alpha_velocity: Default::default(),
            y: fdi_common::records::Joints::from_slice(&[tag]),
            yd: Default::default(),
            active: false,
            delivery: Default::default(),
        })
    }

    fn tag(rec: &TraceRecord) -> f64 {
        match rec {
            TraceRecord::Attack(a) => a.y.as_slice()[0],
            other => panic!("not an attack record: {other:?}"),
        }
    }

    fn write(records: &[TraceRecord]) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().expect("scratch");
        let path = dir.path().join("attacker.trace");
        let header = TraceHeader {
            format_version: FORMAT_VERSION,
            process: "attacker".into(),
            scenario_toml: String::new(),
            seed: 1,
            clock: "lockstep".into(),
            kept: Default::default(),
        };
        let mut w = TraceWriter::create(&path, &header).expect("writer");
        for r in records {
            w.write(r).expect("write");
        }
        w.flush().expect("flush");
        (dir, path)
    }

    /// Agent 2's records written 10 000 ticks after agent 1's (each pipeline runs on its
    /// own) come out in (tick, agent) order; duplicates keep their file order.
    #[test]
    fn records_come_out_in_tick_then_agent_order_however_far_apart_they_were_written() {
        let mut recs: Vec<TraceRecord> = (0..10_000).map(|k| attack(k, 1, k as f64)).collect();
        recs.extend((0..3).map(|k| attack(k, 2, -(k as f64))));
        recs.push(attack(2, 2, -2.5));
        let (_dir, path) = write(&recs);
        let mut reader = TraceReader::open(&path).expect("reader");
        let mut n = 0;
        let mut got = Vec::new();
        read_sorted(&path, &mut reader, &mut n, |rec, _| {
            got.push(Kind::of(rec).map(|(_, k, a)| (k, a, tag(rec))));
            Ok(())
        })
        .expect("sorted");
        assert_eq!(n, 10_004);
        let head: Vec<_> = got.iter().take(7).flatten().copied().collect();
        assert_eq!(
            head,
            [
                (0, 1, 0.0),
                (0, 2, -0.0),
                (1, 1, 1.0),
                (1, 2, -1.0),
                (2, 1, 2.0),
                (2, 2, -2.0),
                (2, 2, -2.5)
            ]
        );
        assert_eq!(got.len(), 10_004);
        assert_eq!(got.last(), Some(&Some((9_999, 1, 9_999.0))));
    }

    #[test]
    fn a_stream_out_of_tick_order_is_refused_naming_the_record() {
        let (_dir, path) = write(&[attack(5, 1, 0.0), attack(4, 1, 0.0)]);
        let mut reader = TraceReader::open(&path).expect("reader");
        let mut n = 0;
        let e = read_sorted(&path, &mut reader, &mut n, |_, _| Ok(())).expect_err("out of order");
        let text = format!("{e:#}");
        assert!(
            text.contains("record 2") && text.contains("tick 4 of agent 1 comes after tick 5"),
            "{text}"
        );
    }
}
