//! The one function each that admits a received measurement or torque.

/// What a receiver of measurements (attacker, control center) does with one message: structure
/// first (dof within the payload before any indexing, the expected dof, a finite time stamp),
/// then the sequence (`sequence`, limit = the run's tick count). A gap is recorded as an event; a
/// refusal (duplicate, replay, forged far-future number, malformed) is recorded and never moves
/// the stream on. Returns whether to use the message.
pub fn admit_measurement(
    m: &crate::ipc::MeasurementMsg,
    dof: usize,
    sequence: &mut crate::ipc::msg::SequenceTracker,
    control_period_s: f64,
    trace: &mut fdi_common::trace::TraceWriter,
) -> bool {
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
        return true;
    }
    let message = match (structure, verdict) {
        (Err(e), _) => e.to_string(),
        (_, v) => format!("agent {}, sequence {}: refused ({v:?})", m.agent, m.seq),
    };
    let _ = trace.write(&TraceRecord::Event { t: m.t, message });
    false
}

/// What the agent does with one torque message on its own channel: it must name this agent,
/// carry `N` links, a finite stamp, and a sequence number below `ticks` (the run's tick count)
/// that is `next_seq` (the one after the last admitted) in lockstep, where nothing is ever
/// lost, and no older than `next_seq` in realtime (a later one means the ones between never
/// came). Returns the torque to take into the delay line, which refuses non-finite values and
/// stamps that do not increase.
pub fn admit_torque<const N: usize>(
    m: &crate::ipc::TorqueMsg,
    own_agent: u32,
    next_seq: u64,
    ticks: u64,
    clock: fdi_common::scenario::ClockMode,
) -> Result<fdi_common::model::Vector<N>, crate::ipc::msg::MsgError> {
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
    Ok(to_vector::<N>(&m.u))
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
        }
    }

    /// Regression: a forged torque with `seq = u64::MAX` passed (`next` then overflowed), and in
    /// lockstep a forged later `seq` was taken and made every honest torque after it stale.
    #[test]
    fn forged_sequence_numbers_are_refused() {
        let ok = admit_torque::<2>(&torque(1, 5), 1, 5, 100, Lockstep);
        assert_eq!(ok.map(|u| u[0]), Ok(1.0));
        assert!(matches!(
            admit_torque::<2>(&torque(1, u64::MAX), 1, 5, 100, Realtime),
            Err(MsgError::SeqOutOfRange { limit: 100, .. })
        ));
        assert!(matches!(
            admit_torque::<2>(&torque(1, 100), 1, 5, 100, Lockstep),
            Err(MsgError::OutOfSequence { .. })
        ));
        assert!(matches!(
            admit_torque::<2>(&torque(1, 9), 1, 5, 100, Lockstep),
            Err(MsgError::OutOfSequence { expected: 5, .. })
        ));
        assert!(admit_torque::<2>(&torque(1, 9), 1, 5, 100, Realtime).is_ok());
        assert!(matches!(
            admit_torque::<2>(&torque(1, 4), 1, 5, 100, Realtime),
            Err(MsgError::Stale { next: 5, .. })
        ));
        assert!(matches!(
            admit_torque::<2>(&torque(2, 5), 1, 5, 100, Lockstep),
            Err(MsgError::UnknownAgent { agent: 2 })
        ));
        assert!(matches!(
            admit_torque::<3>(&torque(1, 5), 1, 5, 100, Lockstep),
            Err(MsgError::WrongDof { .. })
        ));
        let mut nan = torque(1, 5);
        nan.t_send = f64::NAN;
        assert!(matches!(
            admit_torque::<2>(&nan, 1, 5, 100, Lockstep),
            Err(MsgError::BadTime { .. })
        ));
    }
}
