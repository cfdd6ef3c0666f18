//! The control center's side of a controller program (`[roles.controller]`, docs/protocol.md,
//! "The controller program"): each tick of each agent is asked of the program on
//! `fdi/external/controller/in` (what the pipeline shows a controller: the measurement in use,
//! the reference, `e_u`, the delay, the model's terms), and its answer on
//! `fdi/external/controller/out` is the torque sent. An agent's next tick is asked once its
//! last one is answered (its `e_u` integrates that torque); the agents are asked side by side.
//!
//! An answer with the wrong number of joints or a non-finite number holds the last good torque,
//! counted and named in the closing note; an answer out of order or for an unknown agent stops
//! the run, naming the program. Lockstep waits for every answer, at most `timeout_s`; in
//! realtime a tick unanswered `deadline_ms` after its tick's time holds the last good torque
//! (its answer, when it comes, is dropped and counted), and a tick already past its deadline
//! when its turn comes is closed at once (asked all the same): the control center keeps the
//! run's pace.

use std::collections::{BTreeSet, VecDeque};
use std::time::{Duration, Instant};

use fdi_common::control::{Answer, AnyCenterAgent, CenterAgent, Command, Question};
use fdi_common::engine::tick_time;
use fdi_common::roles::ExternalRole;
use fdi_common::trace::TraceWriter;
use fdi_runtime::ipc::msg::{from_matrix, from_vector, to_vector};
use fdi_runtime::ipc::{
    monotonic_ns, ControllerInMsg, ControllerOutMsg, Inbox as _, IpcError, MeasurementMsg,
    Outbox as _, Stream, Transport, Wake, Waker as _,
};
use fdi_runtime::process::external::LateBell;
use fdi_runtime::process::RoleError;

use crate::{deliver, Ports, Slot};

/// The ports towards the controller program.
#[derive(Debug)]
pub struct ControllerPorts<X: Transport> {
    pub questions: X::Outbox<ControllerInMsg>,
    pub answers: X::Inbox<ControllerOutMsg>,
    /// The program's wake-up event.
    pub bell: LateBell<X>,
}

impl<X: Transport> ControllerPorts<X> {
    pub fn open(transport: &X) -> Result<Self, IpcError> {
        Ok(Self {
            questions: transport.publisher(Stream::ControllerIn)?,
            answers: transport.subscriber(Stream::ControllerOut)?,
            bell: LateBell::open(transport, Wake::ExternalController)?,
        })
    }
}

/// A measurement admitted for a tick, waiting until its agent's last tick is answered.
#[derive(Debug, Clone, Copy)]
struct Admitted {
    m: MeasurementMsg,
    /// Its values are the tick's measurement (else the tick's input is missing).
    usable: bool,
    received: u64,
}

/// What the program did over the run.
#[derive(Debug, Default, Clone, Copy)]
struct Tally {
    answers: u64,
    /// Answers with a non-finite torque or `Ŝ` (the last good torque held).
    non_finite: u64,
    /// Answers with another number of joints than their agent's (the last good torque held).
    wrong_dof: u64,
    /// Realtime: ticks unanswered at their deadline (the last good torque held).
    late: u64,
    /// Realtime: answers that came after their tick was given up (dropped).
    dropped_late: u64,
}

/// The rules of the exchange with a controller program, the same whichever engine asks it
/// (the control center's [`ControllerProgram`], the in-process engine's [`Asker`]): whom it
/// answers for, what an answer must say, and what it did over the run.
#[derive(Debug)]
pub struct Exchange {
    label: String,
    ids: Vec<u32>,
    /// Lockstep: the longest wait for an answer.
    timeout: Duration,
    tally: Tally,
}

impl Exchange {
    /// The program of `role` for the agents `ids`.
    pub fn new(role: &ExternalRole, ids: &[u32]) -> Self {
        Self {
            label: role.label(),
            ids: ids.to_vec(),
            timeout: role.timeout(),
            tally: Tally::default(),
        }
    }

    fn violation(&self, what: String) -> RoleError {
        RoleError::External(format!("controller `{}`: {what}", self.label))
    }

    /// Where the agent `agent` stands among the agents asked (`None`: not one of them).
    fn index(&self, agent: u32) -> Option<usize> {
        self.ids.iter().position(|&id| id == agent)
    }

    /// Where the agent answer `a` is for stands; an agent the run does not have stops the run.
    fn agent_of(&self, a: &ControllerOutMsg) -> Result<usize, RoleError> {
        self.index(a.agent).ok_or_else(|| {
            self.violation(format!(
                "answer for agent {}, which the run does not have (tick {})",
                a.agent, a.seq
            ))
        })
    }

    /// An answer `a` for another tick than `asked`, the one asked of its agent (`None`: none
    /// was).
    fn out_of_order(&self, a: &ControllerOutMsg, asked: Option<u64>) -> RoleError {
        let what = match asked {
            Some(seq) => format!("tick {seq} was asked"),
            None => "no tick of it was asked".into(),
        };
        self.violation(format!(
            "agent {}: answered tick {} where {what} (one answer per question, in tick order)",
            a.agent, a.seq
        ))
    }

    /// Lockstep: no answer to tick `seq` of `agent` within the timeout.
    fn silent(&self, seq: u64, agent: u32) -> RoleError {
        self.violation(format!(
            "no answer to tick {seq} of agent {agent} within {:?} (lockstep waits for every \
             answer; `[roles.controller] timeout_s` sets the limit)",
            self.timeout
        ))
    }

    /// The answer `a` as the pipeline takes it: `None` (counted; the first of each kind said
    /// on stderr, naming the program) when it has another number of joints than `N` or a
    /// non-finite entry.
    fn usable<const N: usize>(&mut self, a: &ControllerOutMsg) -> Option<Answer<N>> {
        let (tally, label) = (&mut self.tally, &self.label);
        let say = |what: String| {
            fdi_runtime::process::print_warning(format_args!(
                "controller `{label}`: agent {}, tick {}: {what}; the last good torque is held \
                 (every such answer is counted in the trace's closing note)",
                a.agent, a.seq
            ))
        };
        if a.dof as usize != N {
            if tally.wrong_dof == 0 {
                say(format!("an answer of {} joints for a robot of {N}", a.dof));
            }
            tally.wrong_dof += 1;
            return None;
        }
        let (u, s_hat) = (to_vector::<N>(&a.u), to_vector::<N>(&a.s_hat));
        if !u.iter().chain(s_hat.iter()).all(|x| x.is_finite()) {
            if tally.non_finite == 0 {
                say(format!(
                    "a non-finite torque or Ŝ (u = {:?}, Ŝ = {:?})",
                    u.as_slice(),
                    s_hat.as_slice()
                ));
            }
            tally.non_finite += 1;
            return None;
        }
        Some(Answer {
            command: Command { u, s_hat },
            alarm: a.alarm(),
        })
    }

    /// What the program did, for the trace's closing note; `deadline_ns`: a realtime run's
    /// deadline after a tick's time.
    pub fn summary(&self, deadline_ns: Option<u64>) -> String {
        let t = self.tally;
        let mut s = format!(
            "controller `{}`: {} answers, {} with a non-finite torque or Ŝ, {} with another \
             number of joints than their agent's (the last good torque held for each)",
            self.label, t.answers, t.non_finite, t.wrong_dof
        );
        if let Some(deadline_ns) = deadline_ns {
            s.push_str(&format!(
                ", {} ticks past the {:.3} ms deadline after their tick's time (the last good \
                 torque held), {} late answers dropped",
                t.late,
                deadline_ns as f64 / 1e6,
                t.dropped_late
            ));
        }
        s
    }
}

/// The control center's state of a controller program.
#[derive(Debug)]
pub struct ControllerProgram {
    exchange: Exchange,
    /// Per agent: measurements admitted and not asked yet, in tick order.
    queued: Vec<VecDeque<Admitted>>,
    /// Per agent: the tick asked and not answered, and its deadline (realtime: CLOCK_MONOTONIC,
    /// ns).
    asked: Vec<Option<(Admitted, u64)>>,
    /// Realtime, per agent: ticks given up at their deadline, whose answers are dropped.
    given_up: Vec<BTreeSet<u64>>,
    lockstep: bool,
    dt: f64,
    /// Realtime: CLOCK_MONOTONIC of sim time zero, ns.
    epoch_ns: u64,
    deadline_ns: u64,
    /// The last answer (or the first question it owed one to): the lockstep timeout counts
    /// from it.
    progress: Instant,
}

impl ControllerProgram {
    /// The program of `role` for the agents `ids`, in a run of period `dt` that started at
    /// `epoch_ns`.
    pub fn new(role: &ExternalRole, ids: &[u32], dt: f64, lockstep: bool, epoch_ns: u64) -> Self {
        Self {
            exchange: Exchange::new(role, ids),
            queued: vec![VecDeque::new(); ids.len()],
            asked: vec![None; ids.len()],
            given_up: vec![BTreeSet::new(); ids.len()],
            lockstep,
            dt,
            epoch_ns,
            deadline_ns: role.deadline_ns(),
            progress: Instant::now(),
        }
    }

    /// Queues the admitted measurement `m` of scenario agent `i` (received at `received`;
    /// `usable`: its values are the tick's input, else the input is missing).
    pub fn queue(&mut self, i: usize, m: &MeasurementMsg, usable: bool, received: u64) {
        self.queued[i].push_back(Admitted {
            m: *m,
            usable,
            received,
        });
    }

    /// Asks the program every tick it may be asked now: each agent's next queued one, when its
    /// last one is answered. Realtime: a tick already past its deadline (the program is behind)
    /// is asked all the same, but its last good torque is held at once (`answered` marks its
    /// agent) and its answer will be dropped. Returns how many were asked (the program is rung
    /// once for them).
    pub(crate) fn ask<X: Transport>(
        &mut self,
        from: &ControllerPorts<X>,
        (slots, ports): (&mut [Slot], &Ports<X>),
        answered: &mut [bool],
        trace: &mut TraceWriter,
    ) -> Result<usize, RoleError> {
        let dt = self.dt;
        let mut asked = 0;
        for i in 0..self.exchange.ids.len() {
            while self.asked[i].is_none() {
                let Some(a) = self.queued[i].pop_front() else {
                    break;
                };
                let msg = fdi_common::on_joint_count!(AnyCenterAgent, &mut slots[i].center, c => {
                    question(c, &a, dt)
                });
                let deadline = self.deadline_of(a.m.seq);
                if !self.waiting() {
                    self.progress = Instant::now();
                }
                from.questions.send(msg)?;
                asked += 1;
                if !self.lockstep && msg.center_sent_ns >= deadline {
                    // Asked all the same (the program sees every tick); its answer is dropped.
                    self.give_up(i, &a, (slots, ports), trace)?;
                    answered[i] = true;
                    continue;
                }
                self.asked[i] = Some((a, deadline));
            }
        }
        Ok(asked)
    }

    /// Realtime: the latest time the answer to tick `k` may come, CLOCK_MONOTONIC ns.
    fn deadline_of(&self, k: u64) -> u64 {
        let t_ns = (tick_time(k, self.dt) * 1e9) as u64;
        self.epoch_ns + t_ns + self.deadline_ns
    }

    /// Whether some tick waits for its answer.
    fn waiting(&self) -> bool {
        self.asked.iter().any(Option::is_some)
    }

    /// Takes every answer waiting: each closes its agent's tick (its torque sent and recorded,
    /// or the last good one held when it is unusable). Returns how many ticks were closed;
    /// `answered` marks their agents.
    pub(crate) fn take_answers<X: Transport>(
        &mut self,
        from: &ControllerPorts<X>,
        (slots, ports): (&mut [Slot], &Ports<X>),
        answered: &mut [bool],
        trace: &mut TraceWriter,
    ) -> Result<usize, RoleError> {
        let mut got = Vec::new();
        from.answers.drain(|a| got.push(a))?;
        let mut closed = 0;
        for a in got {
            let i = self.exchange.agent_of(&a)?;
            self.progress = Instant::now();
            if self.given_up[i].remove(&a.seq) {
                self.exchange.tally.dropped_late += 1;
                continue;
            }
            let Some((asked, _)) = self.asked[i].filter(|(x, _)| x.m.seq == a.seq) else {
                let asked = self.asked[i].map(|(x, _)| x.m.seq);
                return Err(self.exchange.out_of_order(&a, asked));
            };
            self.asked[i] = None;
            self.exchange.tally.answers += 1;
            self.close(i, &asked, Some(&a), (slots, ports), trace)?;
            answered[i] = true;
            closed += 1;
        }
        Ok(closed)
    }

    /// Closes agent `i`'s tick `asked` with the program's answer `a` (`None`: none came in
    /// time): the torque sent and recorded.
    fn close<X: Transport>(
        &mut self,
        i: usize,
        asked: &Admitted,
        a: Option<&ControllerOutMsg>,
        (slots, ports): (&mut [Slot], &Ports<X>),
        trace: &mut TraceWriter,
    ) -> Result<(), RoleError> {
        let link = &ports.links[ports.route[i]];
        let Slot { center, next } = &mut slots[i];
        *next = asked.m.seq + 1;
        let (exchange, dt) = (&mut self.exchange, self.dt);
        fdi_common::on_joint_count!(AnyCenterAgent, center, c => {
            let answer = a.and_then(|a| exchange.usable(a));
            match c.answer(answer.as_ref()) {
                Some(out) => {
                    let t = tick_time(asked.m.seq, dt);
                    deliver(&out, (&asked.m, t), asked.received, link, trace)
                }
                None => Ok(()),
            }
        })
    }

    /// Lockstep: fails once no answer came for the timeout while one is due. Realtime: holds
    /// the last good torque for every tick unanswered at its deadline (its answer, if it comes,
    /// is dropped); `answered` marks their agents.
    pub(crate) fn enforce<X: Transport>(
        &mut self,
        now_ns: u64,
        (slots, ports): (&mut [Slot], &Ports<X>),
        answered: &mut [bool],
        trace: &mut TraceWriter,
    ) -> Result<(), RoleError> {
        if self.lockstep {
            let due = self.asked.iter().flatten().next();
            if let (Some((a, _)), true) = (due, self.progress.elapsed() > self.exchange.timeout) {
                return Err(self.exchange.silent(a.m.seq, a.m.agent));
            }
            return Ok(());
        }
        for (i, got_torque) in answered.iter_mut().enumerate() {
            let Some((a, deadline)) = self.asked[i] else {
                continue;
            };
            if now_ns < deadline {
                continue;
            }
            self.asked[i] = None;
            self.give_up(i, &a, (slots, ports), trace)?;
            *got_torque = true;
        }
        Ok(())
    }

    /// Realtime: closes agent `i`'s tick `a` past its deadline with the last good torque; its
    /// answer, if it comes, is dropped.
    fn give_up<X: Transport>(
        &mut self,
        i: usize,
        a: &Admitted,
        (slots, ports): (&mut [Slot], &Ports<X>),
        trace: &mut TraceWriter,
    ) -> Result<(), RoleError> {
        self.exchange.tally.late += 1;
        let given_up = &mut self.given_up[i];
        given_up.insert(a.m.seq);
        // Answers come in tick order: one 4096 ticks older is not coming any more.
        while given_up.first().is_some_and(|&k| k + 4096 < a.m.seq) {
            given_up.pop_first();
        }
        self.close(i, a, None, (slots, ports), trace)
    }

    /// What the program did, for the trace's closing note.
    pub fn summary(&self) -> String {
        self.exchange
            .summary((!self.lockstep).then_some(self.deadline_ns))
    }
}

/// Opens the tick of `a` in `center` and makes its question.
fn question<const N: usize>(center: &mut CenterAgent<N>, a: &Admitted, dt: f64) -> ControllerInMsg {
    let t = tick_time(a.m.seq, dt);
    let input = a
        .usable
        .then(|| (to_vector::<N>(&a.m.y), to_vector::<N>(&a.m.yd)));
    let q = center.ask(t, input.as_ref().map(|(y, yd)| (y, yd)));
    question_msg(a.m.seq, a.m.agent, &q)
}

/// The wire form of question `q` of tick `seq` of `agent`.
pub fn question_msg<const N: usize>(seq: u64, agent: u32, q: &Question<N>) -> ControllerInMsg {
    let flags = if q.missing {
        ControllerInMsg::MISSING
    } else if q.rejected {
        ControllerInMsg::REJECTED
    } else {
        0
    };
    ControllerInMsg {
        seq,
        agent,
        dof: N as u32,
        t: q.t,
        tau: q.tau,
        y: from_vector(&q.y),
        yd: from_vector(&q.yd),
        q_d: from_vector(&q.reference.q),
        qd_d: from_vector(&q.reference.qd),
        qdd_d: from_vector(&q.reference.qdd),
        e_u: from_vector(&q.e_u),
        inertia_ref: from_matrix(&q.inertia_ref),
        inverse_inertia_ref: from_matrix(&q.inverse_inertia_ref),
        inertia: from_matrix(&q.inertia),
        bias: from_vector(&q.bias),
        center_sent_ns: monotonic_ns(),
        flags,
        reserved: 0,
    }
}

/// The controller program as the in-process engine asks it ([`fdi_common::engine::Asking`]),
/// over the run's shared memory from the launcher's own node: the questions, the rules
/// ([`Exchange`]) and the closing note of the control center's, in lockstep (it waits for each
/// answer, at most the role's `timeout_s`). Between its waits `watch` says whether the run may
/// go on (the program alive, no stop): its error stops the run.
pub struct Asker<'a, X: Transport> {
    transport: &'a X,
    ports: AskerPorts<X>,
    exchange: Exchange,
    /// Per agent: the tick asked and not answered.
    asked: Vec<Option<u64>>,
    /// Per agent: its answer, taken and not yet used.
    answers: Vec<Option<ControllerOutMsg>>,
    /// The program was rung for the questions asked since its last answer.
    rung: bool,
    /// The last answer (or the first question it owed one to): the timeout counts from it.
    progress: Instant,
    /// When `watch` was last asked.
    watched: Instant,
    watch: &'a mut dyn FnMut() -> Result<(), RoleError>,
}

/// The ports of an [`Asker`], opened before the program is started: every service it opens
/// then exists, and its notifier reaches the listener.
#[derive(Debug)]
pub struct AskerPorts<X: Transport> {
    controller: ControllerPorts<X>,
    /// The program rings the control center's event once it answered.
    woken: X::Waker,
}

impl<X: Transport> AskerPorts<X> {
    pub fn open(transport: &X) -> Result<Self, IpcError> {
        Ok(Self {
            controller: ControllerPorts::open(transport)?,
            woken: transport.waker(Wake::Center)?,
        })
    }
}

impl<X: Transport> std::fmt::Debug for Asker<'_, X> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Asker")
            .field("exchange", &self.exchange)
            .field("asked", &self.asked)
            .finish_non_exhaustive()
    }
}

impl<'a, X: Transport> Asker<'a, X> {
    /// How long one wait for an answer lasts, and how often `watch` is asked while answers
    /// are awaited.
    const WAIT: Duration = Duration::from_millis(50);

    /// Asks the program of `role` for the agents `ids` through `ports` on the node
    /// `transport`, once it is ready and the run started.
    pub fn new(
        (transport, ports): (&'a X, AskerPorts<X>),
        role: &ExternalRole,
        ids: &[u32],
        watch: &'a mut dyn FnMut() -> Result<(), RoleError>,
    ) -> Self {
        Self {
            transport,
            ports,
            exchange: Exchange::new(role, ids),
            asked: vec![None; ids.len()],
            answers: vec![None; ids.len()],
            rung: false,
            progress: Instant::now(),
            watched: Instant::now(),
            watch,
        }
    }

    /// What the program did, for the closing note.
    pub fn summary(&self) -> String {
        self.exchange.summary(None)
    }

    fn index(&self, agent: u32) -> Result<usize, RoleError> {
        self.exchange.index(agent).ok_or_else(|| {
            self.exchange.violation(format!(
                "agent {agent} is not one the program was started for"
            ))
        })
    }

    /// Takes the answers that arrived, each checked against the tick asked of its agent.
    fn take(&mut self) -> Result<(), RoleError> {
        let mut got = Vec::new();
        self.ports.controller.answers.drain(|a| got.push(a))?;
        for a in got {
            let i = self.exchange.agent_of(&a)?;
            if self.asked[i] != Some(a.seq) {
                return Err(self.exchange.out_of_order(&a, self.asked[i]));
            }
            self.asked[i] = None;
            self.answers[i] = Some(a);
            self.exchange.tally.answers += 1;
            self.progress = Instant::now();
        }
        Ok(())
    }
}

impl<X: Transport> fdi_common::engine::TorqueProgram for Asker<'_, X> {
    type Error = RoleError;

    fn ask<const N: usize>(
        &mut self,
        k: u64,
        agent: u32,
        question: &Question<N>,
    ) -> Result<(), RoleError> {
        let i = self.index(agent)?;
        if self.asked.iter().all(Option::is_none) {
            self.progress = Instant::now();
        }
        self.ports
            .controller
            .questions
            .send(question_msg(k, agent, question))?;
        self.asked[i] = Some(k);
        self.rung = false;
        Ok(())
    }

    fn answer<const N: usize>(
        &mut self,
        k: u64,
        agent: u32,
    ) -> Result<Option<Answer<N>>, RoleError> {
        let i = self.index(agent)?;
        if !self.rung {
            self.ports.controller.bell.ring(self.transport)?;
            self.rung = true;
        }
        loop {
            if let Some(a) = self.answers[i].take() {
                return Ok(self.exchange.usable::<N>(&a));
            }
            if self.asked[i].is_none() {
                return Err(self
                    .exchange
                    .violation(format!("agent {agent}: tick {k} was never asked")));
            }
            self.take()?;
            if self.answers[i].is_some() {
                continue;
            }
            if self.progress.elapsed() > self.exchange.timeout {
                return Err(self.exchange.silent(k, agent));
            }
            // A program that died or a stop rings nothing: looked at after a quiet wait, and
            // at least every `WAIT` however often the program rings.
            if !self.ports.woken.wait(Self::WAIT)? || self.watched.elapsed() > Self::WAIT {
                self.watched = Instant::now();
                (self.watch)()?;
            }
        }
    }
}
