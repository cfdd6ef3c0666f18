//! The errors of the network side.

use std::time::Duration;

use fdi_runtime::ipc::{IpcError, Source};

/// Errors of the network side name the key or the host concerned.
#[derive(Debug, thiserror::Error)]
pub enum NetError {
    #[error("opening the Zenoh session ({what}): {source}")]
    Session {
        what: String,
        #[source]
        source: Source,
    },
    #[error("Zenoh key `{key}`: {source}")]
    Key {
        key: String,
        #[source]
        source: Source,
    },
    #[error("{message}")]
    Refused { key: String, message: String },
    #[error("no answer on `{key}` within {:.1} s", .timeout.as_secs_f64())]
    NoAnswer { key: String, timeout: Duration },
    #[error("frame on `{key}`: {what}")]
    Frame { key: String, what: String },
    #[error(transparent)]
    Ipc(#[from] IpcError),
}

/// A thread that could not be started or ended in a panic, as an error of the transport.
pub(crate) fn thread_error(e: impl std::fmt::Display) -> IpcError {
    IpcError::Node {
        name: "bridge".into(),
        source: e.to_string().into(),
    }
}
