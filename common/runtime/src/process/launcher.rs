//! The link to the launcher: opening the transport, the start handshake, status reports.

use std::time::Instant;

use super::{ProcessArgs, ProcessError, RoleError, Shutdown, START_TIMEOUT, WAIT_SLICE};
use crate::ipc::{Bell, ControlMsg, Inbox, IpcError, Outbox, Role, StatusMsg, Waker};

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

    /// Tells the launcher that `agent`, declared lost, is heard from again at `tick`.
    pub fn report_rejoined(&self, agent: u32, tick: u64) -> Result<(), IpcError> {
        self.status.send(StatusMsg {
            role: self.role.code(),
            agent,
            kind: StatusMsg::REJOINED,
            reserved: 0,
            tick,
        })?;
        self.bell.ring()
    }

    /// Tells the launcher that `agent` was declared lost after `tick`.
    pub fn report_lost(&self, agent: u32, tick: u64) -> Result<(), IpcError> {
        self.status.send(StatusMsg {
            role: self.role.code(),
            agent,
            kind: StatusMsg::LOST,
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

/// The start-up every process shell shares: SIGINT/SIGTERM and parent-death handling, the
/// run's scenario, and the transport with its launcher link and waker.
pub fn start(
    args: &ProcessArgs,
    role: Role,
    wake: crate::ipc::Wake,
) -> Result<(Shutdown, fdi_common::scenario::Resolved, Connection), RoleError> {
    let shutdown = Shutdown::install(args.launcher_pid).map_err(RoleError::Signals)?;
    args.placement.apply().map_err(RoleError::Scheduling)?;
    let resolved = fdi_common::scenario::load_file(&args.scenario)?;
    let conn = connect(args, role, wake, sizing_for(&resolved))?;
    Ok((shutdown, resolved, conn))
}

/// Sizing of a run's services: every process computes the same from the scenario.
pub fn sizing_for(resolved: &fdi_common::scenario::Resolved) -> crate::ipc::Sizing {
    // Lookahead lets an agent run up to τ_max/Δ ticks ahead of its commands.
    let s = &resolved.scenario;
    let tau_max = s.agents.iter().map(|a| a.delay.max()).fold(0.0, f64::max);
    let ahead = (tau_max / s.control_period_s).ceil() as usize + 2;
    crate::ipc::Sizing {
        agents: resolved.agent_count(),
        in_flight: ahead,
    }
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
    }
}
