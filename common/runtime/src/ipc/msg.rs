//! Zero-copy payloads of the runtime's services: `#[repr(C)]`, fixed size, explicit type names.
//! nalgebra types are not `ZeroCopySend`, so vectors travel as `[f64; MAX_DOF]` plus `dof`.

use iceoryx2::prelude::ZeroCopySend;
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

use fdi_common::model::Vector;
use fdi_common::scenario::MAX_DOF;

/// Copies the first `N` entries of a payload array into a vector.
pub fn to_vector<const N: usize>(a: &[f64; MAX_DOF]) -> Vector<N> {
    let mut v = Vector::<N>::zeros();
    for (o, x) in v.iter_mut().zip(a.iter()) {
        *o = *x;
    }
    v
}

/// Copies a vector into a payload array (unused entries zero).
pub fn from_vector<const N: usize>(v: &Vector<N>) -> [f64; MAX_DOF] {
    let mut a = [0.0; MAX_DOF];
    for (o, x) in a.iter_mut().zip(v.iter()) {
        *o = *x;
    }
    a
}

/// A measurement: agent → attacker (clean), attacker → control center (tampered).
#[derive(
    Debug, Clone, Copy, PartialEq, ZeroCopySend, IntoBytes, FromBytes, Immutable, KnownLayout,
)]
#[repr(C)]
#[type_name("fdi_mas::MeasurementMsg")]
pub struct MeasurementMsg {
    /// Tick `k`.
    pub seq: u64,
    pub agent: u32,
    pub dof: u32,
    /// `t_k`, s.
    pub t: f64,
    /// Position `y`, rad.
    pub y: [f64; MAX_DOF],
    /// Velocity `ẏ`, rad/s.
    pub yd: [f64; MAX_DOF],
    /// CLOCK_MONOTONIC when the agent published, ns.
    pub agent_sent_ns: u64,
    /// CLOCK_MONOTONIC when the attacker took the clean message, ns (0 on the clean hop).
    pub attacker_received_ns: u64,
    /// CLOCK_MONOTONIC when the attacker relayed, ns (0 on the clean hop).
    pub attacker_sent_ns: u64,
    /// [`MeasurementMsg::GAP`] or 0.
    pub flags: u32,
    pub reserved: u32,
}

impl MeasurementMsg {
    /// Flag of a gap marker: the attacker's word that nothing arrives for tick `seq` (dropped,
    /// not yet delivered under a delay, or replaced by a replayed message). It carries no data;
    /// the receiver's stand-in for the deadline at which it knows nothing came.
    pub const GAP: u32 = 1;

    /// A gap marker for tick `seq` of `agent`, stamped `t`.
    pub fn gap(seq: u64, agent: u32, dof: u32, t: f64) -> Self {
        Self {
            seq,
            agent,
            dof,
            t,
            y: [0.0; MAX_DOF],
            yd: [0.0; MAX_DOF],
            agent_sent_ns: 0,
            attacker_received_ns: 0,
            attacker_sent_ns: 0,
            flags: Self::GAP,
            reserved: 0,
        }
    }

    pub fn is_gap(&self) -> bool {
        self.flags & Self::GAP != 0
    }
}

/// A torque command: control center → agent, stamped with its send time `t_k`.
#[derive(
    Debug, Clone, Copy, PartialEq, ZeroCopySend, IntoBytes, FromBytes, Immutable, KnownLayout,
)]
#[repr(C)]
#[type_name("fdi_mas::TorqueMsg")]
pub struct TorqueMsg {
    /// Tick `k` of the measurement it answers.
    pub seq: u64,
    pub agent: u32,
    pub dof: u32,
    /// Send stamp `t_k`, s: the delay line holds it from `t_k + τ`.
    pub t_send: f64,
    /// Torque, N·m.
    pub u: [f64; MAX_DOF],
    pub agent_sent_ns: u64,
    pub attacker_received_ns: u64,
    pub attacker_sent_ns: u64,
    pub center_received_ns: u64,
    pub center_sent_ns: u64,
    /// How much later than the channel's known delay the command takes effect (a delay
    /// attack on the torque path), s; 0 otherwise.
    pub held_s: f64,
    /// [`TorqueMsg::GAP`] or 0.
    pub flags: u32,
    pub reserved: u32,
}

impl TorqueMsg {
    /// Flag of a gap marker: nothing arrives for tick `seq` (see [`MeasurementMsg::GAP`]).
    pub const GAP: u32 = 1;

    pub fn is_gap(&self) -> bool {
        self.flags & Self::GAP != 0
    }
}

/// Launcher → every process.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend, IntoBytes, FromBytes, Immutable, KnownLayout,
)]
#[repr(C)]
#[type_name("fdi_mas::ControlMsg")]
pub struct ControlMsg {
    /// [`ControlMsg::START`] or [`ControlMsg::STOP`].
    pub command: u32,
    pub reserved: u32,
    /// CLOCK_MONOTONIC of sim time zero, ns (realtime clock).
    pub epoch_ns: u64,
}

impl ControlMsg {
    pub const START: u32 = 1;
    pub const STOP: u32 = 2;
}

/// Process → launcher.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend, IntoBytes, FromBytes, Immutable, KnownLayout,
)]
#[repr(C)]
#[type_name("fdi_mas::StatusMsg")]
pub struct StatusMsg {
    /// [`Role`] code.
    pub role: u32,
    /// Agent id for agents, 0 otherwise.
    pub agent: u32,
    /// [`StatusMsg::READY`], [`StatusMsg::PROGRESS`], [`StatusMsg::DONE`], [`StatusMsg::LOST`]
    /// or [`StatusMsg::REJOINED`].
    pub kind: u32,
    pub reserved: u32,
    /// Ticks completed.
    pub tick: u64,
}

impl StatusMsg {
    pub const READY: u32 = 1;
    pub const PROGRESS: u32 = 2;
    pub const DONE: u32 = 3;
    /// Sent by the control center: the agent in [`StatusMsg::agent`] fell silent (realtime) and
    /// is no longer controlled; `tick` is the last tick heard from it.
    pub const LOST: u32 = 4;
    /// Sent by the control center: the lost agent in [`StatusMsg::agent`] is heard from again
    /// at `tick` and controlled again.
    pub const REJOINED: u32 = 5;
}

/// A monitor's verdict on one tick of one agent: monitor program → control center, one per
/// agent and tick, in tick order (docs/protocol.md).
#[derive(
    Debug, Clone, Copy, PartialEq, ZeroCopySend, IntoBytes, FromBytes, Immutable, KnownLayout,
)]
#[repr(C)]
#[type_name("fdi_mas::AlarmMsg")]
pub struct AlarmMsg {
    /// Tick `k` judged.
    pub seq: u64,
    pub agent: u32,
    /// 1: the alarm is on at this tick; 0: off.
    pub alarm: u32,
    /// The monitor's statistic at this tick (any unit; NaN when it has none).
    pub statistic: f64,
    /// CLOCK_MONOTONIC when the monitor published, ns (0 if it does not say).
    pub monitor_sent_ns: u64,
}

/// Entries of a square matrix in a payload: [`MAX_DOF`]², row-major, of which the first
/// `dof` rows and columns are meaningful (row `i` at `i · MAX_DOF`).
pub const MATRIX_ENTRIES: usize = MAX_DOF * MAX_DOF;

/// Copies the `N × N` matrix `m` into a payload array, row-major with rows of [`MAX_DOF`]
/// entries (unused entries zero).
pub fn from_matrix<const N: usize>(m: &fdi_common::model::Matrix<N>) -> [f64; MATRIX_ENTRIES] {
    let mut a = [0.0; MATRIX_ENTRIES];
    for i in 0..N {
        for j in 0..N {
            a[i * MAX_DOF + j] = m[(i, j)];
        }
    }
    a
}

/// What the control center shows a controller program (`[roles.controller]`) of one tick of
/// one agent: control center → controller program (docs/protocol.md, "The controller program").
#[derive(
    Debug, Clone, Copy, PartialEq, ZeroCopySend, IntoBytes, FromBytes, Immutable, KnownLayout,
)]
#[repr(C)]
#[type_name("fdi_mas::ControllerInMsg")]
pub struct ControllerInMsg {
    /// Tick `k`.
    pub seq: u64,
    pub agent: u32,
    pub dof: u32,
    /// `t_k`, s.
    pub t: f64,
    /// The known delay `τ(t_k)` of the torque channel, s.
    pub tau: f64,
    /// The measurement in use (this tick's, or the last good one): `y`, rad, and `ẏ`, rad/s.
    pub y: [f64; MAX_DOF],
    pub yd: [f64; MAX_DOF],
    /// The reference at `t_k`: `q_d`, `q̇_d`, `q̈_d`.
    pub q_d: [f64; MAX_DOF],
    pub qd_d: [f64; MAX_DOF],
    pub qdd_d: [f64; MAX_DOF],
    /// `e_u = ∫_{t−τ(t)}^{t} u ds` over the torques sent, N·m·s.
    pub e_u: [f64; MAX_DOF],
    /// `M(q_d)`, row-major ([`MATRIX_ENTRIES`]).
    pub inertia_ref: [f64; MATRIX_ENTRIES],
    /// `A = M(q_d)⁻¹`, row-major.
    pub inverse_inertia_ref: [f64; MATRIX_ENTRIES],
    /// `M(y)` at the measurement in use, row-major.
    pub inertia: [f64; MATRIX_ENTRIES],
    /// `V(y, ẏ) ẏ + G(y) + F(ẏ)` at the measurement in use, N·m.
    pub bias: [f64; MAX_DOF],
    /// CLOCK_MONOTONIC when the control center published, ns.
    pub center_sent_ns: u64,
    /// [`ControllerInMsg::MISSING`], [`ControllerInMsg::REJECTED`] or 0.
    pub flags: u32,
    pub reserved: u32,
}

impl ControllerInMsg {
    /// The tick has no measurement (a gap marker, a forged stamp, a replay): `y`, `ẏ` are the
    /// last good ones.
    pub const MISSING: u32 = 1;
    /// The tick's measurement was rejected (non-finite or absurd): `y`, `ẏ` are the last good
    /// ones.
    pub const REJECTED: u32 = 2;
}

/// A controller program's answer to one [`ControllerInMsg`]: the torque to send and its attack
/// estimate (docs/protocol.md, "The controller program").
#[derive(
    Debug, Clone, Copy, PartialEq, ZeroCopySend, IntoBytes, FromBytes, Immutable, KnownLayout,
)]
#[repr(C)]
#[type_name("fdi_mas::ControllerOutMsg")]
pub struct ControllerOutMsg {
    /// Tick `k` answered.
    pub seq: u64,
    pub agent: u32,
    pub dof: u32,
    /// The torque to send, N·m.
    pub u: [f64; MAX_DOF],
    /// Its attack estimate `Ŝ` (0 without one).
    pub s_hat: [f64; MAX_DOF],
    /// CLOCK_MONOTONIC when the program published, ns (0 if it does not say).
    pub controller_sent_ns: u64,
    /// [`ControllerOutMsg::ALARM`] and [`ControllerOutMsg::OWN_ALARM`] bits, or 0.
    pub flags: u32,
    pub reserved: u32,
}

impl ControllerOutMsg {
    /// Its alarm is on at this tick (read with [`ControllerOutMsg::OWN_ALARM`]).
    pub const ALARM: u32 = 1;
    /// It has an alarm of its own: [`ControllerOutMsg::ALARM`] is recorded as the control
    /// center's alarm in place of the alarm on `‖Ŝ‖`.
    pub const OWN_ALARM: u32 = 2;

    /// Its own alarm at this tick, if it has one.
    pub fn alarm(&self) -> Option<bool> {
        (self.flags & Self::OWN_ALARM != 0).then_some(self.flags & Self::ALARM != 0)
    }
}

/// Which process a status message comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    Agent,
    Attacker,
    Center,
    /// The monitor program: detectors outside the project.
    Monitor,
    /// The external program that takes the attacker role.
    ExternalAttacker,
    /// The controller program (`[roles.controller]`): the control center's torques.
    ExternalController,
}

impl Role {
    /// Every role, for tables and checks.
    pub const ALL: [Self; 6] = [
        Self::Agent,
        Self::Attacker,
        Self::Center,
        Self::Monitor,
        Self::ExternalAttacker,
        Self::ExternalController,
    ];

    pub fn code(self) -> u32 {
        match self {
            Self::Agent => 1,
            Self::Attacker => 2,
            Self::Center => 3,
            Self::Monitor => 4,
            Self::ExternalAttacker => 5,
            Self::ExternalController => 6,
        }
    }

    pub fn from_code(c: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|r| r.code() == c)
    }
}

/// Why a received message was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MsgError {
    #[error("message for unknown agent {agent}")]
    UnknownAgent { agent: u32 },
    #[error("agent {agent}: dof {dof} where the scenario has {expected}")]
    WrongDof {
        agent: u32,
        dof: u32,
        expected: usize,
    },
    #[error("agent {agent}: sequence {seq} where {expected} was expected")]
    OutOfSequence { agent: u32, seq: u64, expected: u64 },
    #[error(
        "agent {agent}: sequence {seq} is behind the next one due, {next} (duplicate or replay)"
    )]
    Stale { agent: u32, seq: u64, next: u64 },
    #[error("agent {agent}: sequence {seq} is beyond the run's last tick ({limit} ticks): forged or corrupted")]
    SeqOutOfRange { agent: u32, seq: u64, limit: u64 },
    #[error("agent {agent}: dof {dof} exceeds the {MAX_DOF} entries a payload holds")]
    DofOutOfRange { agent: u32, dof: u32 },
    #[error("agent {agent}, sequence {seq}: time stamp {t} is not finite")]
    BadTime { agent: u32, seq: u64, t: f64 },
}

/// Which sequence numbers a receiver takes at this point of the stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SeqRule {
    /// Exactly this one (strict lockstep order).
    Exactly(u64),
    /// This one or a later one: a later one means the ones between never came (realtime); an
    /// earlier one is a duplicate or a replay.
    AtLeast(u64),
    /// Any: the receiver judges the number itself with a [`SequenceTracker`], which tells gaps,
    /// duplicates, replays and forged numbers apart.
    Tracked,
}

impl From<u64> for SeqRule {
    fn from(seq: u64) -> Self {
        Self::Exactly(seq)
    }
}

/// Checks the structure of a message (not its values: non-finite data is the control center's
/// business, it rejects and counts it): the agent is `known`, `dof` is `expected_dof` and `seq`
/// follows `rule`.
pub fn check_header(
    agent: u32,
    dof: u32,
    seq: u64,
    expected_dof: usize,
    known: impl Fn(u32) -> bool,
    rule: impl Into<SeqRule>,
) -> Result<(), MsgError> {
    if !known(agent) {
        return Err(MsgError::UnknownAgent { agent });
    }
    if dof as usize != expected_dof {
        return Err(MsgError::WrongDof {
            agent,
            dof,
            expected: expected_dof,
        });
    }
    match rule.into() {
        SeqRule::Exactly(expected) if seq != expected => Err(MsgError::OutOfSequence {
            agent,
            seq,
            expected,
        }),
        SeqRule::AtLeast(next) if seq < next => Err(MsgError::Stale { agent, seq, next }),
        _ => Ok(()),
    }
}

/// The values of a measurement that passed [`validate_measurement`]: exactly `dof` entries each.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredValues<'a> {
    /// Position `y`, rad.
    pub y: &'a [f64],
    /// Velocity `ẏ`, rad/s.
    pub yd: &'a [f64],
}

/// The structural checks shared by both payloads, in this order: `dof` within the payload
/// ([`MAX_DOF`], before anything is indexed), then [`check_header`], then a finite time stamp.
fn check_structure(
    agent: u32,
    dof: u32,
    seq: u64,
    t: f64,
    expected_dof: usize,
    known: impl Fn(u32) -> bool,
    rule: SeqRule,
) -> Result<usize, MsgError> {
    let n = dof as usize;
    if n > MAX_DOF {
        // Unknown agents are reported as such first, like check_header does.
        if !known(agent) {
            return Err(MsgError::UnknownAgent { agent });
        }
        return Err(MsgError::DofOutOfRange { agent, dof });
    }
    check_header(agent, dof, seq, expected_dof, known, rule)?;
    if !t.is_finite() {
        return Err(MsgError::BadTime { agent, seq, t });
    }
    Ok(n)
}

/// Everything a receiver must check on a measurement before it uses any value of it: the agent
/// is `known`, `dof` fits the payload and equals `expected_dof`, `seq` follows `rule`, the
/// time stamp `t` is finite. Returns the first `dof` entries of `y` and `ẏ`.
///
/// The values themselves are not checked: a non-finite or absurd `y`/`ẏ` is the control
/// center's business ([`fdi_common::control::CenterAgent::tick`] rejects, counts and holds the last
/// good one). To leave the sequence to a [`SequenceTracker`], pass [`SeqRule::Tracked`].
pub fn validate_measurement(
    msg: &MeasurementMsg,
    expected_dof: usize,
    known: impl Fn(u32) -> bool,
    rule: impl Into<SeqRule>,
) -> Result<MeasuredValues<'_>, MsgError> {
    let n = check_structure(
        msg.agent,
        msg.dof,
        msg.seq,
        msg.t,
        expected_dof,
        known,
        rule.into(),
    )?;
    Ok(MeasuredValues {
        y: &msg.y[..n],
        yd: &msg.yd[..n],
    })
}

/// [`validate_measurement`] for a torque command on agent `own_agent`'s channel: the message
/// must name that agent, have `expected_dof` links, a `seq` that follows `rule`, and a finite
/// `t_send`.
/// Returns the first `dof` entries of `u`. Non-finite torques are refused by the agent's delay
/// line ([`fdi_common::plant::Plant::receive`]), which also refuses stamps that do not increase.
pub fn validate_torque(
    msg: &TorqueMsg,
    expected_dof: usize,
    own_agent: u32,
    rule: impl Into<SeqRule>,
) -> Result<&[f64], MsgError> {
    let n = check_structure(
        msg.agent,
        msg.dof,
        msg.seq,
        msg.t_send,
        expected_dof,
        |a| a == own_agent,
        rule.into(),
    )?;
    Ok(&msg.u[..n])
}

/// What [`SequenceTracker::observe`] makes of one message's sequence number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SeqVerdict {
    /// The next one due. Use it.
    InOrder,
    /// Ahead of the next one due: `missing` messages in between never arrived (yet) — lost, or
    /// overwritten in a full buffer (safe overflow). Use it; the tracker moves on to `seq + 1`.
    Gap { missing: u64 },
    /// The newest accepted message again. Drop it.
    Duplicate,
    /// Older than the newest accepted one and already seen before, or older than the tracker can
    /// remember ([`SequenceTracker::WINDOW`] messages): a replay. Drop it.
    Replayed { behind: u64 },
    /// Older than the newest accepted one but never seen: a message a gap skipped arrives late
    /// (reordered). Its tick is already past; in lockstep this cannot happen, in realtime the
    /// caller drops it (the tracker records it as seen, so a second copy is `Replayed`).
    OutOfOrder { behind: u64 },
    /// At or beyond the tracker's `seq_limit` (the run's tick count): no honest sender produces
    /// it; forged or corrupted. Drop it; the tracker does not move (so one forged huge `seq`
    /// cannot make every later honest message look old).
    OutOfRange { limit: u64 },
    /// From an agent the tracker does not know. Drop it.
    UnknownAgent,
}

impl SeqVerdict {
    /// True when the message should be used: [`Self::InOrder`] and [`Self::Gap`].
    pub fn is_accepted(self) -> bool {
        matches!(self, Self::InOrder | Self::Gap { .. })
    }
}

/// How many messages got each [`SeqVerdict`] (for one agent, or summed over all).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SeqCounts {
    pub in_order: u64,
    /// Number of [`SeqVerdict::Gap`] verdicts (events).
    pub gaps: u64,
    /// Sum of their `missing`: messages skipped (a late arrival still counts here, and once
    /// more in `out_of_order`).
    pub missing: u64,
    pub duplicates: u64,
    pub replayed: u64,
    pub out_of_order: u64,
    pub out_of_range: u64,
    pub unknown_agent: u64,
}

impl SeqCounts {
    /// Messages not used: everything but in-order and gap verdicts.
    pub fn dropped(&self) -> u64 {
        self.duplicates + self.replayed + self.out_of_order + self.out_of_range + self.unknown_agent
    }

    fn add(&mut self, other: &Self) {
        self.in_order += other.in_order;
        self.gaps += other.gaps;
        self.missing += other.missing;
        self.duplicates += other.duplicates;
        self.replayed += other.replayed;
        self.out_of_order += other.out_of_order;
        self.out_of_range += other.out_of_range;
        self.unknown_agent += other.unknown_agent;
    }
}

/// Per-agent sequence state.
#[derive(Debug, Clone, Copy, Default)]
struct AgentSeq {
    /// Newest accepted sequence number; `None` before the first.
    newest: Option<u64>,
    /// Bit `i` set: `newest − i` was seen (bit 0 is `newest` itself).
    seen: u64,
    counts: SeqCounts,
}

/// Judges the sequence numbers of a stream with several senders (one per agent): in order,
/// gap, duplicate, replay, late (out of order), out of range. Every sender starts at 0.
///
/// ```
/// use fdi_runtime::ipc::msg::{SeqVerdict, SequenceTracker};
/// let mut t = SequenceTracker::new([1, 2], 1000);
/// assert_eq!(t.observe(1, 0), SeqVerdict::InOrder);
/// assert_eq!(t.observe(1, 3), SeqVerdict::Gap { missing: 2 });   // 1 and 2 lost (so far)
/// assert_eq!(t.observe(1, 3), SeqVerdict::Duplicate);
/// assert_eq!(t.observe(1, 2), SeqVerdict::OutOfOrder { behind: 1 }); // 2 arrives late
/// assert_eq!(t.observe(1, 2), SeqVerdict::Replayed { behind: 1 });   // and again: a replay
/// assert_eq!(t.observe(1, 5000), SeqVerdict::OutOfRange { limit: 1000 });
/// assert_eq!(t.observe(9, 0), SeqVerdict::UnknownAgent);
/// assert_eq!(t.expected(1), Some(4));
/// assert_eq!(t.counts(1).map(|c| c.dropped()), Some(4));
/// ```
///
/// A process loop calls [`Self::observe`] once per received message, before using it, and uses
/// the message only when the verdict [`SeqVerdict::is_accepted`]. It never panics, whatever
/// the input (`u64::MAX` included).
#[derive(Debug, Clone)]
pub struct SequenceTracker {
    agents: Vec<(u32, AgentSeq)>,
    seq_limit: u64,
    unknown: SeqCounts,
}

impl SequenceTracker {
    /// How far back duplicates and replays are told apart from late arrivals.
    pub const WINDOW: u64 = 64;

    /// A tracker for `agents`, each expected to send `0, 1, 2, …`; a `seq ≥ seq_limit` is
    /// [`SeqVerdict::OutOfRange`] (pass the run's tick count; `u64::MAX` refuses only
    /// `u64::MAX` itself).
    pub fn new(agents: impl IntoIterator<Item = u32>, seq_limit: u64) -> Self {
        let mut list: Vec<(u32, AgentSeq)> = agents
            .into_iter()
            .map(|a| (a, AgentSeq::default()))
            .collect();
        list.sort_by_key(|(a, _)| *a);
        list.dedup_by_key(|(a, _)| *a);
        Self {
            agents: list,
            seq_limit,
            unknown: SeqCounts::default(),
        }
    }

    fn slot(&mut self, agent: u32) -> Option<&mut AgentSeq> {
        let i = self.agents.binary_search_by_key(&agent, |(a, _)| *a).ok()?;
        Some(&mut self.agents[i].1)
    }

    /// Judges `seq` from `agent`, updates the agent's state and counts the verdict.
    pub fn observe(&mut self, agent: u32, seq: u64) -> SeqVerdict {
        let limit = self.seq_limit;
        let Some(a) = self.slot(agent) else {
            self.unknown.unknown_agent += 1;
            return SeqVerdict::UnknownAgent;
        };
        let verdict = if seq >= limit {
            SeqVerdict::OutOfRange { limit }
        } else {
            match a.newest {
                None => {
                    a.newest = Some(seq);
                    a.seen = 1;
                    if seq == 0 {
                        SeqVerdict::InOrder
                    } else {
                        SeqVerdict::Gap { missing: seq }
                    }
                }
                Some(newest) if seq > newest => {
                    let step = seq - newest;
                    a.seen = if step >= Self::WINDOW {
                        1
                    } else {
                        (a.seen << step) | 1
                    };
                    a.newest = Some(seq);
                    match step - 1 {
                        0 => SeqVerdict::InOrder,
                        missing => SeqVerdict::Gap { missing },
                    }
                }
                Some(newest) if seq == newest => SeqVerdict::Duplicate,
                Some(newest) => {
                    let behind = newest - seq;
                    if behind < Self::WINDOW && a.seen & (1 << behind) == 0 {
                        a.seen |= 1 << behind;
                        SeqVerdict::OutOfOrder { behind }
                    } else {
                        SeqVerdict::Replayed { behind }
                    }
                }
            }
        };
        let c = &mut a.counts;
        match verdict {
            SeqVerdict::InOrder => c.in_order += 1,
            SeqVerdict::Gap { missing } => {
                c.gaps += 1;
                c.missing += missing;
            }
            SeqVerdict::Duplicate => c.duplicates += 1,
            SeqVerdict::Replayed { .. } => c.replayed += 1,
            SeqVerdict::OutOfOrder { .. } => c.out_of_order += 1,
            SeqVerdict::OutOfRange { .. } => c.out_of_range += 1,
            SeqVerdict::UnknownAgent => c.unknown_agent += 1,
        }
        verdict
    }

    /// The next sequence number due from `agent` (`None` for an unknown agent, or after
    /// `u64::MAX` was accepted).
    pub fn expected(&self, agent: u32) -> Option<u64> {
        let i = self.agents.binary_search_by_key(&agent, |(a, _)| *a).ok()?;
        match self.agents[i].1.newest {
            None => Some(0),
            Some(n) => n.checked_add(1),
        }
    }

    /// The counts of `agent` (`None` for an unknown agent).
    pub fn counts(&self, agent: u32) -> Option<SeqCounts> {
        let i = self.agents.binary_search_by_key(&agent, |(a, _)| *a).ok()?;
        Some(self.agents[i].1.counts)
    }

    /// The counts summed over every agent, messages of unknown agents included.
    pub fn totals(&self) -> SeqCounts {
        let mut t = self.unknown;
        for (_, a) in &self.agents {
            t.add(&a.counts);
        }
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fdi_common::control::center::MAX_ABS_MEASUREMENT;
    use fdi_common::control::CenterAgent;
    use fdi_common::engine::tick_time;
    use fdi_common::plant::Plant;
    use fdi_common::scenario::{paper, Resolved};
    use proptest::prelude::*;

    fn paper_scenario() -> Resolved {
        paper().expect("the embedded paper scenario is valid")
    }

    /// The control center's pipeline of agent 1 of the paper's scenario.
    fn center(r: &Resolved) -> CenterAgent<2> {
        let s = &r.scenario;
        CenterAgent::<2>::new(s.center_params(&s.agents[0])).expect("a two-link model")
    }

    /// Any f64 bit pattern, with NaN, the infinities, subnormals, the rejection boundary and
    /// ordinary values (so that some messages are good) all likely.
    fn any_f64() -> impl Strategy<Value = f64> {
        prop_oneof![
            4 => -10.0f64..10.0,
            2 => any::<u64>().prop_map(f64::from_bits),
            1 => Just(f64::NAN),
            1 => any::<u64>().prop_map(|b| f64::from_bits(b | 0x7ff0_0000_0000_0001)), // NaNs, any payload
            1 => Just(f64::INFINITY),
            1 => Just(f64::NEG_INFINITY),
            1 => (1u64..(1 << 52)).prop_map(f64::from_bits), // positive subnormals
            1 => (1u64..(1 << 52)).prop_map(|b| -f64::from_bits(b)),
            1 => Just(MAX_ABS_MEASUREMENT),
            1 => Just(-MAX_ABS_MEASUREMENT),
            1 => Just(f64::from_bits(MAX_ABS_MEASUREMENT.to_bits() + 1)),
            1 => Just(1e300),
            1 => Just(f64::MAX),
            1 => Just(f64::MIN_POSITIVE),
            1 => Just(-0.0),
        ]
    }

    /// Half the payloads wholly ordinary, half with any entries.
    fn any_array() -> impl Strategy<Value = [f64; MAX_DOF]> {
        prop_oneof![
            prop::array::uniform::<_, MAX_DOF>(-10.0f64..10.0),
            prop::array::uniform::<_, MAX_DOF>(any_f64()),
        ]
    }

    /// Header fields: mostly right (agent 1, dof 2, the expected seq: `None` here, filled in by
    /// the test), sometimes anything.
    fn any_agent() -> impl Strategy<Value = u32> {
        prop_oneof![6 => Just(1u32), 1 => 0u32..8, 1 => any::<u32>()]
    }
    fn any_dof() -> impl Strategy<Value = u32> {
        prop_oneof![6 => Just(2u32), 1 => 0u32..24, 1 => any::<u32>()]
    }
    /// `None`: the expected one; `Some(x)`: `x` as is.
    fn any_seq() -> impl Strategy<Value = Option<u64>> {
        prop_oneof![6 => Just(None), 1 => (0u64..40).prop_map(Some), 1 => any::<u64>().prop_map(Some)]
    }
    fn any_time() -> impl Strategy<Value = Option<f64>> {
        prop_oneof![6 => Just(None), 1 => any_f64().prop_map(Some)]
    }

    #[derive(Debug, Clone)]
    struct Fields {
        agent: u32,
        dof: u32,
        seq: Option<u64>,
        t: Option<f64>,
        a: [f64; MAX_DOF],
        b: [f64; MAX_DOF],
        ns: (u64, u64),
    }

    fn any_fields() -> impl Strategy<Value = Fields> {
        (
            any_agent(),
            any_dof(),
            any_seq(),
            any_time(),
            any_array(),
            any_array(),
            (any::<u64>(), any::<u64>()),
        )
            .prop_map(|(agent, dof, seq, t, a, b, ns)| Fields {
                agent,
                dof,
                seq,
                t,
                a,
                b,
                ns,
            })
    }

    fn sane(v: &[f64]) -> bool {
        v.iter()
            .all(|x| x.is_finite() && x.abs() <= MAX_ABS_MEASUREMENT)
    }

    proptest! {
        #[test]
        fn check_header_never_panics_and_accepts_only_the_expected(agent in any::<u32>(), dof in any::<u32>(), seq in any::<u64>(), exp in 0u64..1000) {
            let r = check_header(agent, dof, seq, 2, |a| (1..=4).contains(&a), exp);
            let good = (1..=4).contains(&agent) && dof == 2 && seq == exp;
            prop_assert_eq!(r.is_ok(), good);
        }
    }

    proptest! {
        /// Arbitrary measurements through the validation path and the control center: no
        /// panic; every structurally bad message refused (and counted); every good one ticked,
        /// rejected by the center exactly when a value is non-finite or above 1e6; every torque
        /// finite.
        #[test]
        fn arbitrary_measurements_never_panic_and_every_bad_one_is_refused_or_rejected(
            msgs in prop::collection::vec(any_fields(), 1..24)
        ) {
            let r = paper_scenario();
            let dt = r.scenario.control_period_s;
            let mut center = center(&r);
            let (mut expected, mut refused, mut value_bad) = (0u64, 0u64, 0u64);
            for f in &msgs {
                let seq = f.seq.unwrap_or(expected);
                let m = MeasurementMsg {
                    seq,
                    agent: f.agent,
                    dof: f.dof,
                    t: f.t.unwrap_or_else(|| tick_time(seq, dt)),
                    y: f.a,
                    yd: f.b,
                    agent_sent_ns: f.ns.0,
                    attacker_received_ns: f.ns.1,
                    attacker_sent_ns: f.ns.1,
                    flags: 0,
                    reserved: 0,
                };
                let header = check_header(m.agent, m.dof, m.seq, 2, |a| a == 1, expected);
                let structurally_good =
                    m.agent == 1 && m.dof == 2 && m.seq == expected && m.t.is_finite();
                prop_assert_eq!(header.is_ok(), m.agent == 1 && m.dof == 2 && m.seq == expected);
                match validate_measurement(&m, 2, |a| a == 1, expected) {
                    Err(e) => {
                        prop_assert!(!structurally_good, "refused a good message: {}", e);
                        prop_assert!(!e.to_string().is_empty());
                        refused += 1;
                    }
                    Ok(v) => {
                        prop_assert!(structurally_good, "accepted {:?}", m);
                        prop_assert_eq!((v.y.len(), v.yd.len()), (2, 2));
                        let bad = !(sane(v.y) && sane(v.yd));
                        let before = center.rejected_inputs;
                        let y = fdi_common::model::Vector::<2>::from_column_slice(v.y);
                        let yd = fdi_common::model::Vector::<2>::from_column_slice(v.yd);
                        let out = center.tick(tick_time(seq, dt), &y, &yd);
                        prop_assert_eq!(out.rejected_input, bad);
                        prop_assert_eq!(center.rejected_inputs, before + u64::from(bad));
                        prop_assert!(out.u.iter().all(|x| x.is_finite()), "torque {:?}", out.u);
                        value_bad += u64::from(bad);
                        expected += 1;
                    }
                }
            }
            prop_assert_eq!(refused + expected, msgs.len() as u64);
            prop_assert_eq!(center.rejected_inputs, value_bad);
        }

        /// Arbitrary torque commands through the validation path and an agent's delay line: no
        /// panic; structurally bad ones refused; a good one is taken exactly when its torque is
        /// finite and its stamp newer than the newest held.
        #[test]
        fn arbitrary_torques_never_panic_and_only_finite_increasing_ones_are_taken(
            msgs in prop::collection::vec(any_fields(), 1..24)
        ) {
            let r = paper_scenario();
            let dt = r.scenario.control_period_s;
            let mut plant =
                Plant::<2>::new(r.scenario.plant_params(&r.scenario.agents[0])).expect("plant");
            let mut expected = 0u64;
            for f in &msgs {
                let seq = f.seq.unwrap_or(expected);
                let m = TorqueMsg {
                    seq,
                    agent: f.agent,
                    dof: f.dof,
                    t_send: f.t.unwrap_or_else(|| tick_time(seq, dt)),
                    u: f.a,
                    agent_sent_ns: f.ns.0,
                    attacker_received_ns: f.ns.1,
                    attacker_sent_ns: f.ns.1,
                    center_received_ns: f.ns.0,
                    center_sent_ns: f.ns.1,
                    held_s: 0.0,
                    flags: 0,
                    reserved: 0,
                };
                let good = m.agent == 1 && m.dof == 2 && m.seq == expected && m.t_send.is_finite();
                match validate_torque(&m, 2, 1, expected) {
                    Err(_) => prop_assert!(!good),
                    Ok(u) => {
                        prop_assert!(good);
                        let newest = plant.newest_command_stamp();
                        let takeable = u.iter().all(|x| x.is_finite())
                            && newest.is_none_or(|n| m.t_send > n);
                        let refused_before = plant.refused_commands;
                        let got = plant.receive(m.t_send, fdi_common::model::Vector::<2>::from_column_slice(u));
                        prop_assert_eq!(got.is_ok(), takeable);
                        prop_assert_eq!(plant.refused_commands, refused_before + u64::from(!takeable));
                        expected += 1;
                    }
                }
            }
        }

        /// Whatever the sequence numbers, the tracker never panics, its counts add up to the
        /// messages observed, and it accepts each sequence number at most once.
        #[test]
        fn sequence_tracker_counts_every_message_once_and_accepts_each_seq_at_most_once(
            obs in prop::collection::vec((0u32..4, prop_oneof![4 => 0u64..200, 1 => any::<u64>()]), 0..300)
        ) {
            let mut t = SequenceTracker::new([1, 2], 150);
            let mut accepted = std::collections::BTreeSet::new();
            for &(agent, seq) in &obs {
                let v = t.observe(agent, seq);
                if v.is_accepted() {
                    prop_assert!(accepted.insert((agent, seq)), "{:?} accepted twice", (agent, seq));
                    prop_assert!(seq < 150);
                }
                if agent == 0 || agent == 3 {
                    prop_assert_eq!(v, SeqVerdict::UnknownAgent);
                }
            }
            let c = t.totals();
            prop_assert_eq!(c.in_order + c.gaps + c.dropped(), obs.len() as u64);
            prop_assert_eq!(c.in_order + c.gaps, accepted.len() as u64);
        }
    }

    #[test]
    fn validation_checks_the_dof_against_the_payload_before_indexing() {
        let m = MeasurementMsg {
            seq: 0,
            agent: 1,
            dof: MAX_DOF as u32 + 1,
            t: 0.0,
            y: [0.0; MAX_DOF],
            yd: [0.0; MAX_DOF],
            agent_sent_ns: 0,
            attacker_received_ns: 0,
            attacker_sent_ns: 0,
            flags: 0,
            reserved: 0,
        };
        // Even a receiver configured for more links than a payload holds never slices past it.
        let over = MAX_DOF as u32 + 1;
        assert_eq!(
            validate_measurement(&m, over as usize, |_| true, 0),
            Err(MsgError::DofOutOfRange {
                agent: 1,
                dof: over
            })
        );
        let full = MeasurementMsg {
            dof: MAX_DOF as u32,
            ..m
        };
        let v = validate_measurement(&full, MAX_DOF, |_| true, 0).expect("a full payload fits");
        assert_eq!(v.y.len(), MAX_DOF);
        assert_eq!(
            validate_measurement(&MeasurementMsg { dof: u32::MAX, ..m }, 2, |_| true, 0),
            Err(MsgError::DofOutOfRange {
                agent: 1,
                dof: u32::MAX
            })
        );
        assert_eq!(
            validate_measurement(
                &MeasurementMsg {
                    agent: 9,
                    dof: 99,
                    ..m
                },
                2,
                |a| a == 1,
                0
            ),
            Err(MsgError::UnknownAgent { agent: 9 })
        );
        let nan_t = MeasurementMsg {
            dof: 2,
            t: f64::NAN,
            ..m
        };
        assert!(matches!(
            validate_measurement(&nan_t, 2, |_| true, 0),
            Err(MsgError::BadTime {
                agent: 1,
                seq: 0,
                ..
            })
        ));
        let torque = TorqueMsg {
            seq: 3,
            agent: 2,
            dof: 2,
            t_send: 0.003,
            u: [1.0; MAX_DOF],
            agent_sent_ns: 0,
            attacker_received_ns: 0,
            attacker_sent_ns: 0,
            center_received_ns: 0,
            center_sent_ns: 0,
            held_s: 0.0,
            flags: 0,
            reserved: 0,
        };
        assert_eq!(validate_torque(&torque, 2, 2, 3).map(<[f64]>::len), Ok(2));
        assert_eq!(
            validate_torque(&torque, 2, 1, 3),
            Err(MsgError::UnknownAgent { agent: 2 })
        );
        assert!(matches!(
            validate_torque(
                &TorqueMsg {
                    t_send: f64::INFINITY,
                    ..torque
                },
                2,
                2,
                3
            ),
            Err(MsgError::BadTime { .. })
        ));
    }

    #[test]
    fn sequence_tracker_in_order_and_gaps() {
        let mut t = SequenceTracker::new([1, 2], 1_000);
        for k in 0..5 {
            assert_eq!(t.observe(1, k), SeqVerdict::InOrder);
        }
        assert_eq!(t.expected(1), Some(5));
        assert_eq!(t.observe(1, 8), SeqVerdict::Gap { missing: 3 });
        assert_eq!(t.expected(1), Some(9));
        // Agents are independent: agent 2 still expects 0; its first message may skip some.
        assert_eq!(t.expected(2), Some(0));
        assert_eq!(t.observe(2, 2), SeqVerdict::Gap { missing: 2 });
        // A jump beyond the window forgets the seen bits, but is still just a gap.
        assert_eq!(t.observe(1, 500), SeqVerdict::Gap { missing: 491 });
        assert_eq!(t.observe(1, 501), SeqVerdict::InOrder);
        let c = t.counts(1).expect("agent 1");
        assert_eq!((c.in_order, c.gaps, c.missing, c.dropped()), (6, 2, 494, 0));
        assert!(SeqVerdict::InOrder.is_accepted() && SeqVerdict::Gap { missing: 1 }.is_accepted());
    }

    #[test]
    fn sequence_tracker_duplicates_replays_and_late_arrivals() {
        let mut t = SequenceTracker::new([4], 1_000);
        for k in 0..10 {
            t.observe(4, k);
        }
        // The newest again: duplicate.
        assert_eq!(t.observe(4, 9), SeqVerdict::Duplicate);
        assert_eq!(t.observe(4, 9), SeqVerdict::Duplicate);
        // An older one already seen: replay.
        assert_eq!(t.observe(4, 3), SeqVerdict::Replayed { behind: 6 });
        assert_eq!(t.observe(4, 0), SeqVerdict::Replayed { behind: 9 });
        // Skip 10 and 11, then they arrive late: out of order once, replayed after.
        assert_eq!(t.observe(4, 12), SeqVerdict::Gap { missing: 2 });
        assert_eq!(t.observe(4, 11), SeqVerdict::OutOfOrder { behind: 1 });
        assert_eq!(t.observe(4, 10), SeqVerdict::OutOfOrder { behind: 2 });
        assert_eq!(t.observe(4, 10), SeqVerdict::Replayed { behind: 2 });
        // None of these moved the tracker.
        assert_eq!(t.expected(4), Some(13));
        // Older than the window: cannot be told from a replay, so it is one.
        for k in 13..100 {
            assert_eq!(t.observe(4, k), SeqVerdict::InOrder);
        }
        assert_eq!(
            t.observe(4, 99 - SequenceTracker::WINDOW),
            SeqVerdict::Replayed {
                behind: SequenceTracker::WINDOW
            }
        );
        let c = t.counts(4).expect("agent 4");
        assert_eq!(
            (c.duplicates, c.replayed, c.out_of_order, c.gaps, c.missing),
            (2, 4, 2, 1, 2)
        );
        assert_eq!(c.dropped(), 8);
        assert!(!SeqVerdict::Duplicate.is_accepted());
        assert!(!SeqVerdict::Replayed { behind: 1 }.is_accepted());
        assert!(!SeqVerdict::OutOfOrder { behind: 1 }.is_accepted());
    }

    #[test]
    fn sequence_tracker_refuses_out_of_range_and_unknown_agents_without_moving() {
        let mut t = SequenceTracker::new([1], 40_000);
        assert_eq!(t.observe(1, 0), SeqVerdict::InOrder);
        // One forged far-future seq must not make every honest message after it look old.
        assert_eq!(
            t.observe(1, u64::MAX),
            SeqVerdict::OutOfRange { limit: 40_000 }
        );
        assert_eq!(
            t.observe(1, 40_000),
            SeqVerdict::OutOfRange { limit: 40_000 }
        );
        assert_eq!(t.observe(1, 1), SeqVerdict::InOrder);
        assert_eq!(t.observe(7, 2), SeqVerdict::UnknownAgent);
        assert_eq!(t.expected(7), None);
        assert_eq!(t.counts(7), None);
        let all = t.totals();
        assert_eq!(
            (all.out_of_range, all.unknown_agent, all.in_order),
            (2, 1, 2)
        );
        // Without a limit, u64::MAX is the only value refused, and nothing overflows.
        let mut open = SequenceTracker::new([1], u64::MAX);
        assert_eq!(
            open.observe(1, u64::MAX - 1),
            SeqVerdict::Gap {
                missing: u64::MAX - 1
            }
        );
        assert_eq!(open.expected(1), Some(u64::MAX));
        assert_eq!(
            open.observe(1, u64::MAX),
            SeqVerdict::OutOfRange { limit: u64::MAX }
        );
        assert_eq!(
            open.observe(1, 0),
            SeqVerdict::Replayed {
                behind: u64::MAX - 1
            }
        );
    }

    #[test]
    fn vectors_round_trip_through_payload_arrays() {
        let v = Vector::<2>::new(1.25, -3.5);
        assert_eq!(to_vector::<2>(&from_vector(&v)), v);
    }
}
