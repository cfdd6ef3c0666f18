//! The in-process lockstep engine: the whole run on one thread, with the same per-process
//! pieces ([`Plant`], [`crate::attack::AgentAttack`], [`CenterAgent`]) and the same order of
//! floating-point operations as the multi-process runtime. It is the oracle for tests and the
//! floor for the IPC overhead benchmark.
//!
//! The attacker is a value: [`run_inproc_any`] runs the scenario's attack profile
//! ([`crate::attack::ProfileAttacker`]); [`run_inproc_any_with`] runs any [`Attacker`] a caller
//! supplies. Each robot runs with its own number of joints: a team may mix arms. A run whose
//! torques a program decides (`[controller] mode = "external"`) is [`Asking`]'s: the caller
//! gives it the program ([`TorqueProgram`]; the launcher's is the control center's `Asker`,
//! which asks a program over shared memory as the control-center process does).

use std::collections::BTreeMap;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::attack::{Attacker, Injection, Sent, TorqueInjection};
use crate::control::{Answer, CenterAgent, CenterOutput, ControllerMode, Question};
use crate::metrics::{AgentMetrics, Evaluator};
use crate::model::primed::{prime, Wants};
use crate::model::robot::SIDE_BY_SIDE_MIN;
use crate::model::Vector;
use crate::plant::{Measurement, Plant, StepReport};
use crate::records::{
    ActuationRecord, AgentRecord, AttackRecord, CenterRecord, Joints, TickRecord, TraceDigest,
};
use crate::scenario::{AgentConfig, Resolved, Scenario};

/// The time of tick `k` ([`crate::time`], where the pieces the engine runs take it too).
pub use crate::time::tick_time;

/// The control center's tick from what reached it: the delivered measurement, or, when the
/// tick's input is missing, the last good one held ([`CenterAgent::tick_missing`]).
pub fn center_tick<const N: usize>(
    center: &mut CenterAgent<N>,
    t: f64,
    input: Option<&Measurement<N>>,
) -> CenterOutput<N> {
    match input {
        Some(m) => center.tick(t, &m.y, &m.yd),
        None => center.tick_missing(t),
    }
}

/// Builds the agent's record of tick `k` (true state captured before the step).
pub fn agent_record<const N: usize>(
    k: u64,
    agent: u32,
    t: f64,
    state: (&Vector<N>, &Vector<N>),
    m: &Measurement<N>,
    step: &StepReport<N>,
) -> AgentRecord {
    AgentRecord {
        k,
        agent,
        t,
        q: state.0.into(),
        qd: state.1.into(),
        qdd: step.qdd.into(),
        y: m.y.into(),
        yd: m.yd.into(),
        u_applied: step.u_applied.into(),
        tau: step.tau,
        missed: step.missed,
    }
}

/// Builds the attacker's record of tick `k` for one agent's measurement (`active`: the attack
/// is in force).
pub fn attack_record<const N: usize>(
    k: u64,
    agent: u32,
    sent: &Sent<Measurement<N>>,
    inj: &Injection<N>,
) -> AttackRecord {
    let (y, yd) = sent
        .usable()
        .map_or((Joints::default(), Joints::default()), |(m, _)| {
            (m.y.into(), m.yd.into())
        });
    AttackRecord {
        k,
        agent,
        alpha_position: inj.position.into(),
        alpha_velocity: inj.velocity.into(),
        y,
        yd,
        active: inj.in_force(),
        delivery: sent.delivery(),
    }
}

/// Builds the attacker's record of the torque of tick `k` for one agent.
pub fn actuation_record<const N: usize>(
    k: u64,
    agent: u32,
    sent: &Sent<Vector<N>>,
    inj: &TorqueInjection<N>,
) -> ActuationRecord {
    let (u, held_s) = sent
        .usable()
        .map_or((Joints::default(), 0.0), |(u, h)| (u.into(), h));
    ActuationRecord {
        k,
        agent,
        alpha_u: inj.u.into(),
        u,
        held_s,
        active: inj.in_force(),
        delivery: sent.delivery(),
    }
}

/// Builds the control center's record of tick `k` for one agent.
pub fn center_record<const N: usize>(k: u64, agent: u32, o: &CenterOutput<N>) -> CenterRecord {
    CenterRecord {
        k,
        agent,
        s_hat: o.s_hat.into(),
        q_hat: o.q_hat.into(),
        qd_hat: o.qd_hat.into(),
        qdd_hat: o.qdd_hat.into(),
        u: o.u.into(),
        alarm: o.alarm,
        rejected_input: o.rejected_input,
        rejected_torque: o.rejected_torque,
        state_reset: o.state_reset,
        history_miss: o.history_miss,
        missing_input: o.missing_input,
    }
}

/// A realtime agent that died or fell silent while the run went on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LostAgent {
    pub agent: u32,
    /// Sim time of the last tick heard from it, when the control center reported the loss.
    pub t_s: Option<f64>,
    /// How it ended (exit status or signal) or `fell silent`.
    pub reason: String,
    /// Sim time of the tick at which it was heard from again and controlled again (it
    /// rejoined: the gap is from `t_s` to here); `None` while it stayed lost to the end.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rejoined_t_s: Option<f64>,
}

/// Summary of a run, as `run --json` prints it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunSummary {
    pub scenario: String,
    pub engine: String,
    pub clock: String,
    pub controller: String,
    pub attack: String,
    pub seed: u64,
    pub agents: usize,
    /// Ticks joined (every process recorded them): what the metrics cover at most.
    pub ticks: u64,
    /// Ticks of the scenario as planned; `ticks` (and each robot's `metrics.ticks`) of it is the
    /// share the metrics cover. 0 in summaries written before it existed.
    #[serde(default)]
    pub planned_ticks: u64,
    #[serde(with = "crate::json_float")]
    pub sim_s: f64,
    #[serde(with = "crate::json_float")]
    pub wall_s: f64,
    /// RMSE per agent id, rad.
    #[serde(with = "crate::json_float::map")]
    pub rmse_rad: BTreeMap<String, f64>,
    pub trace_digest: String,
    /// Per agent id: RMSE, detection, rejected inputs, deadline misses.
    pub metrics: BTreeMap<String, AgentMetrics>,
    /// Realtime agents lost during the run (their metrics cover the time before the loss).
    #[serde(default)]
    pub lost_agents: Vec<LostAgent>,
    /// How the run's processes were placed when not left to the defaults: `SCHED_FIFO 10 on
    /// CPUs 1` (`--rt-priority`, `--cpus`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub placement: Option<String>,
    /// A run split over hosts (`--hosts`): one line per host, its processes and its clock.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub hosts: Vec<String>,
    /// A run split over hosts: how its network path was secured and what it refused.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub network: Option<NetworkPath>,
    /// A run watched live (`--live`): what its server published and what it lost.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub live: Option<LiveStats>,
    /// Set when the run ended before its scenario's end (interrupted): every metric covers the
    /// `ticks` recorded, not the `planned_ticks`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub partial: Option<Partial>,
    /// The controller and numerics options of the run that differ from the paper's
    /// calibration (empty: the paper's); [`crate::numerics`].
    #[serde(default)]
    pub numerics: Vec<crate::numerics::Difference>,
}

/// The network path of a run split over hosts.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct NetworkPath {
    /// TLS with mutual authentication and per-host access control between the hosts; false:
    /// plain TCP, which anyone on the network could read and write (the deployment file said
    /// `insecure = true`).
    pub authenticated: bool,
    /// Frames the hosts' bridges refused on the run's keys: from a host that does not send that
    /// stream in the run, or out of order (forged, duplicated or replayed). Any: the run's data
    /// may have been altered outside the attacker process, and its results cannot be
    /// attributed to its attack (exit 6).
    pub refused_frames: u64,
    /// Per host that refused any: how many and the first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub refusals: Vec<String>,
}

/// What the live server of a run (`run --live`) did. Nothing it did changes the run: these
/// count what viewers were shown.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LiveStats {
    /// The address it listened on (`ws://…`).
    pub address: String,
    /// Clients that connected during the run.
    pub clients: u64,
    /// Ticks whose messages were published while a client subscribed to some topic (the
    /// stream is decimated: docs/traces.md).
    pub ticks_published: u64,
    /// Messages handed to the server for at least one subscribed client.
    pub messages_published: u64,
    /// Joined ticks' records the server never saw: its queue was full (the run does not wait
    /// for it). Any: the detectors' topics stopped at the first, their statistics need every
    /// tick.
    pub records_dropped: u64,
    /// Events and latency stamps the server never saw (its queue was full).
    #[serde(default)]
    pub events_dropped: u64,
    /// Messages (the run's data and time broadcasts) dropped from slow clients' outboxes, oldest
    /// first, summed over clients (the run never waits for a client).
    #[serde(default)]
    pub client_messages_dropped: u64,
    /// Clients let go: their outbox was full of the protocol's control messages, or they came
    /// when the most connections were open.
    #[serde(default)]
    pub clients_let_go: u64,
    /// Connections the SDK's server took that did not come through the door (a process of
    /// this machine that connected to its loopback port: outside the door's cap and counts).
    #[serde(default)]
    pub clients_outside_the_door: u64,
    /// The first message that could not be made (none expected; said rather than hidden).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// What a run that ended early covers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Partial {
    /// Why it ended early, e.g. `interrupted by SIGINT`.
    pub reason: String,
    /// Ticks of the scenario as planned (`ticks` of the summary holds those recorded).
    pub planned_ticks: u64,
    /// The signal that interrupted the run, if a signal did.
    #[serde(default)]
    pub signal: Option<i32>,
}

impl RunSummary {
    /// True when the control center lost every robot for good (none rejoined): from then on no
    /// robot was controlled, so the run failed whatever its metrics say.
    pub fn lost_every_agent(&self) -> bool {
        let mut gone: Vec<u32> = self
            .lost_agents
            .iter()
            .filter(|l| l.rejoined_t_s.is_none())
            .map(|l| l.agent)
            .collect();
        gone.sort_unstable();
        gone.dedup();
        self.agents > 0 && gone.len() >= self.agents
    }

    /// `(agent, uncontrolled ticks, ticks it recorded)` of every robot that ran without control
    /// for some ticks, in agent order.
    pub fn uncontrolled(&self) -> Vec<(&str, u64, u64)> {
        self.metrics
            .iter()
            .filter(|(_, m)| m.uncontrolled_ticks > 0)
            .map(|(id, m)| (id.as_str(), m.uncontrolled_ticks, m.agent_ticks))
            .collect()
    }

    /// `(agent, deadline misses, steps it recorded)` of every robot that fell behind its clock:
    /// it missed more than [`MISSES_TOLERATED`] of its steps' deadlines (a realtime run on an
    /// overloaded machine, or at a rate the machine cannot keep), in agent order.
    pub fn fell_behind(&self) -> Vec<(&str, u64, u64)> {
        self.metrics
            .iter()
            .filter(|(_, m)| m.deadline_misses as f64 > MISSES_TOLERATED * m.agent_ticks as f64)
            .map(|(id, m)| (id.as_str(), m.deadline_misses, m.agent_ticks))
            .collect()
    }

    /// Whether the run is not a clean one though every robot was controlled to its end: a
    /// robot lost for a while, one that ran uncontrolled for some ticks, or one that fell
    /// behind its clock (exit status 3).
    pub fn not_clean(&self) -> bool {
        !self.lost_agents.is_empty()
            || !self.uncontrolled().is_empty()
            || !self.fell_behind().is_empty()
    }

    /// `(agent, t)` of every robot that diverged, in agent order.
    pub fn diverged(&self) -> Vec<(&str, f64)> {
        self.metrics
            .iter()
            .filter_map(|(id, m)| m.diverged_at_s.map(|t| (id.as_str(), t)))
            .collect()
    }
}

/// The share of its steps whose deadline a robot may miss (the command due not in force) in a
/// clean run: beyond it the run fell behind its clock, and it is a result, not a clean one
/// (exit status 3). A loaded machine misses a few (docs/performance.md).
pub const MISSES_TOLERATED: f64 = 0.10;

/// Joins metrics and digest into a summary.
pub fn summarize(
    resolved: &Resolved,
    engine: &str,
    ticks: u64,
    wall_s: f64,
    digest: TraceDigest,
    evaluator: Evaluator,
) -> RunSummary {
    let s = &resolved.scenario;
    let metrics: BTreeMap<String, AgentMetrics> = evaluator
        .finish()
        .into_iter()
        .map(|(id, m)| (id.to_string(), m))
        .collect();
    RunSummary {
        scenario: s.name.clone(),
        engine: engine.into(),
        clock: s.clock.as_str().into(),
        controller: s.controller.mode.as_str().into(),
        attack: resolved.attack_name(),
        seed: s.seed,
        agents: s.agents.len(),
        ticks,
        planned_ticks: resolved.ticks(),
        sim_s: tick_time(ticks, s.control_period_s),
        wall_s,
        rmse_rad: metrics
            .iter()
            .map(|(id, m)| (id.clone(), m.rmse_rad))
            .collect(),
        trace_digest: digest.finish(),
        metrics,
        lost_agents: Vec::new(),
        placement: None,
        hosts: Vec::new(),
        network: None,
        live: None,
        partial: None,
        numerics: crate::numerics::differences_from_paper(s, crate::numerics::Compare::WithMode),
    }
}

/// An evaluator for the agents of `resolved`, with the scenario's detectors beside the paper's
/// alarm.
pub fn evaluator_for(resolved: &Resolved) -> Evaluator {
    let s = &resolved.scenario;
    let evaluator = Evaluator::new(
        s.agents
            .iter()
            .map(|a| (a.id, a.trajectory.clone(), a.model.clone())),
    )
    .with_detectors(&s.detectors, s.control_period_s, &s.controller);
    match s.roles.monitor_name() {
        Some(name) => evaluator.with_monitor(name),
        None => evaluator,
    }
}

/// Errors of the engine.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    #[error("agent {agent}: its model does not have {dof} links")]
    ModelDof { agent: u32, dof: usize },
    #[error("the scenario has no agents")]
    NoAgents,
    #[error(
        "controller `external` asks a program for its torques (`[roles.controller]`): the \
         in-process engine cannot run it without that program (`fdi-launch run` starts it, on \
         either engine)"
    )]
    ExternalController,
    #[error("controller `{0}` decides the torques itself: no program is asked")]
    NotExternal(&'static str),
    /// The program that decides the torques failed, broke the protocol, or the run was stopped
    /// while it waited.
    #[error("{0}")]
    Program(Box<dyn std::error::Error + Send + Sync>),
}

/// Runs `resolved` to the end on this thread; `sink` sees every joined tick record in digest
/// order (tick, then agent order of the scenario). The attacker is the scenario's attack
/// profile ([`Resolved::profile_attacker`]). Each robot runs with its own number of joints.
pub fn run_inproc_any(
    resolved: &Resolved,
    sink: impl FnMut(&TickRecord),
) -> Result<RunSummary, EngineError> {
    run_inproc_any_with(resolved, &mut resolved.profile_attacker(), sink)
}

/// [`run_inproc_any`] with `attacker` in place of the scenario's attack profile (whose
/// `attack` is then ignored): at each tick and for each agent, in the scenario's agent order,
/// the engine asks it for the measurement the control center receives, then, when it sits on
/// the agent's torque path, for the torque the robot receives ([`Attacker`] says what its
/// answers must say). The summary's `attack` is [`Attacker::name`].
pub fn run_inproc_any_with<A: Attacker>(
    resolved: &Resolved,
    attacker: &mut A,
    sink: impl FnMut(&TickRecord),
) -> Result<RunSummary, EngineError> {
    run_inproc_any_until(resolved, attacker, sink, || true)
}

/// [`run_inproc_any_with`] that asks `go_on` before each tick and stops where it says no (an
/// interrupt): the summary then covers the ticks run (`ticks` says how many; the caller says
/// why in its `partial`).
pub fn run_inproc_any_until<A: Attacker>(
    resolved: &Resolved,
    attacker: &mut A,
    mut sink: impl FnMut(&TickRecord),
    go_on: impl FnMut() -> bool,
) -> Result<RunSummary, EngineError> {
    // What `Lockstep` does tick by tick: each record into the books, then to the sink.
    let mut books = Books::new(resolved);
    let ticked = tick_inproc_any_with(
        resolved,
        attacker,
        |rec| {
            books.push(rec);
            sink(rec);
        },
        go_on,
    )?;
    Ok(books.summary(resolved, ticked.ticks, ticked.wall_s, attacker.name()))
}

/// The books of a run: the trace digest and the metrics of every joined tick record, in
/// digest order. [`Lockstep`] keeps them as it ticks; a caller of [`tick_inproc_any_with`]
/// keeps them from the records its sink sees (on another thread, say), to the same bits.
#[derive(Debug)]
pub struct Books {
    digest: TraceDigest,
    evaluator: Evaluator,
}

impl Books {
    /// Empty books for the run of `resolved`.
    pub fn new(resolved: &Resolved) -> Self {
        Self {
            digest: TraceDigest::new(),
            evaluator: evaluator_for(resolved),
        }
    }

    /// Enters the next record (digest order).
    pub fn push(&mut self, rec: &TickRecord) {
        self.digest.push(rec);
        self.evaluator.push(rec);
    }

    /// The metrics so far.
    pub fn evaluator(&self) -> &Evaluator {
        &self.evaluator
    }

    /// The summary of an in-process run of `ticks` ticks in `wall_s`, under the attack name
    /// `attack`.
    pub fn summary(self, resolved: &Resolved, ticks: u64, wall_s: f64, attack: &str) -> RunSummary {
        let mut summary = summarize(
            resolved,
            "inproc",
            ticks,
            wall_s,
            self.digest,
            self.evaluator,
        );
        summary.attack = attack.to_owned();
        summary
    }
}

/// One robot's plant and its control center's pipeline, with the robot's number of joints.
#[derive(Debug)]
struct AgentLoop<const N: usize> {
    plant: Plant<N>,
    center: CenterAgent<N>,
    /// A tick asked of a program and not answered yet ([`Self::ask`]).
    asked: Option<Measured<N>>,
}

crate::per_joint_count!(
    /// An [`AgentLoop`] of any joint count: a team may mix robots.
    #[derive(Debug)]
    enum AnyLoop = AgentLoop
);

impl<const N: usize> AgentLoop<N> {
    fn new(s: &Scenario, a: &AgentConfig) -> Option<Self> {
        Some(Self {
            plant: Plant::<N>::new(s.plant_params(a))?,
            center: CenterAgent::<N>::new(s.center_params(a))?,
            asked: None,
        })
    }

    /// Sets its control center's torque correction: `N` entries, or none; else `Err(N)`.
    fn set_correction(&mut self, c: &[f64]) -> Result<(), usize> {
        match c.len() {
            0 => self.center.set_correction(None),
            n if n == N => self
                .center
                .set_correction(Some(Vector::<N>::from_column_slice(c))),
            _ => return Err(N),
        }
        Ok(())
    }

    /// Tick `k` at `t` of this robot, with `attacker` ([`run_inproc_any_with`] says how it is
    /// asked); `sink` sees its record.
    fn tick<A: Attacker>(
        &mut self,
        attacker: &mut A,
        (k, t): (u64, f64),
        sink: &mut impl FnMut(&TickRecord),
    ) {
        let open = self.measure(attacker, (k, t));
        let out = center_tick(&mut self.center, t, open.sent.usable().map(|(m, _)| m));
        self.close(attacker, (k, t), open, &out, sink);
    }

    /// The first half of tick `k` at `t`: the state before the step, the measurement, and what
    /// `attacker` made of it on its way to the control center.
    fn measure<A: Attacker>(&mut self, attacker: &mut A, (k, t): (u64, f64)) -> Measured<N> {
        let (q, qd) = (self.plant.q, self.plant.qd);
        let m = self.plant.measure();
        let (sent, inj) = attacker.measurement::<N>(self.plant.agent_id(), k, t, &m);
        Measured {
            q,
            qd,
            m,
            sent,
            inj,
        }
    }

    /// The second half of tick `k` at `t`, once the control center decided `out`: its torque
    /// on its way to the robot ([`Self::hand`]), the robot's step, and the tick's record to
    /// `sink`.
    fn close<A: Attacker>(
        &mut self,
        attacker: &mut A,
        (k, t): (u64, f64),
        open: Measured<N>,
        out: &CenterOutput<N>,
        sink: &mut impl FnMut(&TickRecord),
    ) {
        let actuation = self.hand(attacker, (k, t), out);
        let step = self.plant.advance(k);
        sink(&self.record((k, t), open, out, actuation, &step));
    }

    /// The torque `out` of tick `k` at `t` on its way to the robot (through `attacker` when it
    /// sits on the torque path), taken by the plant; what the attacker did to it.
    fn hand<A: Attacker>(
        &mut self,
        attacker: &mut A,
        (k, t): (u64, f64),
        out: &CenterOutput<N>,
    ) -> Option<ActuationRecord> {
        let plant = &mut self.plant;
        let id = plant.agent_id();
        // A refused or missing command is counted by the plant; the run goes on.
        if attacker.on_torque_path(id) {
            let (sent, tinj) = attacker.torque::<N>(id, k, t, &out.u);
            let _ = plant.take_command(t, sent.usable().map(|(u, h)| (*u, h)));
            Some(actuation_record(k, id, &sent, &tinj))
        } else {
            let _ = plant.take_command(t, Some((out.u, 0.0)));
            None
        }
    }

    /// The record of tick `k` at `t` once the robot took its `step`.
    fn record(
        &self,
        (k, t): (u64, f64),
        Measured {
            q,
            qd,
            m,
            sent,
            inj,
        }: Measured<N>,
        out: &CenterOutput<N>,
        actuation: Option<ActuationRecord>,
        step: &StepReport<N>,
    ) -> TickRecord {
        let id = self.plant.agent_id();
        TickRecord {
            agent: agent_record(k, id, t, (&q, &qd), &m, step),
            attack: attack_record(k, id, &sent, &inj),
            center: center_record(k, id, out),
            actuation,
            monitor: None,
        }
    }

    /// The first half of tick `k` at `t` of a robot whose torques a program decides: measured
    /// as in [`Self::tick`], the tick opened at the control center and its question asked of
    /// `program`.
    fn ask<A: Attacker, P: TorqueProgram>(
        &mut self,
        attacker: &mut A,
        program: &mut P,
        (k, t): (u64, f64),
    ) -> Result<(), P::Error> {
        let open = self.measure(attacker, (k, t));
        let input = open.sent.usable().map(|(m, _)| (&m.y, &m.yd));
        let question = self.center.ask(t, input);
        self.asked = Some(open);
        program.ask(k, self.plant.agent_id(), &question)
    }

    /// The second half of the tick [`Self::ask`] asked: `program`'s answer (none usable: the
    /// last good torque held, as [`CenterAgent::answer`] says), then as [`Self::tick`].
    fn answer<A: Attacker, P: TorqueProgram>(
        &mut self,
        attacker: &mut A,
        program: &mut P,
        (k, t): (u64, f64),
        sink: &mut impl FnMut(&TickRecord),
    ) -> Result<(), P::Error> {
        let id = self.plant.agent_id();
        let answer = program.answer::<N>(k, id)?;
        let (Some(open), Some(out)) = (self.asked.take(), self.center.answer(answer.as_ref()))
        else {
            // [`Asking::tick`] asks every agent before it takes any answer.
            unreachable!("agent {id}: tick {k} answered without being asked");
        };
        self.close(attacker, (k, t), open, &out, sink);
        Ok(())
    }
}

/// What the first half of a robot's tick measured ([`AgentLoop::measure`]).
#[derive(Debug)]
struct Measured<const N: usize> {
    q: Vector<N>,
    qd: Vector<N>,
    m: Measurement<N>,
    sent: Sent<Measurement<N>>,
    inj: Injection<N>,
}

/// The program that decides the torques of a run whose controller is `external`
/// (`[roles.controller]`), as the in-process engine asks it ([`Asking`]): each tick, the
/// question of every agent (what the control center shows a controller:
/// [`CenterAgent::ask`]), in the scenario's agent order, then the answer of each, in the same
/// order. The multi-process control center asks it the same questions over shared memory.
pub trait TorqueProgram {
    /// Why the run cannot go on (the program failed, broke the protocol, or was stopped).
    type Error;
    /// Asks tick `k` of agent `agent`.
    fn ask<const N: usize>(
        &mut self,
        k: u64,
        agent: u32,
        question: &Question<N>,
    ) -> Result<(), Self::Error>;
    /// The answer to tick `k` of agent `agent`, asked before: `None` when it is not usable
    /// (another number of joints, a non-finite entry): the last good torque is then held.
    fn answer<const N: usize>(
        &mut self,
        k: u64,
        agent: u32,
    ) -> Result<Option<Answer<N>>, Self::Error>;
}

/// The in-process engine's ticking alone: every agent's plant, attacker and control center,
/// tick by tick, each joined record handed to a sink. [`Lockstep`] is this with its [`Books`].
/// Each robot runs with its own number of joints.
#[derive(Debug)]
pub struct Ticker {
    loops: Vec<AnyLoop>,
    /// The loops, cut into runs of consecutive robots of one model whose plants step side by
    /// side ([`Plant::advance_side_by_side`]); a robot of its own is a run of one.
    runs: Vec<std::ops::Range<usize>>,
    control_period_s: f64,
    k: u64,
    ticks: u64,
    started: Instant,
}

impl Ticker {
    /// The run of `resolved` at its start (tick 0 next). A run whose torques a program decides
    /// is [`Asking`]'s.
    pub fn new(resolved: &Resolved) -> Result<Self, EngineError> {
        // Its ticks would go unanswered: every torque held at zero, a run of wrong numbers.
        if resolved.scenario.controller.mode == ControllerMode::External {
            return Err(EngineError::ExternalController);
        }
        Self::build(resolved)
    }

    fn build(resolved: &Resolved) -> Result<Self, EngineError> {
        let s = &resolved.scenario;
        if s.agents.is_empty() {
            return Err(EngineError::NoAgents);
        }
        let mut loops = Vec::with_capacity(s.agents.len());
        for a in &s.agents {
            let dof = a.model.dof();
            let agent =
                crate::with_joint_count!(dof, N => AgentLoop::<N>::new(s, a).map(AnyLoop::from));
            loops.push(
                agent
                    .flatten()
                    .ok_or(EngineError::ModelDof { agent: a.id, dof })?,
            );
        }
        Ok(Self {
            runs: side_by_side(&s.agents, &loops),
            loops,
            control_period_s: s.control_period_s,
            k: 0,
            ticks: resolved.ticks(),
            started: Instant::now(),
        })
    }

    /// The next tick to run.
    pub fn k(&self) -> u64 {
        self.k
    }

    /// Ticks of the run as planned.
    pub fn ticks(&self) -> u64 {
        self.ticks
    }

    /// Seconds since the start.
    pub fn wall_s(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }

    /// Sets the torque correction of agent `agent`'s control center
    /// ([`CenterAgent::set_correction`]): `correction` holds one entry per joint of its robot,
    /// or none (no correction). Errors naming the agent or the count when they do not fit.
    pub fn set_correction(&mut self, agent: u32, correction: &[f64]) -> Result<(), String> {
        let Some(l) = self
            .loops
            .iter_mut()
            .find(|l| crate::on_joint_count!(AnyLoop, &**l, a => a.plant.agent_id()) == agent)
        else {
            return Err(format!("agent {agent} is not an agent of the run"));
        };
        crate::on_joint_count!(AnyLoop, l, a => a.set_correction(correction)).map_err(|n| {
            format!(
                "agent {agent}: a correction of {} entries for {n} joints",
                correction.len()
            )
        })
    }

    /// Runs the next tick of every agent, in the scenario's agent order, with `attacker`
    /// ([`run_inproc_any_with`] says how it is asked); `sink` sees each agent's record. False,
    /// and nothing run, once every tick has run.
    pub fn tick<A: Attacker>(
        &mut self,
        attacker: &mut A,
        mut sink: impl FnMut(&TickRecord),
    ) -> bool {
        if self.k >= self.ticks {
            return false;
        }
        let k = self.k;
        let t = tick_time(k, self.control_period_s);
        for run in &self.runs {
            let loops = &mut self.loops[run.clone()];
            match loops {
                [one] => {
                    crate::on_joint_count!(AnyLoop, one, a => a.tick(attacker, (k, t), &mut sink))
                }
                _ => {
                    let tick =
                        crate::on_joint_count!(AnyLoop, &loops[0], a => side_by_side_tick(&**a));
                    tick(loops, attacker, (k, t), &mut sink);
                }
            }
        }
        self.k += 1;
        true
    }
}

/// The runs of [`Ticker::runs`]: consecutive agents, at least [`SIDE_BY_SIDE_MIN`], whose robots
/// are of one model that computes several states side by side
/// ([`crate::model::EulerLagrange::side_by_side`]); every other agent a run of its own.
fn side_by_side(agents: &[AgentConfig], loops: &[AnyLoop]) -> Vec<std::ops::Range<usize>> {
    let batched =
        |i: usize| crate::on_joint_count!(AnyLoop, &loops[i], a => a.plant.side_by_side());
    let mut runs: Vec<std::ops::Range<usize>> = Vec::new();
    for i in 0..agents.len() {
        match runs.last_mut() {
            Some(run)
                if batched(i)
                    && batched(run.start)
                    && agents[run.start].model == agents[i].model =>
            {
                run.end = i + 1;
            }
            _ => runs.push(i..i + 1),
        }
    }
    (runs.into_iter())
        .flat_map(|run| match run.len() {
            n if n >= SIDE_BY_SIDE_MIN => vec![run],
            _ => run.map(|i| i..i + 1).collect(),
        })
        .collect()
}

/// [`tick_side_by_side`] for robots of `first`'s joint count.
fn side_by_side_tick<const N: usize, A: Attacker, S: FnMut(&TickRecord)>(
    _first: &AgentLoop<N>,
) -> fn(&mut [AnyLoop], &mut A, (u64, f64), &mut S) {
    tick_side_by_side::<N, A, S>
}

/// Tick `k` at `t` of a run of robots of one model and `N` joints: each
/// measured, controlled and handed its torque in turn, as [`AgentLoop::tick`] does, then
/// their plants stepped side by side, then each record to `sink` in the agents' order — the
/// records of one by one, to the bit.
fn tick_side_by_side<const N: usize, A: Attacker, S: FnMut(&TickRecord)>(
    loops: &mut [AnyLoop],
    attacker: &mut A,
    (k, t): (u64, f64),
    sink: &mut S,
) {
    let mut team: Vec<&mut AgentLoop<N>> = (loops.iter_mut())
        .map(|l| {
            let any: &mut dyn std::any::Any = crate::on_joint_count!(AnyLoop, l, a => &mut **a);
            any.downcast_mut::<AgentLoop<N>>()
                .expect("a run holds robots of one model")
        })
        .collect();
    // The control centers' `M(q_d)⁻¹` and drifts of the tick, side by side.
    let wants: Vec<Wants<N>> = team.iter_mut().map(|a| a.center.wants(t)).collect();
    let primes = prime(team[0].center.model(), &wants);
    for (a, primes) in team.iter_mut().zip(primes) {
        a.center.prime(primes);
    }
    let mut opened = Vec::with_capacity(team.len());
    for a in team.iter_mut() {
        let open = a.measure(attacker, (k, t));
        let out = center_tick(&mut a.center, t, open.sent.usable().map(|(m, _)| m));
        let actuation = a.hand(attacker, (k, t), &out);
        opened.push((open, out, actuation));
    }
    let steps = {
        let mut plants: Vec<&mut Plant<N>> = team.iter_mut().map(|a| &mut a.plant).collect();
        Plant::advance_side_by_side(&mut plants, k)
    };
    for ((a, (open, out, actuation)), step) in team.iter().zip(opened).zip(&steps) {
        sink(&a.record((k, t), open, &out, actuation, step));
    }
}

/// The in-process engine when a program decides the torques (`[controller] mode =
/// "external"`, `[roles.controller]`): [`Ticker`] whose ticks are asked of a [`TorqueProgram`]
/// side by side, every agent's question of a tick before any answer, as the multi-process
/// control center asks them. Its records are those of the same run over IPC.
#[derive(Debug)]
pub struct Asking(Ticker);

impl Asking {
    /// The run of `resolved` at its start (tick 0 next).
    pub fn new(resolved: &Resolved) -> Result<Self, EngineError> {
        let mode = resolved.scenario.controller.mode;
        if mode != ControllerMode::External {
            return Err(EngineError::NotExternal(mode.as_str()));
        }
        Ticker::build(resolved).map(Self)
    }

    /// The next tick to run.
    pub fn k(&self) -> u64 {
        self.0.k
    }

    /// Seconds since the start.
    pub fn wall_s(&self) -> f64 {
        self.0.wall_s()
    }

    /// Runs the next tick of every agent, its torques decided by `program`, with `attacker`
    /// ([`run_inproc_any_with`] says how it is asked); `sink` sees each agent's record, in the
    /// scenario's agent order. False, and nothing run, once every tick has run; the program's
    /// error stops the run where it came (the records of the tick not yet seen).
    pub fn tick<A: Attacker, P: TorqueProgram>(
        &mut self,
        attacker: &mut A,
        program: &mut P,
        mut sink: impl FnMut(&TickRecord),
    ) -> Result<bool, P::Error> {
        let ticker = &mut self.0;
        if ticker.k >= ticker.ticks {
            return Ok(false);
        }
        let k = ticker.k;
        let kt = (k, tick_time(k, ticker.control_period_s));
        for agent in &mut ticker.loops {
            crate::on_joint_count!(AnyLoop, agent, a => a.ask(attacker, program, kt))?;
        }
        for agent in &mut ticker.loops {
            crate::on_joint_count!(AnyLoop, agent, a => {
                a.answer(attacker, program, kt, &mut sink)
            })?;
        }
        ticker.k += 1;
        Ok(true)
    }
}

/// The in-process engine one tick at a time: what [`run_inproc_any_with`] runs to the end, for a
/// caller that decides between ticks (an environment whose agent acts every few ticks).
/// Ticking it to the end and finishing it is, record for record and digest for digest,
/// [`run_inproc_any_with`].
#[derive(Debug)]
pub struct Lockstep {
    ticker: Ticker,
    books: Books,
}

impl Lockstep {
    /// The run of `resolved` at its start (tick 0 next).
    pub fn new(resolved: &Resolved) -> Result<Self, EngineError> {
        Ok(Self {
            ticker: Ticker::new(resolved)?,
            books: Books::new(resolved),
        })
    }

    /// The next tick to run.
    pub fn k(&self) -> u64 {
        self.ticker.k()
    }

    /// Ticks of the run as planned.
    pub fn ticks(&self) -> u64 {
        self.ticker.ticks()
    }

    /// The metrics so far (and, through them, each detector's alarm after the last tick).
    pub fn evaluator(&self) -> &Evaluator {
        self.books.evaluator()
    }

    /// [`Ticker::set_correction`].
    pub fn set_correction(&mut self, agent: u32, correction: &[f64]) -> Result<(), String> {
        self.ticker.set_correction(agent, correction)
    }

    /// [`Ticker::tick`], each record entered in the books before `sink` sees it.
    pub fn tick<A: Attacker>(
        &mut self,
        attacker: &mut A,
        mut sink: impl FnMut(&TickRecord),
    ) -> bool {
        let books = &mut self.books;
        self.ticker.tick(attacker, |rec| {
            books.push(rec);
            sink(rec);
        })
    }

    /// The summary of the ticks run (all of them, or the first [`Self::k`] when it stopped
    /// early: `ticks` then says how many), under the attack name `attack`.
    pub fn finish(self, resolved: &Resolved, attack: &str) -> RunSummary {
        let (ticks, wall_s) = (self.ticker.k(), self.ticker.wall_s());
        self.books.summary(resolved, ticks, wall_s, attack)
    }
}

/// What [`tick_inproc_any_with`] ran: its ticks and its wall time, s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ticked {
    pub ticks: u64,
    pub wall_s: f64,
}

/// [`run_inproc_any_with`] without its books: `sink` sees every record, in digest order, and
/// the caller keeps the [`Books`] from them (on another thread, say: the command line's run
/// digests, evaluates and writes the records there while this thread ticks). [`Books::summary`]
/// of those books is [`run_inproc_any_with`]'s summary, to the bit. `go_on` is asked before
/// each tick: where it says no (an interrupt), the run stops, and `ticks` says how far it got.
pub fn tick_inproc_any_with<A: Attacker>(
    resolved: &Resolved,
    attacker: &mut A,
    mut sink: impl FnMut(&TickRecord),
    mut go_on: impl FnMut() -> bool,
) -> Result<Ticked, EngineError> {
    let mut ticker = Ticker::new(resolved)?;
    while go_on() && ticker.tick(attacker, &mut sink) {}
    Ok(Ticked {
        ticks: ticker.k(),
        wall_s: ticker.wall_s(),
    })
}

/// [`tick_inproc_any_with`] for a run whose torques `program` decides ([`Asking`]): a failure
/// of the program stops the run ([`EngineError::Program`]).
pub fn tick_inproc_asking<A: Attacker, P: TorqueProgram>(
    resolved: &Resolved,
    (attacker, program): (&mut A, &mut P),
    mut sink: impl FnMut(&TickRecord),
    mut go_on: impl FnMut() -> bool,
) -> Result<Ticked, EngineError>
where
    P::Error: std::error::Error + Send + Sync + 'static,
{
    let mut asking = Asking::new(resolved)?;
    while go_on() {
        match asking.tick(attacker, program, &mut sink) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => return Err(EngineError::Program(Box::new(e))),
        }
    }
    Ok(Ticked {
        ticks: asking.k(),
        wall_s: asking.wall_s(),
    })
}
