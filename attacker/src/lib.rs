//! The attacker process: a man in the middle between the agents and the control center.
//! It relays every measurement in order, tampered by the profile
//! ([`AgentAttack::measurement`]), and, for the agents whose torques the profile attacks,
//! every torque on its way back ([`AgentAttack::torque`]); it records what it did to each.
//! A message the attack keeps from its receiver is replaced by a gap marker. Purely
//! event-driven in both clocks. One [`Role`] of the run (its lifecycle and process shell:
//! [`fdi_runtime::role`]).

pub mod external;

use external::{External, ExternalPorts};

use fdi_common::attack::{AgentAttack, Sent};
use fdi_common::engine::{actuation_record, attack_record, tick_time};
use fdi_common::model::Vector;
use fdi_common::plant::Measurement;
use fdi_common::records::{ActuationRecord, Delivery, Joints};
use fdi_common::run_dir::Process;
use fdi_common::scenario::{ClockMode, Resolved};
use fdi_common::trace::{TraceRecord, TraceWriter};
use fdi_runtime::ipc::msg::{from_vector, to_vector, SequenceTracker};
use fdi_runtime::ipc::{
    self, monotonic_ns, Bell as _, Inbox as _, MeasurementMsg, Outbox, Stream, TorqueMsg,
    Transport, Wake, Waker as _,
};
use fdi_runtime::process::{self, Connection, Liveness, ProcessArgs, WaitStrategy};
use fdi_runtime::role::{self, End, Opened, Role, Turn};

/// Errors of the attacker process.
pub type AttackerError = fdi_runtime::process::RoleError;

/// The attacker's ports.
#[derive(Debug)]
pub struct Ports<X: Transport> {
    pub measurement: X::Inbox<MeasurementMsg>,
    pub tampered: X::Outbox<MeasurementMsg>,
    pub center: X::Bell,
    /// The actuation path, when the run attacks some agent's torques.
    pub actuation: Option<Actuation<X>>,
    /// The program that takes the attacker role (`[roles.attacker]`), when there is one.
    pub external: Option<ExternalPorts<X>>,
}

/// The attacker of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attacker;

impl Role for Attacker {
    type Ports<X: Transport> = Ports<X>;
    type Running<'a, X: Transport + 'a> = Relay<'a, X>;

    fn identity(&self) -> (ipc::Role, Wake) {
        (ipc::Role::Attacker, Wake::Attacker)
    }

    fn program(&self) -> String {
        "fdi-attacker".into()
    }

    fn trace_name(&self) -> Option<String> {
        Some(Process::Attacker.to_string())
    }

    fn open<X: Transport>(
        &self,
        transport: &X,
        resolved: &Resolved,
    ) -> Result<Ports<X>, AttackerError> {
        Ports::open(transport, resolved)
    }

    fn prepare<'a, X: Transport + 'a>(
        &'a self,
        resolved: &'a Resolved,
        opened: &'a Opened<X, Ports<X>>,
    ) -> Result<Relay<'a, X>, AttackerError> {
        Ok(Relay::new(resolved, opened, Target::all(resolved)))
    }
}

impl<X: Transport> Ports<X> {
    /// The attacker's ports on its node.
    fn open(transport: &X, resolved: &Resolved) -> Result<Self, AttackerError> {
        let mut agents = Vec::new();
        for a in &resolved.scenario.agents {
            if resolved.attack.attacks_torque_of(a.id) {
                agents.push((
                    a.id,
                    transport.publisher(Stream::Torque(a.id))?,
                    transport.notifier(Wake::Agent(a.id))?,
                ));
            }
        }
        let actuation = if agents.is_empty() {
            None
        } else {
            Some(Actuation {
                torques: transport.subscriber(Stream::Actuation)?,
                agents,
            })
        };
        let external = match resolved.scenario.roles.attacker {
            Some(_) => Some(ExternalPorts::open(transport)?),
            None => None,
        };
        Ok(Self {
            measurement: transport.subscriber(Stream::Measurement)?,
            tampered: transport.publisher(Stream::Tampered)?,
            center: transport.notifier(Wake::Center)?,
            actuation,
            external,
        })
    }
}

/// The actuation path through the attacker: the torques of the agents whose torques the run
/// attacks, from the control center, and each such agent's torque channel and bell.
#[derive(Debug)]
pub struct Actuation<X: Transport> {
    pub torques: X::Inbox<TorqueMsg>,
    /// `(agent id, its torque channel, its bell)`, in the scenario's agent order.
    pub agents: Vec<(u32, X::Outbox<TorqueMsg>, X::Bell)>,
}

/// One attacked agent.
#[derive(Debug)]
struct Target {
    id: u32,
    /// Its robot's number of links.
    dof: usize,
    attack: AgentAttack,
    /// Next measurement due.
    next: u64,
    /// Its torques go through the attacker: the index of its channel in
    /// [`Actuation::agents`], and the next torque due.
    routed: Option<(usize, u64)>,
}

impl Target {
    /// Every agent of the run, with its attack compiled from the run's profile.
    fn all(resolved: &Resolved) -> Vec<Self> {
        let s = &resolved.scenario;
        let mut routed = 0;
        s.agents
            .iter()
            .map(|a| Self {
                id: a.id,
                dof: a.model.dof(),
                attack: resolved.agent_attack(a.id),
                next: 0,
                routed: resolved.attack.attacks_torque_of(a.id).then(|| {
                    routed += 1;
                    (routed - 1, 0)
                }),
            })
            .collect()
    }

    /// Every message of the agent went through, both ways.
    fn finished(&self, ticks: u64) -> bool {
        self.next >= ticks && self.routed.is_none_or(|(_, n)| n >= ticks)
    }
}

/// A message of either path, as the attacker sends on what the attack made of it.
trait Wire: fdi_runtime::ipc::Payload + Copy {
    /// The gap marker standing for this message's tick.
    fn gap(&self) -> Self;
    /// Its stamp: `t` of a measurement, `t_send` of a torque.
    fn stamp(&mut self) -> &mut f64;
    fn renumber(&mut self, seq: u64);
    /// Takes effect `held_s` later than the known delay (the torque path; 0 elsewhere).
    fn hold(&mut self, held_s: f64);
}

impl Wire for MeasurementMsg {
    fn gap(&self) -> Self {
        MeasurementMsg::gap(self.seq, self.agent, self.dof, self.t)
    }
    fn stamp(&mut self) -> &mut f64 {
        &mut self.t
    }
    fn renumber(&mut self, seq: u64) {
        self.seq = seq;
    }
    fn hold(&mut self, _: f64) {}
}

impl Wire for TorqueMsg {
    fn gap(&self) -> Self {
        TorqueMsg {
            flags: TorqueMsg::GAP,
            ..*self
        }
    }
    fn stamp(&mut self) -> &mut f64 {
        &mut self.t_send
    }
    fn renumber(&mut self, seq: u64) {
        self.seq = seq;
    }
    fn hold(&mut self, held_s: f64) {
        self.held_s = held_s;
    }
}

/// Sends on `out` what the attack made of the message `m` (`sent`; `with` puts a payload into
/// a copy of `m`): the message, a gap marker in place of what it keeps back, a forged stamp,
/// or the recorded message under its original header followed by the tick's gap marker.
fn forward<M: Wire, P>(
    out: &impl Outbox<M>,
    sent: &Sent<P>,
    m: &M,
    with: impl Fn(&P) -> M,
    dt: f64,
) -> Result<(), fdi_runtime::ipc::IpcError> {
    match sent {
        Sent::Delivered { payload, held_s } => {
            let mut msg = with(payload);
            msg.hold(*held_s);
            out.send(msg)?;
        }
        Sent::Missing => {
            out.send(m.gap())?;
        }
        Sent::Forged { payload, shift_s } => {
            let mut msg = with(payload);
            *msg.stamp() += shift_s;
            out.send(msg)?;
        }
        Sent::Replayed { k, payload } => {
            let mut msg = with(payload);
            msg.renumber(*k);
            *msg.stamp() = tick_time(*k, dt);
            out.send(msg)?;
            out.send(m.gap())?;
        }
    }
    Ok(())
}

/// Tampers the admitted measurement `m` (received at `received`) with `target`'s attack,
/// relays what the attack lets through to the control center (a gap marker in place of what
/// it keeps back) and records what it did.
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
    let (sent, inj) = target.attack.measurement::<N>(m.seq, t, &clean);
    let with = |p: &Measurement<N>| MeasurementMsg {
        y: from_vector(&p.y),
        yd: from_vector(&p.yd),
        attacker_received_ns: received,
        attacker_sent_ns: monotonic_ns(),
        ..*m
    };
    let result = forward(&ports.tampered, &sent, m, with, dt);
    // The record is written even when the send failed: the trace shows what was injected.
    let written = trace.write(&TraceRecord::Attack(attack_record(
        m.seq, m.agent, &sent, &inj,
    )));
    result?;
    written?;
    Ok(())
}

/// Tampers the torque `m` from the control center (received at `received`) with `target`'s
/// attack, relays what the attack lets through on the agent's channel (a gap marker in place
/// of what it keeps back) and records what it did. `command`: the torque, `None` when the
/// center's message stood for its tick without a usable command (relayed as a gap).
fn relay_torque<X: Transport, const N: usize>(
    target: &mut Target,
    (m, command): (&TorqueMsg, Option<Vector<N>>),
    received: u64,
    out: &X::Outbox<TorqueMsg>,
    dt: f64,
    trace: &mut TraceWriter,
) -> Result<(), AttackerError> {
    let Some(u) = command else {
        let result = out.send(m.gap());
        trace.write(&TraceRecord::Actuation(ActuationRecord {
            k: m.seq,
            agent: m.agent,
            alpha_u: Joints::default(),
            u: Joints::default(),
            held_s: 0.0,
            active: false,
            delivery: Delivery::Missing,
        }))?;
        result?;
        return Ok(());
    };
    let t = tick_time(m.seq, dt);
    let (sent, inj) = target.attack.torque::<N>(m.seq, t, &u);
    let with = |p: &Vector<N>| TorqueMsg {
        u: from_vector(p),
        attacker_received_ns: received,
        attacker_sent_ns: monotonic_ns(),
        ..*m
    };
    let result = forward(out, &sent, m, with, dt);
    let written = trace.write(&TraceRecord::Actuation(actuation_record(
        m.seq, m.agent, &sent, &inj,
    )));
    result?;
    written?;
    Ok(())
}

/// Admits the torque `m` for `target`, whose robot has `N` links, and relays it on `out`:
/// whether it was admitted (a refused one moves nothing on).
fn admit_and_relay_torque<X: Transport, const N: usize>(
    target: &mut Target,
    m: &TorqueMsg,
    received: u64,
    out: &X::Outbox<TorqueMsg>,
    (ticks, dt, clock): (u64, f64, ClockMode),
    trace: &mut TraceWriter,
) -> Result<bool, AttackerError> {
    let Some((i, next)) = target.routed else {
        return Ok(false);
    };
    let Ok(command) = process::admit_torque::<N>(m, target.id, next, (ticks, dt), clock) else {
        return Ok(false);
    };
    target.routed = Some((i, m.seq + 1));
    let command = command.torque.map(|(u, _)| u);
    relay_torque::<X, N>(target, (m, command), received, out, dt, trace)?;
    Ok(true)
}

/// Admits and relays every torque waiting on the actuation path; rings each agent that got
/// one. Returns the messages refused.
fn relay_torques<X: Transport>(
    targets: &mut [Target],
    actuation: &Actuation<X>,
    (ticks, dt, clock): (u64, f64, ClockMode),
    trace: &mut TraceWriter,
) -> Result<u64, AttackerError> {
    let mut refused = 0;
    let mut failure = None;
    let mut answered = vec![false; actuation.agents.len()];
    actuation.torques.drain(|m| {
        let received = monotonic_ns();
        let Some(target) = targets.iter_mut().find(|t| t.id == m.agent) else {
            refused += 1;
            return;
        };
        let Some((i, _)) = target.routed else {
            refused += 1;
            return;
        };
        let out = &actuation.agents[i].1;
        let relayed = fdi_common::with_joint_count!(target.dof, N => {
            admit_and_relay_torque::<X, N>(target, &m, received, out, (ticks, dt, clock), trace)
        });
        match relayed {
            Some(Ok(true)) => answered[i] = true,
            Some(Ok(false)) | None => refused += 1,
            Some(Err(e)) => {
                failure.get_or_insert(e);
                answered[i] = true;
            }
        }
    })?;
    if let Some(e) = failure {
        return Err(e);
    }
    for (flag, (_, _, bell)) in answered.iter().zip(&actuation.agents) {
        if *flag {
            bell.ring()?;
        }
    }
    Ok(refused)
}

/// The attacker over a run: the agents it relays for, what it refused, the checks of what
/// arrives, the program that takes its role (if any), and the run's timing.
pub struct Relay<'a, X: Transport> {
    resolved: &'a Resolved,
    ports: &'a Ports<X>,
    conn: &'a Connection<X>,
    targets: Vec<Target>,
    /// Messages refused so far.
    refused: u64,
    sequence: SequenceTracker,
    /// Realtime: relaying ends when every agent has finished or fell silent (lost).
    liveness: Liveness,
    external: Option<External>,
    strategy: WaitStrategy,
    ticks: u64,
    dt: f64,
    realtime: bool,
    end_ns: u64,
}

impl<X: Transport> role::Running for Relay<'_, X> {
    /// The run started at `epoch_ns`: the agents' liveness counts from then, and the program
    /// that takes the attacker role (if any) is given its time from then.
    fn begin(&mut self, epoch_ns: u64, _: &mut TraceWriter) -> Result<(), AttackerError> {
        let s = &self.resolved.scenario;
        let since = monotonic_ns().max(epoch_ns);
        self.liveness = Liveness::new(self.targets.len(), since, process::lost_after_ns(self.dt));
        self.end_ns = process::realtime_end_ns(epoch_ns, s.duration_s, self.dt);
        let ids: Vec<u32> = s.agents.iter().map(|a| a.id).collect();
        self.external = match (&s.roles.attacker, &self.ports.external) {
            // Validation gives a program in the role a team of one joint count.
            (Some(role), Some(_)) => {
                let dof = self.targets.first().map_or(0, |t| t.dof);
                Some(External::new(role, &ids, dof, self.dt, self.realtime))
            }
            _ => None,
        };
        Ok(())
    }

    fn turn(&mut self, trace: &mut TraceWriter) -> Result<Turn, AttackerError> {
        let (relayed, forwarded) = self.take_measurements(trace)?;
        self.pass_on(relayed, forwarded, trace)?;
        self.take_torques(trace)?;
        Ok(if self.settled() {
            Turn::Done
        } else {
            Turn::Pending
        })
    }

    /// Waits for the next input (or, in realtime with answers due, the earliest deadline).
    fn wait(&mut self) -> Result<(), AttackerError> {
        self.wait_for_input()
    }

    /// A note of what was refused and what the program did.
    fn end(self, _: &mut TraceWriter) -> Result<End, AttackerError> {
        let mut notes = Vec::new();
        if self.refused > 0 {
            notes.push(format!("{} measurement messages refused", self.refused));
        }
        if let Some(x) = &self.external {
            notes.push(x.summary());
        }
        let note =
            (!notes.is_empty()).then(|| (self.resolved.scenario.duration_s, notes.join("; ")));
        Ok(End {
            ticks: self.ticks,
            note,
        })
    }
}

impl<'a, X: Transport> Relay<'a, X> {
    /// The state of a run (its clocks are set at the start).
    fn new(resolved: &'a Resolved, opened: &'a Opened<X, Ports<X>>, targets: Vec<Target>) -> Self {
        let s = &resolved.scenario;
        let ticks = resolved.ticks();
        let dt = s.control_period_s;
        let strategy = WaitStrategy::for_clock(s.clock);
        let realtime = s.clock == ClockMode::Realtime;
        let liveness = Liveness::new(targets.len(), 0, process::lost_after_ns(dt));
        let sequence = SequenceTracker::new(s.agents.iter().map(|a| a.id), ticks);
        let (external, end_ns) = (None, 0);
        Self {
            resolved,
            ports: &opened.ports,
            conn: &opened.conn,
            targets,
            refused: 0,
            sequence,
            liveness,
            external,
            strategy,
            ticks,
            dt,
            realtime,
            end_ns,
        }
    }

    /// Admits every measurement waiting and relays it (or hands it to the program that takes
    /// the attacker role). Returns how many were relayed to the center and how many handed over.
    fn take_measurements(
        &mut self,
        trace: &mut TraceWriter,
    ) -> Result<(usize, usize), AttackerError> {
        let Self {
            ports,
            targets,
            refused,
            sequence,
            liveness,
            external,
            dt,
            ..
        } = self;
        let (ports, dt) = (*ports, *dt);
        let mut relayed = 0;
        let mut forwarded = 0;
        let mut failure = None;
        ports.measurement.drain(|m| {
            let received = monotonic_ns();
            let Some(i) = targets.iter().position(|t| t.id == m.agent) else {
                *refused += 1;
                return;
            };
            // A gap marker or forged stamp from elsewhere is relayed as the tick's message:
            // the attack acts on what the agent sent, and the center judges it again.
            let dof = targets[i].dof;
            if process::admit_measurement(&m, dof, sequence, dt, trace)
                == process::Admission::Refused
            {
                *refused += 1;
                return;
            }
            liveness.seen(i, received);
            let result = match (&mut *external, &ports.external) {
                (Some(x), Some(p)) => {
                    targets[i].next = m.seq + 1;
                    forwarded += 1;
                    x.forward(i, &m, received, p)
                }
                _ => {
                    relayed += 1;
                    let target = &mut targets[i];
                    fdi_common::with_joint_count!(dof, N => {
                        relay::<X, N>(target, &m, received, ports, dt, trace)
                    })
                    // A robot of no joint count a model has: no relay, said as the run's failure.
                    .unwrap_or(Err(AttackerError::Dof(m.agent)))
                }
            };
            if let Err(e) = result {
                failure.get_or_insert(e);
            }
        })?;
        if let Some(e) = failure {
            return Err(e);
        }
        Ok((relayed, forwarded))
    }

    /// Rings the program that takes the attacker role when it was handed measurements, relays
    /// its answers (and, in realtime, gap markers past its deadline), and rings the center when
    /// anything went to it.
    fn pass_on(
        &mut self,
        mut relayed: usize,
        forwarded: usize,
        trace: &mut TraceWriter,
    ) -> Result<(), AttackerError> {
        let ports = self.ports;
        if let (Some(x), Some(p)) = (&mut self.external, &ports.external) {
            if forwarded > 0 {
                p.ring(&self.conn.transport)?;
            }
            relayed += x.take_answers(p, &ports.tampered, trace)?;
            relayed += x.enforce(monotonic_ns(), &ports.tampered, trace)?;
        }
        if relayed > 0 {
            ports.center.ring()?;
        }
        Ok(())
    }

    /// Relays the torques waiting on the actuation path, when the run attacks some.
    fn take_torques(&mut self, trace: &mut TraceWriter) -> Result<(), AttackerError> {
        if let Some(actuation) = &self.ports.actuation {
            let clock = self.resolved.scenario.clock;
            self.refused += relay_torques::<X>(
                &mut self.targets,
                actuation,
                (self.ticks, self.dt, clock),
                trace,
            )?;
        }
        Ok(())
    }

    /// Whether relaying is over: every agent finished (and answered, with a program in the
    /// role) or lost past the run's end. Realtime: marks the agents fallen silent first.
    fn settled(&mut self) -> bool {
        let Self {
            targets,
            liveness,
            external,
            ticks,
            realtime,
            end_ns,
            ..
        } = self;
        let (ticks, end_ns) = (*ticks, *end_ns);
        let now = monotonic_ns();
        if *realtime {
            liveness.newly_lost(now, |i| targets[i].next >= ticks);
        }
        // A lost agent may rejoin until the run's wall-clock end: relaying goes on till then.
        let answered = |i: usize| external.as_ref().is_none_or(|x| x.finished(i, ticks));
        targets
            .iter()
            .enumerate()
            .all(|(i, t)| liveness.settled(i, t.finished(ticks) && answered(i), now, end_ns))
    }

    fn wait_for_input(&self) -> Result<(), AttackerError> {
        let ports = self.ports;
        let has_input = || {
            Ok(ports.measurement.has_messages()?
                || match &ports.actuation {
                    Some(a) => a.torques.has_messages()?,
                    None => false,
                }
                || match &ports.external {
                    Some(p) => p.from.has_messages()?,
                    None => false,
                })
        };
        match self
            .external
            .as_ref()
            .and_then(|x| x.next_deadline_in(monotonic_ns()))
        {
            // Realtime with answers due: wake at the earliest deadline at the latest.
            Some(due) if self.realtime => {
                (self.conn.waker).wait_precise(due.min(fdi_runtime::process::LIVENESS_CHECK))?;
            }
            _ => {
                self.strategy.wait_for_input(
                    self.resolved.scenario.clock,
                    &self.conn.waker,
                    has_input,
                )?;
            }
        }
        Ok(())
    }
}

/// The process of the `fdi-attacker` binary (and of `fdi-launch process attacker`).
pub fn run_process(args: ProcessArgs) -> Result<role::Ended, role::Failed> {
    role::run_process(&Attacker, &args)
}
