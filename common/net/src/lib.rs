//! fdi-net: the network side of the transport: a run's services carried between hosts over Zenoh, and
//! the few Zenoh calls the launcher and `fdi-launch serve` make to find each other. The only
//! code that calls Zenoh (docs/multi-host.md).
//!
//! Inside a host the run's processes talk over shared memory as on one host; they never know
//! the run is split. On each host a [`Bridge`] stands in for the processes of the other hosts:
//! it listens on their wake-up events, so a local process that publishes for one of them wakes
//! the bridge, which drains the stream and puts each payload's bytes (its `#[repr(C)]` layout)
//! on Zenoh; on the receiving host the bridge publishes them into shared memory and only then
//! rings the local receiver, so a wake-up never overtakes its data. Which streams go out and
//! which come in on a host is decided by [`plan`] from where each process runs.
//!
//! Zenoh sample delivery is reliable and in order per key; publishers block rather than drop
//! (`CongestionControl::Block`), so lockstep across hosts loses nothing and stays
//! deterministic. A cut network is noticed through Zenoh's liveliness tokens, which vanish when
//! the session's lease ([`LEASE`]) runs out.
//!
//! Keys (all built in [`keys`]), under `fdi-mas/`, name who may use them: what host `h` says
//! (puts, liveliness) is under `p/<h>/...`, what it asks host `t` (queries) under
//! `q/<t>/<h>/...`. With TLS (the default), Zenoh's access control lets a host's certificate
//! put only under its own `p/<h>/`, ask only as `q/*/<h>/`, and answer only under `q/<h>/`
//! ([`NetConfig`]), so a key says truly who sent on it.

// A test reads top to bottom: the limit on long functions (clippy.toml) is for the rest.
#![cfg_attr(test, allow(clippy::too_many_lines))]

mod access;
mod bridge;
mod clock;
mod endpoint;
mod error;
pub mod keys;
mod plan;
mod session;
mod wire;

pub use access::{access_control, admit_only};
pub use bridge::{Bridge, BridgeCounts, InSide, OutSide, Routes, ZenohBridge};
pub use clock::ClockOffset;
pub use endpoint::{check_endpoint, check_host_name, endpoint_address, Link};
pub use error::NetError;
pub use plan::{plan, streams, HostPlan, Inbound, Layout};
pub use session::{
    choose_zenoh_threads, Answering, Net, NetConfig, NetOutbox, Request, Requests, Security,
    Subscription, Token, ACCEPT_PENDING, ACCEPT_TIMEOUT, LEASE, MAX_MESSAGE_BYTES,
    ONE_RUNTIME_THREAD, ZENOH_RUNTIME_VAR,
};
