//! What every runtime process shares around its main loop, one module per concern: the
//! launcher's arguments ([`ProcessArgs`]), placement on CPUs and scheduling ([`Placement`]),
//! shutdown on SIGINT/SIGTERM or the launcher's death ([`Shutdown`]), waiting for peers
//! ([`WaitStrategy`]), the launcher handshake and status reports ([`LauncherLink`]), admission of
//! received messages ([`admit_measurement`], [`admit_torque`]), liveness ([`Liveness`]) and what
//! `/proc` says about processes ([`procfs`]).

mod admission;
mod args;
mod error;
pub mod external;
mod launcher;
mod liveness;
mod placement;
pub mod procfs;
mod shutdown;
mod wait;

pub use crate::stderr::{print_failure, print_warning};
pub use admission::{admit_measurement, admit_torque, Admission, Command};
pub use args::ProcessArgs;
pub use error::{ProcessError, RoleError, PROGRESS_EVERY};
pub use launcher::{
    connect, finish, node_name, sizing_for, start, trace_header, Connection, LauncherLink, Start,
    HOLD_LIMIT,
};
pub use liveness::{lost_after_ns, realtime_end_ns, Liveness, LIVENESS_CHECK, LOST_AFTER_NS};
pub use placement::{use_fifo, use_idle, CpuList, Placement};
pub use shutdown::Shutdown;
pub use wait::{WaitStrategy, DEFAULT_SPIN_US, START_TIMEOUT, WAIT_SLICE};
