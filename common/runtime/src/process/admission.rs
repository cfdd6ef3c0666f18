//! The one function each that admits a received measurement or torque.

/// What a receiver does with one message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Admission<T> {
    /// The tick's input.
    Use(T),
    /// The message stands for its tick, but the tick's input is missing: a gap marker, a
    /// forged stamp (not the tick time of its sequence number), or unusable content. The
    /// receiver holds its last input and counts the tick.
    Missing,
    /// Not the tick's message at all (malformed, another agent's, a duplicate, a replay, a
    /// forged number): dropped and counted; the stream does not move on.
    Refused,
}

/// Whether `t` is the stamp an honest sender puts on tick `seq`: the very expression it
/// computes ([`tick_time`](fdi_common::engine::tick_time)), so the comparison is exact.
fn honest_stamp(seq: u64, t: f64, control_period_s: f64) -> bool {
    t == fdi_common::engine::tick_time(seq, control_period_s)
}

/// What a receiver of measurements (attacker, control center) does with one message: structure
/// first (dof within the payload before any indexing, the expected dof, a finite time stamp),
/// then the sequence (`sequence`, limit = the run's tick count), then the content (a gap
/// marker or a forged stamp: the tick's input is missing). A gap is recorded as an event; a
/// refusal (duplicate, replay, forged far-future number, malformed) is recorded and never moves
/// the stream on.
pub fn admit_measurement(
    m: &crate::ipc::MeasurementMsg,
    dof: usize,
    sequence: &mut crate::ipc::msg::SequenceTracker,
    control_period_s: f64,
    trace: &mut fdi_common::trace::TraceWriter,
) -> Admission<()> {
    use crate::ipc::msg::{validate_measurement, SeqRule, SeqVerdict};
    use fdi_common::engine::tick_time;
    use fdi_common::trace::TraceRecord;
    let structure = validate_measurement(m, dof, |_| true, SeqRule::Tracked).map(|_| ());
    let verdict = structure
        .as_ref()
        .ok()
        .map(|()| sequence.observe(m.agent, m.seq));
    // Events are diagnostics: a failing trace write surfaces on the next record write.
    if let Some(SeqVerdict::Gap { missing }) = verdict {
        let message = format!(
            "agent {}: {missing} measurements missing before tick {}",
            m.agent, m.seq
        );
        let _ = trace.write(&TraceRecord::Event {
            t: tick_time(m.seq, control_period_s),
            message,
        });
    }
    if verdict.is_some_and(SeqVerdict::is_accepted) {
        return if m.is_gap() || !honest_stamp(m.seq, m.t, control_period_s) {
            Admission::Missing
        } else {
            Admission::Use(())
        };
    }
    let message = match (structure, verdict) {
        (Err(e), _) => e.to_string(),
        (_, v) => format!("agent {}, sequence {}: refused ({v:?})", m.agent, m.seq),
    };
    let _ = trace.write(&TraceRecord::Event { t: m.t, message });
    Admission::Refused
}

/// A torque command admitted for its tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Command<const N: usize> {
    /// The tick's honest stamp `t_k`.
    pub stamp: f64,
    /// The torque and how much later than the known delay it takes effect; `None` when the
    /// tick's command is missing (gap marker, forged stamp, bad `held_s`).
    pub torque: Option<(fdi_common::model::Vector<N>, f64)>,
}

/// What a receiver of torques (the agent, or the attacker on the actuation path) does with one
/// message on agent `own_agent`'s channel: it must name that agent, carry `N` links, a finite
/// stamp, and a sequence number below `ticks` (the run's tick count) that is `next_seq` (the
/// one after the last admitted) in lockstep, where nothing is ever lost, and no older than
/// `next_seq` in realtime (a later one means the ones between never came); `Err` refuses it
/// without moving the stream on. An admitted one stands for its tick; its command is missing
/// when it is a gap marker, its stamp is not the tick's time (forged), or its `held_s` is not
/// finite and ≥ 0. The delay line then refuses non-finite values and stamps that do not
/// increase ([`fdi_common::plant::Plant::take_command`]).
pub fn admit_torque<const N: usize>(
    m: &crate::ipc::TorqueMsg,
    own_agent: u32,
    next_seq: u64,
    (ticks, control_period_s): (u64, f64),
    clock: fdi_common::scenario::ClockMode,
) -> Result<Command<N>, crate::ipc::msg::MsgError> {
    use crate::ipc::msg::{to_vector, validate_torque, MsgError, SeqRule};
    use fdi_common::scenario::ClockMode;
    let rule = match clock {
        ClockMode::Lockstep => SeqRule::Exactly(next_seq),
        ClockMode::Realtime => SeqRule::AtLeast(next_seq),
    };
    validate_torque(m, N, own_agent, rule)?;
    if m.seq >= ticks {
        return Err(MsgError::SeqOutOfRange {
            agent: m.agent,
            seq: m.seq,
            limit: ticks,
        });
    }
    let usable = !m.is_gap()
        && honest_stamp(m.seq, m.t_send, control_period_s)
        && m.held_s.is_finite()
        && m.held_s >= 0.0;
    Ok(Command {
        stamp: fdi_common::engine::tick_time(m.seq, control_period_s),
        torque: usable.then(|| (to_vector::<N>(&m.u), m.held_s)),
    })
}

#[cfg(test)]
mod tests {
    use super::admit_torque;
    use crate::ipc::msg::MsgError;
    use crate::ipc::TorqueMsg;
    use fdi_common::scenario::ClockMode::{Lockstep, Realtime};

    fn torque(agent: u32, seq: u64) -> TorqueMsg {
        TorqueMsg {
            seq,
            agent,
            dof: 2,
            t_send: seq as f64 * 1e-3,
            u: [1.0; fdi_common::scenario::MAX_DOF],
            agent_sent_ns: 0,
            attacker_received_ns: 0,
            attacker_sent_ns: 0,
            center_received_ns: 0,
            center_sent_ns: 0,
            held_s: 0.0,
            flags: 0,
            reserved: 0,
        }
    }

    /// Regression: a forged torque with `seq = u64::MAX` passed (`next` then overflowed), and in
    /// lockstep a forged later `seq` was taken and made every honest torque after it stale.
    #[test]
    fn forged_sequence_numbers_are_refused() {
        let ok = admit_torque::<2>(&torque(1, 5), 1, 5, (100, 1e-3), Lockstep);
        assert_eq!(ok.map(|c| c.torque.map(|(u, _)| u[0])), Ok(Some(1.0)));
        assert!(matches!(
            admit_torque::<2>(&torque(1, u64::MAX), 1, 5, (100, 1e-3), Realtime),
            Err(MsgError::SeqOutOfRange { limit: 100, .. })
        ));
        assert!(matches!(
            admit_torque::<2>(&torque(1, 100), 1, 5, (100, 1e-3), Lockstep),
            Err(MsgError::OutOfSequence { .. })
        ));
        assert!(matches!(
            admit_torque::<2>(&torque(1, 9), 1, 5, (100, 1e-3), Lockstep),
            Err(MsgError::OutOfSequence { expected: 5, .. })
        ));
        assert!(admit_torque::<2>(&torque(1, 9), 1, 5, (100, 1e-3), Realtime).is_ok());
        assert!(matches!(
            admit_torque::<2>(&torque(1, 4), 1, 5, (100, 1e-3), Realtime),
            Err(MsgError::Stale { next: 5, .. })
        ));
        assert!(matches!(
            admit_torque::<2>(&torque(2, 5), 1, 5, (100, 1e-3), Lockstep),
            Err(MsgError::UnknownAgent { agent: 2 })
        ));
        assert!(matches!(
            admit_torque::<3>(&torque(1, 5), 1, 5, (100, 1e-3), Lockstep),
            Err(MsgError::WrongDof { .. })
        ));
        let mut nan = torque(1, 5);
        nan.t_send = f64::NAN;
        assert!(matches!(
            admit_torque::<2>(&nan, 1, 5, (100, 1e-3), Lockstep),
            Err(MsgError::BadTime { .. })
        ));
    }

    /// A gap marker, a forged stamp or a bad `held_s` stand for their tick (the stream moves
    /// on) with the command missing; a held command keeps its delay.
    #[test]
    fn gap_markers_and_forged_stamps_leave_the_tick_without_a_command() {
        let take = |m: &TorqueMsg| admit_torque::<2>(m, 1, 5, (100, 1e-3), Lockstep);
        let mut gap = torque(1, 5);
        gap.flags = TorqueMsg::GAP;
        let mut forged = torque(1, 5);
        forged.t_send += 1e-3;
        let mut negative = torque(1, 5);
        negative.held_s = -1e-3;
        let mut nan = torque(1, 5);
        nan.held_s = f64::NAN;
        for m in [gap, forged, negative, nan] {
            let c = take(&m).expect("admitted for its tick");
            assert_eq!((c.stamp, c.torque), (5e-3, None), "{m:?}");
        }
        let mut held = torque(1, 5);
        held.held_s = 0.01;
        let c = take(&held).expect("admitted");
        assert_eq!(c.torque.map(|(_, h)| h), Some(0.01));
    }
}
