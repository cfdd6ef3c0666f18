//! fdi-runtime: the process side every fdi-mas role shares.
//!
//! [`ipc`] is the transport: the [`ipc::Transport`] trait the roles are generic over, and its
//! iceoryx2 implementation (shared memory between processes, or in-process between threads for
//! tests), the only code that calls iceoryx2 and knows where its files live.
//! Runs split over hosts carry these services between hosts in their own crate, `fdi-net` (the
//! only code that calls Zenoh): a run on one host compiles and links none of it.
//! [`process`] is the shell around a role's loop: the launcher's arguments and the placement of
//! the process, shutdown on signals or the launcher's death, the start handshake and status
//! reports, admission of received messages, and the liveness of realtime peers. The math the
//! roles run is in `fdi-common`, which does no I/O besides reading scenario and trace files.
// A test reads top to bottom: the limit on long functions (clippy.toml) is for the rest.
#![cfg_attr(test, allow(clippy::too_many_lines))]

pub mod ipc;
pub mod process;
pub mod role;
pub mod stderr;
