//! Zero-copy payloads of the runtime's services: `#[repr(C)]`, fixed size, explicit type names.
//! nalgebra types are not `ZeroCopySend`, so vectors travel as `[f64; MAX_DOF]` plus `dof`.

use iceoryx2::prelude::ZeroCopySend;

use crate::model::Vector;
use crate::scenario::MAX_DOF;

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
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
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
    /// CLOCK_MONOTONIC when the attacker relayed, ns (0 on the clean hop).
    pub attacker_sent_ns: u64,
}

/// A torque command: control center → agent, stamped with its send time `t_k`.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
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
    pub attacker_sent_ns: u64,
    pub center_received_ns: u64,
    pub center_sent_ns: u64,
}

/// Launcher → every process.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
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
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("fdi_mas::StatusMsg")]
pub struct StatusMsg {
    /// [`Role`] code.
    pub role: u32,
    /// Agent id for agents, 0 otherwise.
    pub agent: u32,
    /// [`StatusMsg::READY`], [`StatusMsg::PROGRESS`] or [`StatusMsg::DONE`].
    pub kind: u32,
    pub reserved: u32,
    /// Ticks completed.
    pub tick: u64,
}

impl StatusMsg {
    pub const READY: u32 = 1;
    pub const PROGRESS: u32 = 2;
    pub const DONE: u32 = 3;
}

/// Which process a status message comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    Agent,
    Attacker,
    Center,
}

impl Role {
    pub fn code(self) -> u32 {
        match self {
            Self::Agent => 1,
            Self::Attacker => 2,
            Self::Center => 3,
        }
    }

    pub fn from_code(c: u32) -> Option<Self> {
        match c {
            1 => Some(Self::Agent),
            2 => Some(Self::Attacker),
            3 => Some(Self::Center),
            _ => None,
        }
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
}

/// Checks the structure of a message (not its values: non-finite data is the control center's
/// business, it rejects and counts it). `expected_seq` is the next tick due from that agent.
pub fn check_header(
    agent: u32,
    dof: u32,
    seq: u64,
    expected_dof: usize,
    known: impl Fn(u32) -> bool,
    expected_seq: u64,
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
    if seq != expected_seq {
        return Err(MsgError::OutOfSequence {
            agent,
            seq,
            expected: expected_seq,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn check_header_never_panics_and_accepts_only_the_expected(agent in any::<u32>(), dof in any::<u32>(), seq in any::<u64>(), exp in 0u64..1000) {
            let r = check_header(agent, dof, seq, 2, |a| (1..=4).contains(&a), exp);
            let good = (1..=4).contains(&agent) && dof == 2 && seq == exp;
            prop_assert_eq!(r.is_ok(), good);
        }
    }

    #[test]
    fn vectors_round_trip_through_payload_arrays() {
        let v = Vector::<2>::new(1.25, -3.5);
        assert_eq!(to_vector::<2>(&from_vector(&v)), v);
    }
}
