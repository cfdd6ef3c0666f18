//! The control-center process: one [`CenterAgent`] per agent (with its robot's number of links), fed by the attacker's (tampered)
//! measurements; each torque goes back to its agent stamped with its tick time, straight or,
//! for an agent whose torques the run attacks, through the attacker. Purely
//! event-driven: every agent's tick is computed as soon as its measurement arrives (agents are
//! independent, so the result does not depend on the order in which agents arrive). One
//! [`Role`] of the run (its lifecycle and process shell: [`fdi_runtime::role`]).

pub mod controller;
pub mod monitor;

use controller::{ControllerPorts, ControllerProgram};
use monitor::{Monitor, MonitorPorts};

use fdi_common::control::{AnyCenterAgent, CenterAgent, CenterOutput};
use fdi_common::engine::{center_record, center_tick, tick_time};
use fdi_common::plant::Measurement;
use fdi_common::run_dir::Process;
use fdi_common::scenario::{ClockMode, Resolved};
use fdi_common::trace::{TraceRecord, TraceWriter};
use fdi_runtime::ipc::msg::{from_vector, to_vector, SequenceTracker};
use fdi_runtime::ipc::{
    self, monotonic_ns, Bell as _, Inbox as _, MeasurementMsg, Outbox as _, StatusMsg, Stream,
    TorqueMsg, Transport, Wake,
};
use fdi_runtime::process::{self, Connection, LauncherLink, Liveness, ProcessArgs, WaitStrategy};
use fdi_runtime::role::{self, End, Opened, Role, Turn};

/// Errors of the control-center process.
pub type CenterError = fdi_runtime::process::RoleError;

/// Ports towards one agent.
#[derive(Debug)]
pub struct AgentLink<X: Transport> {
    pub torque: X::Outbox<TorqueMsg>,
    pub bell: X::Bell,
}

/// The control center's ports.
#[derive(Debug)]
pub struct Ports<X: Transport> {
    pub tampered: X::Inbox<MeasurementMsg>,
    /// Where torques go: each direct agent's own channel, and the actuation path to the
    /// attacker when the run attacks some agent's torques.
    pub links: Vec<AgentLink<X>>,
    /// Per agent in the scenario's order, the index of its link in `links`.
    pub route: Vec<usize>,
    /// The monitor program (`[roles.monitor]`), when the run has one.
    pub monitor: Option<MonitorPorts<X>>,
    /// The controller program (`[roles.controller]`), when the run has one.
    pub controller: Option<ControllerPorts<X>>,
}

/// The control center of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ControlCenter;

impl Role for ControlCenter {
    type Ports<X: Transport> = Ports<X>;
    type Running<'a, X: Transport + 'a> = Center<'a, X>;

    fn identity(&self) -> (ipc::Role, Wake) {
        (ipc::Role::Center, Wake::Center)
    }

    fn program(&self) -> String {
        "fdi-control-center".into()
    }

    fn trace_name(&self) -> Option<String> {
        Some(Process::Center.to_string())
    }

    fn open<X: Transport>(
        &self,
        transport: &X,
        resolved: &Resolved,
    ) -> Result<Ports<X>, CenterError> {
        Ports::open(transport, resolved)
    }

    fn prepare<'a, X: Transport + 'a>(
        &'a self,
        resolved: &'a Resolved,
        opened: &'a Opened<X, Ports<X>>,
    ) -> Result<Center<'a, X>, CenterError> {
        let s = &resolved.scenario;
        let slots = (s.agents.iter())
            .map(|a| {
                AnyCenterAgent::new(s.center_params(a))
                    .map(|center| Slot { center, next: 0 })
                    .ok_or(CenterError::Dof(a.id))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Center::new(resolved, opened, slots))
    }
}

impl<X: Transport> Ports<X> {
    /// The control center's ports on its node.
    fn open(transport: &X, resolved: &Resolved) -> Result<Self, CenterError> {
        let mut links = Vec::with_capacity(resolved.agent_count());
        let mut route = Vec::with_capacity(resolved.agent_count());
        let mut actuation = None;
        for a in &resolved.scenario.agents {
            if !resolved.attack.attacks_torque_of(a.id) {
                route.push(links.len());
                links.push(AgentLink {
                    torque: transport.publisher(Stream::Torque(a.id))?,
                    bell: transport.notifier(Wake::Agent(a.id))?,
                });
                continue;
            }
            if actuation.is_none() {
                actuation = Some(links.len());
                links.push(AgentLink {
                    torque: transport.publisher(Stream::Actuation)?,
                    bell: transport.notifier(Wake::Attacker)?,
                });
            }
            route.extend(actuation);
        }
        let monitor = match resolved.scenario.roles.monitor {
            Some(_) => Some(MonitorPorts::open(transport)?),
            None => None,
        };
        let controller = match resolved.scenario.roles.controller {
            Some(_) => Some(ControllerPorts::open(transport)?),
            None => None,
        };
        Ok(Self {
            tampered: transport.subscriber(Stream::Tampered)?,
            links,
            route,
            monitor,
            controller,
        })
    }

    /// Wakes every receiver of this batch's torques once (the attacker once for all the
    /// agents routed through it): `answered` is per agent in scenario order. Clears it.
    fn ring(&self, answered: &mut [bool]) -> Result<(), CenterError> {
        let mut rung = vec![false; self.links.len()];
        for (flag, &l) in answered.iter_mut().zip(&self.route) {
            if std::mem::take(flag) && !std::mem::replace(&mut rung[l], true) {
                self.links[l].bell.ring()?;
            }
        }
        Ok(())
    }
}

pub use fdi_runtime::process::PROGRESS_EVERY;

struct Slot {
    center: AnyCenterAgent,
    next: u64,
}

/// What the control center keeps about its input stream: the sequence of each agent, their
/// liveness (realtime), and what one batch of measurements did.
struct Intake {
    sequence: SequenceTracker,
    /// Realtime: an agent silent for [`process::lost_after_ns`] is declared lost; the others
    /// stay controlled.
    liveness: Liveness,
    /// Messages refused so far.
    refused: u64,
    /// The first failure of the batch (sending a torque, writing the trace).
    failure: Option<CenterError>,
    /// Agents heard from again after being declared lost: (slot, silence in ns, tick).
    rejoined: Vec<(usize, u64, u64)>,
    /// Which agents got a torque in this batch: each is woken once per batch.
    answered: Vec<bool>,
}

impl Intake {
    fn new(ids: &[u32], ticks: u64, since_ns: u64, dt: f64) -> Self {
        Self {
            sequence: SequenceTracker::new(ids.iter().copied(), ticks),
            liveness: Liveness::new(ids.len(), since_ns, process::lost_after_ns(dt)),
            refused: 0,
            failure: None,
            rejoined: Vec::new(),
            answered: vec![false; ids.len()],
        }
    }

    /// Admits measurement `m` (refused ones are counted) and controls its agent, or queues
    /// it for the controller `program`.
    fn take<X: Transport>(
        &mut self,
        m: &MeasurementMsg,
        (slots, program): (&mut [Slot], Option<&mut ControllerProgram>),
        ports: &Ports<X>,
        dt: f64,
        trace: &mut TraceWriter,
    ) {
        let Some(i) = slots.iter().position(|x| x.center.agent_id() == m.agent) else {
            self.refused += 1;
            return;
        };
        let Slot { center, next } = &mut slots[i];
        fdi_common::on_joint_count!(AnyCenterAgent, center, c => {
            self.take_for(m, (i, c, next), program, ports, dt, trace)
        });
    }

    /// [`Self::take`] for agent `i`, whose control center `center` has `N` links.
    fn take_for<X: Transport, const N: usize>(
        &mut self,
        m: &MeasurementMsg,
        (i, center, next): (usize, &mut CenterAgent<N>, &mut u64),
        program: Option<&mut ControllerProgram>,
        ports: &Ports<X>,
        dt: f64,
        trace: &mut TraceWriter,
    ) {
        let received = monotonic_ns();
        let input = match process::admit_measurement(m, N, &mut self.sequence, dt, trace) {
            process::Admission::Use(()) => Some(Measurement {
                y: to_vector::<N>(&m.y),
                yd: to_vector::<N>(&m.yd),
            }),
            process::Admission::Missing => None,
            process::Admission::Refused => {
                self.refused += 1;
                return;
            }
        };
        if let Some(silent) = self.liveness.seen(i, received) {
            self.rejoined.push((i, silent, m.seq));
        }
        if let Some(p) = program {
            p.queue(i, m, input.is_some(), received);
            return;
        }
        let link = &ports.links[ports.route[i]];
        if let Err(e) = control(
            (center, next),
            (m, input.as_ref()),
            received,
            link,
            dt,
            trace,
        ) {
            self.failure.get_or_insert(e);
        }
        self.answered[i] = true;
    }
}

/// Computes the tick of the agent of `center` (its next tick due: `next`) from the admitted
/// message `m` (received at `received`) and its measurement (`None`: the tick's input is
/// missing), and delivers the torque on `link`.
fn control<X: Transport, const N: usize>(
    (center, next): (&mut CenterAgent<N>, &mut u64),
    (m, input): (&MeasurementMsg, Option<&Measurement<N>>),
    received: u64,
    link: &AgentLink<X>,
    dt: f64,
    trace: &mut TraceWriter,
) -> Result<(), CenterError> {
    *next = m.seq + 1;
    let t = tick_time(m.seq, dt);
    let out = center_tick(center, t, input);
    deliver(&out, (m, t), received, link, trace)
}

/// Sends the torque of tick `out` (the tick of the admitted message `m`, received at
/// `received`, whose tick time is `t`) on `link`, stamped `t`, and records the tick.
fn deliver<X: Transport, const N: usize>(
    out: &CenterOutput<N>,
    (m, t): (&MeasurementMsg, f64),
    received: u64,
    link: &AgentLink<X>,
    trace: &mut TraceWriter,
) -> Result<(), CenterError> {
    let sent = link.torque.send(TorqueMsg {
        seq: m.seq,
        agent: m.agent,
        dof: N as u32,
        t_send: t,
        u: from_vector(&out.u),
        agent_sent_ns: m.agent_sent_ns,
        attacker_received_ns: m.attacker_received_ns,
        attacker_sent_ns: m.attacker_sent_ns,
        center_received_ns: received,
        center_sent_ns: monotonic_ns(),
        held_s: 0.0,
        flags: 0,
        reserved: 0,
    });
    // The record is written even when the send failed: the trace shows what was computed.
    let written = trace.write(&TraceRecord::Center(center_record(m.seq, m.agent, out)));
    sent?;
    written?;
    Ok(())
}

/// Records and reports that agent `id`, declared lost, is heard from again at tick `k` after
/// `silent_ns` of silence.
fn announce_rejoined<X: Transport>(
    id: u32,
    silent_ns: u64,
    k: u64,
    dt: f64,
    launcher: &LauncherLink<X>,
    trace: &mut TraceWriter,
) -> Result<(), CenterError> {
    let message = format!(
        "agent {id} rejoined at tick {k} after {:.1} ms of silence; controlled again",
        silent_ns as f64 / 1e6
    );
    trace.write(&TraceRecord::Event {
        t: tick_time(k, dt),
        message,
    })?;
    launcher.report_rejoined(id, k)?;
    Ok(())
}

/// Reports progress to the launcher, over the agents controlled now, every
/// [`PROGRESS_EVERY`] ticks and at the end.
fn report_progress<X: Transport>(
    slots: &[Slot],
    liveness: &Liveness,
    reported: &mut u64,
    ticks: u64,
    launcher: &LauncherLink<X>,
) -> Result<(), CenterError> {
    let done = slots
        .iter()
        .enumerate()
        .filter(|(i, _)| !liveness.is_lost(*i))
        .map(|(_, x)| x.next)
        .min()
        .unwrap_or(0);
    if done >= *reported + PROGRESS_EVERY || done >= ticks {
        *reported = done;
        launcher.report(StatusMsg::PROGRESS, done)?;
    }
    Ok(())
}

/// Realtime: records and reports every agent silent for [`process::lost_after_ns`] as lost
/// (the others stay controlled).
fn declare_lost<X: Transport>(
    slots: &[Slot],
    liveness: &mut Liveness,
    now: u64,
    ticks: u64,
    dt: f64,
    launcher: &LauncherLink<X>,
    trace: &mut TraceWriter,
) -> Result<(), CenterError> {
    for i in liveness.newly_lost(now, |i| slots[i].next >= ticks) {
        let (id, last) = (slots[i].center.agent_id(), slots[i].next.saturating_sub(1));
        let silent_ms = liveness.silence_ns(i, now) as f64 / 1e6;
        let limit_ms = liveness.limit_ns() as f64 / 1e6;
        let message = format!("agent {id} lost: detected {silent_ms:.1} ms after its last measurement (limit {limit_ms} ms, after tick {last}); the others stay controlled");
        trace.write(&TraceRecord::Event {
            t: tick_time(last, dt),
            message,
        })?;
        launcher.report_lost(id, last)?;
    }
    Ok(())
}

/// The control center over a run: an agent controller per agent, the intake, the monitor (if
/// any) and the run's timing.
pub struct Center<'a, X: Transport> {
    resolved: &'a Resolved,
    ports: &'a Ports<X>,
    conn: &'a Connection<X>,
    slots: Vec<Slot>,
    intake: Intake,
    monitor: Option<Monitor>,
    /// The controller program (`[roles.controller]`), when the run has one.
    program: Option<ControllerProgram>,
    /// Measurements the monitor let through, to be controlled.
    ready: Vec<MeasurementMsg>,
    /// The tick last reported to the launcher.
    reported: u64,
    ticks: u64,
    dt: f64,
    realtime: bool,
    end_ns: u64,
    strategy: WaitStrategy,
}

impl<X: Transport> role::Running for Center<'_, X> {
    /// The run started at `epoch_ns`: the agents' liveness counts from then, and the monitor
    /// program (if any) is given its time from then.
    fn begin(&mut self, epoch_ns: u64, _: &mut TraceWriter) -> Result<(), CenterError> {
        let s = &self.resolved.scenario;
        let ids: Vec<u32> = s.agents.iter().map(|a| a.id).collect();
        self.end_ns = process::realtime_end_ns(epoch_ns, s.duration_s, self.dt);
        self.intake = Intake::new(&ids, self.ticks, monotonic_ns().max(epoch_ns), self.dt);
        self.monitor = match (&s.roles.monitor, &self.ports.monitor) {
            (Some(role), Some(_)) => {
                Some(Monitor::new(role, &ids, self.dt, !self.realtime, epoch_ns))
            }
            _ => None,
        };
        self.program = match (&s.roles.controller, &self.ports.controller) {
            (Some(role), Some(_)) => Some(ControllerProgram::new(
                role,
                &ids,
                self.dt,
                !self.realtime,
                epoch_ns,
            )),
            _ => None,
        };
        Ok(())
    }

    fn turn(&mut self, trace: &mut TraceWriter) -> Result<Turn, CenterError> {
        let arrived = self.take_measurements(trace)?;
        self.ring(arrived)?;
        let now = self.follow_agents(trace)?;
        Ok(if self.done(now)? {
            Turn::Done
        } else {
            Turn::Pending
        })
    }

    fn wait(&mut self) -> Result<(), CenterError> {
        let ports = self.ports;
        self.strategy
            .wait_for_input(self.resolved.scenario.clock, &self.conn.waker, || {
                Ok(ports.tampered.has_messages()?
                    || match &ports.monitor {
                        Some(m) => m.alarms.has_messages()?,
                        None => false,
                    }
                    || match &ports.controller {
                        Some(c) => c.answers.has_messages()?,
                        None => false,
                    })
            })?;
        Ok(())
    }

    /// A note of what was refused, rejected or missing and what the monitor did.
    fn end(self, _: &mut TraceWriter) -> Result<End, CenterError> {
        let ticks = self.ticks;
        let (refused, rejected, missing) = (
            self.intake.refused,
            self.slots
                .iter()
                .map(|x| x.center.rejected_inputs())
                .sum::<u64>(),
            self.slots
                .iter()
                .map(|x| x.center.missing_inputs())
                .sum::<u64>(),
        );
        let mut notes = Vec::new();
        if refused > 0 || rejected > 0 || missing > 0 {
            notes.push(format!(
                "{refused} messages refused, {rejected} measurements rejected as non-finite or \
                 absurd, {missing} ticks without a measurement (gap markers, forged stamps; the last \
                 good one held)"
            ));
        }
        if let Some(mon) = &self.monitor {
            notes.push(mon.summary(ticks));
        }
        if let Some(p) = &self.program {
            notes.push(p.summary());
        }
        let note =
            (!notes.is_empty()).then(|| (self.resolved.scenario.duration_s, notes.join("; ")));
        Ok(End { ticks, note })
    }
}

impl<'a, X: Transport> Center<'a, X> {
    /// The state of a run (its clocks are set at the start).
    fn new(resolved: &'a Resolved, opened: &'a Opened<X, Ports<X>>, slots: Vec<Slot>) -> Self {
        let s = &resolved.scenario;
        let ids: Vec<u32> = s.agents.iter().map(|a| a.id).collect();
        let ticks = resolved.ticks();
        let dt = s.control_period_s;
        let realtime = s.clock == ClockMode::Realtime;
        let intake = Intake::new(&ids, ticks, 0, dt);
        let (monitor, program, end_ns) = (None, None, 0);
        let strategy = WaitStrategy::for_clock(s.clock);
        Self {
            resolved,
            ports: &opened.ports,
            conn: &opened.conn,
            slots,
            intake,
            monitor,
            program,
            ready: Vec::new(),
            reported: 0,
            ticks,
            dt,
            realtime,
            end_ns,
            strategy,
        }
    }

    /// Takes every measurement waiting (through the monitor, when there is one) and controls
    /// its agent. Returns how many measurements the monitor was handed.
    fn take_measurements(&mut self, trace: &mut TraceWriter) -> Result<usize, CenterError> {
        let Self {
            ports,
            slots,
            intake,
            monitor,
            program,
            ready,
            dt,
            ..
        } = self;
        let (ports, dt) = (*ports, *dt);
        // With a monitor, it is rung whenever measurements came: it taps them too, and in
        // lockstep the center may be waiting for its verdicts on them.
        let mut arrived = 0;
        match (monitor, &ports.monitor) {
            (Some(mon), Some(mp)) => {
                arrived = ports.tampered.drain(|m| mon.admit(m, ready))?;
                mon.take_verdicts(mp, trace, ready)?;
                for m in ready.drain(..) {
                    intake.take(&m, (slots, program.as_mut()), ports, dt, trace);
                }
            }
            _ => {
                ports
                    .tampered
                    .drain(|m| intake.take(&m, (slots, program.as_mut()), ports, dt, trace))?;
            }
        }
        if let Some(e) = intake.failure.take() {
            return Err(e);
        }
        if let (Some(p), Some(cp)) = (program, &ports.controller) {
            if converse(p, cp, (slots, ports), &mut intake.answered, trace)? > 0 {
                cp.bell.ring(&self.conn.transport)?;
            }
        }
        Ok(arrived)
    }

    /// Rings every agent that got a torque, and the monitor when measurements came (`arrived`)
    /// or torques went.
    fn ring(&mut self, arrived: usize) -> Result<(), CenterError> {
        let ports = self.ports;
        let computed = self.intake.answered.iter().any(|a| *a);
        ports.ring(&mut self.intake.answered)?;
        if let Some(mp) = &ports.monitor {
            if computed || arrived > 0 {
                mp.ring(&self.conn.transport)?;
            }
        }
        Ok(())
    }

    /// Announces the agents that rejoined, declares the agents fallen silent lost (realtime)
    /// and reports progress. Returns the time it looked at the agents.
    fn follow_agents(&mut self, trace: &mut TraceWriter) -> Result<u64, CenterError> {
        let (launcher, dt, ticks) = (&self.conn.launcher, self.dt, self.ticks);
        let slots = &self.slots;
        let liveness = &mut self.intake.liveness;
        for (i, silent, k) in self.intake.rejoined.drain(..) {
            announce_rejoined(slots[i].center.agent_id(), silent, k, dt, launcher, trace)?;
        }
        let now = monotonic_ns();
        if self.realtime {
            declare_lost(slots, liveness, now, ticks, dt, launcher, trace)?;
        }
        report_progress(slots, liveness, &mut self.reported, ticks, launcher)?;
        Ok(now)
    }

    /// Whether the run is over: every agent finished, or is lost past the run's wall-clock
    /// end (until then a lost agent may rejoin), and the monitor gave its last verdicts.
    fn done(&mut self, now: u64) -> Result<bool, CenterError> {
        let (ticks, end_ns) = (self.ticks, self.end_ns);
        let liveness = &self.intake.liveness;
        let controlled = self
            .slots
            .iter()
            .enumerate()
            .all(|(i, x)| liveness.settled(i, x.next >= ticks, now, end_ns));
        // With a monitor, the end waits for its last verdicts too: in lockstep all of them
        // (within its timeout), in realtime for its deadline and a little more.
        let judged = match &mut self.monitor {
            None => true,
            Some(mon) => mon.judged(ticks, controlled)?,
        };
        Ok(controlled && judged)
    }
}

/// Asks the controller program `p` every tick it may be asked, closes every tick it answered
/// (and asks the next ones), and holds the torque of every tick past its deadline (realtime)
/// or fails past the timeout (lockstep). `answered` marks the agents that got a torque.
/// Returns how many ticks were asked (the program is rung once for them).
fn converse<X: Transport>(
    p: &mut ControllerProgram,
    cp: &ControllerPorts<X>,
    (slots, ports): (&mut [Slot], &Ports<X>),
    answered: &mut [bool],
    trace: &mut TraceWriter,
) -> Result<usize, CenterError> {
    let mut asked = p.ask(cp, (slots, ports), answered, trace)?;
    while p.take_answers(cp, (slots, ports), answered, trace)? > 0 {
        asked += p.ask(cp, (slots, ports), answered, trace)?;
    }
    p.enforce(monotonic_ns(), (slots, ports), answered, trace)?;
    asked += p.ask(cp, (slots, ports), answered, trace)?;
    Ok(asked)
}

/// The process of the `fdi-control-center` binary (and of `fdi-launch process
/// control-center`).
pub fn run_process(args: ProcessArgs) -> Result<role::Ended, role::Failed> {
    role::run_process(&ControlCenter, &args)
}
