//! The agent process: a thin shell around [`fdi_common::plant::Plant`].
//!
//! Lockstep: publish measurement `k`, integrate `[t_k, t_{k+1}]` as soon as every command that
//! step looks up has arrived (with `τ > Δ` that is before torque `k` itself: lookahead), publish
//! `k + 1`, and so on. Realtime: at wall time `epoch + t_k` integrate `[t_{k−1}, t_k]` with
//! whatever commands have arrived (a command due but missing is a deadline miss: the last one is
//! held), then publish measurement `k`.

use std::process::ExitCode;
use std::time::Duration;

use fdi_common::engine::{agent_record, tick_time};
use fdi_common::model::{EulerLagrange, ForLinks, Vector};
use fdi_common::plant::{Measurement, Plant};
use fdi_common::scenario::{ClockMode, Resolved};
use fdi_common::trace::{HopStamps, TraceRecord, TraceWriter};
use fdi_runtime::ipc::msg::from_vector;
use fdi_runtime::ipc::{
    monotonic_ns, Bell as _, Inbox as _, MeasurementMsg, Outbox as _, Role, Shm, StatusMsg, Stream,
    TorqueMsg, Transport, Wake, Waker as _,
};
use fdi_runtime::process::{
    self, Connection, LauncherLink, ProcessArgs, Shutdown, Start, WaitStrategy, PROGRESS_EVERY,
    WAIT_SLICE,
};

/// Errors of the agent process.
pub type AgentError = fdi_runtime::process::RoleError;

/// The agent's ports.
#[derive(Debug)]
pub struct Ports<X: Transport> {
    pub measurement: X::Outbox<MeasurementMsg>,
    pub torque: X::Inbox<TorqueMsg>,
    pub attacker: X::Bell,
    pub waker: X::Waker,
    pub launcher: LauncherLink<X>,
    /// The node; declared last so that it is dropped after the ports.
    pub transport: X,
}

impl<X: Transport> Ports<X> {
    /// Opens agent `id`'s node in the run `prefix` and its ports.
    pub fn open(prefix: &str, id: u32, resolved: &Resolved) -> Result<Self, AgentError> {
        let conn: Connection<X> = process::connect(
            prefix,
            Role::Agent,
            Wake::Agent(id),
            process::sizing_for(resolved),
        )?;
        Ok(Self {
            measurement: conn.transport.publisher(Stream::Measurement)?,
            torque: conn.transport.subscriber(Stream::Torque(id))?,
            attacker: conn.transport.notifier(Wake::Attacker)?,
            waker: conn.waker,
            launcher: conn.launcher,
            transport: conn.transport,
        })
    }
}

/// How the run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    Completed { ticks: u64, deadline_misses: u64 },
    Stopped { ticks: u64 },
}

/// State of the torque stream.
#[derive(Debug)]
struct Inflow {
    /// Sequence number of the next torque due.
    next: u64,
    refused: u64,
    /// The run's tick count: no torque is numbered beyond.
    ticks: u64,
    dt: f64,
    clock: ClockMode,
}

/// A tick measured and published but not yet integrated.
#[derive(Debug, Clone, Copy)]
struct Published<const N: usize> {
    k: u64,
    state: (Vector<N>, Vector<N>),
    measurement: Measurement<N>,
}

/// Takes every waiting torque into the plant's delay line, in order; a torque for a tick already
/// passed (duplicate, replay) or malformed is refused and counted; one that stands for its tick
/// without a usable command (gap marker, forged stamp) leaves the tick's command missing
/// ([`Plant::take_command`]). With `stamps`, the per-hop latency of every torque is recorded
/// (realtime: in lockstep latencies say nothing).
fn take_torques<X: Transport, const N: usize>(
    plant: &mut Plant<N>,
    ports: &Ports<X>,
    trace: &mut TraceWriter,
    inflow: &mut Inflow,
    stamps: bool,
) -> Result<(), AgentError> {
    let id = plant.agent_id();
    let mut err = None;
    ports.torque.drain(|m| {
        let received = monotonic_ns();
        let admitted = process::admit_torque::<N>(
            &m,
            id,
            inflow.next,
            (inflow.ticks, inflow.dt),
            inflow.clock,
        );
        let Ok(command) = admitted else {
            inflow.refused += 1;
            return;
        };
        // A refused value or stamp is counted by the plant, as a missing command.
        let _ = plant.take_command(command.stamp, command.torque);
        inflow.next = m.seq + 1;
        if !stamps || command.torque.is_none() {
            return;
        }
        let stamps = HopStamps {
            agent_sent_ns: m.agent_sent_ns,
            attacker_received_ns: m.attacker_received_ns,
            attacker_sent_ns: m.attacker_sent_ns,
            center_received_ns: m.center_received_ns,
            center_sent_ns: m.center_sent_ns,
            agent_received_ns: received,
        };
        if let Err(e) = trace.write(&TraceRecord::Latency {
            k: m.seq,
            agent: id,
            stamps,
        }) {
            err = Some(e);
        }
    })?;
    err.map_or(Ok(()), |e| Err(e.into()))
}

/// Measures and publishes tick `k`. Lockstep rings the attacker once per batch, realtime at
/// every tick (`ring`).
fn publish<X: Transport, const N: usize>(
    plant: &mut Plant<N>,
    ports: &Ports<X>,
    k: u64,
    t: f64,
    ring: bool,
) -> Result<Measurement<N>, AgentError> {
    let m = plant.measure();
    ports.measurement.send(MeasurementMsg {
        seq: k,
        agent: plant.agent_id(),
        dof: N as u32,
        t,
        y: from_vector(&m.y),
        yd: from_vector(&m.yd),
        agent_sent_ns: monotonic_ns(),
        attacker_received_ns: 0,
        attacker_sent_ns: 0,
        flags: 0,
        reserved: 0,
    })?;
    if ring {
        ports.attacker.ring()?;
    }
    Ok(m)
}

/// Runs agent `agent_id` of `resolved` to the end (or until `shutdown`).
pub fn run<X: Transport, const N: usize>(
    agent_id: u32,
    resolved: &Resolved,
    ports: &Ports<X>,
    shutdown: &Shutdown,
    trace: &mut TraceWriter,
    pace: Option<f64>,
) -> Result<Outcome, AgentError> {
    let s = &resolved.scenario;
    let agent = s
        .agents
        .iter()
        .find(|a| a.id == agent_id)
        .ok_or(AgentError::NotInScenario(agent_id))?;
    let mut plant = Plant::<N>::new(s.plant_params(agent)).ok_or(AgentError::Dof(agent_id))?;
    let epoch_ns = match ports
        .launcher
        .ready_and_wait_start(&ports.waker, shutdown)?
    {
        Start::Go { epoch_ns } => epoch_ns,
        Start::Shutdown => return Ok(Outcome::Stopped { ticks: 0 }),
    };
    let ticks = resolved.ticks();
    let dt = s.control_period_s;
    let mut inflow = Inflow {
        next: 0,
        refused: 0,
        ticks,
        dt,
        clock: s.clock,
    };
    let stopped_at = match s.clock {
        ClockMode::Lockstep => {
            let pace = pace.map(|factor| Pace { epoch_ns, factor });
            lockstep(&mut plant, ports, shutdown, trace, &mut inflow, pace)?
        }
        ClockMode::Realtime => realtime(
            &mut plant,
            ports,
            shutdown,
            trace,
            &mut inflow,
            dt,
            epoch_ns,
        )?,
    };
    if let Some(k) = stopped_at {
        return Ok(Outcome::Stopped { ticks: k });
    }
    let note = (inflow.refused > 0 || plant.missing_commands > 0).then(|| {
        let message = format!(
            "{} torque messages refused (wrong agent, dof, sequence or stamp), {} ticks without \
             a usable command (dropped, forged, replayed or refused by the delay line; the one \
             before held)",
            inflow.refused, plant.missing_commands
        );
        (s.duration_s, message)
    });
    process::finish(
        trace,
        note,
        ticks,
        (&ports.launcher, &ports.waker),
        shutdown,
    )?;
    Ok(Outcome::Completed {
        ticks,
        deadline_misses: plant.deadline_misses,
    })
}

/// A lockstep run slowed for watching (`run --pace`): tick k is measured no sooner than
/// `t_k / factor` s after the start.
#[derive(Debug, Clone, Copy)]
struct Pace {
    epoch_ns: u64,
    factor: f64,
}

impl Pace {
    /// Sleeps until tick `t` s is due, waking every [`WAIT_SLICE`] to look for a stop. Whether
    /// the run was stopped meanwhile.
    fn wait<X: Transport>(
        self,
        t: f64,
        ports: &Ports<X>,
        shutdown: &Shutdown,
    ) -> Result<bool, AgentError> {
        let due = self.epoch_ns + (t / self.factor * 1e9) as u64;
        while let Some(left) = due.checked_sub(monotonic_ns()).filter(|l| *l > 0) {
            if shutdown.requested() || ports.launcher.stop_requested()? {
                return Ok(true);
            }
            std::thread::sleep(Duration::from_nanos(left).min(WAIT_SLICE));
        }
        Ok(false)
    }
}

/// The lockstep loop. Returns the tick it stopped at, when stopped before the end.
fn lockstep<X: Transport, const N: usize>(
    plant: &mut Plant<N>,
    ports: &Ports<X>,
    shutdown: &Shutdown,
    trace: &mut TraceWriter,
    inflow: &mut Inflow,
    pace: Option<Pace>,
) -> Result<Option<u64>, AgentError> {
    let (ticks, agent_id, dt) = (inflow.ticks, plant.agent_id(), inflow.dt);
    let strategy = WaitStrategy::for_clock(ClockMode::Lockstep);
    // Lookahead (conservative parallel simulation): step k runs as soon as the next
    // command not yet received (stamp t_n) would not be in force at the step's latest
    // query t − τ(t). The step then looks up exactly the commands it looks up in strict
    // lockstep, so the trace is bit-identical; with τ > Δ the agent runs ticks ahead and
    // the processes exchange batches instead of single messages.
    let mut published: Option<Published<N>> = None;
    let mut unrung = false;
    let mut k = 0;
    while k < ticks {
        let t = tick_time(k, dt);
        let p = match published.take() {
            Some(p) if p.k == k => p,
            _ => {
                if let Some(pace) = pace {
                    // What was measured is announced before the pause (it is measured again
                    // just after: `unrung` is set again).
                    if unrung {
                        ports.attacker.ring()?;
                    }
                    if pace.wait(t, ports, shutdown)? {
                        return Ok(Some(k));
                    }
                }
                let state = (plant.q, plant.qd);
                let measurement = publish(plant, ports, k, t, false)?;
                unrung = true;
                Published {
                    k,
                    state,
                    measurement,
                }
            }
        };
        if plant.can_advance_without(k, tick_time(inflow.next, dt)) {
            let step = plant.advance(k);
            trace.write(&TraceRecord::Agent(agent_record(
                k,
                agent_id,
                t,
                (&p.state.0, &p.state.1),
                &p.measurement,
                &step,
            )))?;
            k += 1;
            continue;
        }
        published = Some(p);
        if unrung {
            ports.attacker.ring()?;
            unrung = false;
        }
        let before = inflow.next;
        while inflow.next == before {
            if shutdown.requested() || ports.launcher.stop_requested()? {
                return Ok(Some(k));
            }
            strategy.wait(&ports.waker, &ports.torque)?;
            take_torques(plant, ports, trace, inflow, false)?;
        }
    }
    // The last measurements may have gone out without a ring (the final steps needed
    // no further torque): announce them, or the attacker only sees them on a timeout.
    if unrung {
        ports.attacker.ring()?;
    }
    Ok(None)
}

/// The realtime loop, paced from `epoch_ns`. Returns the tick it stopped at, when stopped
/// before the end.
fn realtime<X: Transport, const N: usize>(
    plant: &mut Plant<N>,
    ports: &Ports<X>,
    shutdown: &Shutdown,
    trace: &mut TraceWriter,
    inflow: &mut Inflow,
    dt: f64,
    epoch_ns: u64,
) -> Result<Option<u64>, AgentError> {
    let (ticks, agent_id) = (inflow.ticks, plant.agent_id());
    let mut state = (plant.q, plant.qd);
    let mut m = publish(plant, ports, 0, 0.0, true)?;
    for k in 1..=ticks {
        let t = tick_time(k, dt);
        let deadline = epoch_ns + (t * 1e9) as u64;
        // Wait for the deadline with a high-resolution timeout (ppoll), waking at every
        // torque arrival to stamp it: the event wait's own timeout has scheduler-tick
        // granularity (4–10 ms), far too coarse for 1 kHz.
        loop {
            take_torques(plant, ports, trace, inflow, true)?;
            let Some(left) = deadline.checked_sub(monotonic_ns()).filter(|l| *l > 0) else {
                break;
            };
            if shutdown.requested() || ports.launcher.stop_requested()? {
                return Ok(Some(k - 1));
            }
            ports
                .waker
                .wait_precise(Duration::from_nanos(left).min(WAIT_SLICE))?;
        }
        let t_prev = tick_time(k - 1, dt);
        let step = plant.advance(k - 1);
        trace.write(&TraceRecord::Agent(agent_record(
            k - 1,
            agent_id,
            t_prev,
            (&state.0, &state.1),
            &m,
            &step,
        )))?;
        if k < ticks {
            state = (plant.q, plant.qd);
            m = publish(plant, ports, k, t, true)?;
        }
        // A robot that fell behind its clock (an overloaded machine) goes on after the control
        // center is done: its reports tell the launcher it is not stalled.
        if k % PROGRESS_EVERY == 0 {
            ports.launcher.report(StatusMsg::PROGRESS, k)?;
        }
    }
    Ok(None)
}

/// [`run`] with the number of links of agent `agent_id`'s model.
pub fn run_any<X: Transport>(
    agent_id: u32,
    resolved: &Resolved,
    ports: &Ports<X>,
    shutdown: &Shutdown,
    trace: &mut TraceWriter,
    pace: Option<f64>,
) -> Result<Outcome, AgentError> {
    struct Run<'a, X: Transport> {
        agent_id: u32,
        resolved: &'a Resolved,
        ports: &'a Ports<X>,
        shutdown: &'a Shutdown,
        trace: &'a mut TraceWriter,
        pace: Option<f64>,
    }
    impl<X: Transport> ForLinks for Run<'_, X> {
        type Output = Result<Outcome, AgentError>;
        fn call<const N: usize>(self, _: Box<dyn EulerLagrange<N>>) -> Self::Output {
            run::<X, N>(
                self.agent_id,
                self.resolved,
                self.ports,
                self.shutdown,
                self.trace,
                self.pace,
            )
        }
    }
    let agent = resolved
        .scenario
        .agents
        .iter()
        .find(|a| a.id == agent_id)
        .ok_or(AgentError::NotInScenario(agent_id))?;
    agent.model.with_links(Run {
        agent_id,
        resolved,
        ports,
        shutdown,
        trace,
        pace,
    })
}

type Opened = (u32, Resolved, Ports<Shm>, TraceWriter, Shutdown);

fn open(args: &ProcessArgs) -> Result<Opened, AgentError> {
    let id = args.agent.ok_or(AgentError::MissingId)?;
    let (shutdown, resolved) = process::start(args)?;
    let ports = Ports::open(&args.prefix, id, &resolved)?;
    let trace = TraceWriter::create(
        &args.trace,
        &process::trace_header(&format!("agent-{id}"), &resolved),
    )?;
    Ok((id, resolved, ports, trace, shutdown))
}

/// Entry point of the `fdi-agent` binary (and of `fdi-launch`'s multi-call fallback).
pub fn main_with(args: ProcessArgs) -> ExitCode {
    let result = open(&args).and_then(|(id, resolved, ports, mut trace, shutdown)| {
        run_any(id, &resolved, &ports, &shutdown, &mut trace, args.pace)
    });
    match result {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            fdi_runtime::process::print_failure(format_args!(
                "fdi-agent {}: {e}",
                args.agent.map_or("?".into(), |a| a.to_string())
            ));
            ExitCode::FAILURE
        }
    }
}
