//! The network side of the transport: a run's services carried between hosts over Zenoh, and
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

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::Duration;

use zenoh::Wait as _;
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

use crate::ipc::{
    AlarmMsg, Bell as _, ControlMsg, Inbox as _, IpcError, MeasurementMsg, Outbox as _, Payload,
    Sizing, Source, StatusMsg, Stream, TorqueMsg, Transport, Wake, Waker as _,
};

/// How long a host may be silent before Zenoh declares it gone (its liveliness tokens vanish):
/// the session lease. Zenoh's own default is 10 s.
pub const LEASE: Duration = Duration::from_secs(1);

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

/// Checks a host name: 1 to 40 bytes of ASCII letters, digits, `_` and `-` (it becomes part of
/// Zenoh keys and of labels).
pub fn check_host_name(name: &str) -> Result<(), String> {
    if name.is_empty() || name.len() > 40 {
        return Err(format!("host name `{name}` must be 1..=40 bytes"));
    }
    if !name
        .bytes()
        .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
    {
        return Err(format!(
            "host name `{name}`: only ASCII letters, digits, `_` and `-` are allowed"
        ));
    }
    Ok(())
}

/// The transport of an endpoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Link {
    /// QUIC (over UDP): TLS 1.3 with mutual authentication (`quic/<address>:<port>`).
    Quic,
    /// Plain TCP, neither encrypted nor authenticated (`tcp/<address>:<port>`).
    Tcp,
}

/// Checks a Zenoh endpoint of a host, `quic/<address>:<port>` or `tcp/<address>:<port>`, and
/// says which.
pub fn check_endpoint(endpoint: &str) -> Result<Link, String> {
    let (link, rest) = if let Some(rest) = endpoint.strip_prefix("quic/") {
        (Link::Quic, rest)
    } else if let Some(rest) = endpoint.strip_prefix("tcp/") {
        (Link::Tcp, rest)
    } else {
        return Err(format!(
            "endpoint `{endpoint}` must be `quic/<address>:<port>` (or `tcp/<address>:<port>` \
             in a deployment that says `insecure = true`)"
        ));
    };
    let Some((host, port)) = rest.rsplit_once(':') else {
        return Err(format!("endpoint `{endpoint}` has no `:<port>`"));
    };
    if host.is_empty() || port.parse::<u16>().map_or(true, |p| p == 0) {
        return Err(format!(
            "endpoint `{endpoint}` must be `<quic|tcp>/<address>:<port>` with a port in \
             1..=65535"
        ));
    }
    Ok(link)
}

/// The address part of an endpoint (`10.0.0.2` of `quic/10.0.0.2:7447`, without brackets).
pub fn endpoint_address(endpoint: &str) -> Option<&str> {
    let rest = endpoint.split_once('/')?.1;
    let host = rest.rsplit_once(':')?.0;
    Some(host.trim_start_matches('[').trim_end_matches(']'))
}

/// The keys of the network side, built in one place. `p/<h>/...`: what host `h` says;
/// `q/<t>/<h>/...`: what host `h` asks host `t`.
pub mod keys {
    use crate::ipc::Stream;

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
}

/// How the hosts of a run authenticate one another.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Security {
    /// TLS with mutual authentication: every host shows a certificate of the lab's CA whose
    /// common name is its host name, and Zenoh's access control lets each host of `lab` send
    /// only under its own keys; a certificate of no host of `lab` may do nothing.
    Tls {
        /// The lab's CA certificate (PEM).
        ca: std::path::PathBuf,
        /// This host's certificate and private key (PEM).
        cert: std::path::PathBuf,
        key: std::path::PathBuf,
        /// The hosts of the lab (the deployment file's): their certificates' common names.
        lab: Vec<String>,
        /// The addresses the lab's hosts send from (their endpoints'): the QUIC packets of any
        /// other address are dropped by the kernel before Zenoh sees them ([`admit_only`]).
        /// Empty: from anywhere (a session that listens nowhere).
        peers: Vec<std::net::IpAddr>,
    },
    /// Plain TCP: anyone on the network can connect, listen and send (said so by the
    /// deployment file, and in every run's summary).
    Insecure,
}

/// The Zenoh session of a host: where it listens, whom it connects to, how.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NetConfig {
    /// Endpoints this host listens on (`tls/10.0.0.2:7447`).
    pub listen: Vec<String>,
    /// Endpoints of the hosts it connects to.
    pub connect: Vec<String>,
    pub security: Security,
}

/// How long a request that nothing answered waits before it is sent again
/// ([`Net::request`]).
const ASK_AGAIN: Duration = Duration::from_millis(50);

/// How long a connection may take to become a session (its TLS and Zenoh handshakes): a peer
/// that opens a connection and says nothing is dropped then.
pub const ACCEPT_TIMEOUT: Duration = Duration::from_secs(2);
/// The largest message a session takes from a peer.
pub const MAX_MESSAGE_BYTES: usize = 16 << 20;
/// How many connections may be in their handshake at once (Zenoh's default: 100); more are
/// refused until some finish or time out.
pub const ACCEPT_PENDING: usize = 2048;

/// The access control of a TLS session: each host of `lab` (by its certificate's common
/// name) may put and hold liveliness tokens only under `fdi-mas/p/<h>/`, declare queryables and
/// reply only under `fdi-mas/q/<h>/`, ask only as `fdi-mas/q/*/<h>/`, and subscribe to
/// anything of fdi-mas; whatever else comes in is denied, and nothing goes out to a peer that
/// is not a host of `lab`.
pub fn access_control(lab: &[String]) -> String {
    use serde_json::json;
    let all = [
        "put",
        "delete",
        "declare_subscriber",
        "query",
        "declare_queryable",
        "reply",
        "liveliness_token",
        "declare_liveliness_subscriber",
        "liveliness_query",
    ];
    let rule = |id: String, messages: &[&str], flow: &str, keys: Vec<String>| {
        json!({"id": id, "messages": messages, "flows": [flow], "permission": "allow",
               "key_exprs": keys})
    };
    let mut rules = vec![
        rule(
            "listen".into(),
            &[
                "declare_subscriber",
                "declare_liveliness_subscriber",
                "liveliness_query",
            ],
            "ingress",
            vec!["fdi-mas/**".into()],
        ),
        rule("out".into(), &all, "egress", vec!["**".into()]),
    ];
    let (mut subjects, mut policies) = (Vec::new(), Vec::new());
    for (i, h) in lab.iter().enumerate() {
        let own = [
            rule(
                format!("says{i}"),
                &["put", "delete", "liveliness_token", "reply"],
                "ingress",
                vec![format!("fdi-mas/p/{h}/**")],
            ),
            rule(
                format!("answers{i}"),
                &["declare_queryable", "reply"],
                "ingress",
                vec![format!("fdi-mas/q/{h}/**")],
            ),
            rule(
                format!("asks{i}"),
                &["query"],
                "ingress",
                vec![format!("fdi-mas/q/*/{h}/**")],
            ),
        ];
        let mut ids = vec![json!("listen"), json!("out")];
        ids.extend(own.iter().map(|r| r["id"].clone()));
        rules.extend(own);
        subjects.push(json!({"id": format!("host{i}"), "cert_common_names": [h]}));
        policies.push(json!({"rules": ids, "subjects": [format!("host{i}")]}));
    }
    json!({"enabled": true, "default_permission": "deny", "rules": rules,
           "subjects": subjects, "policies": policies})
    .to_string()
}

impl NetConfig {
    fn zenoh(&self) -> Result<zenoh::Config, NetError> {
        let mut c = zenoh::Config::default();
        let set = |c: &mut zenoh::Config, key: &str, value: String| {
            c.insert_json5(key, &value)
                .map_err(|source| NetError::Session {
                    what: format!("setting `{key}`"),
                    source,
                })
        };
        let list = |v: &[String], suffix: &str| {
            let items: Vec<String> = v.iter().map(|e| format!("\"{e}{suffix}\"")).collect();
            format!("[{}]", items.join(", "))
        };
        let quoted = |p: &std::path::Path| serde_json::json!(p.display().to_string()).to_string();
        set(&mut c, "mode", "\"peer\"".into())?;
        // Only the endpoints named: no multicast scouting on a lab network.
        set(&mut c, "scouting/multicast/enabled", "false".into())?;
        set(&mut c, "listen/endpoints", list(&self.listen, ""))?;
        // Reconnect quickly once a cut network is back (Zenoh's default waits seconds).
        set(
            &mut c,
            "connect/endpoints",
            list(
                &self.connect,
                "#retry_period_init_ms=100;retry_period_max_ms=250",
            ),
        )?;
        set(
            &mut c,
            "transport/link/tx/lease",
            LEASE.as_millis().to_string(),
        )?;
        // The door stays open: a connection that does not finish its handshakes in time is
        // dropped, and many may be in them at once.
        set(
            &mut c,
            "transport/unicast/accept_timeout",
            ACCEPT_TIMEOUT.as_millis().to_string(),
        )?;
        set(
            &mut c,
            "transport/unicast/accept_pending",
            ACCEPT_PENDING.to_string(),
        )?;
        // What one peer can make this session hold for one message (Zenoh's default: 1 GiB);
        // a run's largest are the pieces of traces.
        set(
            &mut c,
            "transport/link/rx/max_message_size",
            MAX_MESSAGE_BYTES.to_string(),
        )?;
        set(&mut c, "adminspace/enabled", "false".into())?;
        match &self.security {
            Security::Insecure => {
                set(&mut c, "transport/link/protocols", "[\"tcp\"]".into())?;
            }
            #[rustfmt::skip]
            Security::Tls { ca, cert, key, lab, .. } => {
                // QUIC only (TLS 1.3, mutual authentication): nothing else is accepted. Zenoh's
                // TLS over TCP is not used: its link reads and writes one TLS stream from two
                // tasks at once, which rustls does not support, and under traffic both ways
                // the link fails ("handshake not complete") within a second.
                set(&mut c, "transport/link/protocols", "[\"quic\"]".into())?;
                let tls = "transport/link/tls";
                set(&mut c, &format!("{tls}/root_ca_certificate"), quoted(ca))?;
                set(&mut c, &format!("{tls}/listen_certificate"), quoted(cert))?;
                set(&mut c, &format!("{tls}/listen_private_key"), quoted(key))?;
                set(&mut c, &format!("{tls}/connect_certificate"), quoted(cert))?;
                set(&mut c, &format!("{tls}/connect_private_key"), quoted(key))?;
                set(&mut c, &format!("{tls}/enable_mtls"), "true".into())?;
                set(
                    &mut c,
                    &format!("{tls}/verify_name_on_connect"),
                    "true".into(),
                )?;
                set(&mut c, "access_control", access_control(lab))?;
            }
        }
        Ok(c)
    }
}

/// Makes the kernel drop every datagram that reaches this process's UDP sockets bound to the
/// endpoints `listen` (its QUIC listeners, Zenoh's sockets) unless it comes from one of `peers`
/// or from loopback: a socket filter (classic BPF) on each. Zenoh's QUIC listener takes
/// connections one at a time, and pauses a tenth of a second after each connection opener it
/// could not decrypt: a flood of them from anywhere (no certificate needed) kept the lab's own
/// hosts out (issue 51). The lab's hosts are known by their endpoints; anything else never
/// reaches Zenoh. Fails when a listener's socket is not found or the filter is not taken.
pub fn admit_only(listen: &[String], peers: &[std::net::IpAddr]) -> Result<(), String> {
    use std::net::ToSocketAddrs as _;
    // The program's jumps are a byte long: about 60 addresses at most.
    if peers.len() > MAX_FILTERED_PEERS {
        return Err(format!(
            "{} addresses, more than the {MAX_FILTERED_PEERS} a filter holds",
            peers.len()
        ));
    }
    let program = peer_filter(peers);
    let me = rustix::process::pidfd_open(
        rustix::process::getpid(),
        rustix::process::PidfdFlags::empty(),
    )
    .map_err(|e| format!("opening this process's pidfd: {e}"))?;
    let fds: Vec<i32> = std::fs::read_dir("/proc/self/fd")
        .map_err(|e| format!("reading /proc/self/fd: {e}"))?
        .flatten()
        .filter(|e| {
            std::fs::read_link(e.path()).is_ok_and(|l| l.to_string_lossy().starts_with("socket:"))
        })
        .filter_map(|e| e.file_name().to_str()?.parse().ok())
        .collect();
    for endpoint in listen {
        let (address, port) = endpoint
            .split_once('/')
            .and_then(|(_, rest)| rest.rsplit_once(':'))
            .ok_or_else(|| format!("endpoint `{endpoint}` has no address and port"))?;
        let address = address.trim_start_matches('[').trim_end_matches(']');
        let wanted: Vec<std::net::SocketAddr> = (address, port.parse::<u16>().unwrap_or(0))
            .to_socket_addrs()
            .map_err(|e| format!("endpoint `{endpoint}`: {e}"))?
            .collect();
        let mut filtered = 0;
        for &fd in &fds {
            // A copy of the descriptor: the filter is set on the socket both share.
            let Ok(copy) =
                rustix::process::pidfd_getfd(&me, fd, rustix::process::PidfdGetfdFlags::empty())
            else {
                continue;
            };
            let socket = socket2::SockRef::from(&copy);
            let datagram = socket.r#type().is_ok_and(|t| t == socket2::Type::DGRAM);
            let bound = socket
                .local_addr()
                .ok()
                .and_then(|a| a.as_socket())
                .is_some_and(|a| wanted.contains(&a));
            if datagram && bound {
                socket
                    .attach_filter(&program)
                    .map_err(|e| format!("filtering the socket of `{endpoint}`: {e}"))?;
                filtered += 1;
            }
        }
        if filtered == 0 {
            return Err(format!(
                "no UDP socket of this process is bound to `{endpoint}`"
            ));
        }
    }
    Ok(())
}

/// The most addresses [`admit_only`] filters on.
const MAX_FILTERED_PEERS: usize = 48;

/// A jump of a filter instruction being built: to the final accept, to an instruction, or none.
#[derive(Clone, Copy)]
enum Jump {
    Accept,
    To(usize),
    Fall,
}

/// The classic BPF program of [`admit_only`]: accepts a datagram whose IP source address is
/// one of `peers` or a loopback address, drops any other. It reads the network header (the
/// kernel's negative offset `SKF_NET_OFF`), IPv4 and IPv6 alike.
fn peer_filter(peers: &[std::net::IpAddr]) -> Vec<socket2::SockFilter> {
    use std::net::IpAddr;
    let v4: Vec<u32> = peers
        .iter()
        .filter_map(|p| match p {
            IpAddr::V4(a) => Some(u32::from(*a)),
            IpAddr::V6(a) => a.to_ipv4_mapped().map(u32::from),
        })
        .collect();
    let mut v6: Vec<[u32; 4]> = peers
        .iter()
        .filter_map(|p| match p {
            IpAddr::V6(a) if a.to_ipv4_mapped().is_none() => {
                let s = a.segments();
                Some(std::array::from_fn(|i| {
                    (u32::from(s[2 * i]) << 16) | u32::from(s[2 * i + 1])
                }))
            }
            _ => None,
        })
        .collect();
    v6.push([0, 0, 0, 1]); // ::1
    let mut code: Vec<(u16, Jump, Jump, u32)> = Vec::new();
    // The IP version: the high nibble of the header's first byte; 4 falls through to the
    // IPv4 part, anything else jumps to the IPv6 part (its place is known once the IPv4 part
    // is built).
    code.push((BPF_LD_B, Jump::Fall, Jump::Fall, SKF_NET_OFF));
    code.push((BPF_AND, Jump::Fall, Jump::Fall, 0xf0));
    let version_test = code.len();
    code.push((BPF_JEQ, Jump::Fall, Jump::Fall, 0x40));
    // IPv4: the source address, each peer's; then loopback (127.0.0.0/8).
    code.push((BPF_LD_W, Jump::Fall, Jump::Fall, SKF_NET_OFF + 12));
    code.extend(v4.iter().map(|a| (BPF_JEQ, Jump::Accept, Jump::Fall, *a)));
    code.push((BPF_AND, Jump::Fall, Jump::Fall, 0xff00_0000));
    code.push((BPF_JEQ, Jump::Accept, Jump::Fall, 0x7f00_0000));
    code.push((BPF_RET, Jump::Fall, Jump::Fall, 0));
    code[version_test].2 = Jump::To(code.len());
    // IPv6: each address in four words (the source at bytes 8..24).
    for words in &v6 {
        let test_end = code.len() + 8;
        for (i, w) in words.iter().enumerate() {
            code.push((
                BPF_LD_W,
                Jump::Fall,
                Jump::Fall,
                SKF_NET_OFF + 8 + 4 * i as u32,
            ));
            let matched = if i == 3 { Jump::Accept } else { Jump::Fall };
            code.push((BPF_JEQ, matched, Jump::To(test_end), *w));
        }
    }
    code.push((BPF_RET, Jump::Fall, Jump::Fall, 0));
    let accept = code.len();
    code.push((BPF_RET, Jump::Fall, Jump::Fall, 0xffff_ffff));
    // A jump is an offset past the next instruction.
    let offset = |from: usize, j: Jump| match j {
        Jump::Accept => u8::try_from(accept - from - 1).unwrap_or(u8::MAX),
        Jump::To(to) => u8::try_from(to - from - 1).unwrap_or(u8::MAX),
        Jump::Fall => 0,
    };
    code.iter()
        .enumerate()
        .map(|(i, &(op, t, f, k))| socket2::SockFilter::new(op, offset(i, t), offset(i, f), k))
        .collect()
}

/// Classic BPF: `SKF_NET_OFF` (-0x100000), the offset of the network header.
const SKF_NET_OFF: u32 = 0xfff0_0000;
/// Classic BPF opcodes: `BPF_LD | BPF_W | BPF_ABS`, `BPF_LD | BPF_B | BPF_ABS`,
/// `BPF_ALU | BPF_AND | BPF_K`, `BPF_JMP | BPF_JEQ | BPF_K`, `BPF_RET | BPF_K`.
const BPF_LD_W: u16 = 0x20;
const BPF_LD_B: u16 = 0x30;
const BPF_AND: u16 = 0x54;
const BPF_JEQ: u16 = 0x15;
const BPF_RET: u16 = 0x06;

/// A host's Zenoh session.
#[derive(Debug, Clone)]
pub struct Net {
    session: zenoh::Session,
}

/// A liveliness token: while it is held (and the network is up), the key is alive.
#[derive(Debug)]
pub struct Token(#[allow(dead_code)] zenoh::liveliness::LivelinessToken);

/// A subscription (payloads handed to a callback), held for as long as it is wanted.
#[derive(Debug)]
pub struct Subscription(#[allow(dead_code)] zenoh::pubsub::Subscriber<()>);

/// A queryable answered by a function on a thread of its own, held for as long as it answers
/// (the thread ends once the queryable is gone and the queries taken are answered).
#[derive(Debug)]
pub struct Answering(#[allow(dead_code)] zenoh::query::Queryable<()>);

/// Sends payloads on one key (reliable, in order, blocking rather than dropping).
#[derive(Debug)]
pub struct NetOutbox {
    key: String,
    publisher: zenoh::pubsub::Publisher<'static>,
}

impl NetOutbox {
    /// Whether some subscriber of another session matches the key (Zenoh knows a route).
    pub fn matched(&self) -> bool {
        self.publisher
            .matching_status()
            .wait()
            .is_ok_and(|m| m.matching())
    }

    pub fn put(&self, bytes: &[u8]) -> Result<(), NetError> {
        self.publisher
            .put(bytes.to_vec())
            .wait()
            .map_err(|source| NetError::Key {
                key: self.key.clone(),
                source,
            })
    }
}

/// Requests taken one at a time by the caller (`fdi-launch serve`'s run requests).
#[derive(Debug)]
pub struct Requests {
    key: String,
    queryable: zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<zenoh::query::Query>>,
}

/// One request: its body, answered once.
#[derive(Debug)]
pub struct Request(zenoh::query::Query);

impl Requests {
    /// The next request, or None after `timeout`.
    pub fn next(&self, timeout: Duration) -> Result<Option<Request>, NetError> {
        self.queryable
            .recv_timeout(timeout)
            .map(|q| q.map(Request))
            .map_err(|source| NetError::Key {
                key: self.key.clone(),
                source,
            })
    }
}

impl Request {
    pub fn body(&self) -> Vec<u8> {
        query_body(&self.0)
    }

    /// The host that asks: the sender named in the request's key (with TLS, its certificate's).
    pub fn asker(&self) -> Option<String> {
        keys::sender(self.0.key_expr().as_str()).map(str::to_string)
    }

    /// Answers with `Ok(body)` or refuses with a message.
    pub fn answer(self, answer: Result<Vec<u8>, String>) -> Result<(), NetError> {
        reply(&self.0, answer).map_err(|source| NetError::Key {
            key: self.0.key_expr().to_string(),
            source,
        })
    }
}

/// The body of a query (empty when it has none).
fn query_body(query: &zenoh::query::Query) -> Vec<u8> {
    query
        .payload()
        .map(|p| p.to_bytes().into_owned())
        .unwrap_or_default()
}

/// Answers `query` with `Ok(body)`, or refuses it with a message.
fn reply(query: &zenoh::query::Query, answer: Result<Vec<u8>, String>) -> Result<(), Source> {
    match answer {
        Ok(body) => query.reply(query.key_expr().clone(), body).wait(),
        Err(message) => query.reply_err(message).wait(),
    }
}

/// The variable Zenoh reads its runtimes' threads from, once, at its first use.
pub const ZENOH_RUNTIME_VAR: &str = "ZENOH_RUNTIME";

/// Zenoh's five runtimes (its receiving, sending, accepting, network and application tasks,
/// QUIC's drivers among them) handed over to one runtime with one worker thread. A frame's
/// way through the session is a chain of tasks: on separate threads each link of the chain is
/// a wake-up of another thread, which on the 2-core lab machines costs more than the work
/// (a split run's profile: the machine 93 % busy, its largest items the kernel's task
/// switches). On one thread the tasks run one after the other. Measured on two namespaces
/// (docs/multi-host.md): the paper's 40 s in lockstep split over QUIC 9.8 s → 7.5 s, realtime
/// end-to-end p50 431 µs → 323 µs. A program of its own that runs across hosts through the
/// library calls [`choose_zenoh_threads`] first thing in its `main`, as `fdi-launch` does.
pub const ONE_RUNTIME_THREAD: &str = "(rx: (handover: app), tx: (handover: app), \
     acc: (handover: app), net: (handover: app), app: (worker_threads: 1))";

/// Gives Zenoh [`ONE_RUNTIME_THREAD`] unless the user's environment sets
/// [`ZENOH_RUNTIME_VAR`] (then theirs is kept). Call it first thing in `main`, before any
/// thread exists (the environment is the process's) and before any session is opened (Zenoh
/// reads it once). Returns the value in force.
pub fn choose_zenoh_threads() -> String {
    match std::env::var(ZENOH_RUNTIME_VAR) {
        Ok(theirs) => theirs,
        Err(_) => {
            std::env::set_var(ZENOH_RUNTIME_VAR, ONE_RUNTIME_THREAD);
            ONE_RUNTIME_THREAD.to_string()
        }
    }
}

impl Net {
    /// Opens the session; fails naming the endpoint that cannot be listened on.
    pub fn open(config: &NetConfig) -> Result<Self, NetError> {
        // Zenoh's own log, when asked for with RUST_LOG (docs/multi-host.md, Troubleshooting).
        zenoh::try_init_log_from_env();
        let session = zenoh::open(config.zenoh()?)
            .wait()
            .map_err(|source| NetError::Session {
                what: format!(
                    "listening on [{}], connecting to [{}]",
                    config.listen.join(", "),
                    config.connect.join(", ")
                ),
                source,
            })?;
        if let Security::Tls { peers, .. } = &config.security {
            if !peers.is_empty() && !config.listen.is_empty() {
                if let Err(e) = admit_only(&config.listen, peers) {
                    eprintln!(
                        "fdi-launch: warning: the QUIC listener takes packets from any address \
                         ({e}): a flood of connection openers from outside the lab can keep \
                         runs out (docs/security.md)"
                    );
                }
            }
        }
        Ok(Self { session })
    }

    fn key_error(key: &str) -> impl FnOnce(Source) -> NetError + '_ {
        move |source| NetError::Key {
            key: key.to_string(),
            source,
        }
    }

    /// Declares `key` alive for as long as the token is held.
    pub fn token(&self, key: &str) -> Result<Token, NetError> {
        self.session
            .liveliness()
            .declare_token(key.to_string())
            .wait()
            .map(Token)
            .map_err(Self::key_error(key))
    }

    /// Whether some host declares `key` alive, asked with a bounded wait.
    pub fn alive(&self, key: &str, timeout: Duration) -> Result<bool, NetError> {
        let replies = self
            .session
            .liveliness()
            .get(key.to_string())
            .timeout(timeout)
            .wait()
            .map_err(Self::key_error(key))?;
        while let Ok(reply) = replies.recv() {
            if reply.result().is_ok() {
                return Ok(true);
            }
        }
        Ok(false)
    }

    /// Calls `on_change(true)` when `key` becomes alive (at once if it is) and
    /// `on_change(false)` when it is gone (its host closed it, died, or its network was cut
    /// for longer than the lease).
    pub fn watch(
        &self,
        key: &str,
        on_change: impl Fn(bool) + Send + Sync + 'static,
    ) -> Result<Subscription, NetError> {
        self.session
            .liveliness()
            .declare_subscriber(key.to_string())
            .history(true)
            .callback(move |sample| on_change(sample.kind() == zenoh::sample::SampleKind::Put))
            .wait()
            .map(Subscription)
            .map_err(Self::key_error(key))
    }

    /// A publisher on `key`.
    pub fn outbox(&self, key: &str) -> Result<NetOutbox, NetError> {
        self.outbox_at(key, zenoh::qos::Priority::default())
    }

    /// A publisher on `key` whose payloads go after every other payload of the session (Zenoh's
    /// lowest priority, a queue of its own): bulk data beside a run's frames, which it must not
    /// hold back (the live view's streams of the traces).
    pub fn outbox_background(&self, key: &str) -> Result<NetOutbox, NetError> {
        self.outbox_at(key, zenoh::qos::Priority::Background)
    }

    fn outbox_at(&self, key: &str, priority: zenoh::qos::Priority) -> Result<NetOutbox, NetError> {
        let publisher = self
            .session
            .declare_publisher(key.to_string())
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .priority(priority)
            .wait()
            .map_err(Self::key_error(key))?;
        Ok(NetOutbox {
            key: key.into(),
            publisher,
        })
    }

    /// Hands every payload put on `key` (a key expression) to `f` with the key it came on (on a
    /// Zenoh thread: keep it short).
    pub fn subscribe(
        &self,
        key: &str,
        f: impl Fn(&str, Vec<u8>) + Send + Sync + 'static,
    ) -> Result<Subscription, NetError> {
        self.session
            .declare_subscriber(key.to_string())
            .callback(move |sample| {
                f(
                    sample.key_expr().as_str(),
                    sample.payload().to_bytes().into_owned(),
                )
            })
            .wait()
            .map(Subscription)
            .map_err(Self::key_error(key))
    }

    /// Answers every request on `key` with `f`.
    ///
    /// The answers are made and sent on a thread of the caller's, never in Zenoh's callback:
    /// an answer (a piece of a trace: megabytes) waits for room in the session's queue, which
    /// Zenoh's own tasks free, and those may share the callback's thread
    /// ([`ONE_RUNTIME_THREAD`]).
    pub fn answer(
        &self,
        key: &str,
        f: impl Fn(&[u8]) -> Result<Vec<u8>, String> + Send + 'static,
    ) -> Result<Answering, NetError> {
        let (tx, rx) = mpsc::channel::<zenoh::query::Query>();
        std::thread::Builder::new()
            .name("net answers".into())
            .spawn(move || {
                for query in rx {
                    // A requester gone before the answer: nobody to tell.
                    let _ = reply(&query, f(&query_body(&query)));
                }
            })
            .map_err(|e| NetError::Ipc(thread_error(e)))?;
        self.session
            .declare_queryable(key.to_string())
            .callback(move |query| {
                // The thread ends only when this callback is gone.
                let _ = tx.send(query);
            })
            .wait()
            .map(Answering)
            .map_err(Self::key_error(key))
    }

    /// Requests on `key`, taken by the caller one at a time ([`Requests::next`]).
    pub fn requests(&self, key: &str) -> Result<Requests, NetError> {
        let queryable = self
            .session
            .declare_queryable(key.to_string())
            .wait()
            .map_err(Self::key_error(key))?;
        Ok(Requests {
            key: key.into(),
            queryable,
        })
    }

    /// Sends `body` to whoever answers `key` and returns its answer; a refusal is
    /// [`NetError::Refused`] with the answerer's message. A query that ends at once with no
    /// answer (this session does not know the answerer yet: a session learns the others'
    /// queryables a moment after it connects, longer when their host is busy) is sent again
    /// until `timeout`: a request is answered once, so only one that got no answer is repeated.
    pub fn request(&self, key: &str, body: &[u8], timeout: Duration) -> Result<Vec<u8>, NetError> {
        let began = std::time::Instant::now();
        loop {
            let left = timeout.saturating_sub(began.elapsed());
            let replies = self
                .session
                .get(key.to_string())
                .payload(body.to_vec())
                .timeout(left)
                .wait()
                .map_err(Self::key_error(key))?;
            match replies.recv() {
                Ok(reply) => {
                    return match reply.into_result() {
                        Ok(sample) => Ok(sample.payload().to_bytes().into_owned()),
                        Err(e) => Err(NetError::Refused {
                            key: key.into(),
                            message: String::from_utf8_lossy(&e.payload().to_bytes()).into_owned(),
                        }),
                    }
                }
                Err(_) if began.elapsed() + ASK_AGAIN < timeout => {
                    std::thread::sleep(ASK_AGAIN);
                }
                Err(_) => {
                    return Err(NetError::NoAnswer {
                        key: key.into(),
                        timeout: began.elapsed(),
                    })
                }
            }
        }
    }

    /// Answers clock requests on `key` with this host's CLOCK_MONOTONIC (ns, little endian).
    pub fn answer_clock(&self, key: &str) -> Result<Answering, NetError> {
        self.answer(key, |_| {
            Ok(crate::ipc::monotonic_ns().to_le_bytes().to_vec())
        })
    }

    /// Estimates the offset of the clock answering on `key` from this host's CLOCK_MONOTONIC
    /// by `rounds` round trips, keeping the fastest (its midpoint is the least uncertain).
    pub fn clock_offset(&self, key: &str, rounds: usize) -> Result<ClockOffset, NetError> {
        let mut best: Option<ClockOffset> = None;
        for _ in 0..rounds.max(1) {
            let t0 = crate::ipc::monotonic_ns();
            let answer = self.request(key, &[], Duration::from_secs(5))?;
            let t1 = crate::ipc::monotonic_ns();
            let Ok(bytes) = <[u8; 8]>::try_from(answer.as_slice()) else {
                return Err(NetError::Frame {
                    key: key.into(),
                    what: format!("a clock answer of {} bytes, not 8", answer.len()),
                });
            };
            let theirs = u64::from_le_bytes(bytes);
            let rtt_ns = t1.saturating_sub(t0);
            let mid = t0 / 2 + t1 / 2;
            let Ok(offset_ns) = i64::try_from(i128::from(theirs) - i128::from(mid)) else {
                return Err(NetError::Frame {
                    key: key.into(),
                    what: format!("a clock of {theirs} ns, out of range against ours ({mid} ns)"),
                });
            };
            if best.is_none_or(|b| rtt_ns < b.rtt_ns) {
                best = Some(ClockOffset { offset_ns, rtt_ns });
            }
        }
        best.ok_or_else(|| NetError::NoAnswer {
            key: key.into(),
            timeout: Duration::from_secs(5),
        })
    }
}

/// A remote clock against this host's: theirs = ours + `offset_ns`, known to within half of
/// `rtt_ns`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClockOffset {
    pub offset_ns: i64,
    pub rtt_ns: u64,
}

/// Where the processes of a split run are: which host each process's wake-up event (its
/// identity in the run) belongs to. [`Wake::Launcher`] is on the coordinating host.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Layout {
    pub host_of: BTreeMap<Wake, String>,
    /// The agents whose torques the run attacks: the attacker publishes theirs on
    /// `fdi/torque/<id>`, the control center everyone else's.
    pub attacked_torques: BTreeSet<u32>,
}

impl Layout {
    /// The layout `host_of` of the run `resolved`.
    pub fn new(host_of: BTreeMap<Wake, String>, resolved: &fdi_common::scenario::Resolved) -> Self {
        let attacked_torques = resolved
            .scenario
            .agents
            .iter()
            .map(|a| a.id)
            .filter(|&id| resolved.attack.attacks_torque_of(id))
            .collect();
        Self {
            host_of,
            attacked_torques,
        }
    }
}

/// What the bridge of one host carries.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct HostPlan {
    /// Streams published on this host for processes elsewhere.
    pub outbound: Vec<Stream>,
    /// The wake-up events of those processes: the bridge listens on them in their place.
    pub remote_wakes: Vec<Wake>,
    /// Streams published elsewhere for processes here.
    pub inbound: Vec<Inbound>,
}

/// A stream that comes into a host.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Inbound {
    pub stream: Stream,
    /// The local wake-up events rung after each arrival.
    pub ring: Vec<Wake>,
    /// The hosts that send it: a frame on its key from any other is refused.
    pub from: Vec<String>,
}

impl HostPlan {
    pub fn is_empty(&self) -> bool {
        self.outbound.is_empty() && self.inbound.is_empty()
    }
}

/// The streams of a run whose processes are `procs` and whose attacker forges the torques of
/// `attacked_torques`: (stream, publishers, consumers).
pub fn streams(
    procs: &[Wake],
    attacked_torques: &BTreeSet<u32>,
) -> Vec<(Stream, Vec<Wake>, Vec<Wake>)> {
    let has = |w: Wake| procs.contains(&w);
    let only = |ws: &[Wake]| ws.iter().copied().filter(|w| has(*w)).collect::<Vec<_>>();
    let agents: Vec<u32> = procs
        .iter()
        .filter_map(|w| match w {
            Wake::Agent(id) => Some(*id),
            _ => None,
        })
        .collect();
    let agent_wakes: Vec<Wake> = agents.iter().map(|&id| Wake::Agent(id)).collect();
    let processes: Vec<Wake> = procs
        .iter()
        .copied()
        .filter(|w| *w != Wake::Launcher)
        .collect();
    let mut out = vec![
        (
            Stream::Measurement,
            agent_wakes.clone(),
            only(&[Wake::Attacker]),
        ),
        (
            Stream::Tampered,
            only(&[Wake::Attacker]),
            only(&[Wake::Center, Wake::Monitor]),
        ),
        (
            Stream::Actuation,
            only(&[Wake::Center]),
            only(&[Wake::Attacker]),
        ),
        (Stream::Control, only(&[Wake::Launcher]), processes.clone()),
        (Stream::Status, processes, only(&[Wake::Launcher])),
        (
            Stream::ExternalIn,
            only(&[Wake::Attacker]),
            only(&[Wake::ExternalAttacker]),
        ),
        (
            Stream::ExternalOut,
            only(&[Wake::ExternalAttacker]),
            only(&[Wake::Attacker]),
        ),
        (Stream::Alarm, only(&[Wake::Monitor]), only(&[Wake::Center])),
    ];
    for &id in &agents {
        // The control center publishes an agent's torques, or, when the run attacks them, the
        // attacker does (the center then sends them on `fdi/actuation`).
        let publisher = if attacked_torques.contains(&id) {
            Wake::Attacker
        } else {
            Wake::Center
        };
        out.push((
            Stream::Torque(id),
            only(&[publisher]),
            only(&[Wake::Agent(id), Wake::Monitor]),
        ));
    }
    out.retain(|(_, p, c)| !p.is_empty() && !c.is_empty());
    out
}

/// What the bridge of host `here` carries in the run laid out as `layout`. Errors when a
/// stream would have to go both out of and into one host (a loop the bridges could not break).
pub fn plan(layout: &Layout, here: &str) -> Result<HostPlan, String> {
    let procs: Vec<Wake> = layout.host_of.keys().copied().collect();
    let on = |w: &Wake, host: &str| layout.host_of.get(w).is_some_and(|h| h == host);
    let mut plan = HostPlan::default();
    let mut remote: BTreeSet<Wake> = BTreeSet::new();
    for (stream, pubs, cons) in streams(&procs, &layout.attacked_torques) {
        let out = pubs.iter().any(|p| on(p, here)) && cons.iter().any(|c| !on(c, here));
        let inb = cons.iter().any(|c| on(c, here)) && pubs.iter().any(|p| !on(p, here));
        if out && inb {
            return Err(format!(
                "`{}` would go both out of and into host `{here}`: its publishers and its \
                 receivers are each split over hosts",
                stream.service_name()
            ));
        }
        if out {
            plan.outbound.push(stream);
            remote.extend(cons.iter().copied().filter(|c| !on(c, here)));
        }
        if inb {
            let ring: Vec<Wake> = cons.iter().copied().filter(|c| on(c, here)).collect();
            let from: BTreeSet<String> = pubs
                .iter()
                .filter_map(|p| layout.host_of.get(p))
                .filter(|h| *h != here)
                .cloned()
                .collect();
            plan.inbound.push(Inbound {
                stream,
                ring,
                from: from.into_iter().collect(),
            });
        }
    }
    plan.remote_wakes = remote.into_iter().collect();
    Ok(plan)
}

/// A payload the bridge carries: its bytes are its layout (no padding: checked by zerocopy),
/// and its CLOCK_MONOTONIC stamps are moved to the receiving host's clock.
trait Carried: Payload + IntoBytes + FromBytes + Immutable + KnownLayout {
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

/// Decodes a frame of `T` (exactly its size) and moves its stamps by `by` ns.
fn decode<T: Carried>(key: &str, bytes: &[u8], by: i64) -> Result<T, NetError> {
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
fn encode<T: Carried>(mut value: T, by: i64, batch: &mut Vec<u8>) {
    value.shift_clock(by);
    batch.extend_from_slice(value.as_bytes());
}

/// Splits a batch of frames of `T` (one or more, one after the other: what one put carries)
/// into its frames; a batch that is not a whole number of them is an error naming the key.
fn frames<'b, T: Carried>(
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

/// What a bridge carried.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BridgeCounts {
    /// Payloads put on the network.
    pub sent: u64,
    /// Payloads received and published locally.
    pub received: u64,
    /// Frames refused: sent on a run's key by a host that does not send that stream in the
    /// run, or out of order (a sequence number not after the last let in for its agent: a
    /// forged, duplicated or replayed frame, or the honest frame a forged one overtook).
    pub refused: u64,
}

/// The last sequence number let in per (port, agent), for [`Carried::order`].
type Admitted = BTreeMap<(usize, u32), u64>;

/// Frames refused by a bridge: how many, and the first, described.
#[derive(Debug, Default)]
struct Refusals {
    count: AtomicU64,
    first: std::sync::Mutex<Option<String>>,
}

impl Refusals {
    fn note(&self, what: impl FnOnce() -> String) {
        self.note_many(1, what);
    }

    /// `n` frames refused for one reason (a batch).
    fn note_many(&self, n: u64, what: impl FnOnce() -> String) {
        if self.count.fetch_add(n, Ordering::Relaxed) == 0 {
            *self
                .first
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(what());
        }
    }
}

/// The network publishers of a bridge.
#[derive(Debug, Clone)]
pub struct Routes(Vec<Arc<NetOutbox>>);

impl Routes {
    /// The keys no other host subscribes to yet.
    pub fn unmatched(&self) -> Vec<String> {
        self.0
            .iter()
            .filter(|o| !o.matched())
            .map(|o| o.key.clone())
            .collect()
    }
}

/// The local receiving side of an outbound stream, by payload type.
enum OutPort<X: Transport> {
    Measurement(X::Inbox<MeasurementMsg>),
    Torque(X::Inbox<TorqueMsg>),
    Control(X::Inbox<ControlMsg>),
    Status(X::Inbox<StatusMsg>),
    Alarm(X::Inbox<AlarmMsg>),
}

/// The local publishing side of an inbound stream, by payload type.
enum InPort<X: Transport> {
    Measurement(X::Outbox<MeasurementMsg>),
    Torque(X::Outbox<TorqueMsg>),
    Control(X::Outbox<ControlMsg>),
    Status(X::Outbox<StatusMsg>),
    Alarm(X::Outbox<AlarmMsg>),
}

#[derive(Clone, Copy)]
enum Kind {
    Measurement,
    Torque,
    Control,
    Status,
    Alarm,
}

impl Kind {
    /// The size of one frame of it on the network.
    fn frame_bytes(self) -> usize {
        match self {
            Self::Measurement => std::mem::size_of::<MeasurementMsg>(),
            Self::Torque => std::mem::size_of::<TorqueMsg>(),
            Self::Control => std::mem::size_of::<ControlMsg>(),
            Self::Status => std::mem::size_of::<StatusMsg>(),
            Self::Alarm => std::mem::size_of::<AlarmMsg>(),
        }
    }
}

fn kind(stream: Stream) -> Kind {
    match stream {
        Stream::Measurement | Stream::Tampered | Stream::ExternalIn | Stream::ExternalOut => {
            Kind::Measurement
        }
        Stream::Torque(_) | Stream::Actuation => Kind::Torque,
        Stream::Control => Kind::Control,
        Stream::Status => Kind::Status,
        Stream::Alarm => Kind::Alarm,
    }
}

impl<X: Transport> OutPort<X> {
    fn open(t: &X, stream: Stream) -> Result<Self, IpcError> {
        Ok(match kind(stream) {
            Kind::Measurement => Self::Measurement(t.subscriber(stream)?),
            Kind::Torque => Self::Torque(t.subscriber(stream)?),
            Kind::Control => Self::Control(t.subscriber(stream)?),
            Kind::Status => Self::Status(t.subscriber(stream)?),
            Kind::Alarm => Self::Alarm(t.subscriber(stream)?),
        })
    }

    /// Takes every frame waiting, encoded one after the other into `batch`; how many.
    fn drain(&self, by: i64, batch: &mut Vec<u8>) -> Result<usize, IpcError> {
        match self {
            Self::Measurement(p) => p.drain(|m| encode(m, by, batch)),
            Self::Torque(p) => p.drain(|m| encode(m, by, batch)),
            Self::Control(p) => p.drain(|m| encode(m, by, batch)),
            Self::Status(p) => p.drain(|m| encode(m, by, batch)),
            Self::Alarm(p) => p.drain(|m| encode(m, by, batch)),
        }
    }
}

impl<X: Transport> InPort<X> {
    fn open(t: &X, stream: Stream) -> Result<Self, IpcError> {
        Ok(match kind(stream) {
            Kind::Measurement => Self::Measurement(t.publisher(stream)?),
            Kind::Torque => Self::Torque(t.publisher(stream)?),
            Kind::Control => Self::Control(t.publisher(stream)?),
            Kind::Status => Self::Status(t.publisher(stream)?),
            Kind::Alarm => Self::Alarm(t.publisher(stream)?),
        })
    }

    /// Publishes the frames of the batch `bytes` of port `i` locally, in order, each unless it
    /// is out of order (then `refused` is told why, and that frame is not published); how many
    /// were published. A batch that is not a whole number of frames is an error.
    fn publish(
        &self,
        (i, key): (usize, &str),
        bytes: &[u8],
        by: i64,
        admitted: &mut Admitted,
        refused: &mut impl FnMut(String),
    ) -> Result<usize, NetError> {
        fn admit<T: Carried>(
            (i, key): (usize, &str),
            bytes: &[u8],
            by: i64,
            admitted: &mut Admitted,
            refused: &mut impl FnMut(String),
            mut send: impl FnMut(T) -> Result<(), IpcError>,
        ) -> Result<usize, NetError> {
            let mut published = 0;
            for frame in frames::<T>(key, bytes)? {
                let value: T = decode(key, frame, by)?;
                if let Some((agent, seq)) = value.order() {
                    match admitted.entry((i, agent)) {
                        std::collections::btree_map::Entry::Occupied(mut last) => {
                            if seq <= *last.get() {
                                refused(format!(
                                    "a frame on `{key}` for agent {agent} numbered {seq}, not \
                                     after the last let in ({})",
                                    last.get()
                                ));
                                continue;
                            }
                            last.insert(seq);
                        }
                        std::collections::btree_map::Entry::Vacant(v) => {
                            v.insert(seq);
                        }
                    }
                }
                send(value)?;
                published += 1;
            }
            Ok(published)
        }
        let at = (i, key);
        match self {
            Self::Measurement(p) => {
                admit(at, bytes, by, admitted, refused, |m| p.send(m).map(drop))
            }
            Self::Torque(p) => admit(at, bytes, by, admitted, refused, |m| p.send(m).map(drop)),
            Self::Control(p) => admit(at, bytes, by, admitted, refused, |m| p.send(m).map(drop)),
            Self::Status(p) => admit(at, bytes, by, admitted, refused, |m| p.send(m).map(drop)),
            Self::Alarm(p) => admit(at, bytes, by, admitted, refused, |m| p.send(m).map(drop)),
        }
    }
}

/// How long the outbound thread of a bridge blocks before it looks at its stop flag and drains
/// its streams anyway (a wake-up it missed costs at most this much).
const BRIDGE_POLL: Duration = Duration::from_millis(20);

/// The bridge of one host for one run: a thread carrying the local streams out, and the
/// network's callbacks carrying the other hosts' in (a frame is published locally on the
/// thread that received it, with no hand-over to another thread: one wake-up less per frame).
#[derive(Debug)]
pub struct Bridge {
    shared: Shared,
    /// Its publishers on the network, for [`Bridge::unmatched`].
    routes: Vec<Arc<NetOutbox>>,
    threads: Vec<JoinHandle<Result<(), NetError>>>,
    subscriptions: Vec<Subscription>,
}

/// What a bridge's threads and callbacks share: the stop, the first failure, the counts.
#[derive(Debug, Clone, Default)]
struct Shared {
    stop: Arc<AtomicBool>,
    /// The first error a thread met (it ended there).
    failure: Arc<std::sync::Mutex<Option<String>>>,
    sent: Arc<AtomicU64>,
    received: Arc<AtomicU64>,
    refusals: Arc<Refusals>,
    /// The error that stopped the inbound side: nothing is let in after it.
    inbound_error: Arc<std::sync::Mutex<Option<NetError>>>,
}

impl Shared {
    fn inbound_error(&self) -> std::sync::MutexGuard<'_, Option<NetError>> {
        self.inbound_error
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Stops the inbound side on `e`, kept where [`Bridge::failure`] and [`Bridge::stop`] find
    /// it.
    fn fail_inbound(&self, e: NetError) {
        note_failure(&self.failure, &e);
        self.inbound_error().get_or_insert(e);
    }
}

/// Where a bridge's threads run: the run's prefix on this host's transport, the run on the
/// network, the sizing of its services, and this host's clock against the coordinator's.
#[derive(Debug, Clone, Copy)]
struct Place<'a> {
    prefix: &'a str,
    run: &'a str,
    sizing: Sizing,
    offset_ns: i64,
}

impl Bridge {
    /// Starts the bridge of `plan` for the run `prefix` on this host's transport `X` (the run
    /// is `run` on the network: the same prefix, except in tests that put two "hosts" in one
    /// process, each with a prefix of its own). Stamps travel in the coordinating host's
    /// clock, which is ours + `offset_ns` (0 on that host): ours are moved to it on the way out,
    /// and back to ours on the way in. Returns once its wakers and ports exist: the local
    /// processes may be started then, and none of what they send is lost. `X`'s ports must
    /// work from any thread ([`crate::ipc::ShmShared`]): the inbound side publishes in the
    /// network's callbacks.
    pub fn start<X: Transport + 'static>(
        net: &Net,
        (prefix, run, here): (&str, &str, &str),
        sizing: Sizing,
        plan: &HostPlan,
        offset_ns: i64,
    ) -> Result<Self, NetError>
    where
        OutSide<X>: Send,
        InSide<X>: Send,
    {
        let place = Place {
            prefix,
            run,
            sizing,
            offset_ns,
        };
        let shared = Shared::default();
        let mut bridge = Self {
            shared: shared.clone(),
            routes: Vec::new(),
            threads: Vec::new(),
            subscriptions: Vec::new(),
        };
        if !plan.outbound.is_empty() {
            let outboxes: Vec<(Stream, Arc<NetOutbox>)> = plan
                .outbound
                .iter()
                .map(|&s| Ok((s, Arc::new(net.outbox(&keys::stream(here, run, s))?))))
                .collect::<Result<_, NetError>>()?;
            bridge.routes = outboxes.iter().map(|(_, o)| o.clone()).collect();
            let thread = start_out::<X>(place, &plan.remote_wakes, outboxes, shared.clone())?;
            bridge.threads.push(thread);
        }
        if !plan.inbound.is_empty() {
            let side = Arc::new(std::sync::Mutex::new(InSide::<X>::open(
                place,
                &plan.inbound,
            )?));
            for (i, inbound) in plan.inbound.iter().enumerate() {
                bridge.subscriptions.push(subscribe_in(
                    net,
                    run,
                    (i, inbound),
                    side.clone(),
                    &shared,
                )?);
            }
        }
        Ok(bridge)
    }

    /// The first frame it refused, described ([`BridgeCounts::refused`] counts them all).
    pub fn first_refusal(&self) -> Option<String> {
        self.shared
            .refusals
            .first
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }

    /// Why a thread of the bridge ended early, if one did: the run cannot go on without it.
    pub fn failure(&self) -> Option<String> {
        self.shared
            .failure
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }

    /// The keys it sends on that no other host subscribes to yet: a sample put there now would
    /// be lost. Empty once every route of the run is known.
    pub fn unmatched(&self) -> Vec<String> {
        self.routes().unmatched()
    }

    /// Its publishers on the network, to ask [`Routes::unmatched`] from another thread.
    pub fn routes(&self) -> Routes {
        Routes(self.routes.clone())
    }

    /// What it carried so far.
    pub fn counts(&self) -> BridgeCounts {
        BridgeCounts {
            sent: self.shared.sent.load(Ordering::Relaxed),
            received: self.shared.received.load(Ordering::Relaxed),
            refused: self.shared.refusals.count.load(Ordering::Relaxed),
        }
    }

    /// Stops the bridge (what was published locally before is still sent); the first error a
    /// thread met, if any.
    pub fn stop(mut self) -> Result<BridgeCounts, NetError> {
        self.shared.stop.store(true, Ordering::SeqCst);
        // Nothing more comes in.
        self.subscriptions.clear();
        let mut first = Ok(());
        for t in self.threads.drain(..) {
            let r = t
                .join()
                .unwrap_or_else(|_| Err(NetError::Ipc(thread_error("a bridge thread panicked"))));
            if first.is_ok() {
                first = r;
            }
        }
        if let (Ok(()), Some(e)) = (&first, self.shared.inbound_error().take()) {
            first = Err(e);
        }
        first.map(|()| self.counts())
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// The outbound side of a bridge: its node, the wake-ups of the remote processes it listens
/// on, and the local ports of the streams it carries out.
pub struct OutSide<X: Transport> {
    _t: X,
    waker: X::Waker,
    ports: Vec<OutPort<X>>,
}

/// Starts the thread that carries the local streams out: woken by the local processes'
/// wake-ups of the remote ones (`wakes`), it drains each stream and puts its payloads on the
/// network. Its ports are opened here, so a failure to open them is this call's error; the
/// thread's is kept where [`Bridge::failure`] finds it.
fn start_out<X: Transport + 'static>(
    place: Place,
    wakes: &[Wake],
    outboxes: Vec<(Stream, Arc<NetOutbox>)>,
    shared: Shared,
) -> Result<JoinHandle<Result<(), NetError>>, NetError>
where
    OutSide<X>: Send,
{
    let t = X::open(place.prefix, "bridge-out", place.sizing)?;
    let side = OutSide {
        waker: t.waker_any(wakes)?,
        ports: outboxes
            .iter()
            .map(|(s, _)| OutPort::<X>::open(&t, *s))
            .collect::<Result<Vec<_>, IpcError>>()?,
        _t: t,
    };
    let offset_ns = place.offset_ns;
    let carry = move || {
        // The whole side moves to the thread (a closure would take only its fields).
        let side = side;
        let mut batch = Vec::new();
        loop {
            let stopping = shared.stop.load(Ordering::SeqCst);
            side.waker.wait(BRIDGE_POLL)?;
            // What a port holds goes in one put: one message for the frames of a wake-up.
            for (port, (_, outbox)) in side.ports.iter().zip(&outboxes) {
                batch.clear();
                let n = port.drain(offset_ns, &mut batch)?;
                if n > 0 {
                    outbox.put(&batch)?;
                    shared.sent.fetch_add(n as u64, Ordering::Relaxed);
                }
            }
            // One more drain after the stop was asked: what was sent before it leaves.
            if stopping {
                return Ok(());
            }
        }
    };
    let failure = shared.failure.clone();
    std::thread::Builder::new()
        .name("bridge out".into())
        .spawn(move || noted(&failure, carry))
        .map_err(|e| NetError::Ipc(thread_error(e)))
}

/// The inbound side of a bridge: the local ports of the streams it lets in, and what it let
/// in. Used in the network's callbacks, one at a time.
pub struct InSide<X: Transport> {
    ports: Vec<InPort<X>>,
    /// Per port, the key of each of its sending hosts, for what is said of a frame.
    sent_on: Vec<Vec<String>>,
    /// Per port, the local wake-up events rung after its frames.
    ring: Vec<Vec<Wake>>,
    ringer: Ringer<X>,
    admitted: Admitted,
    /// Moves the stamps from the coordinator's clock to this host's.
    back: i64,
}

impl<X: Transport> InSide<X> {
    fn open(place: Place, inbound: &[Inbound]) -> Result<Self, NetError> {
        let t = X::open(place.prefix, "bridge-in", place.sizing)?;
        let ports = inbound
            .iter()
            .map(|i| InPort::<X>::open(&t, i.stream))
            .collect::<Result<Vec<_>, IpcError>>()?;
        Ok(Self {
            ports,
            sent_on: inbound
                .iter()
                .map(|i| {
                    i.from
                        .iter()
                        .map(|h| keys::stream(h, place.run, i.stream))
                        .collect()
                })
                .collect(),
            ring: inbound.iter().map(|i| i.ring.clone()).collect(),
            ringer: Ringer::new(t),
            admitted: Admitted::new(),
            back: place.offset_ns.wrapping_neg(),
        })
    }

    /// Lets in the batch `bytes` of port `i` sent by its host `from` ([`InPort::publish`]),
    /// and only then rings the local receivers.
    fn carry(
        &mut self,
        (i, from): (usize, usize),
        bytes: &[u8],
        shared: &Shared,
    ) -> Result<(), NetError> {
        let key = &self.sent_on[i][from];
        let mut refused = |why: String| shared.refusals.note(|| why);
        let n =
            self.ports[i].publish((i, key), bytes, self.back, &mut self.admitted, &mut refused)?;
        if n > 0 {
            shared.received.fetch_add(n as u64, Ordering::Relaxed);
            self.ringer.due(&self.ring[i]);
        }
        Ok(self.ringer.ring()?)
    }
}

/// The local wake-up events an inbound bridge rings once a batch of frames is published.
struct Ringer<X: Transport> {
    t: X,
    /// Made at the first ring: the local processes' wakers exist by then (nothing arrives for a
    /// process before the start, which follows its ready).
    bells: BTreeMap<Wake, X::Bell>,
    due: BTreeSet<Wake>,
}

impl<X: Transport> Ringer<X> {
    fn new(t: X) -> Self {
        Self {
            t,
            bells: BTreeMap::new(),
            due: BTreeSet::new(),
        }
    }

    fn due(&mut self, wakes: &[Wake]) {
        self.due.extend(wakes.iter().copied());
    }

    fn ring(&mut self) -> Result<(), IpcError> {
        for wake in std::mem::take(&mut self.due) {
            if let std::collections::btree_map::Entry::Vacant(e) = self.bells.entry(wake) {
                e.insert(self.t.notifier(wake)?);
            }
            if let Some(bell) = self.bells.get(&wake) {
                bell.ring()?;
            }
        }
        Ok(())
    }
}

/// Subscribes to the inbound stream `i` of the run `run` from any host: a batch from a host
/// the plan says sends it is let in by `side` on the network's thread; any other is refused
/// and counted. After an error of the inbound side nothing more is let in.
fn subscribe_in<X: Transport + 'static>(
    net: &Net,
    run: &str,
    (i, inbound): (usize, &Inbound),
    side: Arc<std::sync::Mutex<InSide<X>>>,
    shared: &Shared,
) -> Result<Subscription, NetError>
where
    InSide<X>: Send,
{
    let (from, service) = (inbound.from.clone(), inbound.stream.service_name());
    let frame = kind(inbound.stream).frame_bytes();
    let shared = shared.clone();
    net.subscribe(&keys::stream_any(run, inbound.stream), move |on, bytes| {
        let sender = keys::sender(on);
        match sender.and_then(|h| from.iter().position(|f| f == h)) {
            Some(k) => {
                let mut side = side
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
                if shared.inbound_error().is_some() {
                    return;
                }
                if let Err(e) = side.carry((i, k), &bytes, &shared) {
                    shared.fail_inbound(e);
                }
            }
            // Counted in frames (a batch that is not whole frames counts what it would hold).
            None => shared
                .refusals
                .note_many(bytes.len().div_ceil(frame).max(1) as u64, || {
                    format!(
                    "a frame on `{on}` from host `{}`, which does not send `{service}` in this \
                     run",
                    sender.unwrap_or("?")
                )
                }),
        }
    })
}

/// Runs a bridge thread's body, keeping its error where [`Bridge::failure`] finds it.
fn noted(
    failure: &std::sync::Mutex<Option<String>>,
    body: impl FnOnce() -> Result<(), NetError>,
) -> Result<(), NetError> {
    let r = body();
    if let Err(e) = &r {
        note_failure(failure, e);
    }
    r
}

/// Keeps `e` as the bridge's failure, unless one is kept already.
fn note_failure(failure: &std::sync::Mutex<Option<String>>, e: &NetError) {
    failure
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .get_or_insert_with(|| format!("the bridge between hosts stopped: {e}"));
}

fn thread_error(e: impl std::fmt::Display) -> IpcError {
    IpcError::Node {
        name: "bridge".into(),
        source: e.to_string().into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One frame, encoded as the bridge puts it (alone in its batch).
    fn encoded<T: Carried>(value: T, by: i64) -> Vec<u8> {
        let mut batch = Vec::new();
        encode(value, by, &mut batch);
        batch
    }

    fn layout(entries: &[(Wake, &str)]) -> Layout {
        Layout {
            host_of: entries.iter().map(|(w, h)| (*w, h.to_string())).collect(),
            attacked_torques: BTreeSet::new(),
        }
    }

    fn split() -> Layout {
        layout(&[
            (Wake::Launcher, "control"),
            (Wake::Center, "control"),
            (Wake::Attacker, "control"),
            (Wake::Agent(1), "cell-a"),
            (Wake::Agent(2), "cell-a"),
            (Wake::Agent(3), "cell-b"),
            (Wake::Agent(4), "control"),
        ])
    }

    #[test]
    fn every_stream_between_hosts_goes_out_of_its_publishers_host_into_its_receivers() {
        let l = split();
        let hosts = ["control", "cell-a", "cell-b"];
        let plans: BTreeMap<&str, HostPlan> = hosts
            .iter()
            .map(|h| (*h, plan(&l, h).expect("plan")))
            .collect();
        let procs: Vec<Wake> = l.host_of.keys().copied().collect();
        for (stream, pubs, cons) in streams(&procs, &l.attacked_torques) {
            for p in &pubs {
                for c in &cons {
                    let (hp, hc) = (&l.host_of[p], &l.host_of[c]);
                    if hp == hc {
                        continue;
                    }
                    assert!(
                        plans[hp.as_str()].outbound.contains(&stream),
                        "{stream:?} out of {hp}"
                    );
                    assert!(
                        plans[hp.as_str()].remote_wakes.contains(c),
                        "{c:?} listened on {hp}"
                    );
                    let inbound = &plans[hc.as_str()].inbound;
                    assert!(
                        inbound.iter().any(|i| i.stream == stream
                            && i.ring.contains(c)
                            && i.from.contains(hp)),
                        "{stream:?} into {hc} rings {c:?}, from {hp}"
                    );
                }
            }
        }
        // Nothing crosses where nothing needs to.
        let cell_b = &plans["cell-b"];
        assert!(!cell_b.inbound.iter().any(|i| i.stream == Stream::Torque(1)));
        assert!(!plans["control"].outbound.contains(&Stream::Torque(4)));
        assert_eq!(cell_b.remote_wakes, vec![Wake::Attacker, Wake::Launcher]);
    }

    #[test]
    fn a_run_on_one_host_carries_nothing() {
        let l = layout(&[
            (Wake::Launcher, "h"),
            (Wake::Center, "h"),
            (Wake::Attacker, "h"),
            (Wake::Agent(1), "h"),
        ]);
        assert!(plan(&l, "h").expect("plan").is_empty());
    }

    #[test]
    fn an_attacker_on_a_host_of_its_own_gets_the_measurements_and_the_actuation() {
        let mut l = split();
        l.host_of.insert(Wake::Attacker, "adversary".into());
        let p = plan(&l, "adversary").expect("plan");
        let inbound: Vec<Stream> = p.inbound.iter().map(|i| i.stream).collect();
        assert!(inbound.contains(&Stream::Measurement));
        assert!(inbound.contains(&Stream::Actuation));
        assert!(inbound.contains(&Stream::Control));
        assert_eq!(p.outbound, vec![Stream::Tampered, Stream::Status]);
        // When the run attacks agent 3's torques, the attacker forges them and sends them to
        // its host; the center no longer does.
        l.attacked_torques.insert(3);
        let p = plan(&l, "adversary").expect("plan");
        assert_eq!(
            p.outbound,
            vec![Stream::Tampered, Stream::Status, Stream::Torque(3)]
        );
        assert!(!plan(&l, "control")
            .expect("plan")
            .outbound
            .contains(&Stream::Torque(3)));
        let cell_b = plan(&l, "cell-b").expect("plan");
        assert!(cell_b.inbound.iter().any(|i| i.stream == Stream::Torque(3)
            && i.ring == [Wake::Agent(3)]
            && i.from == ["adversary"]));
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

    /// A free TCP port of the loopback interface (bound, read, released).
    fn free_port() -> u16 {
        std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .map(|a| a.port())
            .expect("a free port")
    }

    /// Two "hosts" in this process: each its own prefix on the in-process transport, each its
    /// own Zenoh session on loopback. Agent 1 on `cell` publishes measurements for the attacker
    /// on `control`: they arrive whole, in order, with their stamps moved, and the attacker's
    /// wake-up event is rung after them; a frame of the wrong size stops the bridge, named.
    #[test]
    fn a_bridge_carries_a_stream_in_order_and_refuses_a_frame_of_another_shape() {
        use crate::ipc::{Local, LocalShared};
        let port = free_port();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let control_net = Net::open(&NetConfig {
            listen: vec![endpoint.clone()],
            connect: Vec::new(),
            security: Security::Insecure,
        })
        .expect("control session");
        let cell_net = Net::open(&NetConfig {
            listen: Vec::new(),
            connect: vec![endpoint],
            security: Security::Insecure,
        })
        .expect("cell session");
        let l = layout(&[
            (Wake::Launcher, "control"),
            (Wake::Attacker, "control"),
            (Wake::Center, "control"),
            (Wake::Agent(1), "cell"),
        ]);
        let sizing = Sizing::new(1, 4);
        let run = format!("bridge{}", std::process::id());
        let (pc, pa) = (format!("{run}c"), format!("{run}a"));
        let control = Bridge::start::<LocalShared>(
            &control_net,
            (&pc, &run, "control"),
            sizing,
            &plan(&l, "control").expect("plan"),
            0,
        )
        .expect("control bridge");
        let cell = Bridge::start::<LocalShared>(
            &cell_net,
            (&pa, &run, "cell"),
            sizing,
            &plan(&l, "cell").expect("plan"),
            250,
        )
        .expect("cell bridge");
        // The attacker on `control` and agent 1 on `cell`.
        let attacker = Local::open(&pc, "attacker", sizing).expect("attacker node");
        let inbox = attacker
            .subscriber::<MeasurementMsg>(Stream::Measurement)
            .expect("sub");
        let woken = attacker.waker(Wake::Attacker).expect("waker");
        let agent = Local::open(&pa, "agent", sizing).expect("agent node");
        let outbox = agent
            .publisher::<MeasurementMsg>(Stream::Measurement)
            .expect("pub");
        let bell = agent.notifier(Wake::Attacker).expect("bell");
        // Wait until the sessions see each other (the subscription reaches the publisher).
        let began = std::time::Instant::now();
        let mut got: Vec<MeasurementMsg> = Vec::new();
        let msg = |seq: u64| MeasurementMsg {
            seq,
            agent: 1,
            dof: 2,
            t: seq as f64 * 1e-3,
            y: [seq as f64; fdi_common::scenario::MAX_DOF],
            yd: [0.0; fdi_common::scenario::MAX_DOF],
            agent_sent_ns: 1_000 + seq,
            attacker_received_ns: 0,
            attacker_sent_ns: 0,
            flags: 0,
            reserved: 0,
        };
        // A probe until the path is up (Zenoh connects in the background).
        while got.is_empty() {
            assert!(
                began.elapsed() < Duration::from_secs(10),
                "no path between the sessions"
            );
            outbox.send(msg(0)).expect("send");
            bell.ring().expect("ring");
            woken.wait(Duration::from_millis(50)).expect("wait");
            inbox.drain(|m| got.push(m)).expect("drain");
        }
        got.clear();
        for seq in 1..=200 {
            outbox.send(msg(seq)).expect("send");
            bell.ring().expect("ring");
        }
        let began = std::time::Instant::now();
        while got.iter().filter(|m| m.seq > 0).count() < 200 {
            assert!(
                began.elapsed() < Duration::from_secs(10),
                "only {} arrived",
                got.len()
            );
            // Rung after the data: each wake-up finds what woke it.
            if woken.wait(Duration::from_millis(100)).expect("wait") {
                assert!(inbox.has_messages().expect("has") || !got.is_empty());
            }
            inbox.drain(|m| got.push(m)).expect("drain");
        }
        let seqs: Vec<u64> = got.iter().map(|m| m.seq).filter(|&s| s > 0).collect();
        assert_eq!(seqs, (1..=200).collect::<Vec<_>>(), "whole and in order");
        let last = got.last().expect("some");
        assert_eq!(
            last.agent_sent_ns,
            1_200 + 250,
            "moved to the coordinator's clock"
        );
        assert_eq!(last.attacker_received_ns, 0, "an unset stamp stays unset");
        // The counts follow the publishing of a batch: wait for them too.
        let began = std::time::Instant::now();
        while control.counts().received < 200 || cell.counts().sent < 200 {
            assert!(
                began.elapsed() < Duration::from_secs(10),
                "{:?} {:?}",
                cell.counts(),
                control.counts()
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(control.failure(), None);
        assert_eq!(control.counts().refused, 0);
        // A frame numbered before the last let in (a replay), and one on the key of a host
        // that does not send measurements in this run: refused, counted, nothing published.
        let received = control.counts().received;
        let stale = encoded(msg(150), 0);
        let own = keys::stream("cell", &run, Stream::Measurement);
        cell_net
            .outbox(&own)
            .expect("raw")
            .put(&stale)
            .expect("put");
        let other = keys::stream("elsewhere", &run, Stream::Measurement);
        cell_net
            .outbox(&other)
            .expect("raw")
            .put(&encoded(msg(500), 0))
            .expect("put");
        let began = std::time::Instant::now();
        while control.counts().refused < 2 {
            assert!(
                began.elapsed() < Duration::from_secs(10),
                "refused: {:?}",
                control.counts()
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        assert_eq!(control.counts().received, received, "nothing let in");
        let first = control.first_refusal().expect("described");
        assert!(
            first.contains("numbered 150") || first.contains("host `elsewhere`"),
            "{first}"
        );
        inbox.drain(|m| panic!("let in: {m:?}")).expect("drain");
        // One put with three frames, the second a duplicate of the first: the first and the
        // third are let in, in order, the duplicate is refused and counted.
        let mut batch = Vec::new();
        for seq in [201, 201, 202] {
            encode(msg(seq), 0, &mut batch);
        }
        cell_net
            .outbox(&own)
            .expect("raw")
            .put(&batch)
            .expect("put");
        let mut late = Vec::new();
        let began = std::time::Instant::now();
        while late.len() < 2
            || control.counts().refused < 3
            || control.counts().received < received + 2
        {
            assert!(
                began.elapsed() < Duration::from_secs(10),
                "of the batch: {late:?}, {:?}",
                control.counts()
            );
            woken.wait(Duration::from_millis(50)).expect("wait");
            inbox.drain(|m| late.push(m.seq)).expect("drain");
        }
        assert_eq!(late, [201, 202]);
        assert_eq!(control.counts().received, received + 2);
        // A frame of another shape on the run's key: the receiving bridge stops, naming it.
        let key = own;
        cell_net
            .outbox(&key)
            .expect("raw")
            .put(&[0u8; 7])
            .expect("put");
        let began = std::time::Instant::now();
        while control.failure().is_none() {
            assert!(
                began.elapsed() < Duration::from_secs(10),
                "the frame was not refused"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        let f = control.failure().expect("failure");
        assert!(
            f.contains("7 bytes") && f.contains("fdi/measurement"),
            "{f}"
        );
        drop((outbox, bell, inbox, woken));
        let _ = cell.stop();
        assert!(control.stop().is_err(), "the refusal is the bridge's error");
    }

    /// The socket filter of [`admit_only`] is a program the kernel takes (it checks every
    /// jump), and a datagram from loopback passes it. (That those of other addresses do not is
    /// the flood test's, in network namespaces: `tests/tests/multihost.rs`.)
    #[test]
    fn the_peer_filter_is_taken_by_the_kernel_and_lets_loopback_through() {
        let peers: Vec<std::net::IpAddr> = ["10.0.0.1", "10.0.0.2", "fe80::1", "::ffff:10.0.0.3"]
            .iter()
            .map(|a| a.parse().expect("address"))
            .collect();
        let program = peer_filter(&peers);
        // 3 + 1 + 3 peers of IPv4 + 3, then 8 per IPv6 address (one, and ::1), and 2 returns.
        assert_eq!(program.len(), 3 + 1 + 3 + 3 + 16 + 2);
        let receiver = std::net::UdpSocket::bind("127.0.0.1:0").expect("bind");
        socket2::SockRef::from(&receiver)
            .attach_filter(&program)
            .expect("the kernel takes the program");
        receiver
            .set_read_timeout(Some(Duration::from_secs(10)))
            .expect("timeout");
        let sender = std::net::UdpSocket::bind("127.0.0.1:0").expect("bind");
        sender
            .send_to(b"hello", receiver.local_addr().expect("address"))
            .expect("send");
        let mut buf = [0u8; 8];
        assert_eq!(receiver.recv(&mut buf).expect("received"), 5);
        let too_many = vec![peers[0]; MAX_FILTERED_PEERS + 1];
        let e = admit_only(&["quic/127.0.0.1:1".into()], &too_many).expect_err("refused");
        assert!(e.contains("more than the 48"), "{e}");
    }

    #[test]
    fn host_names_and_endpoints_are_checked() {
        assert!(check_host_name("cell-a").is_ok());
        assert!(check_host_name("cell a").is_err());
        assert!(check_host_name("").is_err());
        assert_eq!(check_endpoint("tcp/10.0.0.2:7447"), Ok(Link::Tcp));
        assert_eq!(check_endpoint("quic/10.0.0.2:7447"), Ok(Link::Quic));
        assert!(check_endpoint("tls/10.0.0.2:7447").is_err());
        assert!(check_endpoint("tcp/[::1]:7447").is_ok());
        assert_eq!(endpoint_address("quic/[::1]:7447"), Some("::1"));
        assert_eq!(endpoint_address("quic/10.0.0.2:7447"), Some("10.0.0.2"));
        assert_eq!(
            keys::sender("fdi-mas/p/cell/run/x/s/fdi/torque/3"),
            Some("cell")
        );
        assert_eq!(
            keys::sender("fdi-mas/q/cell/control/run/x/release"),
            Some("control")
        );
        assert_eq!(keys::sender("other/p/cell"), None);
        assert!(check_endpoint("udp/10.0.0.2:7447").is_err());
        assert!(check_endpoint("tcp/10.0.0.2").is_err());
        assert!(check_endpoint("tcp/10.0.0.2:0").is_err());
    }
}
