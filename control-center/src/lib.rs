//! The control-center process: one [`CenterAgent`] per agent, fed by the attacker's (tampered)
//! measurements; each torque goes back to its agent stamped with its tick time. Purely
//! event-driven: every agent's tick is computed as soon as its measurement arrives (agents are
//! independent, so the result does not depend on the order in which agents arrive).

use std::process::ExitCode;

use fdi_common::control::{CenterAgent, CenterParams};
use fdi_common::engine::{center_record, tick_time};
use fdi_common::ipc::msg::{check_header, from_vector, to_vector};
use fdi_common::ipc::{
    monotonic_ns, Bell, Inbox, MeasurementMsg, Outbox, Role, StatusMsg, Stream, TorqueMsg, Wake,
};
use fdi_common::process::{
    self, LauncherLink, ProcessArgs, ProcessError, Shutdown, Start, WAIT_SLICE,
};
use fdi_common::scenario::{self, Resolved};
use fdi_common::trace::{TraceError, TraceRecord, TraceWriter};

#[derive(Debug, thiserror::Error)]
pub enum CenterError {
    #[error(transparent)]
    Process(#[from] ProcessError),
    #[error(transparent)]
    Ipc(#[from] fdi_common::ipc::IpcError),
    #[error(transparent)]
    Trace(#[from] TraceError),
    #[error(transparent)]
    Scenario(#[from] scenario::ScenarioError),
    #[error("agent {0}: its model does not have 2 links")]
    Dof(u32),
    #[error("installing signal handlers: {0}")]
    Signals(std::io::Error),
}

/// Ports towards one agent.
#[derive(Debug)]
pub struct AgentLink {
    pub torque: Outbox<TorqueMsg>,
    pub bell: Bell,
}

/// The control center's ports.
#[derive(Debug)]
pub struct Ports {
    pub tampered: Inbox<MeasurementMsg>,
    /// In the scenario's agent order.
    pub agents: Vec<AgentLink>,
    pub waker: fdi_common::ipc::Waker,
    pub launcher: LauncherLink,
    /// The node; declared last so that it is dropped after the ports.
    pub transport: fdi_common::ipc::Transport,
}

/// Ticks between two progress reports to the launcher.
const PROGRESS_EVERY: u64 = 500;

struct Slot {
    center: CenterAgent<2>,
    next: u64,
}

/// Controls every agent until their last tick (or `shutdown`).
pub fn run(
    resolved: &Resolved,
    ports: &Ports,
    shutdown: &Shutdown,
    trace: &mut TraceWriter,
) -> Result<u64, CenterError> {
    let s = &resolved.scenario;
    let mut slots = Vec::with_capacity(s.agents.len());
    for a in &s.agents {
        let center = CenterAgent::<2>::new(CenterParams::new(
            a,
            &s.controller,
            s.seed,
            s.control_period_s,
        ))
        .ok_or(CenterError::Dof(a.id))?;
        slots.push(Slot { center, next: 0 });
    }
    if let Start::Shutdown = ports
        .launcher
        .ready_and_wait_start(&ports.waker, shutdown)?
    {
        return Ok(0);
    }
    let ticks = resolved.ticks();
    let dt = s.control_period_s;
    let mut refused = 0u64;
    let mut failure = None;
    let mut reported = 0;
    loop {
        ports.tampered.drain(|m| {
            let received = monotonic_ns();
            let Some(i) = slots.iter().position(|x| x.center.agent_id() == m.agent) else {
                refused += 1;
                return;
            };
            let slot = &mut slots[i];
            if let Err(e) = check_header(m.agent, m.dof, m.seq, 2, |_| true, slot.next) {
                refused += 1;
                let _ = trace.write(&TraceRecord::Event {
                    t: tick_time(m.seq, dt),
                    message: e.to_string(),
                });
                if m.seq < slot.next {
                    return; // duplicate or replayed: dropped
                }
            }
            slot.next = m.seq + 1;
            let t = tick_time(m.seq, dt);
            let out = slot
                .center
                .tick(t, &to_vector::<2>(&m.y), &to_vector::<2>(&m.yd));
            let link = &ports.agents[i];
            let msg = TorqueMsg {
                seq: m.seq,
                agent: m.agent,
                dof: 2,
                t_send: t,
                u: from_vector(&out.u),
                agent_sent_ns: m.agent_sent_ns,
                attacker_sent_ns: m.attacker_sent_ns,
                center_received_ns: received,
                center_sent_ns: monotonic_ns(),
            };
            if let Err(e) = link.torque.send(msg).and_then(|_| link.bell.ring()) {
                failure.get_or_insert(CenterError::from(e));
            }
            if let Err(e) = trace.write(&TraceRecord::Center(center_record(m.seq, m.agent, &out))) {
                failure.get_or_insert(CenterError::from(e));
            }
        })?;
        if let Some(e) = failure.take() {
            return Err(e);
        }
        let done = slots.iter().map(|x| x.next).min().unwrap_or(ticks);
        if done >= reported + PROGRESS_EVERY || done >= ticks {
            reported = done;
            ports.launcher.report(StatusMsg::PROGRESS, done)?;
        }
        if done >= ticks {
            break;
        }
        if shutdown.requested() || ports.launcher.stop_requested()? {
            return Ok(refused);
        }
        ports.waker.wait(WAIT_SLICE)?;
    }
    let rejected: u64 = slots.iter().map(|x| x.center.rejected_inputs).sum();
    if refused > 0 || rejected > 0 {
        trace.write(&TraceRecord::Event { t: s.duration_s, message: format!("{refused} messages refused, {rejected} measurements rejected as non-finite or absurd") })?;
    }
    trace.flush()?;
    ports.launcher.report(StatusMsg::DONE, ticks)?;
    Ok(refused)
}

fn open(args: &ProcessArgs) -> Result<(Resolved, Ports, TraceWriter, Shutdown), CenterError> {
    let shutdown = Shutdown::install(args.launcher_pid).map_err(CenterError::Signals)?;
    let resolved = scenario::load_file(&args.scenario)?;
    let conn = process::connect(
        args,
        Role::Center,
        Wake::Center,
        process::sizing_for(&resolved),
    )?;
    let mut agents = Vec::with_capacity(resolved.agent_count());
    for a in &resolved.scenario.agents {
        agents.push(AgentLink {
            torque: conn.transport.publisher(Stream::Torque(a.id))?,
            bell: conn.transport.notifier(Wake::Agent(a.id))?,
        });
    }
    let ports = Ports {
        tampered: conn.transport.subscriber(Stream::Tampered)?,
        agents,
        waker: conn.waker,
        launcher: conn.launcher,
        transport: conn.transport,
    };
    let trace = TraceWriter::create(
        &args.trace,
        &process::trace_header("control-center", &resolved),
    )?;
    Ok((resolved, ports, trace, shutdown))
}

/// Entry point of the `fdi-control-center` binary.
pub fn main_with(args: ProcessArgs) -> ExitCode {
    match open(&args).and_then(|(resolved, ports, mut trace, shutdown)| {
        run(&resolved, &ports, &shutdown, &mut trace)
    }) {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("fdi-control-center: {e}");
            ExitCode::FAILURE
        }
    }
}
