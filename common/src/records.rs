//! Per-tick records of each process, and their join. The in-process engine produces the joined
//! [`TickRecord`] directly; the multi-process runtime writes one stream per process and joins
//! them after the run. Both feed the same [`crate::metrics`] and [`TraceDigest`].

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::limits::MAX_DOF;
use crate::model::Vector;

/// A joint-space vector of up to [`MAX_DOF`] entries, stored without heap allocation and
/// serialized as a sequence of its `len` entries.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Joints {
    len: u8,
    v: [f64; MAX_DOF],
}

impl Joints {
    #[inline]
    pub fn as_slice(&self) -> &[f64] {
        &self.v[..usize::from(self.len)]
    }

    /// The first `N` entries as a vector (missing entries are zero).
    #[inline]
    pub fn to_vector<const N: usize>(&self) -> Vector<N> {
        let mut out = Vector::<N>::zeros();
        for (o, v) in out.iter_mut().zip(self.as_slice()) {
            *o = *v;
        }
        out
    }

    #[inline]
    pub fn from_slice(s: &[f64]) -> Self {
        let mut j = Self::default();
        let n = s.len().min(MAX_DOF);
        j.v[..n].copy_from_slice(&s[..n]);
        j.len = n as u8;
        j
    }
}

impl<const N: usize> From<&Vector<N>> for Joints {
    #[inline]
    fn from(v: &Vector<N>) -> Self {
        Self::from_slice(v.as_slice())
    }
}

impl<const N: usize> From<Vector<N>> for Joints {
    #[inline]
    fn from(v: Vector<N>) -> Self {
        Self::from(&v)
    }
}

impl Serialize for Joints {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.as_slice())
    }
}

impl<'de> Deserialize<'de> for Joints {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visit;
        impl<'de> serde::de::Visitor<'de> for Visit {
            type Value = Joints;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                write!(f, "a sequence of at most {MAX_DOF} numbers")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> Result<Joints, A::Error> {
                let mut j = Joints::default();
                while let Some(x) = seq.next_element::<f64>()? {
                    if usize::from(j.len) == MAX_DOF {
                        return Err(serde::de::Error::invalid_length(MAX_DOF + 1, &self));
                    }
                    j.v[usize::from(j.len)] = x;
                    j.len += 1;
                }
                Ok(j)
            }
        }
        d.deserialize_seq(Visit)
    }
}

/// What an agent process knows about tick `k`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AgentRecord {
    pub k: u64,
    pub agent: u32,
    /// `t_k`, s (sim time; in realtime mode, time since the shared epoch).
    pub t: f64,
    /// True state at `t_k`.
    pub q: Joints,
    pub qd: Joints,
    pub qdd: Joints,
    /// Measurement published (with sensor noise, before any attack).
    pub y: Joints,
    pub yd: Joints,
    /// Torque applied at `t_k`: `u(t_k − τ(t_k))`.
    pub u_applied: Joints,
    /// `τ(t_k)`, s.
    pub tau: f64,
    /// The integration step from `t_k` held a command because the due one was missing.
    pub missed: bool,
}

/// What became of the message of one tick on its way through the attacker.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Delivery {
    /// The receiver took it as the tick's input.
    #[default]
    Delivered,
    /// Nothing arrived for the tick (dropped, or nothing delivered yet under a delay).
    Missing,
    /// Sent with a forged stamp and refused: the tick's input is missing.
    Forged,
    /// An earlier message re-sent with its original header in its place, refused as stale:
    /// the tick's input is missing.
    Replayed,
}

impl Delivery {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Delivered => "delivered",
            Self::Missing => "missing",
            Self::Forged => "forged",
            Self::Replayed => "replayed",
        }
    }
}

/// The true attack term of one link that the estimate `Ŝ` tracks, rad/s: `S = S₂ + β S₁`, with
/// `S₁` the injected position (`alpha_position`, rad) and `S₂` the injected velocity
/// (`alpha_velocity`, rad/s). The one place that says it (the report's figures, the exports).
pub fn true_s(alpha_position: f64, alpha_velocity: f64, beta: f64) -> f64 {
    alpha_velocity + beta * alpha_position
}

/// What the attacker process knows about tick `k` of one agent's measurement.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AttackRecord {
    pub k: u64,
    pub agent: u32,
    /// Injected `α`, rad and rad/s.
    pub alpha_position: Joints,
    pub alpha_velocity: Joints,
    /// The measurement the control center took as the tick's input (under a delay, an older
    /// one); empty when the tick's input was missing (`delivery`).
    pub y: Joints,
    pub yd: Joints,
    /// The attack was in force: the injected value was non-zero on some link of either signal,
    /// or a transform or a message attack was in force.
    pub active: bool,
    pub delivery: Delivery,
}

/// What the attacker process knows about the torque of tick `k` of one agent, when the run
/// routes that agent's torques through it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ActuationRecord {
    pub k: u64,
    pub agent: u32,
    /// Injected `α_u`, N·m.
    pub alpha_u: Joints,
    /// The torque the agent took as the tick's command; empty when it was missing.
    pub u: Joints,
    /// How much later than the channel's known delay `τ` it took effect (a delay attack), s.
    pub held_s: f64,
    /// The attack on the torque path was in force.
    pub active: bool,
    pub delivery: Delivery,
}

/// What the control-center process knows about tick `k` of one agent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CenterRecord {
    pub k: u64,
    pub agent: u32,
    /// `Ŝ` used in the tick.
    pub s_hat: Joints,
    /// Observer state after the tick.
    pub q_hat: Joints,
    pub qd_hat: Joints,
    pub qdd_hat: Joints,
    /// Torque sent, stamped `t_k`.
    pub u: Joints,
    pub alarm: bool,
    /// The measurement was rejected (non-finite or absurd).
    pub rejected_input: bool,
    /// The computed torque was non-finite; the last good one was sent.
    pub rejected_torque: bool,
    /// Non-finite observer or estimator state was reset in this tick.
    pub state_reset: bool,
    /// `e_u`, `u_τ` were held: the torque history did not reach back to `t − τ(t)`.
    pub history_miss: bool,
    /// The tick's measurement was missing (dropped, forged, replayed, not yet delivered): the
    /// last good one was used.
    pub missing_input: bool,
}

/// A monitor program's verdict on tick `k` of one agent (`[roles.monitor]`), as the control
/// center received it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MonitorRecord {
    pub k: u64,
    pub agent: u32,
    /// The monitor's alarm at this tick.
    pub alarm: bool,
    /// Its statistic (any unit; NaN when it gave none).
    pub statistic: f64,
    /// Realtime: it arrived later than the monitor's deadline after the tick's time (the
    /// verdict still counts). Always false in lockstep.
    pub late: bool,
}

/// One tick of one agent, joined across processes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TickRecord {
    pub agent: AgentRecord,
    pub attack: AttackRecord,
    pub center: CenterRecord,
    /// The torque's way through the attacker, for an agent whose torques it attacks.
    pub actuation: Option<ActuationRecord>,
    /// The monitor program's verdict on the tick (`[roles.monitor]`); `None` without a
    /// monitor, or when it gave none for the tick (counted as missing).
    #[serde(default)]
    pub monitor: Option<MonitorRecord>,
}

/// SHA-256 over every tick's true state, tampered measurement and torque as f64 bit patterns,
/// in tick order and, within a tick, in the scenario's agent order.
#[derive(Debug, Clone, Default)]
pub struct TraceDigest {
    hasher: Sha256,
}

impl TraceDigest {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn push(&mut self, r: &TickRecord) {
        // The record's bytes in one update (the same byte stream as one update per value).
        let mut bytes = [0u8; 5 * MAX_DOF * 8];
        let mut len = 0;
        for j in [
            &r.agent.q,
            &r.agent.qd,
            &r.attack.y,
            &r.attack.yd,
            &r.center.u,
        ] {
            for x in j.as_slice() {
                bytes[len..len + 8].copy_from_slice(&x.to_bits().to_le_bytes());
                len += 8;
            }
        }
        self.hasher.update(&bytes[..len]);
    }

    /// Lower-case hex.
    pub fn finish(self) -> String {
        self.hasher
            .finalize()
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joints_round_trip_through_json_with_only_their_entries() {
        let j = Joints::from(&Vector::<2>::new(1.5, -2.25));
        let s = serde_json::to_string(&j).expect("serialize");
        assert_eq!(s, "[1.5,-2.25]");
        let back: Joints = serde_json::from_str(&s).expect("deserialize");
        assert_eq!(back, j);
        let full: Vec<String> = (0..MAX_DOF).map(|i| i.to_string()).collect();
        let fits = format!("[{}]", full.join(","));
        assert_eq!(
            serde_json::from_str::<Joints>(&fits)
                .map(|j| j.as_slice().len())
                .ok(),
            Some(MAX_DOF)
        );
        let over = format!("[{},{MAX_DOF}]", full.join(","));
        assert!(serde_json::from_str::<Joints>(&over).is_err());
    }
}
