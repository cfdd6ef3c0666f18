//! The transport layer: the [`Transport`] a run's processes talk over, and the only code that
//! calls iceoryx2 ([`iceoryx`]: [`Shm`] between processes, [`Local`] between the threads of one
//! process, for tests).
//!
//! A transport opens a run by its prefix ([`Transport::open`]: runs never see each other),
//! gives publishers ([`Outbox`]) and subscribers ([`Inbox`]) of the run's streams, and one
//! wake-up event per process: peers ring its [`Bell`], it blocks on its [`Waker`] with a
//! deadline. What a run leaves behind (a crashed run's files) is listed and removed through the
//! transport too ([`Transport::leftovers`], [`Transport::remove_leftovers`]), so nothing else
//! knows where those files live.
//!
//! Services (names built in [`Stream::service_name`] / [`Wake::service_name`], isolated per run by
//! the run prefix of [`Transport::open`]):
//!
//! | stream | payload | publishers → subscribers |
//! |---|---|---|
//! | `fdi/measurement` | [`MeasurementMsg`] | N agents → attacker |
//! | `fdi/tampered` | [`MeasurementMsg`] | attacker → control center |
//! | `fdi/torque/<id>` | [`TorqueMsg`] | control center → agent `id` |
//! | `fdi/control` | [`ControlMsg`] | launcher → every process |
//! | `fdi/status` | [`StatusMsg`] | every process → launcher |
//! | `fdi/actuation` | [`TorqueMsg`] | control center → attacker (torques the run attacks) |
//! | `fdi/external/attacker/in` | [`MeasurementMsg`] | attacker → external attacker program |
//! | `fdi/external/attacker/out` | [`MeasurementMsg`] | external attacker program → attacker |
//! | `fdi/alarm` | [`AlarmMsg`] | monitor program → control center |
//! | `fdi/external/controller/in` | [`ControllerInMsg`] | control center → controller program |
//! | `fdi/external/controller/out` | [`ControllerOutMsg`] | controller program → control center |
//!
//! docs/protocol.md is the contract external programs implement (layouts, handshake, rules);
//! `tests/tests/protocol.rs` checks it against these types.
//!
//! Each process has one wake-up event service (`fdi/wake/...`) that its peers notify after
//! publishing; it blocks on it with a timeout, never spinning.
//!
//! QoS: safe overflow is on for every service, so a dead or stalled subscriber never blocks a
//! publisher (the oldest unread sample is overwritten instead). Buffers are sized so that
//! lockstep never overflows; every receiver checks sequence numbers, so an overwritten sample is
//! detected and counted, never silently lost. No history: a process that joins late sees nothing
//! old, which is why the launcher starts the run only after every process reported ready.

pub mod iceoryx;
pub mod machine;
pub mod msg;
pub mod prefix;
mod transport;

pub use iceoryx::{root_dir, shm_dir, Local, LocalShared, Shm, ShmShared};
pub use machine::MachineError;
pub use msg::{
    AlarmMsg, ControlMsg, ControllerInMsg, ControllerOutMsg, MeasurementMsg, Role, StatusMsg,
    TorqueMsg,
};
pub use prefix::RunPrefix;
pub use transport::*;
