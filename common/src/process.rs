//! What every runtime process shares around its main loop: arguments from the launcher,
//! shutdown on SIGINT/SIGTERM or on the launcher's death, the start handshake and status reports.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::ipc::{Bell, ControlMsg, Inbox, IpcError, Outbox, Role, StatusMsg, Waker};

/// Arguments the launcher passes to every process.
#[derive(Debug, Clone, clap::Args)]
pub struct ProcessArgs {
    /// Run prefix (iceoryx2 `global.prefix`): isolates this run's services.
    #[arg(long)]
    pub prefix: String,
    /// Resolved scenario file of the run.
    #[arg(long)]
    pub scenario: PathBuf,
    /// Trace file this process writes.
    #[arg(long)]
    pub trace: PathBuf,
    /// Agent id (agents only).
    #[arg(long)]
    pub agent: Option<u32>,
    /// Pid of the launcher: the process stops when it dies.
    #[arg(long)]
    pub launcher_pid: Option<u32>,
}

/// Set when the process must stop: SIGINT, SIGTERM, or the launcher died.
#[derive(Debug, Clone)]
pub struct Shutdown {
    flag: Arc<AtomicBool>,
    launcher_pid: Option<u32>,
}

impl Shutdown {
    /// Registers SIGINT/SIGTERM handlers that only set a flag, and asks the kernel to send
    /// SIGTERM when the parent dies.
    pub fn install(launcher_pid: Option<u32>) -> std::io::Result<Self> {
        let flag = Arc::new(AtomicBool::new(false));
        signal_hook::flag::register(signal_hook::consts::SIGTERM, Arc::clone(&flag))?;
        signal_hook::flag::register(signal_hook::consts::SIGINT, Arc::clone(&flag))?;
        if launcher_pid.is_some() {
            rustix::process::set_parent_process_death_signal(Some(rustix::process::Signal::TERM))
                .map_err(std::io::Error::from)?;
        }
        Ok(Self { flag, launcher_pid })
    }

    /// A handle that is never triggered by signals (tests, in-process use).
    pub fn manual() -> Self {
        Self {
            flag: Arc::new(AtomicBool::new(false)),
            launcher_pid: None,
        }
    }

    pub fn request(&self) {
        self.flag.store(true, Ordering::SeqCst);
    }

    /// True once a stop was requested or the launcher is gone.
    pub fn requested(&self) -> bool {
        if self.flag.load(Ordering::Relaxed) {
            return true;
        }
        if let Some(pid) = self.launcher_pid {
            let parent = rustix::process::getppid().map(|p| p.as_raw_nonzero().get());
            if parent != i32::try_from(pid).ok() {
                self.request();
                return true;
            }
        }
        false
    }
}

/// How long a process waits for the launcher's start before giving up.
pub const START_TIMEOUT: Duration = Duration::from_secs(60);
/// Longest single block on a wake-up event; shutdown is checked at least this often.
pub const WAIT_SLICE: Duration = Duration::from_millis(50);

/// Why a process stopped early.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    #[error(transparent)]
    Ipc(#[from] IpcError),
    #[error("no start from the launcher within {0:?}")]
    NoStart(Duration),
    #[error("stopped by the launcher before the start")]
    StoppedBeforeStart,
}

/// Outcome of waiting for the start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Start {
    /// Go; sim time zero is this CLOCK_MONOTONIC instant, ns.
    Go { epoch_ns: u64 },
    /// A signal or the launcher's death arrived first.
    Shutdown,
}

/// The process's link to the launcher.
#[derive(Debug)]
pub struct LauncherLink {
    pub role: Role,
    pub agent: u32,
    pub control: Inbox<ControlMsg>,
    pub status: Outbox<StatusMsg>,
    pub bell: Bell,
}

impl LauncherLink {
    pub fn report(&self, kind: u32, tick: u64) -> Result<(), IpcError> {
        self.status.send(StatusMsg {
            role: self.role.code(),
            agent: self.agent,
            kind,
            reserved: 0,
            tick,
        })?;
        self.bell.ring()
    }

    /// True when the launcher has sent a stop.
    pub fn stop_requested(&self) -> Result<bool, IpcError> {
        let mut stop = false;
        self.control
            .drain(|m| stop |= m.command == ControlMsg::STOP)?;
        Ok(stop)
    }

    /// Reports ready, then blocks on `waker` until the launcher's start.
    pub fn ready_and_wait_start(
        &self,
        waker: &Waker,
        shutdown: &Shutdown,
    ) -> Result<Start, ProcessError> {
        self.report(StatusMsg::READY, 0)?;
        let began = Instant::now();
        loop {
            let mut start = None;
            let mut stop = false;
            self.control.drain(|m| match m.command {
                ControlMsg::START => start = Some(m.epoch_ns),
                ControlMsg::STOP => stop = true,
                _ => {}
            })?;
            if stop {
                return Err(ProcessError::StoppedBeforeStart);
            }
            if let Some(epoch_ns) = start {
                return Ok(Start::Go { epoch_ns });
            }
            if shutdown.requested() {
                return Ok(Start::Shutdown);
            }
            if began.elapsed() > START_TIMEOUT {
                return Err(ProcessError::NoStart(START_TIMEOUT));
            }
            waker.wait(WAIT_SLICE)?;
        }
    }
}

/// Everything a process opens on the transport at start-up.
#[derive(Debug)]
pub struct Connection {
    pub transport: crate::ipc::Transport,
    pub launcher: LauncherLink,
    /// This process's own wake-up event.
    pub waker: Waker,
}

/// Opens the node, the launcher link and this process's waker.
pub fn connect(
    args: &ProcessArgs,
    role: Role,
    wake: crate::ipc::Wake,
    sizing: crate::ipc::Sizing,
) -> Result<Connection, IpcError> {
    use crate::ipc::{Stream, Transport, Wake};
    let name = match wake {
        Wake::Agent(id) => format!("agent-{id}"),
        Wake::Attacker => "attacker".into(),
        Wake::Center => "control-center".into(),
        Wake::Launcher => "launcher".into(),
    };
    let transport = Transport::open(&args.prefix, &name, sizing)?;
    let launcher = LauncherLink {
        role,
        agent: args.agent.unwrap_or(0),
        control: transport.subscriber(Stream::Control)?,
        status: transport.publisher(Stream::Status)?,
        bell: transport.notifier(Wake::Launcher)?,
    };
    let waker = transport.waker(wake)?;
    Ok(Connection {
        transport,
        launcher,
        waker,
    })
}

/// Sizing of a run's services: every process computes the same from the scenario.
pub fn sizing_for(resolved: &crate::scenario::Resolved) -> crate::ipc::Sizing {
    crate::ipc::Sizing {
        agents: resolved.agent_count(),
        in_flight: 1,
    }
}

/// Header of the trace a process writes.
pub fn trace_header(
    process: &str,
    resolved: &crate::scenario::Resolved,
) -> crate::trace::TraceHeader {
    crate::trace::TraceHeader {
        format_version: crate::trace::FORMAT_VERSION,
        process: process.into(),
        scenario_toml: resolved.to_toml(),
        seed: resolved.scenario.seed,
        clock: resolved.scenario.clock.as_str().into(),
    }
}
