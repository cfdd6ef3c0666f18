//! The link to the launcher: opening the transport, the start handshake, status reports.

use fdi_common::run_dir::Process;
use std::time::Instant;

use super::args::ProcessArgs;
use super::error::{ProcessError, RoleError};
use super::shutdown::Shutdown;
use super::wait::{START_TIMEOUT, WAIT_SLICE};
use crate::ipc::{
    Bell as _, ControlMsg, Inbox as _, IpcError, Outbox as _, Role, Sizing, StatusMsg, Stream,
    Transport, Wake, Waker,
};

/// Longest hold of a finished role for the launcher's stop ([`LauncherLink::done_and_hold`]).
pub const HOLD_LIMIT: std::time::Duration = std::time::Duration::from_secs(30);

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
pub struct LauncherLink<X: Transport> {
    pub role: Role,
    pub agent: u32,
    pub control: X::Inbox<ControlMsg>,
    pub status: X::Outbox<StatusMsg>,
    pub bell: X::Bell,
}

impl<X: Transport> LauncherLink<X> {
    /// Reports `kind` (ready, progress, done) for this process at `tick`.
    pub fn report(&self, kind: u32, tick: u64) -> Result<(), IpcError> {
        self.status_of(self.agent, kind, tick)
    }

    /// Tells the launcher that `agent`, declared lost, is heard from again at `tick`.
    pub fn report_rejoined(&self, agent: u32, tick: u64) -> Result<(), IpcError> {
        self.status_of(agent, StatusMsg::REJOINED, tick)
    }

    /// Tells the launcher that `agent` was declared lost after `tick`.
    pub fn report_lost(&self, agent: u32, tick: u64) -> Result<(), IpcError> {
        self.status_of(agent, StatusMsg::LOST, tick)
    }

    fn status_of(&self, agent: u32, kind: u32, tick: u64) -> Result<(), IpcError> {
        self.status.send(StatusMsg {
            role: self.role.code(),
            agent,
            kind,
            reserved: 0,
            tick,
        })?;
        self.bell.ring()
    }

    /// Reports done after the role's last message, then keeps the process's ports open until
    /// the launcher's stop (it sends one once every process is done), a signal or the
    /// launcher's death, or [`HOLD_LIMIT`]: a message not yet read when its publisher goes away
    /// is lost, so a role that left at once could take its last messages with it while a peer
    /// still needs them.
    pub fn done_and_hold(
        &self,
        ticks: u64,
        waker: &impl Waker,
        shutdown: &Shutdown,
    ) -> Result<(), IpcError> {
        self.report(StatusMsg::DONE, ticks)?;
        let began = Instant::now();
        while !self.stop_requested()? && !shutdown.requested() && began.elapsed() < HOLD_LIMIT {
            waker.wait(WAIT_SLICE)?;
        }
        Ok(())
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
        waker: &impl Waker,
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

/// The end every role shares: `note` (what it refused, if anything) on record at `t_end`, its
/// trace flushed, then done reported and its ports held until the launcher's stop
/// ([`LauncherLink::done_and_hold`]).
pub fn finish<X: Transport>(
    trace: &mut fdi_common::trace::TraceWriter,
    note: Option<(f64, String)>,
    ticks: u64,
    conn: (&LauncherLink<X>, &X::Waker),
    shutdown: &Shutdown,
) -> Result<(), RoleError> {
    if let Some((t, message)) = note {
        trace.write(&fdi_common::trace::TraceRecord::Event { t, message })?;
    }
    trace.flush()?;
    conn.0.done_and_hold(ticks, conn.1, shutdown)?;
    Ok(())
}

/// Everything a process opens on the transport at start-up. Fields drop in order: the ports
/// before the node.
#[derive(Debug)]
pub struct Connection<X: Transport> {
    pub launcher: LauncherLink<X>,
    /// This process's own wake-up event.
    pub waker: X::Waker,
    pub transport: X,
}

/// The node name of the process behind `wake`.
pub fn node_name(wake: Wake) -> String {
    match wake {
        Wake::Agent(id) => Process::Agent(id).to_string(),
        Wake::Attacker => Process::Attacker.to_string(),
        Wake::Center => Process::Center.to_string(),
        Wake::Launcher => "launcher".into(),
        Wake::ExternalAttacker => "external-attacker".into(),
        Wake::Monitor => "monitor".into(),
        Wake::ExternalController => "external-controller".into(),
    }
}

/// Opens the node of the process behind `wake` in the run `prefix`, its launcher link and its
/// waker.
pub fn connect<X: Transport>(
    prefix: &str,
    role: Role,
    wake: Wake,
    sizing: Sizing,
) -> Result<Connection<X>, IpcError> {
    let transport = X::open(prefix, &node_name(wake), sizing)?;
    let launcher = LauncherLink {
        role,
        agent: match wake {
            Wake::Agent(id) => id,
            _ => 0,
        },
        control: transport.subscriber(Stream::Control)?,
        status: transport.publisher(Stream::Status)?,
        bell: transport.notifier(Wake::Launcher)?,
    };
    let waker = transport.waker(wake)?;
    Ok(Connection {
        launcher,
        waker,
        transport,
    })
}

/// The start-up every process shell shares: SIGINT/SIGTERM and parent-death handling, its
/// placement, and the run's scenario. The role then [`connect`]s.
pub fn start(args: &ProcessArgs) -> Result<(Shutdown, fdi_common::scenario::Resolved), RoleError> {
    let shutdown = Shutdown::install(args.launcher_pid).map_err(RoleError::Signals)?;
    args.placement.apply().map_err(RoleError::Scheduling)?;
    let resolved = fdi_common::scenario::load_written(&args.scenario)?;
    Ok((shutdown, resolved))
}

/// Sizing of a run's services: every process computes the same from the scenario.
pub fn sizing_for(resolved: &fdi_common::scenario::Resolved) -> Sizing {
    // Lookahead lets an agent run up to τ_max/Δ ticks ahead of its commands.
    let s = &resolved.scenario;
    let tau_max = s.agents.iter().map(|a| a.delay.max()).fold(0.0, f64::max);
    let ahead = (tau_max / s.control_period_s).ceil() as usize + 2;
    Sizing::new(resolved.agent_count(), ahead)
}

/// Header of the trace a process writes.
pub fn trace_header(
    process: &str,
    resolved: &fdi_common::scenario::Resolved,
) -> fdi_common::trace::TraceHeader {
    fdi_common::trace::TraceHeader {
        format_version: fdi_common::trace::FORMAT_VERSION,
        process: process.into(),
        scenario_toml: resolved.to_toml(),
        seed: resolved.scenario.seed,
        clock: resolved.scenario.clock.as_str().into(),
        // A process writes every record; the launcher decimates what it keeps
        // (`fdi-launch run --traces`) and says so in the header of the file it writes.
        kept: fdi_common::trace::Kept::Full,
    }
}
