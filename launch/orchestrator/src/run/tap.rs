//! The online join of a multi-process run that keeps less than every record (`--traces
//! decimate=K|none`): each process writes its trace, as always, but into a named pipe the
//! launcher made at the path it was given; a reader thread per process streams its records
//! into the join (the digest and the metrics of every tick, as [`super::join`] computes them
//! from files) and writes what is kept to the real trace file. The processes are unchanged.
//!
//! Every read blocks on its pipe. The launcher holds a write end of every pipe until every
//! process has exited, so that a process that dies before it opened its trace, or after, ends
//! its pipe only once the run is over; a reader never closes its read end early (a damaged
//! stream is drained to its end), so no process is killed by SIGPIPE. The queues between the
//! readers and the join never block a reader (a bounded queue deadlocked: a process blocked on
//! its full pipe while the join waited for a record its peer still held in its write buffer);
//! in lockstep what they hold is bounded by how far the processes can run apart (their
//! lookahead plus what a trace writer buffers); in realtime a process is never slowed by the
//! launcher.

use std::fs::{File, OpenOptions};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::sync::mpsc;

use anyhow::{Context, Result};
use fdi_common::records::TickRecord;
use fdi_common::run_dir::{Process, RunDir};
use fdi_common::scenario::Resolved;
use fdi_common::trace::{Kept, TraceReader, TraceRecord, TraceWriter};

use fdi_report::join::{Feed, Sources, Walked};
use fdi_report::traces::Traces;

/// Where a reader thread sends the records of one kind (unbounded: see the module's notes).
#[derive(Clone)]
struct Tx(mpsc::Sender<Result<TraceRecord, String>>);

impl Tx {
    /// False once the join is gone (it ended: what follows is not needed).
    fn send(&self, r: Result<TraceRecord, String>) -> bool {
        self.0.send(r).is_ok()
    }
}

/// Which of a process's records go to the join, and where.
#[derive(Clone)]
struct Route {
    /// Agent, attack or center records (by process).
    main: Tx,
    /// The second stream of a process's records: the attacker's torque records, when the run
    /// attacks some agent's torques; the control center's record of a monitor's verdicts.
    side: Option<Tx>,
    /// A live run's server, with the process's trace's name: its events and latency stamps.
    live: Option<(String, fdi_live::RecordFeed)>,
}

impl Route {
    fn send(&mut self, rec: TraceRecord) -> bool {
        match rec {
            TraceRecord::Actuation(_) | TraceRecord::Monitor(_) => {
                self.side.as_ref().is_none_or(|t| t.send(Ok(rec)))
            }
            TraceRecord::Agent(_) | TraceRecord::Attack(_) | TraceRecord::Center(_) => {
                self.main.send(Ok(rec))
            }
            // Neither latency stamps nor events are part of the join.
            TraceRecord::Latency { .. } | TraceRecord::Event { .. } => {
                if let Some((stem, feed)) = &mut self.live {
                    feed.record(stem, &rec);
                }
                true
            }
        }
    }

    fn damage(&self, e: String) {
        if let Some(t) = &self.side {
            t.send(Err(e.clone()));
        }
        self.main.send(Err(e));
    }
}

/// One process's pipe: the launcher's read end (for its reader thread) and its write end (held
/// until every process has exited).
struct Pipe {
    process: Process,
    fifo: PathBuf,
    read: File,
    hold: File,
}

impl Pipe {
    fn make(run_dir: &Path, process: Process) -> Result<Self> {
        let fifo = RunDir::new(run_dir).pipe(process);
        rustix::fs::mknodat(
            rustix::fs::CWD,
            &fifo,
            rustix::fs::FileType::Fifo,
            rustix::fs::Mode::from_raw_mode(0o600),
            0,
        )
        .with_context(|| format!("creating the named pipe {}", fifo.display()))?;
        // Opening a read end without a writer blocks, unless non-blocking; with the read end
        // open, the write end opens at once. Reads then block again.
        let read = OpenOptions::new()
            .read(true)
            .custom_flags(rustix::fs::OFlags::NONBLOCK.bits() as i32)
            .open(&fifo)
            .with_context(|| format!("opening {}", fifo.display()))?;
        let hold = OpenOptions::new()
            .write(true)
            .open(&fifo)
            .with_context(|| format!("opening {}", fifo.display()))?;
        let flags = rustix::fs::fcntl_getfl(&read)
            .with_context(|| format!("reading the flags of {}", fifo.display()))?;
        rustix::fs::fcntl_setfl(&read, flags - rustix::fs::OFlags::NONBLOCK)
            .with_context(|| format!("setting {} to blocking reads", fifo.display()))?;
        Ok(Self {
            process,
            fifo,
            read,
            hold,
        })
    }
}

/// The pipes of a run, before its processes start.
pub struct Tap {
    pipes: Vec<Pipe>,
    kept: Option<Kept>,
    routed: bool,
    run_dir: PathBuf,
}

/// What the tap left once every process exited: the join over every tick, and the first
/// failure to write a kept trace (named).
pub struct Tapped {
    pub walked: Result<Walked>,
    pub write_error: Option<String>,
}

impl Tap {
    /// Makes a named pipe per process of `r` in `run_dir/traces` (which exists).
    pub fn create(r: &Resolved, run_dir: &Path, traces: Traces) -> Result<Self> {
        let kept = match traces {
            Traces::Full => Some(Kept::Full),
            Traces::Decimate(k) => Some(Kept::Decimate { every: k.get() }),
            Traces::None => None,
        };
        let mut tap = Self {
            pipes: Vec::new(),
            kept,
            routed: r
                .scenario
                .agents
                .iter()
                .any(|a| r.attack.attacks_torque_of(a.id)),
            run_dir: run_dir.to_path_buf(),
        };
        for n in Process::of_run(r.scenario.agents.iter().map(|a| a.id)) {
            match Pipe::make(run_dir, n) {
                Ok(p) => tap.pipes.push(p),
                Err(e) => {
                    tap.remove_pipes();
                    return Err(e);
                }
            }
        }
        Ok(tap)
    }

    fn remove_pipes(&self) {
        for p in &self.pipes {
            let _ = std::fs::remove_file(&p.fifo);
        }
    }

    /// Runs `run` (the processes, writing into the pipes) while the readers and the join go on;
    /// returns its result once every pipe ended, with what the join gathered.
    /// A live run's `feed` is handed every joined tick, and the processes' events and latency
    /// stamps.
    pub fn run<T>(
        self,
        r: &Resolved,
        feed: Option<fdi_live::Feed>,
        run: impl FnOnce() -> T,
    ) -> (T, Tapped) {
        let Self {
            pipes,
            kept,
            routed,
            run_dir,
            ..
        } = self;
        let records = feed.as_ref().map(fdi_live::Feed::records);
        let (routes, sources) = route_pipes(&pipes, routed, r, records.as_ref());
        let mut holds = Vec::new();
        let mut readers = Vec::new();
        for (p, route) in pipes.into_iter().zip(routes) {
            holds.push(p.hold);
            let out = kept.map(|k| (RunDir::new(&run_dir).trace(p.process), k));
            readers.push(Reader {
                read: p.read,
                fifo: p.fifo,
                out,
                route,
            });
        }
        let (result, tapped) = read_while(r, sources, readers, holds, feed, run);
        remove_pipe_files(&run_dir);
        (result, tapped)
    }
}

/// A queue from a reader thread to the join.
///
/// The queues never push back on a process: a process blocked on its trace would stall
/// its peers, and a record it still buffers (a writer flushes every 100 ms or 64 KiB)
/// could be the one the join waits for. What they hold stays bounded in lockstep all the
/// same: the processes cannot run further apart than their lookahead plus what a
/// writer buffers.
fn channel() -> (Tx, Feed) {
    let (tx, rx) = mpsc::channel();
    (Tx(tx), Box::new(rx.into_iter()))
}

/// The route of each pipe's records (in the order of `pipes`) and the join's sources they feed.
fn route_pipes(
    pipes: &[Pipe],
    routed: bool,
    r: &Resolved,
    live: Option<&fdi_live::RecordFeed>,
) -> (Vec<Route>, Sources) {
    let mut agents = Vec::new();
    let mut routes = Vec::new();
    let (mut attacker, mut actuation, mut center, mut monitor) = (None, None, None, None);
    for p in pipes {
        let (tx, feed) = channel();
        let mut route = Route {
            main: tx,
            side: None,
            live: live.map(|f| (p.process.to_string(), f.clone())),
        };
        if p.process == Process::Attacker {
            attacker = Some(feed);
            if routed {
                let (tx, feed) = channel();
                route.side = Some(tx);
                actuation = Some(feed);
            }
        } else if p.process == Process::Center {
            center = Some(feed);
            if r.scenario.roles.monitor.is_some() {
                let (tx, feed) = channel();
                route.side = Some(tx);
                monitor = Some(feed);
            }
        } else {
            let id = p
                .process
                .agent()
                .filter(|id| r.scenario.agents.iter().any(|a| a.id == *id));
            if let Some(id) = id {
                agents.push((id, feed));
            }
        }
        routes.push(route);
    }
    let (Some(attacker), Some(center)) = (attacker, center) else {
        unreachable!("the tap makes an attacker and a control-center pipe");
    };
    let sources = Sources::from_feeds(agents, attacker, actuation, center, monitor);
    (routes, sources)
}

/// What a reader thread needs: the read end of a pipe, its path, where and what it keeps, and
/// where its records go.
struct Reader {
    read: File,
    fifo: PathBuf,
    out: Option<(PathBuf, Kept)>,
    route: Route,
}

/// Runs `run` while a thread per pipe reads it and a thread joins what they read; lets go of
/// the pipes' write ends (`holds`) once `run` returned, and waits for every thread.
fn read_while<T>(
    r: &Resolved,
    sources: Sources,
    readers: Vec<Reader>,
    holds: Vec<File>,
    mut feed: Option<fdi_live::Feed>,
    run: impl FnOnce() -> T,
) -> (T, Tapped) {
    std::thread::scope(|s| {
        let join = s.spawn(move || {
            let sink = |rec: &TickRecord| {
                if let Some(f) = &mut feed {
                    f.tick(rec);
                }
            };
            fdi_report::join::walk(r, sources, 1, sink, || Ok(()))
        });
        let readers: Vec<_> = readers
            .into_iter()
            .map(|mut rd| {
                s.spawn(move || read_process(rd.read, &rd.fifo, rd.out.as_ref(), &mut rd.route))
            })
            .collect();
        let result = run();
        // Every process has exited: the pipes end once the launcher lets go of them.
        drop(holds);
        let mut write_error = None;
        for h in readers {
            let e = h
                .join()
                .unwrap_or_else(|_| Some("a trace reader thread panicked".into()));
            if write_error.is_none() {
                write_error = e;
            }
        }
        let walked = join
            .join()
            .unwrap_or_else(|_| Err(anyhow::anyhow!("the online join thread panicked")));
        (
            result,
            Tapped {
                walked,
                write_error,
            },
        )
    })
}

/// Removes the named pipes left in the run's traces folder.
fn remove_pipe_files(run_dir: &Path) {
    for p in std::fs::read_dir(RunDir::new(run_dir).traces())
        .into_iter()
        .flatten()
        .flatten()
    {
        if p.path().extension().is_some_and(|e| e == RunDir::PIPE_EXT) {
            let _ = std::fs::remove_file(p.path());
        }
    }
}

/// Reads one process's trace from its pipe to the end: its records to the join (`route`),
/// those `out` keeps to its trace file. Returns the first failure to write that file.
fn read_process(
    read: File,
    fifo: &Path,
    out: Option<&(PathBuf, Kept)>,
    route: &mut Route,
) -> Option<String> {
    // A second handle on the pipe drains it to its end after damage, so that its writer never
    // blocks nor dies of a closed pipe.
    let drain = read.try_clone().ok();
    let finish = |drain: Option<File>| {
        if let Some(mut d) = drain {
            let _ = std::io::copy(&mut d, &mut std::io::sink());
        }
    };
    let mut reader = match TraceReader::from_pipe(read, fifo) {
        Ok(r) => r,
        Err(e) => {
            route.damage(e.to_string());
            finish(drain);
            return None;
        }
    };
    let mut write_error = None;
    let mut writer = match out {
        Some((path, kept)) => {
            let mut header = reader.header().clone();
            header.kept = *kept;
            match TraceWriter::create(path, &header) {
                Ok(w) => Some((w, *kept)),
                Err(e) => {
                    write_error = Some(e.to_string());
                    None
                }
            }
        }
        None => None,
    };
    let mut joining = true;
    for rec in reader.by_ref() {
        match rec {
            Ok(rec) => {
                if let Some((w, kept)) = &mut writer {
                    if kept.keeps(&rec) {
                        if let Err(e) = w.write(&rec) {
                            write_error.get_or_insert(e.to_string());
                            writer = None;
                        }
                    }
                }
                if joining {
                    joining = route.send(rec);
                }
            }
            Err(e) => {
                route.damage(e.to_string());
                break;
            }
        }
    }
    if let Some((mut w, _)) = writer {
        if let Err(e) = w.flush() {
            write_error.get_or_insert(e.to_string());
        }
    }
    finish(drain);
    write_error
}
