//! Payloads on the network: their bytes are their `#[repr(C)]` layout, their stamps moved to
//! the receiving host's clock, several in one batch.

use fdi_runtime::ipc::{
    AlarmMsg, ControlMsg, ControllerInMsg, ControllerOutMsg, MeasurementMsg, Payload, StatusMsg,
    TorqueMsg,
};
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

use crate::error::NetError;

/// A payload the bridge carries: its bytes are its layout (no padding: checked by zerocopy),
/// and its CLOCK_MONOTONIC stamps are moved to the receiving host's clock.
pub(crate) trait Carried: Payload + IntoBytes + FromBytes + Immutable + KnownLayout {
    /// Adds `by` ns to every stamp that is set (non-zero).
    fn shift_clock(&mut self, by: i64);

    /// (agent, sequence number) of a payload whose sender numbers them in increasing order,
    /// per agent: the bridge refuses one that does not come after the last it let in.
    fn order(&self) -> Option<(u32, u64)> {
        None
    }
}

fn shifted(ns: &mut u64, by: i64) {
    if *ns != 0 {
        *ns = ns.saturating_add_signed(by);
    }
}

impl Carried for MeasurementMsg {
    fn order(&self) -> Option<(u32, u64)> {
        Some((self.agent, self.seq))
    }

    fn shift_clock(&mut self, by: i64) {
        for ns in [
            &mut self.agent_sent_ns,
            &mut self.attacker_received_ns,
            &mut self.attacker_sent_ns,
        ] {
            shifted(ns, by);
        }
    }
}

impl Carried for TorqueMsg {
    fn order(&self) -> Option<(u32, u64)> {
        Some((self.agent, self.seq))
    }

    fn shift_clock(&mut self, by: i64) {
        for ns in [
            &mut self.agent_sent_ns,
            &mut self.attacker_received_ns,
            &mut self.attacker_sent_ns,
            &mut self.center_received_ns,
            &mut self.center_sent_ns,
        ] {
            shifted(ns, by);
        }
    }
}

impl Carried for ControlMsg {
    fn shift_clock(&mut self, by: i64) {
        shifted(&mut self.epoch_ns, by);
    }
}

impl Carried for StatusMsg {
    fn shift_clock(&mut self, _by: i64) {}
}

impl Carried for AlarmMsg {
    fn order(&self) -> Option<(u32, u64)> {
        Some((self.agent, self.seq))
    }

    fn shift_clock(&mut self, by: i64) {
        shifted(&mut self.monitor_sent_ns, by);
    }
}

impl Carried for ControllerInMsg {
    fn order(&self) -> Option<(u32, u64)> {
        Some((self.agent, self.seq))
    }

    fn shift_clock(&mut self, by: i64) {
        shifted(&mut self.center_sent_ns, by);
    }
}

impl Carried for ControllerOutMsg {
    fn order(&self) -> Option<(u32, u64)> {
        Some((self.agent, self.seq))
    }

    fn shift_clock(&mut self, by: i64) {
        shifted(&mut self.controller_sent_ns, by);
    }
}

/// Decodes a frame of `T` (exactly its size) and moves its stamps by `by` ns.
pub(crate) fn decode<T: Carried>(key: &str, bytes: &[u8], by: i64) -> Result<T, NetError> {
    let mut value = T::read_from_bytes(bytes).map_err(|_| NetError::Frame {
        key: key.into(),
        what: format!(
            "{} bytes where {} are {} bytes (do both hosts run the same fdi-mas?)",
            bytes.len(),
            std::any::type_name::<T>(),
            std::mem::size_of::<T>()
        ),
    })?;
    value.shift_clock(by);
    Ok(value)
}

/// Appends `value` to `batch`, its stamps moved by `by` ns.
pub(crate) fn encode<T: Carried>(mut value: T, by: i64, batch: &mut Vec<u8>) {
    value.shift_clock(by);
    batch.extend_from_slice(value.as_bytes());
}

/// Splits a batch of frames of `T` (one or more, one after the other: what one put carries)
/// into its frames; a batch that is not a whole number of them is an error naming the key.
pub(crate) fn frames<'b, T: Carried>(
    key: &str,
    batch: &'b [u8],
) -> Result<std::slice::ChunksExact<'b, u8>, NetError> {
    let size = std::mem::size_of::<T>();
    if batch.is_empty() || !batch.len().is_multiple_of(size) {
        return Err(NetError::Frame {
            key: key.into(),
            what: format!(
                "{} bytes, not a whole number of {} frames of {size} bytes (do both hosts run \
                 the same fdi-mas?)",
                batch.len(),
                std::any::type_name::<T>(),
            ),
        });
    }
    Ok(batch.chunks_exact(size))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// One frame, encoded as the bridge puts it (alone in its batch).
    pub(crate) fn encoded<T: Carried>(value: T, by: i64) -> Vec<u8> {
        let mut batch = Vec::new();
        encode(value, by, &mut batch);
        batch
    }

    #[test]
    fn frames_round_trip_with_their_stamps_moved_and_a_wrong_size_is_refused() {
        let m = MeasurementMsg {
            seq: 7,
            agent: 2,
            dof: 2,
            t: 0.25,
            y: [1.5; fdi_common::scenario::MAX_DOF],
            yd: [-0.5; fdi_common::scenario::MAX_DOF],
            agent_sent_ns: 1_000,
            attacker_received_ns: 0,
            attacker_sent_ns: 3_000,
            flags: 0,
            reserved: 0,
        };
        let bytes = encoded(m, 500);
        assert_eq!(bytes.len(), std::mem::size_of::<MeasurementMsg>());
        let back: MeasurementMsg = decode("k", &bytes, -500).expect("decodes");
        assert_eq!(back, m, "moved there and back, unset stamps stay unset");
        let shifted: MeasurementMsg = decode("k", &bytes, 0).expect("decodes");
        assert_eq!(shifted.agent_sent_ns, 1_500);
        assert_eq!(shifted.attacker_received_ns, 0);
        let err = decode::<MeasurementMsg>("k", &bytes[1..], 0).expect_err("short frame");
        assert!(err.to_string().contains("frame on `k`"), "{err}");
        // A put carries a batch: whole frames one after the other, nothing else.
        let mut batch = Vec::new();
        for seq in [7, 8, 9] {
            encode(MeasurementMsg { seq, ..m }, 0, &mut batch);
        }
        let seqs: Vec<u64> = frames::<MeasurementMsg>("k", &batch)
            .expect("three frames")
            .map(|f| decode::<MeasurementMsg>("k", f, 0).expect("decodes").seq)
            .collect();
        assert_eq!(seqs, [7, 8, 9]);
        for wrong in [&batch[..0], &batch[..batch.len() - 1], &batch[1..]] {
            let err = frames::<MeasurementMsg>("k", wrong).expect_err("not whole frames");
            assert!(
                err.to_string()
                    .contains(&format!("{} bytes, not a whole number", wrong.len())),
                "{err}"
            );
        }
    }
}
