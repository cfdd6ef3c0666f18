//! The live view of a multi-process run that keeps its traces whole: its processes write their
//! trace files as always, and once a viewer subscribed, a thread of the launcher follows those
//! files from their first byte as they grow and joins them ([`fdi_report::join::walk`]) into the
//! live server's feed. Nobody watching, nothing is read: the run costs what it costs without
//! `--live`. The processes never wait for the follower (it reads what their writers flushed:
//! every 100 ms or 64 KiB), and a viewer that comes late sees the run from its start.
//!
//! In a run split over hosts, the traces of the processes on other hosts come as their hosts'
//! serves stream them once subscribed ([`crate::run::split::RemoteTraces`]), and at the end from the
//! copies the run fetched; the coordinator serves every robot's topics.

use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::io::{Cursor, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use fdi_common::run_dir::{Process, RunDir};
use fdi_common::scenario::{ClockMode, Resolved};
use fdi_common::stop::Stop;
use fdi_common::trace::TraceReader;
use fdi_report::join::{Feed, Sources};

use crate::run::relay::lock;
use crate::run::split::{Received, RemoteTraces};

/// How long a follower sleeps when it reached what was written so far.
const POLL: Duration = Duration::from_millis(20);
/// How long after the run's end the follower may still read (a viewer that came late, a machine
/// too busy for its idle thread): then it stops, and the launcher goes on.
const FINISH: Duration = Duration::from_secs(5);
/// In a realtime run, a trace that has not grown for this long is taken to have ended (its
/// process was lost; a live process's trace writer flushes every 100 ms, but the processes may
/// take seconds to start on a loaded machine after writing their headers): the others go on.
const REALTIME_SILENCE: Duration = Duration::from_secs(10);

/// The end of the run, as the follower sees it.
#[derive(Debug, Default)]
pub struct Over {
    at: OnceLock<Instant>,
    flag: AtomicBool,
}

impl Over {
    /// The run is over: every trace is whole.
    pub fn set(&self) {
        let _ = self.at.set(Instant::now());
        self.flag.store(true, Ordering::Release);
    }

    fn is_set(&self) -> bool {
        self.flag.load(Ordering::Acquire)
    }

    fn overdue(&self) -> bool {
        self.at.get().is_some_and(|t| t.elapsed() > FINISH)
    }
}

/// A trace file read as its process writes it: at its end, a read waits for more until the run
/// is over (or, in realtime, the file is silent for [`REALTIME_SILENCE`]), then the file's end
/// is the trace's.
struct Growing {
    file: File,
    over: Arc<Over>,
    silence: Option<Duration>,
    grew: Instant,
}

impl Read for Growing {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        loop {
            // Whether the run was over before this read: then what it finds is all there is.
            let over = self.over.is_set();
            let n = self.file.read(buf)?;
            if n > 0 {
                self.grew = Instant::now();
                return Ok(n);
            }
            if over || self.silence.is_some_and(|s| self.grew.elapsed() > s) {
                return Ok(0);
            }
            std::thread::sleep(POLL);
        }
    }
}

/// Where the follower finds the traces of a split run's processes on other hosts: set once
/// the coordinator reached them, emptied when it fetches them at the end.
pub type RemoteSlot = Arc<Mutex<Option<Arc<dyn RemoteTraces>>>>;

/// A subscription the [`Subscriber`] is asked for: the process, its number of readers, and
/// where to answer.
type Ask = (Process, usize, mpsc::Sender<Vec<Received>>);

/// Subscribes to the streams of the remote traces ([`RemoteTraces`]) on a thread
/// of its own at the run's priority, which holds the subscriptions until every `Subscriber` is
/// dropped. The follower runs under SCHED_IDLE, and a Zenoh call takes locks of the session
/// that a thread the busy run starves must not hold.
#[derive(Clone)]
struct Subscriber {
    to: mpsc::Sender<Ask>,
    slot: RemoteSlot,
}

impl Subscriber {
    fn start(slot: &RemoteSlot) -> Result<Self> {
        let (to, asks) = mpsc::channel::<Ask>();
        let traces = slot.clone();
        std::thread::Builder::new()
            .name("live-subscribe".into())
            .spawn(move || {
                let mut held = Vec::new();
                for (p, readers, answer) in asks {
                    let remote = lock(&traces).clone();
                    let streams = match remote.map(|t| t.subscribe(p, readers)) {
                        Some(Ok(s)) => {
                            held.push(s.held);
                            s.readers
                        }
                        Some(Err(e)) => {
                            log::warn!("live view: {p}: {e:#}");
                            Vec::new()
                        }
                        None => Vec::new(),
                    };
                    let _ = answer.send(streams);
                }
            })
            .context("starting the live view's thread that subscribes to the remote traces")?;
        Ok(Self {
            to,
            slot: slot.clone(),
        })
    }

    /// The stream of the trace of `p` for each of `readers`, or none if it cannot be had (the
    /// run's end).
    fn subscribe(&self, p: Process, readers: usize) -> Vec<Received> {
        let (answer, answered) = mpsc::channel();
        if self.to.send((p, readers, answer)).is_err() {
            return Vec::new();
        }
        answered.recv().unwrap_or_default()
    }

    /// The processes on other hosts, once the coordinator reached them.
    fn elsewhere(&self) -> Option<BTreeSet<Process>> {
        lock(&self.slot).as_ref().map(|t| t.processes())
    }
}

/// The trace of a process on another host, read as it grows: the chunks its host streams;
/// once the run is over, the rest from the copy its end fetched into the run directory (the
/// host then removed its own). A chunk that does not follow on (or is not one) stops the
/// stream: the rest is read at the end.
struct Fetched {
    process: Process,
    chunks: Option<Received>,
    /// How far the trace was read.
    position: u64,
    piece: Cursor<Vec<u8>>,
    /// The fetched copy, read from `position` once the run is over.
    fetched: PathBuf,
    rest: Option<File>,
    over: Arc<Over>,
    silence: Option<Duration>,
    grew: Instant,
}

impl Fetched {
    /// The rest of the trace, from the copy fetched at the run's end.
    fn open_rest(&self) -> std::io::Result<File> {
        let named = |e: std::io::Error| {
            std::io::Error::new(e.kind(), format!("{}: {e}", self.fetched.display()))
        };
        let mut f = File::open(&self.fetched).map_err(named)?;
        f.seek(SeekFrom::Start(self.position)).map_err(named)?;
        Ok(f)
    }

    /// Takes the next chunk, waiting at most [`POLL`]: whether one came.
    fn next_chunk(&mut self) -> bool {
        let Some(chunks) = &self.chunks else {
            std::thread::sleep(POLL);
            return false;
        };
        let broken = match chunks.recv_timeout(POLL) {
            Ok(Ok((offset, bytes))) if offset <= self.position => {
                // (A repeat of what was read is skipped.)
                let seen = usize::try_from(self.position - offset).unwrap_or(usize::MAX);
                if seen >= bytes.len() {
                    return false;
                }
                self.position += (bytes.len() - seen) as u64;
                let mut bytes = bytes;
                bytes.drain(..seen);
                self.piece = Cursor::new(bytes);
                self.grew = Instant::now();
                return true;
            }
            Ok(Ok((offset, _))) => format!(
                "a chunk at byte {offset}, after byte {} (the stream began before the \
                 subscription)",
                self.position
            ),
            Ok(Err(what)) => what,
            Err(mpsc::RecvTimeoutError::Timeout) => return false,
            Err(mpsc::RecvTimeoutError::Disconnected) => "the subscription ended".into(),
        };
        log::warn!(
            "live view: the stream of the trace of {} stopped ({broken}): \
             the rest is read once the run is over",
            self.process
        );
        self.chunks = None;
        false
    }
}

impl Read for Fetched {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        loop {
            if let Some(f) = &mut self.rest {
                return f.read(buf);
            }
            let n = self.piece.read(buf)?;
            if n > 0 {
                return Ok(n);
            }
            if self.over.is_set() {
                let came = (self.chunks.as_ref()).is_some_and(|c| c.try_recv().is_ok());
                if self.position == 0 && !came {
                    // (No stream, or its host never sent: the viewer saw it only after the end.)
                    log::warn!(
                        "live view: the stream of the trace of {} delivered \
                         nothing during the run: its records are read from the fetched copy",
                        self.process
                    );
                }
                self.rest = Some(self.open_rest()?);
                continue;
            }
            if !self.next_chunk() && self.silence.is_some_and(|s| self.grew.elapsed() > s) {
                return Ok(0);
            }
        }
    }
}

/// Which reader of a trace is opened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Reader {
    /// The only one.
    Once,
    /// The first of two.
    Twice,
    /// The second.
    Second,
}

/// Where the traces of a run are, to follow them: its directory, and for a split run the other
/// hosts (once reached).
pub struct Traces<'a> {
    dir: RunDir,
    subscriber: Option<Subscriber>,
    /// The streams of remote traces that are read twice, for their second readers.
    seconds: RefCell<BTreeMap<Process, Received>>,
    over: &'a Arc<Over>,
}

impl<'a> Traces<'a> {
    /// The traces of the run in `run_dir`, and of its processes on other hosts (`remote`):
    /// call it on a thread at the run's priority (it may start one).
    pub fn new(run_dir: &Path, remote: Option<&RemoteSlot>, over: &'a Arc<Over>) -> Result<Self> {
        Ok(Self {
            dir: RunDir::new(run_dir),
            subscriber: remote.map(Subscriber::start).transpose()?,
            seconds: RefCell::default(),
            over,
        })
    }

    /// Waits until the other hosts of a split run are reached: the processes that run there
    /// (none on one host), or `None` if the run is over first.
    fn reached(&self) -> Option<BTreeSet<Process>> {
        let Some(subscriber) = &self.subscriber else {
            return Some(BTreeSet::new());
        };
        loop {
            let was_over = self.over.is_set();
            if let Some(elsewhere) = subscriber.elsewhere() {
                return Some(elsewhere);
            }
            if was_over {
                return None;
            }
            std::thread::sleep(POLL);
        }
    }

    /// The trace of `p` read as it grows, streamed by its host if it is `elsewhere` (`None`:
    /// the run is over without it). `reader`: the first of a trace read `Twice`, or its second.
    fn open(
        &self,
        (p, reader): (Process, Reader),
        elsewhere: &BTreeSet<Process>,
        silence: Option<Duration>,
    ) -> Option<Box<dyn Read + Send>> {
        let path = self.dir.trace(p);
        let over = self.over.clone();
        if let Some(subscriber) = self.subscriber.as_ref().filter(|_| elsewhere.contains(&p)) {
            let chunks = match reader {
                Reader::Second => self.seconds.borrow_mut().remove(&p),
                Reader::Once => subscriber.subscribe(p, 1).pop(),
                Reader::Twice => {
                    let mut streams = subscriber.subscribe(p, 2).into_iter();
                    let first = streams.next();
                    if let Some(second) = streams.next() {
                        self.seconds.borrow_mut().insert(p, second);
                    }
                    first
                }
            };
            return Some(Box::new(Fetched {
                process: p,
                chunks,
                position: 0,
                piece: Cursor::default(),
                fetched: path,
                rest: None,
                over,
                silence,
                grew: Instant::now(),
            }));
        }
        let file = open_when_made(&path, self.over)?;
        Some(Box::new(Growing {
            file,
            over,
            silence,
            grew: Instant::now(),
        }))
    }
}

/// The trace file `path`, once it exists (a process makes it after it starts); `None` if the
/// run is over without it.
fn open_when_made(path: &Path, over: &Over) -> Option<File> {
    loop {
        let was_over = over.is_set();
        if let Ok(f) = File::open(path) {
            return Some(f);
        }
        if was_over {
            return None;
        }
        std::thread::sleep(POLL);
    }
}

/// The records of the trace of `p`, followed as it grows; its events and latency stamps also
/// to the live server (`records`: once per trace, a second reader of it has none).
fn followed(
    (traces, elsewhere): (&Traces, &BTreeSet<Process>),
    (p, reader): (Process, Reader),
    silence: Option<Duration>,
    mut records: Option<fdi_live::RecordFeed>,
) -> Feed {
    let path = traces.dir.trace(p);
    let Some(growing) = traces.open((p, reader), elsewhere, silence) else {
        let missing = format!("{}: the process wrote no trace", path.display());
        return Box::new(std::iter::once(Err(missing)));
    };
    let stem = p.to_string();
    match TraceReader::follow(growing, &path) {
        Ok(reader) => Box::new(reader.map(move |r| {
            // (It takes the events and latency stamps only.)
            if let (Ok(rec), Some(to)) = (&r, &mut records) {
                to.record(&stem, rec);
            }
            r.map_err(|e| e.to_string())
        })),
        Err(e) => Box::new(std::iter::once(Err(e.to_string()))),
    }
}

/// Follows the traces of the run of `r` (`traces`) once `watcher` says a viewer subscribed,
/// until the run is over and every trace read, at most [`FINISH`] after; the joined ticks into
/// `feed`. Returns at once, reading nothing, if the run is over before anyone watched.
/// `actuation`: the attacker's trace holds the torque path's records (the ipc engine; the
/// in-process engine's traces have none).
pub fn follow_run(
    r: &Resolved,
    traces: &Traces,
    (mut feed, watcher): (fdi_live::Feed, &fdi_live::Watcher),
    actuation: bool,
    stop: &Stop,
) -> Result<()> {
    fdi_live::yield_to_the_run();
    let over = traces.over;
    while !watcher.wait(POLL * 5) {
        if over.is_set() {
            return Ok(());
        }
    }
    let Some(elsewhere) = traces.reached() else {
        return Ok(());
    };
    let records = feed.records();
    let s = &r.scenario;
    let silence = (s.clock == ClockMode::Realtime).then_some(REALTIME_SILENCE);
    let at = (traces, &elsewhere);
    let routed = actuation && s.agents.iter().any(|a| r.attack.attacks_torque_of(a.id));
    let monitored = s.roles.monitor.is_some();
    let first = |twice: bool| if twice { Reader::Twice } else { Reader::Once };
    let feed_of =
        |p: Process, twice: bool| followed(at, (p, first(twice)), silence, Some(records.clone()));
    // A second reader of a trace, for its second stream of records.
    let second = |p: Process| followed(at, (p, Reader::Second), silence, None);
    let agents = s
        .agents
        .iter()
        .map(|a| (a.id, feed_of(Process::Agent(a.id), false)))
        .collect();
    let sources = Sources::from_feeds(
        agents,
        feed_of(Process::Attacker, routed),
        routed.then(|| second(Process::Attacker)),
        feed_of(Process::Center, monitored),
        monitored.then(|| second(Process::Center)),
    );
    let walked = fdi_report::join::walk(
        r,
        sources,
        1,
        |rec| feed.tick(rec),
        || {
            stop.check(fdi_common::stop::DURING_THE_RUN)?;
            if over.overdue() {
                bail!(
                    "it had not caught up with the run {} s after its end",
                    FINISH.as_secs()
                );
            }
            Ok(())
        },
    )?;
    for w in walked.warnings() {
        log::warn!("live view: {w}");
    }
    Ok(())
}
