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
/// carry `N` links, a finite stamp, and a sequence number no older than `next_seq` (the one
/// after the last admitted; a later one means the ones between never came). Returns the torque
/// to take into the delay line, which refuses non-finite values and stamps that do not increase.
pub fn admit_torque<const N: usize>(
    m: &crate::ipc::TorqueMsg,
    own_agent: u32,
    next_seq: u64,
) -> Result<fdi_common::model::Vector<N>, crate::ipc::msg::MsgError> {
    use crate::ipc::msg::{to_vector, validate_torque, SeqRule};
    validate_torque(m, N, own_agent, SeqRule::AtLeast(next_seq))?;
    Ok(to_vector::<N>(&m.u))
}
