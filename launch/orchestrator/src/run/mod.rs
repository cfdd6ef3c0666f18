//! Run orchestration: a resolved scenario on an engine. The multi-process runtime (spawn,
//! supervise, tear down: [`runtime`]), the relay of the children's stderr ([`relay`]), the
//! seam of runs split over hosts ([`split`]; `fdi-split` implements it) and the replay of a recorded attacker
//! ([`replayer`]); the in-process engine is `fdi_common::engine`, the join of traces into tick
//! records `fdi_report::join`.

pub mod disk;
pub mod error;
pub mod follow;
pub mod outputs;
pub mod program;
pub mod relay;
pub mod replayer;
pub mod runs;
pub mod runtime;
pub mod split;
pub mod supervisor;
pub mod tap;
pub mod volume;

use std::path::Path;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
pub use error::RunError;
use fdi_common::attack::Attacker;
use fdi_common::engine::{
    run_inproc_any_until, tick_inproc_any_with, tick_inproc_asking, Books, Partial, RunSummary,
};
use fdi_common::observe::Observer;
use fdi_common::records::TickRecord;
use fdi_common::run_dir::{Process, RunDir};
use fdi_common::scenario::{ClockMode, Resolved};
use fdi_common::trace::{Kept, TraceRecord, TraceWriter};

use fdi_common::stop::{Interrupted, Stop, DURING_THE_RUN};
use fdi_report::output;
pub use fdi_report::traces::Traces;

/// Which engine runs the scenario.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Engine {
    /// One process per agent, an attacker and a control center over iceoryx2 shared memory.
    Ipc,
    /// Everything on one thread, no IPC (the oracle).
    Inproc,
}

impl Engine {
    /// Every engine, in the order the command line lists them.
    pub const ALL: [Self; 2] = [Self::Ipc, Self::Inproc];

    pub fn as_str(self) -> &'static str {
        match self {
            Self::Ipc => "ipc",
            Self::Inproc => "inproc",
        }
    }

    /// What the engine is, in a line (the command line's help).
    pub fn describe(self) -> &'static str {
        match self {
            Self::Ipc => {
                "One process per agent, an attacker and a control center over iceoryx2 shared memory"
            }
            Self::Inproc => "Everything on one thread, no IPC (the oracle)",
        }
    }
}

impl std::fmt::Display for Engine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A name that is no engine's.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is no engine (the engines: {all})", all = Engine::ALL.map(Engine::as_str).join(", "))]
pub struct UnknownEngine(pub String);

impl std::str::FromStr for Engine {
    type Err = UnknownEngine;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|e| e.as_str() == s)
            .ok_or_else(|| UnknownEngine(s.to_string()))
    }
}

/// Writes the records of an in-process run as the per-process traces a multi-process run
/// leaves, so that reports and exports read both alike; with `--traces decimate=K` only the
/// ticks 0, K, 2K, … (said in each header).
struct InprocTraces {
    agents: Vec<(u32, TraceWriter)>,
    attacker: TraceWriter,
    center: TraceWriter,
    kept: Kept,
}

impl InprocTraces {
    fn create(dir: &Path, r: &Resolved, kept: Kept) -> Result<Self> {
        let dir = RunDir::new(dir);
        let create = |p: Process| {
            let mut h = fdi_runtime::process::trace_header(&p.to_string(), r);
            h.kept = kept;
            TraceWriter::create(&dir.trace(p), &h)
        };
        let mut agents = Vec::new();
        for a in &r.scenario.agents {
            agents.push((a.id, create(Process::Agent(a.id))?));
        }
        Ok(Self {
            agents,
            attacker: create(Process::Attacker)?,
            center: create(Process::Center)?,
            kept,
        })
    }

    fn write(&mut self, rec: &TickRecord) -> Result<()> {
        let agent = TraceRecord::Agent(rec.agent);
        if !self.kept.keeps(&agent) {
            return Ok(());
        }
        if let Some((_, w)) = self
            .agents
            .iter_mut()
            .find(|(id, _)| *id == rec.agent.agent)
        {
            w.write(&agent)?;
        }
        self.attacker.write(&TraceRecord::Attack(rec.attack))?;
        // The torque path's record, where the attacker sits on it (as the attacker process
        // writes it).
        if let Some(a) = rec.actuation {
            self.attacker.write(&TraceRecord::Actuation(a))?;
        }
        self.center.write(&TraceRecord::Center(rec.center))?;
        Ok(())
    }

    fn flush(mut self) -> Result<()> {
        for (_, w) in &mut self.agents {
            w.flush()?;
        }
        self.attacker.flush()?;
        self.center.flush()?;
        Ok(())
    }
}

/// How a run runs and what it keeps: the progress bar, the processes' placement, the traces the
/// run directory keeps, the stop that interrupts it, its live server and its pace.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// Told the run's ticks (a bar on the command line).
    pub progress: Observer,
    pub placement: runtime::Placement,
    pub traces: Traces,
    pub stop: Stop,
    /// Serve the run live (`--live`).
    pub live: Option<LiveServe>,
    /// A lockstep run slowed to this factor of real time (`--pace`).
    pub pace: Option<f64>,
}

/// Where and how fast a run is served live (`run --live ADDR --live-rate HZ`).
#[derive(Debug, Clone, PartialEq)]
pub struct LiveServe {
    pub addr: std::net::SocketAddr,
    pub rate_hz: f64,
    /// Start the run once a viewer subscribed, waiting at most this long (`--live-wait`).
    pub wait: Option<std::time::Duration>,
}

impl LiveServe {
    /// `--live=ADDR --live-rate HZ --live-wait SECONDS`, each checked.
    pub fn new(addr: std::net::SocketAddr, rate_hz: f64, wait_s: Option<f64>) -> Result<Self> {
        if !(rate_hz.is_finite() && rate_hz > 0.0) {
            bail!("--live-rate {rate_hz}: ticks a second, finite and > 0");
        }
        let wait = match wait_s {
            Some(w) => Some(std::time::Duration::try_from_secs_f64(w).map_err(|_| {
                anyhow::anyhow!("--live-wait {w}: a number of seconds, finite and ≥ 0")
            })?),
            None => None,
        };
        Ok(Self {
            addr,
            rate_hz,
            wait,
        })
    }

    /// The live server's options for a run of `r` on `engine` at `pace`.
    fn options(&self, r: &Resolved, engine: Engine, pace: Option<f64>) -> fdi_live::Options {
        let s = &r.scenario;
        let realtime = s.clock == ClockMode::Realtime;
        let ticks_per_s = if realtime { Some(1.0) } else { pace }.map(|p| p / s.control_period_s);
        fdi_live::Options {
            addr: self.addr,
            rate_hz: self.rate_hz,
            ticks_per_s,
            stamped: realtime && engine == Engine::Ipc,
        }
    }
}

/// The live server of a run of `r` on `engine` when `opts` asks for one, started, its address
/// said on stderr.
fn start_live(
    r: &Resolved,
    engine: Engine,
    opts: &Options,
) -> Result<Option<(fdi_live::Live, fdi_live::Feed)>, RunError> {
    let Some(l) = &opts.live else {
        return Ok(None);
    };
    let (live, feed) = fdi_live::Live::start(r, &l.options(r, engine, opts.pace))
        .map_err(RunError::not_started)?;
    log::info!(
        "live at ws://{} (Foxglove: Open connection, Foxglove WebSocket; layouts in \
         examples/live)",
        live.addr()
    );
    if let Some(wait) = l.wait {
        log::info!(
            "waiting for a viewer to subscribe (at most {} s)",
            wait.as_secs_f64()
        );
        if !live.wait_for_viewer(wait, &opts.stop) {
            log::info!(
                "no viewer subscribed within {} s: the run starts",
                wait.as_secs_f64()
            );
        }
    }
    Ok(Some((live, feed)))
}

/// Refuses a pace that is not a positive finite factor, or a pace of a realtime run.
pub fn check_pace(r: &Resolved, pace: Option<f64>) -> Result<()> {
    let Some(p) = pace else { return Ok(()) };
    if !(p.is_finite() && p > 0.0) {
        bail!("--pace {p}: a factor of real time, finite and > 0 (1 = real time)");
    }
    if r.scenario.clock != ClockMode::Lockstep {
        bail!("--pace {p}: a realtime run runs at real time already; --pace slows lockstep runs");
    }
    Ok(())
}

/// Sleeps the in-process engine until each tick is due at its pace. Once `stop` is raised it
/// sleeps no more: the in-process engine cannot stop mid-run, so the rest of the run goes
/// unpaced and the launcher stops after it.
struct Pacer {
    start: std::time::Instant,
    factor: f64,
    dt: f64,
    last: Option<u64>,
    stop: Stop,
}

impl Pacer {
    /// How often a paced wait looks at the stop.
    const SLICE: std::time::Duration = std::time::Duration::from_millis(50);

    fn wait(&mut self, k: u64) {
        if self.last == Some(k) {
            return;
        }
        self.last = Some(k);
        let due = std::time::Duration::from_secs_f64(
            fdi_common::engine::tick_time(k, self.dt) / self.factor,
        );
        while let Some(left) = due.checked_sub(self.start.elapsed()) {
            if self.stop.pending().is_some() {
                return;
            }
            std::thread::sleep(left.min(Self::SLICE));
        }
    }
}

impl Options {
    /// No progress bar, default placement, `traces` kept, interrupted by `stop`.
    pub fn quiet(traces: Traces, stop: &Stop) -> Self {
        Self {
            progress: Observer::quiet(),
            placement: runtime::Placement::default(),
            traces,
            stop: stop.clone(),
            live: None,
            pace: None,
        }
    }
}

/// Refuses a scenario the in-process engine cannot run: a program in the attacker's or the
/// monitor's role, or a controller program in realtime (its deadlines are the control center
/// process's). A controller program in lockstep it asks itself
/// ([`runtime::with_controller_program`]).
fn inproc_runs(r: &Resolved) -> Result<()> {
    let roles = &r.scenario.roles;
    let taken: Vec<&str> = [
        ("[roles.attacker]", roles.attacker.is_some()),
        ("[roles.monitor]", roles.monitor.is_some()),
    ]
    .into_iter()
    .filter_map(|(name, taken)| taken.then_some(name))
    .collect();
    if !taken.is_empty() {
        bail!(
            "the in-process engine cannot run a program in the attacker's or the monitor's role \
             ({} of the scenario): run it with --engine ipc",
            taken.join(", ")
        );
    }
    if roles.controller.is_some() && r.scenario.clock == ClockMode::Realtime {
        bail!(
            "the in-process engine asks a controller program (`[roles.controller]`) in lockstep \
             only: a realtime run's deadlines are kept by the control center's process; run it \
             with --engine ipc, or `clock = \"lockstep\"`"
        );
    }
    Ok(())
}

/// Runs `r` on the in-process engine with `attacker` in place of the scenario's attack profile
/// ([`fdi_common::engine::run_inproc_any_with`]), into the run directory `dir`: the traces
/// `traces` says and `summary.json`, as [`execute`] writes them for an in-process run (which
/// is this with the profile's attacker).
pub fn execute_inproc_with<A: Attacker>(
    r: &Resolved,
    dir: &Path,
    traces: Traces,
    attacker: &mut A,
) -> Result<RunSummary, RunError> {
    let opts = Options {
        traces,
        ..Options::default()
    };
    execute_inproc_watched(r, dir, &opts, attacker)
}

/// [`execute_inproc_with`], served live and paced as `opts` says.
fn execute_inproc_watched<A: Attacker>(
    r: &Resolved,
    dir: &Path,
    opts: &Options,
    attacker: &mut A,
) -> Result<RunSummary, RunError> {
    inproc_runs(r)?;
    let traces = opts.traces;
    let kept = match traces {
        Traces::Full => Some(Kept::Full),
        Traces::Decimate(k) => Some(Kept::Decimate { every: k.get() }),
        Traces::None => None,
    };
    let writers = match kept {
        Some(kept) => Some(InprocTraces::create(dir, r, kept).map_err(RunError::not_started)?),
        None => None,
    };
    let (live, feed) = start_live(r, Engine::Inproc, opts)?.unzip();
    // With whole traces, a viewer's thread follows them (nothing is read while nobody
    // watches); otherwise the records go to the server as they are made.
    let (direct, followed) = match (traces, feed) {
        (Traces::Full, Some(feed)) => (None, Some(feed)),
        (_, feed) => (feed, None),
    };
    let mut pacer = opts.pace.map(|factor| Pacer {
        start: std::time::Instant::now(),
        factor,
        dt: r.scenario.control_period_s,
        last: None,
        stop: opts.stop.clone(),
    });
    let stop = &opts.stop;
    let run = || -> Result<_> {
        let mut records = RecordThread::start(Books::new(r), writers, direct)?;
        let (ticked, note) = {
            let sink = |rec: &TickRecord| {
                if let Some(p) = &mut pacer {
                    p.wait(rec.center.k);
                }
                records.push(rec);
            };
            // An interrupt stops the engine before its next tick; what it ran is kept.
            let go_on = || stop.pending().is_none();
            let engine = "in-process engine";
            match &r.scenario.roles.controller {
                None => (
                    tick_inproc_any_with(r, attacker, sink, go_on).context(engine)?,
                    None,
                ),
                // A program decides the torques: asked over shared memory, as the control
                // center asks it; its closing note goes into the control center's trace.
                Some(_) => {
                    let (ticked, note) = runtime::with_controller_program(r, dir, stop, |asker| {
                        tick_inproc_asking(r, (attacker, asker), sink, go_on).context(engine)
                    })?;
                    (ticked, Some((r.scenario.duration_s, note)))
                }
            }
        };
        // The run ends when its records are entered and written: the wait for that counts.
        let waited = std::time::Instant::now();
        let books = records.finish(note)?;
        Ok((ticked, books, waited.elapsed().as_secs_f64()))
    };
    let (ticked, books, waited) = match (&live, followed) {
        (Some(live), Some(feed)) => run_followed(
            (r, Engine::Inproc),
            (dir, None),
            &opts.stop,
            (live, feed),
            run,
        ),
        _ => run(),
    }?;
    let wall_s = ticked.wall_s + waited;
    let mut summary = books.summary(r, ticked.ticks, wall_s, attacker.name());
    summary.live = live.map(fdi_live::Live::finish);
    if ticked.ticks < r.ticks() {
        if let Some(signal) = stop.take() {
            interrupted(&mut summary, r, signal, "the in-process engine stopped");
        }
    }
    output::write_run_summary(&RunDir::new(dir), &summary, traces)?;
    Ok(summary)
}

/// Marks `s` as a run interrupted by `signal` after its start (`how`: what was stopped), and
/// says so on stderr: the run directory keeps what was recorded, its metrics cover it.
fn interrupted(s: &mut RunSummary, r: &Resolved, signal: i32, how: &str) {
    log::info!(
        "interrupted by {} after {:.3} s of {} s simulated: {how}; the run directory keeps what was recorded",
        runtime::signal_name(signal),
        s.sim_s,
        r.scenario.duration_s,
    );
    s.partial = Some(Partial {
        reason: format!("interrupted by {}", runtime::signal_name(signal)),
        planned_ticks: r.ticks(),
        signal: Some(signal),
    });
}

/// The records of an in-process run entered in its books (digest, metrics) and written to its
/// traces on a thread of their own: the engine hands them over in batches and ticks on (the
/// books and the traces took two fifths of the engine's thread). At most
/// [`RecordThread::QUEUED`] batches wait, so memory stays bounded when the disk is slower than
/// the engine. A write error stops the writing (the books go on); the run goes on to its end,
/// as it did when it wrote the traces itself, and [`RecordThread::finish`] reports it.
struct RecordThread {
    batch: Vec<TickRecord>,
    to_thread: std::sync::mpsc::SyncSender<Vec<TickRecord>>,
    /// The thread's emptied batches, filled again (fresh ones cost a page fault per page).
    emptied: std::sync::mpsc::Receiver<Vec<TickRecord>>,
    /// The closing note of the control center's trace.
    note: std::sync::mpsc::Sender<(f64, String)>,
    thread: std::thread::JoinHandle<(Books, Result<()>)>,
}

impl RecordThread {
    /// Records per batch.
    const BATCH: usize = 1024;
    /// Batches that may wait for the thread.
    const QUEUED: usize = 4;

    fn start(
        mut books: Books,
        mut traces: Option<InprocTraces>,
        mut live: Option<fdi_live::Feed>,
    ) -> Result<Self> {
        let (to_thread, batches) = std::sync::mpsc::sync_channel::<Vec<TickRecord>>(Self::QUEUED);
        let (give_back, emptied) = std::sync::mpsc::sync_channel(Self::QUEUED + 1);
        let (note, noted) = std::sync::mpsc::channel::<(f64, String)>();
        let thread = std::thread::Builder::new()
            .name("records".into())
            .spawn(move || {
                let mut written = Ok(());
                for mut batch in batches {
                    for rec in &batch {
                        books.push(rec);
                        if let (Some(w), Ok(())) = (&mut traces, &written) {
                            written = w.write(rec);
                        }
                        if let Some(feed) = &mut live {
                            feed.tick(rec);
                        }
                    }
                    batch.clear();
                    // Never waits: a batch that finds no room is dropped.
                    let _ = give_back.try_send(batch);
                }
                if let (Some(w), Ok(())) = (&mut traces, &written) {
                    if let Ok((t, message)) = noted.try_recv() {
                        written = w
                            .center
                            .write(&TraceRecord::Event { t, message })
                            .map_err(Into::into);
                    }
                }
                if let (Some(w), Ok(())) = (traces, &written) {
                    written = w.flush();
                }
                drop(live);
                (books, written)
            })
            .context("starting the thread that keeps the run's records")?;
        Ok(Self {
            batch: Vec::with_capacity(Self::BATCH),
            to_thread,
            emptied,
            note,
            thread,
        })
    }

    fn push(&mut self, rec: &TickRecord) {
        self.batch.push(*rec);
        if self.batch.len() >= Self::BATCH {
            self.send();
        }
    }

    fn send(&mut self) {
        let next = self
            .emptied
            .try_recv()
            .unwrap_or_else(|_| Vec::with_capacity(Self::BATCH));
        let batch = std::mem::replace(&mut self.batch, next);
        // The thread takes every batch until `finish` (it stops only by panicking, which
        // `finish` reports).
        let _ = self.to_thread.send(batch);
    }

    /// Hands over the last records and `note` (a closing note at a time, s, for the control
    /// center's trace), waits for the thread to enter, write and flush them all, and returns
    /// the books, or the first write error.
    fn finish(mut self, note: Option<(f64, String)>) -> Result<Books> {
        if !self.batch.is_empty() {
            self.send();
        }
        if let Some(note) = note {
            // The thread reads it once the batches end, after this send.
            let _ = self.note.send(note);
        }
        drop(self.to_thread);
        let (books, written) = self
            .thread
            .join()
            .map_err(|_| anyhow::anyhow!("the thread that keeps the run's records panicked"))?;
        written?;
        Ok(books)
    }
}

/// Runs a resolved scenario on an engine. With `run_dir`, traces and the summary go there; an
/// ipc run without one uses a scratch folder under the system's temporary directory that keeps
/// no traces and is removed at the end. `opts.traces` says what of the traces the run directory
/// keeps.
pub fn execute(
    r: &Resolved,
    engine: Engine,
    run_dir: Option<&Path>,
    opts: &Options,
) -> Result<RunSummary, RunError> {
    execute_on(r, engine, run_dir, opts, None)
}

/// [`execute`], the run split over the hosts of `split` (`--hosts FILE`, the ipc engine
/// with full traces only).
pub fn execute_on(
    r: &Resolved,
    engine: Engine,
    run_dir: Option<&Path>,
    opts: &Options,
    split: Option<&Arc<dyn split::Split>>,
) -> Result<RunSummary, RunError> {
    let traces = opts.traces;
    if split.is_some() && (engine != Engine::Ipc || run_dir.is_none() || traces != Traces::Full) {
        return Err(anyhow::anyhow!(
            "a run split over hosts (--hosts) needs the ipc engine and full traces (the remote \
             traces are fetched whole at the end)"
        )
        .into());
    }
    check_pace(r, opts.pace)?;
    if engine == Engine::Inproc {
        inproc_runs(r)?;
    }
    match (engine, run_dir) {
        (Engine::Inproc, None) if r.scenario.roles.controller.is_none() => {
            let stop = &opts.stop;
            let mut attacker = r.profile_attacker();
            let mut s = run_inproc_any_until(r, &mut attacker, |_| {}, || stop.pending().is_none())
                .context("in-process engine")?;
            if s.ticks < r.ticks() {
                if let Some(signal) = stop.take() {
                    interrupted(&mut s, r, signal, "the in-process engine stopped");
                }
            }
            Ok(s)
        }
        (Engine::Inproc, Some(dir)) => {
            execute_inproc_watched(r, dir, opts, &mut r.profile_attacker())
        }
        (_, None) => {
            // The processes, and a program that takes a role, need a folder of their own (the
            // scenario as used, their pipes): a scratch run directory that keeps no traces,
            // removed after the run.
            let scratch =
                crate::run_dirs::create_run_dir(&std::env::temp_dir().join("fdi-mas-runs"), r)?;
            let scratch_opts = Options {
                traces: Traces::None,
                ..opts.clone()
            };
            // (A run without a directory has no viewer: campaigns, benchmarks.)
            let summary = execute(r, engine, Some(&scratch), &scratch_opts);
            if let Err(e) = std::fs::remove_dir_all(&scratch) {
                log::warn!(
                    "the scratch run directory {} could not be removed: {e}",
                    scratch.display()
                );
            }
            summary
        }
        (Engine::Ipc, Some(dir)) => execute_ipc(r, dir, opts, split),
    }
}

/// [`execute_on`] on the ipc engine into the run directory `dir`.
fn execute_ipc(
    r: &Resolved,
    dir: &Path,
    opts: &Options,
    split: Option<&Arc<dyn split::Split>>,
) -> Result<RunSummary, RunError> {
    let (progress, placement, traces) = (opts.progress.clone(), &opts.placement, opts.traces);
    let (live, feed) = start_live(r, Engine::Ipc, opts)?.unzip();
    let opts = runtime::IpcOptions {
        run_dir: dir.to_path_buf(),
        progress,
        replay: false,
        placement: placement.clone(),
        pipes: traces != Traces::Full,
        split: split.cloned(),
        stop: opts.stop.clone(),
        pace: opts.pace,
        remote_traces: (live.is_some() && split.is_some()).then(Default::default),
    };
    let (outcome, mut joined, write_error) = if !opts.pipes {
        let outcome = run_ipc_followed(r, &opts, live.as_ref().zip(feed))?;
        let joined = fdi_report::join::join_run(r, &RunDir::new(dir), outcome.wall_s, |_| {})?;
        (outcome, joined, None)
    } else {
        // Joined online: the processes write into pipes, the launcher keeps what
        // `traces` says.
        std::fs::create_dir_all(RunDir::new(dir).traces())
            .context("creating the traces folder")
            .map_err(RunError::not_started)?;
        let tap = tap::Tap::create(r, dir, traces).map_err(RunError::not_started)?;
        let (outcome, tapped) = tap.run(r, feed, || runtime::run_ipc(r, &opts));
        let outcome = outcome?;
        let joined = tapped
            .walked
            .context("joining the processes' records")?
            .summarize(r, outcome.wall_s);
        (outcome, joined, tapped.write_error)
    };
    joined.summary.lost_agents = outcome.lost;
    joined.summary.live = live.map(fdi_live::Live::finish);
    joined.summary.hosts = outcome.hosts;
    joined.summary.network = outcome.network;
    if let Some(signal) = outcome.interrupted {
        let how = format!("every process was stopped ({})", outcome.exits);
        interrupted(&mut joined.summary, r, signal, &how);
    }
    if *placement != runtime::Placement::default() {
        joined.summary.placement = Some(placement.describe());
    }
    for w in &joined.warnings {
        log::warn!("{w}");
    }
    if !outcome.leftovers.is_empty() {
        log::warn!(
            "{} shared-memory files of run {} could not be removed",
            outcome.leftovers.len(),
            outcome.prefix
        );
    }
    output::write_run_summary(&RunDir::new(dir), &joined.summary, traces)?;
    if let Some(e) = write_error {
        return Err(anyhow::anyhow!(
            "a trace could not be kept: {e}; summary.json covers every tick of the run"
        )
        .into());
    }
    Ok(joined.summary)
}

/// [`runtime::run_ipc`], its traces followed into a live server when there is one.
fn run_ipc_followed(
    r: &Resolved,
    opts: &runtime::IpcOptions,
    live: Option<(&fdi_live::Live, fdi_live::Feed)>,
) -> Result<runtime::IpcOutcome, RunError> {
    match live {
        Some(live) => run_followed(
            (r, Engine::Ipc),
            (&opts.run_dir, opts.remote_traces.as_ref()),
            &opts.stop,
            live,
            || runtime::run_ipc(r, opts),
        ),
        None => runtime::run_ipc(r, opts),
    }
}

/// Runs `run` (which writes the traces of a run of `r` into `run_dir`) with a thread that
/// follows those traces into the live server's `feed` once a viewer subscribed ([`follow`]).
fn run_followed<T>(
    (r, engine): (&Resolved, Engine),
    (run_dir, remote): (&Path, Option<&follow::RemoteSlot>),
    stop: &Stop,
    (live, feed): (&fdi_live::Live, fdi_live::Feed),
    run: impl FnOnce() -> T,
) -> T {
    let actuation = engine == Engine::Ipc;
    let over = std::sync::Arc::new(follow::Over::default());
    let watcher = live.watcher();
    std::thread::scope(|s| {
        let follower = std::thread::Builder::new()
            .name("live-follow".into())
            .spawn_scoped(s, || {
                follow::Traces::new(run_dir, remote, &over)
                    .and_then(|t| follow::follow_run(r, &t, (feed, &watcher), actuation, stop))
            });
        if let Err(e) = &follower {
            log::warn!("the live view could not start its thread: {e}");
        }
        let result = run();
        over.set();
        match follower.map(std::thread::ScopedJoinHandle::join) {
            Ok(Ok(Ok(()))) | Err(_) => {}
            Ok(Ok(Err(e))) => log::warn!("the live view stopped: {e:#}"),
            Ok(Err(_)) => log::warn!("the live view's thread panicked"),
        }
        result
    })
}

/// Validates a scenario after command-line overrides (duration, seed, attack, ...) changed
/// it: every problem with its field path, named as the command line's.
pub fn check_overrides(r: Resolved) -> Result<Resolved> {
    Ok(fdi_common::overrides::validated(r)?)
}

/// Refuses `--rt-priority` / `--cpus` where they do not apply or are not permitted, before
/// anything starts (and before a run directory exists).
pub fn check_placement(r: &Resolved, engine: Engine, placement: &runtime::Placement) -> Result<()> {
    if *placement == runtime::Placement::default() {
        return Ok(());
    }
    if engine != Engine::Ipc {
        bail!("--rt-priority and --cpus place the processes of the ipc engine only");
    }
    if let Some(priority) = placement.rt_priority {
        if r.scenario.clock != ClockMode::Realtime {
            bail!(
                "--rt-priority {priority} applies to realtime runs only (lockstep processes \
                 spin before they block: under SCHED_FIFO a spinning process would starve \
                 everything else on its CPU)"
            );
        }
    }
    placement.check().map_err(anyhow::Error::msg)
}

/// Refuses a summary that covers less than its scenario: tables and benchmarks need whole
/// runs.
pub fn require_whole(summary: RunSummary) -> Result<RunSummary> {
    match &summary.partial {
        Some(Partial {
            signal: Some(signal),
            ..
        }) => Err(Interrupted {
            signal: *signal,
            phase: DURING_THE_RUN,
        }
        .into()),
        Some(p) => bail!(
            "the run ended early ({}): {} of {} ticks",
            p.reason,
            summary.ticks,
            p.planned_ticks
        ),
        None => Ok(summary),
    }
}
