//! The keys of the network side, built in one place. `p/<h>/...`: what host `h` says;
//! `q/<t>/<h>/...`: what host `h` asks host `t`.

use fdi_runtime::ipc::Stream;

/// Liveliness token of the serve of host `name`.
pub fn serve(name: &str) -> String {
    format!("fdi-mas/p/{name}/serve")
}

/// A run request of host `from` to the serve of host `to`.
pub fn run_request(to: &str, from: &str) -> String {
    format!("fdi-mas/q/{to}/{from}/run")
}

/// Where the serve of host `to` takes run requests (from any host).
pub fn run_requests(to: &str) -> String {
    format!("fdi-mas/q/{to}/*/run")
}

/// What host `from` says in the run `prefix`: `coordinator`, `events`, `cmd/<host>`, ...
pub fn said(from: &str, prefix: &str, what: &str) -> String {
    format!("fdi-mas/p/{from}/run/{prefix}/{what}")
}

/// What host `from` asks host `to` in the run `prefix`: `clock`, `traces`, `routes`,
/// `release`.
pub fn asked(to: &str, from: &str, prefix: &str, what: &str) -> String {
    format!("fdi-mas/q/{to}/{from}/run/{prefix}/{what}")
}

/// The service `stream` of the run `prefix` as host `from` sends it.
pub fn stream(from: &str, prefix: &str, stream: Stream) -> String {
    said(from, prefix, &format!("s/{}", stream.service_name()))
}

/// The service `stream` of the run `prefix` as any host sends it.
pub fn stream_any(prefix: &str, service: Stream) -> String {
    stream("*", prefix, service)
}

/// The host that says what is on `key` (`p/<h>/...`) or asks it (`q/<t>/<h>/...`).
pub fn sender(key: &str) -> Option<&str> {
    let mut parts = key.strip_prefix("fdi-mas/")?.split('/');
    match parts.next()? {
        "p" => parts.next(),
        "q" => parts.nth(1),
        _ => None,
    }
}
