//! What an export reads and how it fails: the run's trace files, what the run was
//! ([`RunInfo`]), each trace's records sorted by tick ([`Sorted`]), and the output folder
//! written whole or not at all ([`OutDir`]).

use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::io;
use std::path::{Path, PathBuf};
use std::rc::Rc;

pub(super) use crate::topics::RunInfo;
use anyhow::{bail, Context, Result};
use fdi_common::trace::{TraceError, TraceReader, TraceRecord};

/// The `*.trace` files of `RUN_DIR/traces`, sorted; an error when there are none.
pub(super) fn trace_files(run_dir: &Path) -> Result<Vec<PathBuf>> {
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

/// The export folder `RUN_DIR/export`, made if need be, and the export's writes into it.
pub(super) struct OutDir {
    pub(super) path: PathBuf,
    /// This export made it: an abandoned export removes it again.
    pub(super) made: bool,
    pub(super) writes: Writes,
}

impl OutDir {
    pub(super) fn open(run_dir: &Path) -> Result<Self> {
        let path = fdi_common::run_dir::RunDir::new(run_dir).export();
        let made = !path.is_dir();
        let writes = Writes::default();
        std::fs::create_dir_all(&path).map_err(|e| writes.io(&path, e))?;
        Ok(Self { path, made, writes })
    }

    /// After an abandoned export: removes the folder if this export made it (and it is empty).
    pub(super) fn discard(&self) {
        if self.made {
            let _ = std::fs::remove_dir(&self.path);
        }
    }
}

/// A write of the export's own files that failed (a full disk, a read-only folder). `path` is
/// the file the export was making (its final name).
#[derive(Debug)]
struct WriteFailed {
    path: PathBuf,
    cause: String,
}

impl fmt::Display for WriteFailed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "writing {}: {}", self.path.display(), self.cause)
    }
}

/// The writes of one export, which its writers share, and the first of them that failed: a
/// failed write ends the whole export (its temporary files are then removed), where a trace
/// that cannot be read whole only ends that trace's part. An error met while exporting is told
/// apart by asking [`Writes::failed`], not by looking into the error.
#[derive(Debug, Clone, Default)]
pub(super) struct Writes(Rc<RefCell<Option<WriteFailed>>>);

impl Writes {
    /// The file `path` could not be written: `e`, in words a person can act on.
    pub(super) fn io(&self, path: &Path, e: io::Error) -> anyhow::Error {
        self.fail(WriteFailed {
            path: path.to_path_buf(),
            cause: crate::io_cause::describe(&e),
        })
    }

    /// The file `path` could not be written, for another `cause` than the operating system's.
    pub(super) fn other(&self, path: &Path, cause: impl fmt::Display) -> anyhow::Error {
        self.fail(WriteFailed {
            path: path.to_path_buf(),
            cause: cause.to_string(),
        })
    }

    fn fail(&self, w: WriteFailed) -> anyhow::Error {
        let e = anyhow::anyhow!("{w}");
        self.0.borrow_mut().get_or_insert(w);
        e
    }

    /// Whether a write of the export failed (which ends it).
    pub(super) fn failed(&self) -> bool {
        self.0.borrow().is_some()
    }

    /// The error of an export abandoned on `e` (its temporary files already removed): a failed
    /// write says so, naming the file and the cause; any other error is `e`.
    pub(super) fn abandoned(&self, e: anyhow::Error, format: &str) -> anyhow::Error {
        match &*self.0.borrow() {
            Some(w) => anyhow::anyhow!(
                "{w}: the {format} export is abandoned, its temporary files removed (nothing partial is left)"
            ),
            None => e,
        }
    }
}

/// The file stem of a trace (`agent-1`, `attacker`, …).
pub(super) fn stem(path: &Path) -> String {
    path.file_stem()
        .map_or_else(|| "trace".into(), |s| s.to_string_lossy().into_owned())
}

/// The failures of an export, as one error.
pub(super) fn failed(failures: Vec<String>) -> Result<()> {
    match failures.len() {
        0 => Ok(()),
        1 => bail!("{}", failures[0]),
        n => bail!(
            "{n} traces could not be exported whole:\n{}",
            failures.join("\n")
        ),
    }
}

/// The kinds of per-tick records.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(super) enum Kind {
    Agent,
    Attack,
    Center,
    Latency,
    Actuation,
    Monitor,
}

impl Kind {
    /// The kind, tick and agent of a record; `None` for an event.
    pub(super) fn of(rec: &TraceRecord) -> Option<(Self, u64, u32)> {
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
pub(super) type Streams = BTreeSet<(Kind, u32)>;

/// One (kind, agent) stream of a trace: a reader of its own over the file, handing out only
/// that stream's records.
pub(super) struct Stream {
    pub(super) reader: TraceReader,
    pub(super) kind: Kind,
    pub(super) agent: u32,
}

impl Stream {
    /// The stream's next record and its byte offset; `None` at the end of the file, or at a
    /// damage (the first pass over the file reports it).
    pub(super) fn next(&mut self) -> Option<(u64, TraceRecord, u64)> {
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
pub(super) struct Sorted {
    pub(super) streams: Vec<Stream>,
    pub(super) heads: BTreeMap<(u64, u32, Kind, usize), (TraceRecord, u64)>,
}

impl Sorted {
    pub(super) fn open(path: &Path, keys: &Streams) -> Result<Self, TraceError> {
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
    pub(super) fn peek(&self) -> Option<(u64, u32, Kind)> {
        self.heads
            .first_key_value()
            .map(|(&(k, agent, kind, _), _)| (k, agent, kind))
    }

    /// The next record and its byte offset.
    pub(super) fn pop(&mut self) -> Option<(TraceRecord, u64)> {
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
pub(super) fn scan(
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
pub(super) fn read_sorted(
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
