//! The attacker process: a man in the middle between the agents and the control center.
//! It relays every measurement in order, adding the profile's `α(t)` ([`fdi_common::engine::tamper`]),
//! and records what it injected. Purely event-driven in both clocks.

use std::process::ExitCode;

use fdi_common::attack::AgentAttack;
use fdi_common::engine::{attack_record, tamper, tick_time};
use fdi_common::model::{EulerLagrange, ForLinks};
use fdi_common::plant::Measurement;
use fdi_common::scenario::{ClockMode, Resolved};
use fdi_common::trace::{TraceRecord, TraceWriter};
use fdi_runtime::ipc::msg::{from_vector, to_vector, SequenceTracker};
use fdi_runtime::ipc::{
    monotonic_ns, Bell as _, Inbox as _, MeasurementMsg, Outbox as _, Role, Shm, Stream, Transport,
    Wake,
};
use fdi_runtime::process::{
    self, Connection, LauncherLink, Liveness, ProcessArgs, Shutdown, Start, WaitStrategy,
    LOST_AFTER_NS,
};

/// Errors of the attacker process.
pub type AttackerError = fdi_runtime::process::RoleError;

/// The attacker's ports.
#[derive(Debug)]
pub struct Ports<X: Transport> {
    pub measurement: X::Inbox<MeasurementMsg>,
    pub tampered: X::Outbox<MeasurementMsg>,
    pub center: X::Bell,
    pub waker: X::Waker,
    pub launcher: LauncherLink<X>,
    /// The node; declared last so that it is dropped after the ports.
    pub transport: X,
}

impl<X: Transport> Ports<X> {
    /// Opens the attacker's node in the run `prefix` and its ports.
    pub fn open(prefix: &str, resolved: &Resolved) -> Result<Self, AttackerError> {
        let conn: Connection<X> = process::connect(
            prefix,
            Role::Attacker,
            Wake::Attacker,
            process::sizing_for(resolved),
        )?;
        Ok(Self {
            measurement: conn.transport.subscriber(Stream::Measurement)?,
            tampered: conn.transport.publisher(Stream::Tampered)?,
            center: conn.transport.notifier(Wake::Center)?,
            waker: conn.waker,
            launcher: conn.launcher,
            transport: conn.transport,
        })
    }
}

/// One attacked agent.
#[derive(Debug)]
struct Target {
    id: u32,
    attack: AgentAttack,
    next: u64,
}

impl Target {
    /// Every agent of the run, with its attack compiled from the run's profile.
    fn all(resolved: &Resolved) -> Vec<Self> {
        let s = &resolved.scenario;
        s.agents
            .iter()
            .map(|a| Self {
                id: a.id,
                attack: AgentAttack::compile(&resolved.attack, a.id, s.seed),
                next: 0,
            })
            .collect()
    }
}

/// Tampers the admitted measurement `m` (received at `received`) with `target`'s attack,
/// relays it to the control center and records what was injected.
fn relay<X: Transport, const N: usize>(
    target: &mut Target,
    m: &MeasurementMsg,
    received: u64,
    ports: &Ports<X>,
    dt: f64,
    trace: &mut TraceWriter,
) -> Result<(), AttackerError> {
    target.next = m.seq + 1;
    let t = tick_time(m.seq, dt);
    let clean = Measurement {
        y: to_vector::<N>(&m.y),
        yd: to_vector::<N>(&m.yd),
    };
    let (out, inj) = tamper(&mut target.attack, t, &clean);
    let sent = ports.tampered.send(MeasurementMsg {
        y: from_vector(&out.y),
        yd: from_vector(&out.yd),
        attacker_received_ns: received,
        attacker_sent_ns: monotonic_ns(),
        ..*m
    });
    // The record is written even when the send failed: the trace shows what was injected.
    let written = trace.write(&TraceRecord::Attack(attack_record(
        m.seq, m.agent, &out, &inj,
    )));
    sent?;
    written?;
    Ok(())
}

/// Relays until every agent's last tick went through (or `shutdown`). Returns messages refused.
pub fn run<X: Transport, const N: usize>(
    resolved: &Resolved,
    ports: &Ports<X>,
    shutdown: &Shutdown,
    trace: &mut TraceWriter,
) -> Result<u64, AttackerError> {
    let s = &resolved.scenario;
    let mut targets = Target::all(resolved);
    let epoch_ns = match ports
        .launcher
        .ready_and_wait_start(&ports.waker, shutdown)?
    {
        Start::Go { epoch_ns } => epoch_ns,
        Start::Shutdown => return Ok(0),
    };
    let ticks = resolved.ticks();
    let dt = s.control_period_s;
    let mut refused = 0u64;
    let mut failure = None;
    let strategy = WaitStrategy::for_clock(s.clock);
    let realtime = s.clock == ClockMode::Realtime;
    // Realtime: relaying ends when every agent has finished or fell silent (lost).
    let mut liveness = Liveness::new(targets.len(), monotonic_ns().max(epoch_ns), LOST_AFTER_NS);
    let end_ns = process::realtime_end_ns(epoch_ns, s.duration_s);
    let mut sequence = SequenceTracker::new(s.agents.iter().map(|a| a.id), ticks);
    loop {
        let mut relayed = 0;
        ports.measurement.drain(|m| {
            let received = monotonic_ns();
            let Some(i) = targets.iter().position(|t| t.id == m.agent) else {
                refused += 1;
                return;
            };
            if !process::admit_measurement(&m, N, &mut sequence, dt, trace) {
                refused += 1;
                return;
            }
            liveness.seen(i, received);
            if let Err(e) = relay::<X, N>(&mut targets[i], &m, received, ports, dt, trace) {
                failure.get_or_insert(e);
            }
            relayed += 1;
        })?;
        if let Some(e) = failure.take() {
            return Err(e);
        }
        if relayed > 0 {
            ports.center.ring()?;
        }
        let now = monotonic_ns();
        if realtime {
            liveness.newly_lost(now, |i| targets[i].next >= ticks);
        }
        // A lost agent may rejoin until the run's wall-clock end: relaying goes on till then.
        if targets
            .iter()
            .enumerate()
            .all(|(i, t)| liveness.settled(i, t.next >= ticks, now, end_ns))
        {
            break;
        }
        if shutdown.requested() || ports.launcher.stop_requested()? {
            return Ok(refused);
        }
        strategy.wait_for_input(s.clock, &ports.waker, &ports.measurement)?;
    }
    let note = (refused > 0).then(|| {
        (
            s.duration_s,
            format!("{refused} measurement messages refused"),
        )
    });
    process::finish(
        trace,
        note,
        ticks,
        (&ports.launcher, &ports.waker),
        shutdown,
    )?;
    Ok(refused)
}

/// [`run`] with the number of links of the run's agents.
pub fn run_any<X: Transport>(
    resolved: &Resolved,
    ports: &Ports<X>,
    shutdown: &Shutdown,
    trace: &mut TraceWriter,
) -> Result<u64, AttackerError> {
    struct Run<'a, X: Transport> {
        resolved: &'a Resolved,
        ports: &'a Ports<X>,
        shutdown: &'a Shutdown,
        trace: &'a mut TraceWriter,
    }
    impl<X: Transport> ForLinks for Run<'_, X> {
        type Output = Result<u64, AttackerError>;
        fn call<const N: usize>(self, _: Box<dyn EulerLagrange<N>>) -> Self::Output {
            run::<X, N>(self.resolved, self.ports, self.shutdown, self.trace)
        }
    }
    resolved
        .with_links(Run {
            resolved,
            ports,
            shutdown,
            trace,
        })
        .unwrap_or(Ok(0))
}

type Opened = (Resolved, Ports<Shm>, TraceWriter, Shutdown);

fn open(args: &ProcessArgs) -> Result<Opened, AttackerError> {
    let (shutdown, resolved) = process::start(args)?;
    let ports = Ports::open(&args.prefix, &resolved)?;
    let trace = TraceWriter::create(&args.trace, &process::trace_header("attacker", &resolved))?;
    Ok((resolved, ports, trace, shutdown))
}

/// Entry point of the `fdi-attacker` binary.
pub fn main_with(args: ProcessArgs) -> ExitCode {
    match open(&args).and_then(|(resolved, ports, mut trace, shutdown)| {
        run_any(&resolved, &ports, &shutdown, &mut trace)
    }) {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            fdi_runtime::process::print_failure(format_args!("fdi-attacker: {e}"));
            ExitCode::FAILURE
        }
    }
}
