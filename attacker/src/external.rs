//! The attacker process relaying for an external program (`[roles.attacker]`, docs/protocol.md):
//! each clean measurement goes to the program on `fdi/external/attacker/in`; its answers come back
//! on `fdi/external/attacker/out`, are checked against the protocol (a violation stops the run,
//! naming the program), recorded as the attacker's records (what it sent, classified), and
//! relayed to the control center as they are.

use std::collections::{BTreeSet, VecDeque};
use std::time::{Duration, Instant};

use fdi_common::engine::tick_time;
use fdi_common::records::{AttackRecord, Delivery, Joints};
use fdi_common::roles::ExternalRole;
use fdi_common::trace::{TraceRecord, TraceWriter};
use fdi_runtime::ipc::{
    monotonic_ns, Inbox as _, IpcError, MeasurementMsg, Outbox as _, Stream, Transport, Wake,
};
use fdi_runtime::process::external::LateBell;
use fdi_runtime::process::RoleError;

/// The ports towards the external program.
#[derive(Debug)]
pub struct ExternalPorts<X: Transport> {
    /// Clean measurements to the program.
    pub to: X::Outbox<MeasurementMsg>,
    /// Its answers.
    pub from: X::Inbox<MeasurementMsg>,
    /// Its wake-up event.
    pub bell: LateBell<X>,
}

impl<X: Transport> ExternalPorts<X> {
    pub fn open(transport: &X) -> Result<Self, IpcError> {
        Ok(Self {
            to: transport.publisher(Stream::ExternalIn)?,
            from: transport.subscriber(Stream::ExternalOut)?,
            bell: LateBell::open(transport, Wake::ExternalAttacker)?,
        })
    }

    /// Rings the program once after a batch was forwarded.
    pub fn ring(&self, transport: &X) -> Result<(), IpcError> {
        self.bell.ring(transport)
    }
}

/// Per agent: what was sent to the program and not answered yet.
#[derive(Debug, Default)]
struct Agent {
    id: u32,
    /// Clean messages forwarded and not answered, oldest first, with when they were forwarded.
    waiting: VecDeque<(MeasurementMsg, u64)>,
    /// The next tick whose answer is due.
    answered: u64,
    /// Older messages it sent before the answer of the tick due (replays under original headers).
    replays: u64,
    /// Realtime: ticks given up at their deadline (a gap marker went instead); their answers are
    /// dropped when they come. Pruned as the run goes on.
    given_up: BTreeSet<u64>,
}

/// What the program did over the run.
#[derive(Debug, Default, Clone, Copy)]
pub struct Tally {
    pub answers: u64,
    pub replays: u64,
    pub gaps: u64,
    pub forged: u64,
    /// Realtime: ticks whose answer missed the deadline (gap marker sent instead).
    pub late: u64,
    /// Realtime: answers that came after their tick was given up (dropped).
    pub dropped_late: u64,
}

/// The relay's state for an external program.
#[derive(Debug)]
pub struct External {
    label: String,
    agents: Vec<Agent>,
    dof: usize,
    dt: f64,
    timeout: Duration,
    deadline_ns: u64,
    realtime: bool,
    /// The last time an answer came (or the start): the lockstep timeout counts from it.
    progress: Instant,
    tally: Tally,
}

impl External {
    pub fn new(role: &ExternalRole, ids: &[u32], dof: usize, dt: f64, realtime: bool) -> Self {
        Self {
            label: role.label(),
            agents: ids
                .iter()
                .map(|&id| Agent {
                    id,
                    ..Agent::default()
                })
                .collect(),
            dof,
            dt,
            timeout: role.timeout(),
            deadline_ns: role.deadline_ns(),
            realtime,
            progress: Instant::now(),
            tally: Tally::default(),
        }
    }

    fn violation(&self, what: String) -> RoleError {
        RoleError::External(format!("external attacker `{}`: {what}", self.label))
    }

    /// Hands the admitted clean measurement `m` (received at `received`) of scenario agent `i`
    /// to the program.
    pub fn forward<X: Transport>(
        &mut self,
        i: usize,
        m: &MeasurementMsg,
        received: u64,
        ports: &ExternalPorts<X>,
    ) -> Result<(), RoleError> {
        let msg = MeasurementMsg {
            attacker_received_ns: received,
            ..*m
        };
        ports.to.send(msg)?;
        if !self.waiting() {
            // The lockstep timeout counts from the first message it owes an answer to.
            self.progress = Instant::now();
        }
        self.agents[i].waiting.push_back((msg, monotonic_ns()));
        Ok(())
    }

    /// Whether every tick of agent `i` was answered (or given up).
    pub fn finished(&self, i: usize, ticks: u64) -> bool {
        self.agents[i].answered >= ticks
    }

    /// Whether some forwarded message waits for its answer.
    pub fn waiting(&self) -> bool {
        self.agents.iter().any(|a| !a.waiting.is_empty())
    }

    /// Takes every answer waiting: checks it, records it and relays it to the control center on
    /// `out`. Returns how many messages went to the center.
    pub fn take_answers<X: Transport>(
        &mut self,
        ports: &ExternalPorts<X>,
        out: &impl fdi_runtime::ipc::Outbox<MeasurementMsg>,
        trace: &mut TraceWriter,
    ) -> Result<usize, RoleError> {
        let mut answers = Vec::new();
        ports.from.drain(|m| answers.push(m))?;
        let mut relayed = 0;
        for a in answers {
            if self.take(&a, out, trace)? {
                relayed += 1;
            }
        }
        Ok(relayed)
    }

    /// One message from the program; true when it went to the center.
    fn take(
        &mut self,
        a: &MeasurementMsg,
        out: &impl fdi_runtime::ipc::Outbox<MeasurementMsg>,
        trace: &mut TraceWriter,
    ) -> Result<bool, RoleError> {
        let Some(i) = self.agents.iter().position(|x| x.id == a.agent) else {
            return Err(self.violation(format!(
                "sent a message for agent {}, which the run does not have (sequence {})",
                a.agent, a.seq
            )));
        };
        if a.dof as usize != self.dof {
            return Err(self.violation(format!(
                "agent {}, sequence {}: dof {} where the run's agents have {}",
                a.agent, a.seq, a.dof, self.dof
            )));
        }
        self.progress = Instant::now();
        let agent = &mut self.agents[i];
        if agent.given_up.remove(&a.seq) {
            self.tally.dropped_late += 1;
            return Ok(false);
        }
        if a.seq < agent.answered {
            // An older message before the answer of the tick due: relayed as sent (the center
            // refuses it as stale); the tick's record says replayed.
            agent.replays += 1;
            self.tally.replays += 1;
            out.send(stamped(a))?;
            return Ok(true);
        }
        let due = agent.answered;
        let Some((clean, _)) = agent
            .waiting
            .front()
            .copied()
            .filter(|(c, _)| c.seq == a.seq)
        else {
            let what = match agent.waiting.back() {
                Some((last, _)) if a.seq <= last.seq => format!(
                    "agent {}: answered tick {} before tick {due} (answers come in tick order)",
                    a.agent, a.seq
                ),
                _ => format!(
                    "agent {}: answered tick {}, which was not sent to it yet (the next tick due \
                     is {due})",
                    a.agent, a.seq
                ),
            };
            return Err(self.violation(what));
        };
        agent.waiting.pop_front();
        let replayed = std::mem::take(&mut agent.replays) > 0;
        agent.answered = a.seq + 1;
        let rec = record(&clean, a, replayed, self.dt, self.dof);
        self.tally.answers += 1;
        self.tally.gaps += u64::from(a.is_gap());
        self.tally.forged += u64::from(rec.delivery == Delivery::Forged);
        let sent = out.send(stamped(a));
        trace.write(&TraceRecord::Attack(rec))?;
        sent?;
        Ok(true)
    }

    /// Realtime: gives up every tick whose answer is past the deadline (a gap marker goes to
    /// the center instead; the answer, if it comes, is dropped). Lockstep: fails once no answer
    /// came for the timeout while one is due. Returns the gap markers sent.
    pub fn enforce(
        &mut self,
        now_ns: u64,
        out: &impl fdi_runtime::ipc::Outbox<MeasurementMsg>,
        trace: &mut TraceWriter,
    ) -> Result<usize, RoleError> {
        if !self.realtime {
            if let Some(a) = self.agents.iter().find(|a| !a.waiting.is_empty()) {
                if self.progress.elapsed() > self.timeout {
                    return Err(self.violation(format!(
                        "no answer to tick {} of agent {} within {:?} (lockstep waits for every \
                         answer; `[roles.attacker] timeout_s` sets the limit)",
                        a.answered, a.id, self.timeout
                    )));
                }
            }
            return Ok(0);
        }
        let mut sent = 0;
        for agent in &mut self.agents {
            while let Some((clean, at)) = agent.waiting.front().copied() {
                if now_ns < at + self.deadline_ns {
                    break;
                }
                agent.waiting.pop_front();
                agent.answered = clean.seq + 1;
                agent.replays = 0;
                agent.given_up.insert(clean.seq);
                if let Some(&old) = agent.given_up.first() {
                    if old + 4096 < clean.seq {
                        agent.given_up.remove(&old);
                    }
                }
                self.tally.late += 1;
                let gap = MeasurementMsg::gap(clean.seq, clean.agent, clean.dof, clean.t);
                let result = out.send(stamped(&gap));
                let mut rec = record(&clean, &gap, false, self.dt, self.dof);
                rec.active = false; // not the program's doing: it was too slow
                trace.write(&TraceRecord::Attack(rec))?;
                result?;
                sent += 1;
            }
        }
        Ok(sent)
    }

    /// Realtime: how long until the earliest deadline of a waiting message.
    pub fn next_deadline_in(&self, now_ns: u64) -> Option<Duration> {
        self.agents
            .iter()
            .filter_map(|a| a.waiting.front())
            .map(|(_, at)| Duration::from_nanos((at + self.deadline_ns).saturating_sub(now_ns)))
            .min()
    }

    /// What the program did, for the trace's closing note.
    pub fn summary(&self) -> String {
        let t = self.tally;
        let mut s = format!(
            "external attacker `{}`: {} answers ({} gap markers, {} forged stamps), {} older \
             messages relayed as replays",
            self.label, t.answers, t.gaps, t.forged, t.replays
        );
        if self.realtime {
            s.push_str(&format!(
                ", {} ticks past the {:.3} ms deadline (gap markers sent instead), {} late answers \
                 dropped",
                t.late,
                self.deadline_ns as f64 / 1e6,
                t.dropped_late
            ));
        }
        s
    }
}

/// The message as relayed: the attacker's send stamp is the relay's.
fn stamped(m: &MeasurementMsg) -> MeasurementMsg {
    MeasurementMsg {
        attacker_sent_ns: monotonic_ns(),
        ..*m
    }
}

/// The attacker's record of the tick of `clean`, answered by `a`: the injection is what it sent
/// minus what the agent sent; a gap marker is missing (replayed when older messages came
/// before it), a stamp that is not the tick's time is forged.
pub fn record(
    clean: &MeasurementMsg,
    a: &MeasurementMsg,
    replayed: bool,
    dt: f64,
    dof: usize,
) -> AttackRecord {
    let diff = |x: &[f64], y: &[f64]| -> Vec<f64> {
        x.iter().zip(y).take(dof).map(|(a, c)| a - c).collect()
    };
    let honest = a.t == tick_time(a.seq, dt);
    let delivery = match (a.is_gap(), honest) {
        (true, _) if replayed => Delivery::Replayed,
        (true, _) => Delivery::Missing,
        (false, false) => Delivery::Forged,
        (false, true) => Delivery::Delivered,
    };
    let (alpha_position, alpha_velocity) = if a.is_gap() {
        (vec![0.0; dof], vec![0.0; dof])
    } else {
        (diff(&a.y, &clean.y), diff(&a.yd, &clean.yd))
    };
    let injected = alpha_position
        .iter()
        .chain(&alpha_velocity)
        .any(|x| *x != 0.0);
    let (y, yd) = if delivery == Delivery::Delivered {
        (
            Joints::from_slice(&a.y[..dof]),
            Joints::from_slice(&a.yd[..dof]),
        )
    } else {
        (Joints::default(), Joints::default())
    };
    AttackRecord {
        k: clean.seq,
        agent: clean.agent,
        alpha_position: Joints::from_slice(&alpha_position),
        alpha_velocity: Joints::from_slice(&alpha_velocity),
        y,
        yd,
        active: injected || delivery != Delivery::Delivered || replayed,
        delivery,
    }
}
