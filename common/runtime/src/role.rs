//! One lifecycle for every role of a run (agent, attacker, control center, replayer), and the
//! process shell that drives it, written once.
//!
//! A role is opened (its ports on the run's transport), prepared for the run (each robot with
//! its own number of links; before it reports ready: a role that cannot run fails before the
//! start), begun at the
//! launcher's start, then turned and waited on until its part of the run is done, and ended
//! (what it says on record, its trace flushed, done reported, its ports held until the
//! launcher's stop). [`drive`] does this on any transport — shared memory between processes
//! ([`run_process`], what each role's binary runs), or in-process between threads (the tests) —
//! and checks the stop (a signal, the launcher's death or its stop message) between every turn
//! and wait, so no role writes its own loop around them.

use fdi_common::scenario::Resolved;
use fdi_common::trace::TraceWriter;

use crate::ipc::{self, Shm, Transport, Wake};
use crate::process::{self, Connection, ProcessArgs, RoleError, Shutdown, Start};

/// What a turn of a running role came to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Turn {
    /// It did what it could; it waits for more ([`Running::wait`]).
    Pending,
    /// Its part of the run is done.
    Done,
}

/// How a driven role ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    /// Its part of the run is done, on record, and the launcher let it go.
    Completed,
    /// Stopped before the end (a signal, the launcher's death or its stop).
    Stopped,
}

/// A role's process failed; its failure is said on stderr, naming the program (the launcher
/// relays it). The program exits with a failure status.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Failed;

/// What a role says at its end: the ticks it reports done with, and a note on record at `t`.
#[derive(Debug, Clone, PartialEq)]
pub struct End {
    pub ticks: u64,
    pub note: Option<(f64, String)>,
}

/// A role's ports and the connection every process has (its node, its launcher link and its
/// waker). The ports are dropped before the node.
#[derive(Debug)]
pub struct Opened<X: Transport, P> {
    pub ports: P,
    pub conn: Connection<X>,
}

/// One role of a run. Its ports are opened on a connection the shell makes
/// ([`Role::identity`]); its state over a run is [`Role::Running`] (a role whose state
/// depends on a robot's number of links picks it in [`Role::prepare`]: [`Boxed`]).
pub trait Role {
    /// Its own ports on the transport `X`.
    type Ports<X: Transport>;
    /// Its state over a run.
    type Running<'a, X: Transport + 'a>: Running
    where
        Self: 'a;

    /// Who it is on the transport: its kind in status messages, and its wake-up event.
    fn identity(&self) -> (ipc::Role, Wake);
    /// The program named in its failures (`fdi-agent 3`, `fdi-attacker`).
    fn program(&self) -> String;
    /// The process named in its trace's header (`agent-3`); `None`: it writes no trace (the
    /// replayer, whose `--trace` is the recording it reads).
    fn trace_name(&self) -> Option<String>;
    /// Opens its ports on the node `transport`.
    fn open<X: Transport>(
        &self,
        transport: &X,
        resolved: &Resolved,
    ) -> Result<Self::Ports<X>, RoleError>;
    /// Its state for the run, before it reports ready.
    fn prepare<'a, X: Transport + 'a>(
        &'a self,
        resolved: &'a Resolved,
        opened: &'a Opened<X, Self::Ports<X>>,
    ) -> Result<Self::Running<'a, X>, RoleError>;
}

/// A role over a run, from the launcher's start to its end.
pub trait Running {
    /// The run started at `epoch_ns` (CLOCK_MONOTONIC).
    fn begin(&mut self, epoch_ns: u64, trace: &mut TraceWriter) -> Result<(), RoleError>;
    /// Takes what arrived and does what it can without blocking.
    fn turn(&mut self, trace: &mut TraceWriter) -> Result<Turn, RoleError>;
    /// Blocks until something may have arrived, for a bounded time.
    fn wait(&mut self) -> Result<(), RoleError>;
    /// Once done: the ticks it reports done with, and its note on record.
    fn end(self, trace: &mut TraceWriter) -> Result<End, RoleError>;
}

/// A [`Running`] role whose type is chosen at run time (an agent's, by its robot's number of
/// links).
pub struct Boxed<'a>(Box<dyn BoxedRunning + 'a>);

impl<'a> Boxed<'a> {
    pub fn new(running: impl Running + 'a) -> Self {
        Self(Box::new(running))
    }
}

/// [`Running`] behind a box: its end takes the box.
trait BoxedRunning {
    fn begin(&mut self, epoch_ns: u64, trace: &mut TraceWriter) -> Result<(), RoleError>;
    fn turn(&mut self, trace: &mut TraceWriter) -> Result<Turn, RoleError>;
    fn wait(&mut self) -> Result<(), RoleError>;
    fn end(self: Box<Self>, trace: &mut TraceWriter) -> Result<End, RoleError>;
}

impl<R: Running> BoxedRunning for R {
    fn begin(&mut self, epoch_ns: u64, trace: &mut TraceWriter) -> Result<(), RoleError> {
        Running::begin(self, epoch_ns, trace)
    }
    fn turn(&mut self, trace: &mut TraceWriter) -> Result<Turn, RoleError> {
        Running::turn(self, trace)
    }
    fn wait(&mut self) -> Result<(), RoleError> {
        Running::wait(self)
    }
    fn end(self: Box<Self>, trace: &mut TraceWriter) -> Result<End, RoleError> {
        Running::end(*self, trace)
    }
}

impl Running for Boxed<'_> {
    fn begin(&mut self, epoch_ns: u64, trace: &mut TraceWriter) -> Result<(), RoleError> {
        self.0.begin(epoch_ns, trace)
    }
    fn turn(&mut self, trace: &mut TraceWriter) -> Result<Turn, RoleError> {
        self.0.turn(trace)
    }
    fn wait(&mut self) -> Result<(), RoleError> {
        self.0.wait()
    }
    fn end(self, trace: &mut TraceWriter) -> Result<End, RoleError> {
        self.0.end(trace)
    }
}

/// Connects `role` in the run `prefix` and opens its ports.
pub fn open<R: Role, X: Transport>(
    role: &R,
    prefix: &str,
    resolved: &Resolved,
) -> Result<Opened<X, R::Ports<X>>, RoleError> {
    let (kind, wake) = role.identity();
    let conn = process::connect(prefix, kind, wake, process::sizing_for(resolved))?;
    Ok(Opened {
        ports: role.open(&conn.transport, resolved)?,
        conn,
    })
}

/// Drives `role` over the run `resolved` on its opened `ports`: prepared, ready, begun at the
/// start, turned and waited on until done (the stop checked between each), ended.
pub fn drive<R: Role, X: Transport>(
    role: &R,
    resolved: &Resolved,
    opened: &Opened<X, R::Ports<X>>,
    shutdown: &Shutdown,
    trace: &mut TraceWriter,
) -> Result<Ended, RoleError> {
    let running = role.prepare::<X>(resolved, opened)?;
    drive_running(running, &opened.conn, shutdown, trace)
}

fn drive_running<X: Transport>(
    mut running: impl Running,
    Connection {
        launcher, waker, ..
    }: &Connection<X>,
    shutdown: &Shutdown,
    trace: &mut TraceWriter,
) -> Result<Ended, RoleError> {
    let epoch_ns = match launcher.ready_and_wait_start(waker, shutdown)? {
        Start::Go { epoch_ns } => epoch_ns,
        Start::Shutdown => return Ok(Ended::Stopped),
    };
    running.begin(epoch_ns, trace)?;
    loop {
        if running.turn(trace)? == Turn::Done {
            break;
        }
        if shutdown.requested() || launcher.stop_requested()? {
            return Ok(Ended::Stopped);
        }
        running.wait()?;
    }
    let End { ticks, note } = running.end(trace)?;
    process::finish(trace, note, ticks, (launcher, waker), shutdown)?;
    Ok(Ended::Completed)
}

/// The process shell of every role: SIGINT/SIGTERM and the launcher's death handled, placed
/// on its CPUs, the run's scenario read, its ports opened on shared memory, its trace created,
/// then [`drive`]n; a failure is printed on stderr (the launcher relays it) naming the program.
/// The program's `main` turns what it returns into its exit status.
pub fn run_process<R: Role>(role: &R, args: &ProcessArgs) -> Result<Ended, Failed> {
    let result = process::start(args).and_then(|(shutdown, resolved)| {
        let opened = open::<R, Shm>(role, &args.prefix, &resolved)?;
        let mut trace = match role.trace_name() {
            Some(name) => {
                TraceWriter::create(&args.trace, &process::trace_header(&name, &resolved))?
            }
            None => TraceWriter::discarding(),
        };
        drive(role, &resolved, &opened, &shutdown, &mut trace)
    });
    result.map_err(|e| {
        process::print_failure(format_args!("{}: {e}", role.program()));
        Failed
    })
}

/// The `main` of a role's binary, the same for every role: its command line (the program
/// `name`, a line `about` it, the [`ProcessArgs`]) parsed (a bad one said by clap, which exits),
/// then `run` (the role's [`run_process`]); success unless it [`Failed`].
#[cfg(feature = "clap")]
pub fn main(
    name: &'static str,
    about: &'static str,
    run: impl FnOnce(ProcessArgs) -> Result<Ended, Failed>,
) -> std::process::ExitCode {
    use clap::{Args as _, FromArgMatches as _};
    // (After the arguments: their struct's doc would stand as the program's `about`.)
    let matches = ProcessArgs::augment_args(clap::Command::new(name))
        .about(about)
        .get_matches();
    let args = ProcessArgs::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    match run(args) {
        Ok(_) => std::process::ExitCode::SUCCESS,
        Err(Failed) => std::process::ExitCode::FAILURE,
    }
}
