//! A host's Zenoh session: how it is configured, and the calls made on it (tokens,
//! publishers, subscriptions, requests and their answers).

use std::sync::mpsc;
use std::time::Duration;

use fdi_runtime::ipc::Source;
use zenoh::Wait as _;

use crate::access::{access_control, admit_only};
use crate::error::{thread_error, NetError};
use crate::keys;

/// How long a host may be silent before Zenoh declares it gone (its liveliness tokens vanish):
/// the session lease. Zenoh's own default is 10 s.
pub const LEASE: Duration = Duration::from_secs(1);

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

/// A host's Zenoh session.
#[derive(Debug, Clone)]
pub struct Net {
    session: zenoh::Session,
    /// Why the QUIC listener takes packets from any address, when the lab's filter could not be
    /// set ([`Net::unfiltered`]).
    unfiltered: Option<String>,
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
    /// The key it sends on.
    pub fn key(&self) -> &str {
        &self.key
    }

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
        let mut unfiltered = None;
        if let Security::Tls { peers, .. } = &config.security {
            if !peers.is_empty() && !config.listen.is_empty() {
                unfiltered = admit_only(&config.listen, peers).err();
            }
        }
        Ok(Self {
            session,
            unfiltered,
        })
    }

    /// A warning for the user when the session listens for the lab's hosts but the kernel's
    /// filter ([`admit_only`]) could not be set: the QUIC listener then takes packets from any
    /// address, and a flood of connection openers from outside the lab can keep runs out
    /// (docs/security.md).
    pub fn unfiltered(&self) -> Option<String> {
        self.unfiltered.as_ref().map(|e| {
            format!(
                "the QUIC listener takes packets from any address ({e}): a flood of connection \
                 openers from outside the lab can keep runs out (docs/security.md)"
            )
        })
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
}
