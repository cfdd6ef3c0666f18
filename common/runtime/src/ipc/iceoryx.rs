//! The iceoryx2 implementation of [`Transport`], in its two service variants: [`Shm`]
//! (`ipc::Service`: shared memory between the processes of a run, the runtime's transport) and
//! [`Local`] (`local::Service`: the same ports between the threads of one process, so that tests
//! run the roles without spawning binaries). The only code that calls iceoryx2 and knows where
//! its files live.

use std::path::{Path, PathBuf};
use std::time::Duration;

use iceoryx2::port::listener::{Listener, ListenerCreateError};
use iceoryx2::port::notifier::{Notifier, NotifierCreateError};
use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::prelude::*;
use iceoryx2::prelude::{ipc, ipc_threadsafe, local, local_threadsafe};

use super::transport::{
    check_prefix, Bell, Inbox, IpcError, Outbox, Payload, Sizing, Source, Stream, Transport, Wake,
    Waker,
};

/// The shared-memory transport between the processes of a run.
pub type Shm = Iceoryx<ipc::Service>;
/// The in-process transport between the threads of one process (tests).
pub type Local = Iceoryx<local::Service>;
/// [`Shm`] whose ports may be used from any thread (each behind a lock): the same services,
/// opened by the bridge between hosts, which publishes in the network's callbacks.
pub type ShmShared = Iceoryx<ipc_threadsafe::Service>;
/// [`Local`] whose ports may be used from any thread (tests of the bridge).
pub type LocalShared = Iceoryx<local_threadsafe::Service>;

/// The iceoryx2 service variants the runtime uses.
pub trait Variant: iceoryx2::service::Service {
    /// Whether the variant keeps files (shared memory, its root folder) that outlive a crash.
    const HAS_FILES: bool;
}

impl Variant for ipc::Service {
    const HAS_FILES: bool = true;
}

impl Variant for local::Service {
    const HAS_FILES: bool = false;
}

impl Variant for ipc_threadsafe::Service {
    const HAS_FILES: bool = true;
}

impl Variant for local_threadsafe::Service {
    const HAS_FILES: bool = false;
}

/// A process's (or, with [`Local`], a thread's) node of a run.
#[derive(Debug)]
pub struct Iceoryx<S: Variant> {
    node: Node<S>,
    config: Config,
    sizing: Sizing,
    prefix: String,
}

/// Maps a port-creation failure on `service` to [`IpcError::Port`]; one that `full` says is
/// the service's limit of ports of that kind is explained ([`Crowded`]).
fn port_error<E: std::error::Error + Send + Sync + 'static>(
    service: &str,
    full: fn(&E) -> bool,
) -> impl FnOnce(E) -> IpcError + '_ {
    move |e| IpcError::Port {
        service: service.to_string(),
        source: if full(&e) {
            Box::new(Crowded(e.into()))
        } else {
            e.into()
        },
    }
}

/// A port refused because its service already has every port of that kind the run sized it for
/// (`PublisherCreateError::ExceedsMaxSupportedPublishers` and the like): more processes opened
/// the run's services than the run has, and the likely cause is two "hosts" of a split run on
/// one machine sharing one shared memory. Its text says so; its source is iceoryx2's error.
#[derive(Debug)]
struct Crowded(Source);

impl std::fmt::Display for Crowded {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: the service already has every port of this kind that the run's processes \
             need, so processes beyond the run's opened it. Most likely two \"hosts\" of a \
             split run share one shared memory: network namespaces on one machine see the \
             same {} and {} unless each gets its own (a tmpfs on each, docs/multi-host.md, \
             \"Several hosts on one machine\"), and then every host's processes and bridge \
             open the same services",
            self.0,
            shm_dir().display(),
            root_dir().display()
        )
    }
}

impl std::error::Error for Crowded {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(&*self.0)
    }
}

fn config_for(prefix: &str) -> Result<Config, IpcError> {
    check_prefix(prefix)?;
    route_iceoryx2_log();
    let mut config = Config::default();
    config.global.prefix = FileName::new(prefix.as_bytes()).map_err(|e| IpcError::Prefix {
        prefix: prefix.into(),
        source: e.into(),
    })?;
    Ok(config)
}

impl<S: Variant> Iceoryx<S> {
    fn pubsub<T: Payload>(
        &self,
        stream: Stream,
    ) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<S, T, ()>, IpcError>
    {
        let service = stream.service_name();
        let (pubs, subs, buffer) = self.sizing.qos(stream);
        let name = ServiceName::new(&service).map_err(|e| IpcError::Service {
            service: service.clone(),
            source: e.into(),
        })?;
        self.node
            .service_builder(&name)
            .publish_subscribe::<T>()
            .max_publishers(pubs)
            .max_subscribers(subs)
            .max_nodes(self.sizing.agents + 8)
            .subscriber_max_buffer_size(buffer)
            .history_size(0)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(|e| IpcError::Service {
                service,
                source: e.into(),
            })
    }

    fn event(
        &self,
        wake: Wake,
    ) -> Result<iceoryx2::service::port_factory::event::PortFactory<S>, IpcError> {
        let service = wake.service_name();
        let name = ServiceName::new(&service).map_err(|e| IpcError::Service {
            service: service.clone(),
            source: e.into(),
        })?;
        self.node
            .service_builder(&name)
            .event()
            .max_notifiers(self.sizing.agents + 6)
            .max_listeners(2)
            .max_nodes(self.sizing.agents + 8)
            .open_or_create()
            .map_err(|e| IpcError::Service {
                service,
                source: e.into(),
            })
    }
}

impl<S: Variant> Transport for Iceoryx<S>
where
    Listener<S>: FileDescriptorBased,
{
    type Outbox<T: Payload> = IoxOutbox<S, T>;
    type Inbox<T: Payload> = IoxInbox<S, T>;
    type Bell = IoxBell<S>;
    type Waker = IoxWaker<S>;

    fn open(prefix: &str, name: &str, sizing: Sizing) -> Result<Self, IpcError> {
        let config = config_for(prefix)?;
        let err = |source: Source| IpcError::Node {
            name: name.into(),
            source,
        };
        let node_name = NodeName::new(name).map_err(|e| err(e.into()))?;
        // iceoryx2 reports an `InternalError` when a file of its shared node registry changes
        // under it while the node's files are created (another run being cleaned up at that
        // moment): transient, so a few bounded retries.
        let mut attempt = 0;
        let node = loop {
            let created = NodeBuilder::new()
                .name(&node_name)
                .config(&config)
                // Signals are ours: the processes set a flag on SIGINT/SIGTERM and flush traces.
                .signal_handling_mode(SignalHandlingMode::Disabled)
                .create::<S>();
            match created {
                Ok(node) => break node,
                Err(iceoryx2::node::NodeCreationFailure::InternalError) if attempt < 5 => {
                    attempt += 1;
                    std::thread::sleep(Duration::from_millis(20));
                }
                Err(e) => return Err(err(e.into())),
            }
        };
        Ok(Self {
            node,
            config,
            sizing,
            prefix: prefix.into(),
        })
    }

    fn prefix(&self) -> &str {
        &self.prefix
    }

    fn publisher<T: Payload>(&self, stream: Stream) -> Result<IoxOutbox<S, T>, IpcError> {
        let factory = self.pubsub::<T>(stream)?;
        let service = stream.service_name();
        let port = factory
            .publisher_builder()
            .create()
            .map_err(port_error(&service, |e| {
                matches!(e, PublisherCreateError::ExceedsMaxSupportedPublishers)
            }))?;
        Ok(IoxOutbox { port, service })
    }

    fn subscriber<T: Payload>(&self, stream: Stream) -> Result<IoxInbox<S, T>, IpcError> {
        let factory = self.pubsub::<T>(stream)?;
        let service = stream.service_name();
        let port = factory
            .subscriber_builder()
            .create()
            .map_err(port_error(&service, |e| {
                matches!(e, SubscriberCreateError::ExceedsMaxSupportedSubscribers)
            }))?;
        Ok(IoxInbox { port, service })
    }

    fn notifier(&self, wake: Wake) -> Result<IoxBell<S>, IpcError> {
        let service = wake.service_name();
        let port = self
            .event(wake)?
            .notifier_builder()
            .create()
            .map_err(port_error(&service, |e| {
                matches!(e, NotifierCreateError::ExceedsMaxSupportedNotifiers)
            }))?;
        Ok(IoxBell { port, service })
    }

    fn waker(&self, wake: Wake) -> Result<IoxWaker<S>, IpcError> {
        self.waker_any(&[wake])
    }

    fn waker_any(&self, wakes: &[Wake]) -> Result<IoxWaker<S>, IpcError> {
        let mut ports = Vec::with_capacity(wakes.len());
        for &wake in wakes {
            let service = wake.service_name();
            let port = self
                .event(wake)?
                .listener_builder()
                .create()
                .map_err(port_error(&service, |e| {
                    matches!(e, ListenerCreateError::ExceedsMaxSupportedListeners)
                }))?;
            ports.push(port);
        }
        let service = wakes
            .iter()
            .map(|w| w.service_name())
            .collect::<Vec<_>>()
            .join(", ");
        Ok(IoxWaker { ports, service })
    }

    fn subscribers_of<T: Payload>(&self, stream: Stream) -> Result<usize, IpcError> {
        Ok(self
            .pubsub::<T>(stream)?
            .dynamic_config()
            .number_of_subscribers())
    }

    fn reap_dead_nodes(&self) -> usize {
        reap_dead_nodes::<S>(&self.config)
    }

    fn leftovers(prefix: &str) -> Vec<PathBuf> {
        if !S::HAS_FILES {
            return Vec::new();
        }
        let Ok(config) = config_for(prefix) else {
            return Vec::new();
        };
        let root = PathBuf::from(config.global.root_path().to_string());
        let mut out = Vec::new();
        for d in resource_dirs(&root) {
            if let Ok(entries) = std::fs::read_dir(&d) {
                out.extend(
                    entries
                        .flatten()
                        .filter(|e| e.file_name().to_string_lossy().starts_with(prefix))
                        .map(|e| e.path()),
                );
            }
        }
        out
    }

    /// First iceoryx2's own cleanup of dead nodes, then every file of the prefix in the
    /// shared-memory and iceoryx2 root folders (including the files iceoryx2 keeps on purpose
    /// after a clean shutdown).
    fn remove_leftovers(prefix: &str) -> Result<usize, IpcError> {
        let config = config_for(prefix)?;
        reap_dead_nodes::<S>(&config);
        if !S::HAS_FILES {
            return Ok(0);
        }
        let root = PathBuf::from(config.global.root_path().to_string());
        let nodes = root.join("nodes");
        let mut removed = 0;
        for dir in resource_dirs(&root) {
            removed += remove_prefixed(&dir, prefix);
            // Per-node folders are named by node id, not by prefix; their files carry it.
            if dir.parent() == Some(nodes.as_path()) {
                let _ = std::fs::remove_dir(&dir); // only succeeds when empty
            }
        }
        Ok(removed)
    }

    /// Looks in every folder where iceoryx2 keeps files (shared memory and its root folder
    /// alike).
    fn runs_with_leftovers(parse: impl Fn(&str) -> Option<String>) -> Vec<String> {
        if !S::HAS_FILES {
            return Vec::new();
        }
        let mut out: Vec<String> = resource_dirs(&root_dir())
            .iter()
            .filter_map(|d| std::fs::read_dir(d).ok())
            .flat_map(|entries| entries.flatten())
            .filter_map(|e| parse(&e.file_name().to_string_lossy()))
            .filter(|p| check_prefix(p).is_ok())
            .collect();
        out.sort();
        out.dedup();
        out
    }
}

fn reap_dead_nodes<S: Variant>(config: &Config) -> usize {
    let mut reaped = 0;
    let _ = Node::<S>::list(config, |state| {
        if let NodeState::Dead(view) = state {
            if view.try_remove_stale_resources().is_ok() {
                reaped += 1;
            }
        }
        CallbackProgression::Continue
    });
    reaped
}

/// Every folder where iceoryx2 keeps files of a run: the shared-memory folder, its root folder,
/// the root's `services/` and `nodes/`, and each per-node folder in `nodes/`.
fn resource_dirs(root: &Path) -> Vec<PathBuf> {
    let mut dirs = vec![
        shm_dir(),
        root.to_path_buf(),
        root.join("services"),
        root.join("nodes"),
    ];
    if let Ok(entries) = std::fs::read_dir(root.join("nodes")) {
        dirs.extend(entries.flatten().map(|e| e.path()).filter(|p| p.is_dir()));
    }
    dirs
}

fn remove_prefixed(dir: &Path, prefix: &str) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(prefix))
        .filter(|e| {
            e.path().is_file() || std::fs::symlink_metadata(e.path()).is_ok_and(|m| !m.is_dir())
        })
        .filter(|e| std::fs::remove_file(e.path()).is_ok())
        .count()
}

/// Longest line of iceoryx2's log that is printed; the rest is counted, not shown (an error
/// after the launcher's death once dumped 6 KB of internal state).
pub const LOG_LINE_BYTES: usize = 300;

/// iceoryx2's log, through the project's own output: one line on stderr per message, named
/// by the program (`fdi-agent: iceoryx2 error: …`), at most [`LOG_LINE_BYTES`].
struct Iceoryx2Log;

impl iceoryx2_log_types::Log for Iceoryx2Log {
    fn log(
        &self,
        level: iceoryx2_log_types::LogLevel,
        origin: std::fmt::Arguments,
        message: std::fmt::Arguments,
    ) {
        let program = std::env::args_os()
            .next()
            .and_then(|a| {
                Path::new(&a)
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
            })
            .unwrap_or_else(|| "fdi".into());
        crate::stderr::print_failure(format_args!(
            "{program}: {}",
            log_line(level, &origin.to_string(), &message.to_string())
        ));
    }
}

/// One line of iceoryx2's log: `iceoryx2 <level>: <origin>: <message>`, whitespace runs (line
/// breaks of a multi-line dump) made one space, cut at [`LOG_LINE_BYTES`] with the count of
/// what was left out.
pub fn log_line(level: iceoryx2_log_types::LogLevel, origin: &str, message: &str) -> String {
    use iceoryx2_log_types::LogLevel as L;
    let level = match level {
        L::Trace => "trace",
        L::Debug => "debug",
        L::Info => "info",
        L::Warn => "warning",
        L::Error => "error",
        L::Fatal => "fatal error",
    };
    let text = format!("{origin}: {message}");
    let words: Vec<&str> = text.split_whitespace().collect();
    let mut line = format!("iceoryx2 {level}: {}", words.join(" "));
    if line.len() > LOG_LINE_BYTES {
        let mut cut = LOG_LINE_BYTES;
        while !line.is_char_boundary(cut) {
            cut -= 1;
        }
        let left = line.len() - cut;
        line.truncate(cut);
        line.push_str(&format!(
            " … ({left} more bytes; IOX2_LOG_LEVEL sets what iceoryx2 logs)"
        ));
    }
    line
}

/// Routes iceoryx2's log through [`Iceoryx2Log`], from `Error` up (its warnings are about its
/// own fallbacks, e.g. `No config file was loaded` on every dead-node cleanup; the transport
/// always passes its own config); `IOX2_LOG_LEVEL` (iceoryx2's variable) asks for more. Once
/// per process, before any other iceoryx2 call of the transport.
fn route_iceoryx2_log() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        static LOGGER: Iceoryx2Log = Iceoryx2Log;
        iceoryx2::prelude::set_logger(&LOGGER);
        iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    });
}

/// The folder of the shared memory iceoryx2 makes (`/dev/shm` on Linux), as iceoryx2's
/// platform settings name it.
pub fn shm_dir() -> PathBuf {
    let dir = String::from_utf8_lossy(iceoryx2_pal_configuration::SHARED_MEMORY_DIRECTORY);
    PathBuf::from(dir.trim_end_matches('/'))
}

/// The iceoryx2 root folder (the same for every prefix), where it keeps its node and service
/// files.
pub fn root_dir() -> PathBuf {
    route_iceoryx2_log();
    PathBuf::from(Config::default().global.root_path().to_string())
}

/// Sending side of a stream.
#[derive(Debug)]
pub struct IoxOutbox<S: Variant, T: Payload> {
    port: Publisher<S, T, ()>,
    service: String,
}

impl<S: Variant, T: Payload> Outbox<T> for IoxOutbox<S, T> {
    fn send(&self, value: T) -> Result<usize, IpcError> {
        let err = |source: Source| IpcError::Send {
            service: self.service.clone(),
            source,
        };
        let sample = self.port.loan_uninit().map_err(|e| err(e.into()))?;
        sample
            .write_payload(value)
            .send()
            .map_err(|e| err(e.into()))
    }
}

/// Receiving side of a stream.
#[derive(Debug)]
pub struct IoxInbox<S: Variant, T: Payload> {
    port: Subscriber<S, T, ()>,
    service: String,
}

impl<S: Variant, T: Payload> Inbox<T> for IoxInbox<S, T> {
    /// Reads the shared-memory queue; no system call.
    fn has_messages(&self) -> Result<bool, IpcError> {
        self.port.has_samples().map_err(|e| IpcError::Receive {
            service: self.service.clone(),
            source: e.into(),
        })
    }

    fn drain(&self, mut f: impl FnMut(T)) -> Result<usize, IpcError> {
        let mut n = 0;
        while let Some(sample) = self.port.receive().map_err(|e| IpcError::Receive {
            service: self.service.clone(),
            source: e.into(),
        })? {
            f(*sample.payload());
            n += 1;
        }
        Ok(n)
    }
}

/// Rings a peer's wake-up event.
#[derive(Debug)]
pub struct IoxBell<S: Variant> {
    port: Notifier<S>,
    service: String,
}

impl<S: Variant> Bell for IoxBell<S> {
    fn ring(&self) -> Result<(), IpcError> {
        self.port.notify().map(|_| ()).map_err(|e| IpcError::Send {
            service: self.service.clone(),
            source: e.into(),
        })
    }
}

/// This process's wake-up event (or, for the bridge between hosts, the events of several
/// processes of other hosts).
#[derive(Debug)]
pub struct IoxWaker<S: Variant> {
    ports: Vec<Listener<S>>,
    service: String,
}

impl<S: Variant> IoxWaker<S> {
    /// Consumes every pending notification without blocking; whether there was one.
    fn poll(&self) -> Result<bool, IpcError> {
        let mut rung = false;
        for port in &self.ports {
            port.try_wait(|_| rung = true).map_err(|e| IpcError::Wait {
                service: self.service.clone(),
                source: e.into(),
            })?;
        }
        Ok(rung)
    }
}

impl<S: Variant> Waker for IoxWaker<S>
where
    Listener<S>: FileDescriptorBased,
{
    fn wait(&self, timeout: Duration) -> Result<bool, IpcError> {
        let [port] = self.ports.as_slice() else {
            return self.wait_precise(timeout);
        };
        // iceoryx2 turns the timeout into SO_RCVTIMEO with microsecond resolution, and a zero
        // timeval there means "block forever": below 1 µs, only poll.
        if timeout < Duration::from_micros(1) {
            return self.poll();
        }
        let mut rung = false;
        match port.timed_wait(|_| rung = true, timeout) {
            Ok(_) => {}
            Err(iceoryx2::port::listener::ListenerWaitError::InterruptSignal) => return Ok(false),
            Err(e) => {
                return Err(IpcError::Wait {
                    service: self.service.clone(),
                    source: e.into(),
                })
            }
        }
        // Coalesce whatever else arrived meanwhile.
        let _ = port.try_wait(|_| rung = true);
        Ok(rung)
    }

    /// `ppoll` on the listeners' file descriptors (a high-resolution timer) instead of the
    /// socket receive timeout, whose resolution is the scheduler tick.
    ///
    /// The event is more than its descriptor: a shared-memory state tells notifiers whether a
    /// wake-up is already pending, and while it says so they send nothing. Consuming
    /// notifications can leave that state "pending" with an empty socket (a notifier slipped in
    /// between the listener's two steps); polling the descriptor then would sleep through every
    /// later ring until the timeout. So the pending state is consumed first, through the
    /// listener's own non-blocking wait, and the descriptors are polled only when nothing is
    /// pending.
    #[allow(unsafe_code)]
    fn wait_precise(&self, timeout: Duration) -> Result<bool, IpcError> {
        if self.poll()? {
            return Ok(true);
        }
        let fds: Vec<rustix::fd::BorrowedFd<'_>> = self
            .ports
            .iter()
            .map(|port| {
                // SAFETY: the descriptor is owned by the listener, which outlives this call; it
                // is only borrowed for the poll below and never closed or duplicated here.
                let raw = unsafe { port.file_descriptor().native_handle() };
                // SAFETY: `raw` is open for the whole borrow (see above).
                unsafe { rustix::fd::BorrowedFd::borrow_raw(raw) }
            })
            .collect();
        let ts = rustix::time::Timespec {
            tv_sec: i64::try_from(timeout.as_secs()).unwrap_or(i64::MAX),
            tv_nsec: i64::from(timeout.subsec_nanos()),
        };
        let mut polled: Vec<rustix::event::PollFd<'_>> = fds
            .iter()
            .map(|fd| rustix::event::PollFd::new(fd, rustix::event::PollFlags::IN))
            .collect();
        match rustix::event::poll(&mut polled, Some(&ts)) {
            Ok(_) | Err(rustix::io::Errno::INTR) => {}
            Err(e) => {
                return Err(IpcError::Wait {
                    service: self.service.clone(),
                    source: e.into(),
                })
            }
        }
        self.poll()
    }
}

#[cfg(test)]
mod tests {
    /// Regression (issue 18): iceoryx2 printed `[W] Config::global_config() No config file was
    /// loaded` on its own console logger, and a child a 6 KB multi-line dump after the launcher
    /// was killed. Its log now goes through one bounded line of ours.
    #[test]
    fn iceoryx2_log_is_one_bounded_line_of_ours() {
        use iceoryx2_log_types::LogLevel;
        let dump = format!(
            "state {{\n    a: 1,\n{}\n}}",
            "    field: value,\n".repeat(400)
        );
        let line = super::log_line(LogLevel::Error, "Node::cleanup", &dump);
        assert!(
            line.starts_with("iceoryx2 error: Node::cleanup: state { a: 1, field: value,"),
            "{line}"
        );
        assert!(!line.contains('\n'), "{line}");
        assert!(line.len() < super::LOG_LINE_BYTES + 100, "{}", line.len());
        assert!(line.contains("more bytes; IOX2_LOG_LEVEL"), "{line}");
        let short = super::log_line(LogLevel::Warn, "o", "é".repeat(10).as_str());
        assert_eq!(short, format!("iceoryx2 warning: o: {}", "é".repeat(10)));
        let cut = super::log_line(LogLevel::Fatal, "o", "é".repeat(400).as_str());
        assert!(cut.starts_with("iceoryx2 fatal error: o: é"), "{cut}");
    }

    use super::super::StatusMsg;
    use super::*;

    fn prefix(tag: &str) -> String {
        format!("fdiut{}_{tag}_", std::process::id())
    }

    /// A node `name` of run `prefix`, sized for one agent and one message in flight.
    fn open_small(prefix: &str, name: &str) -> Shm {
        Shm::open(prefix, name, Sizing::new(1, 1)).expect("node")
    }

    /// Regression (issue 33): two "hosts" of a split run in network namespaces that shared one
    /// `/dev/shm` failed with a bare `PublisherCreateError::ExceedsMaxSupportedPublishers`. A
    /// port beyond the service's limit is still an error, which now says what it means.
    #[test]
    fn a_port_beyond_the_services_limit_says_that_two_hosts_may_share_one_shared_memory() {
        let p = prefix("crowd");
        {
            let a = open_small(&p, "host-a");
            let b = open_small(&p, "host-b");
            // One publisher per torque stream in a run: the second "host's" is one too many.
            let _first = Transport::publisher::<super::super::TorqueMsg>(&a, Stream::Torque(1))
                .expect("the run's publisher");
            let e = Transport::publisher::<super::super::TorqueMsg>(&b, Stream::Torque(1))
                .expect_err("a second publisher on a service sized for one");
            let text = e.to_string();
            assert!(
                matches!(e, IpcError::Port { ref service, .. } if service == "fdi/torque/1"),
                "{text}"
            );
            assert!(
                text.contains("PublisherCreateError::ExceedsMaxSupportedPublishers")
                    && text.contains("two \"hosts\" of a split run share one shared memory")
                    && text.contains(&shm_dir().display().to_string())
                    && text.contains("docs/multi-host.md"),
                "{text}"
            );
            let first = std::error::Error::source(&e).expect("its cause");
            let iceoryx2 = first
                .source()
                .expect("iceoryx2's error, kept as the source");
            assert_eq!(
                iceoryx2.to_string(),
                "PublisherCreateError::ExceedsMaxSupportedPublishers"
            );
        }
        Shm::remove_leftovers(&p).expect("cleanup");
    }

    #[test]
    fn a_run_whose_files_are_only_in_the_iceoryx2_root_is_still_found_and_removed() {
        let p = prefix("rp");
        let mine = |name: &str| name.starts_with(&p).then(|| p.clone());
        {
            let t = open_small(&p, "test");
            let _w = t.waker(Wake::Launcher).expect("listener");
            assert_eq!(Shm::runs_with_leftovers(mine), vec![p.clone()]);
            // A killed run's leftovers need not include a shared-memory file (the launcher's
            // stale-run search used to look in /dev/shm only).
            for f in Shm::leftovers(&p) {
                if f.starts_with("/dev/shm") {
                    std::fs::remove_file(&f).expect("remove");
                }
            }
            assert!(!Shm::leftovers(&p).is_empty(), "files in the root folder");
            assert_eq!(Shm::runs_with_leftovers(mine), vec![p.clone()]);
        }
        Shm::remove_leftovers(&p).expect("removed");
        assert_eq!(Shm::leftovers(&p), Vec::<PathBuf>::new());
        assert!(Shm::runs_with_leftovers(mine).is_empty());
    }

    #[test]
    fn waker_wait_with_a_sub_microsecond_timeout_returns_instead_of_blocking_forever() {
        let p = prefix("w");
        {
            let t = open_small(&p, "test");
            let waker = t.waker(Wake::Launcher).expect("listener");
            let started = std::time::Instant::now();
            for ns in [0u64, 1, 500, 999] {
                assert!(!waker.wait(Duration::from_nanos(ns)).expect("wait"));
            }
            // Not a timing assertion on speed: a hang here would block the test forever.
            assert!(started.elapsed() < Duration::from_secs(60));
            t.notifier(Wake::Launcher)
                .expect("notifier")
                .ring()
                .expect("ring");
            assert!(waker.wait(Duration::from_nanos(10)).expect("wait"));
            // The precise wait: times out without a ring, returns true after one.
            assert!(!waker
                .wait_precise(Duration::from_micros(200))
                .expect("precise wait"));
            t.notifier(Wake::Launcher)
                .expect("notifier")
                .ring()
                .expect("ring");
            assert!(waker
                .wait_precise(Duration::from_secs(5))
                .expect("precise wait"));
        }
        Shm::remove_leftovers(&p).expect("cleanup");
        assert!(Shm::leftovers(&p).is_empty(), "{:?}", Shm::leftovers(&p));
    }

    /// The precise wait under concurrent rings: three threads ring together on a common beat,
    /// as the agents of a realtime run do; a wait that times out although some ringer
    /// completed two rings meanwhile (one ring began and ended inside the wait) slept through
    /// a ring. (The race this guards against — see [`Waker::wait_precise`] — needs the
    /// listener to be preempted inside a sub-microsecond window; it showed in realtime runs as
    /// 5 ms liveness timeouts of the attacker, ~10 per 30 s, and does not show reliably here:
    /// the runtime counts such missed wake-ups and `bench latency` reports them.)
    #[test]
    fn a_precise_wait_wakes_for_concurrent_rings() {
        use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
        use std::sync::Arc;
        const RINGERS: usize = 3;
        const BEATS: u32 = 4000;
        let p = prefix("race");
        let sizing = Sizing::new(RINGERS, 1);
        {
            let t = Shm::open(&p, "listener", sizing).expect("node");
            let waker = t.waker(Wake::Center).expect("listener");
            let rings: Arc<Vec<AtomicU64>> =
                Arc::new((0..RINGERS).map(|_| AtomicU64::new(0)).collect());
            let done = Arc::new(AtomicBool::new(false));
            let start = std::time::Instant::now() + Duration::from_millis(20);
            let ringers: Vec<_> = (0..RINGERS)
                .map(|i| {
                    let (p, rings) = (p.clone(), rings.clone());
                    std::thread::spawn(move || {
                        let t = Shm::open(&p, &format!("ringer{i}"), sizing).expect("node");
                        let bell = t.notifier(Wake::Center).expect("notifier");
                        for beat in 0..BEATS {
                            let at = start + Duration::from_micros(250) * beat;
                            std::thread::sleep(
                                at.saturating_duration_since(std::time::Instant::now()),
                            );
                            bell.ring().expect("ring");
                            rings[i].fetch_add(1, Ordering::SeqCst);
                        }
                    })
                })
                .collect();
            let timeout = Duration::from_millis(20);
            let (mut waits, mut slept_through) = (0u64, 0u64);
            while !done.load(Ordering::SeqCst) {
                let before: Vec<u64> = rings.iter().map(|r| r.load(Ordering::SeqCst)).collect();
                let began = std::time::Instant::now();
                let rung = waker.wait_precise(timeout).expect("precise wait");
                // Only tells a timeout from an early return: nothing depends on speed.
                let timed_out = began.elapsed() >= timeout;
                let rang_inside = rings
                    .iter()
                    .zip(&before)
                    .any(|(r, b)| r.load(Ordering::SeqCst) >= b + 2);
                if !rung && timed_out && rang_inside {
                    slept_through += 1;
                }
                waits += 1;
                if ringers.iter().all(|r| r.is_finished()) {
                    done.store(true, Ordering::SeqCst);
                }
            }
            for r in ringers {
                r.join().expect("ringer");
            }
            assert_eq!(slept_through, 0, "of {waits} waits");
        }
        Shm::remove_leftovers(&p).expect("cleanup");
        assert!(Shm::leftovers(&p).is_empty(), "{:?}", Shm::leftovers(&p));
    }

    /// The in-process variant: threads of one process reach each other through it, and it
    /// leaves no file behind (so tests using it need no cleanup).
    #[test]
    fn the_local_transport_connects_threads_and_keeps_no_files() {
        let p = prefix("local");
        let sizing = Sizing::new(1, 1);
        let t = Local::open(&p, "receiver", sizing).expect("node");
        let waker = t.waker(Wake::Launcher).expect("waker");
        let inbox = t.subscriber::<StatusMsg>(Stream::Status).expect("sub");
        // The sender keeps its ports until the message was read (a publisher's samples go
        // with it).
        let (read_tx, read_rx) = std::sync::mpsc::channel::<()>();
        let sender = {
            let p = p.clone();
            std::thread::spawn(move || {
                let t = Local::open(&p, "sender", sizing).expect("node");
                let outbox = t.publisher::<StatusMsg>(Stream::Status).expect("pub");
                let bell = t.notifier(Wake::Launcher).expect("bell");
                let msg = StatusMsg {
                    role: 1,
                    agent: 1,
                    kind: 1,
                    reserved: 0,
                    tick: 42,
                };
                assert_eq!(outbox.send(msg).expect("send"), 1, "one subscriber");
                bell.ring().expect("ring");
                let _ = read_rx.recv_timeout(Duration::from_secs(30));
            })
        };
        assert!(waker.wait(Duration::from_secs(10)).expect("wait"));
        let mut ticks = Vec::new();
        inbox.drain(|m| ticks.push(m.tick)).expect("drain");
        read_tx.send(()).expect("sender waits");
        sender.join().expect("sender");
        assert_eq!(ticks, vec![42]);
        assert!(Shm::leftovers(&p).is_empty(), "{:?}", Shm::leftovers(&p));
        assert!(Local::leftovers(&p).is_empty());
    }

    /// What the roles' hold after their last message ([`crate::process::LauncherLink::hold`])
    /// is for: a message not yet read when its publisher goes away is lost, in both variants.
    #[test]
    fn unread_messages_go_with_their_publisher() {
        fn unread_after_drop<X: Transport>(p: &str) -> usize {
            let t = X::open(p, "receiver", Sizing::new(1, 1)).expect("node");
            let inbox = t.subscriber::<StatusMsg>(Stream::Status).expect("sub");
            {
                let sender = X::open(p, "sender", Sizing::new(1, 1)).expect("node");
                let outbox = sender.publisher::<StatusMsg>(Stream::Status).expect("pub");
                let msg = StatusMsg {
                    role: 1,
                    agent: 1,
                    kind: 1,
                    reserved: 0,
                    tick: 42,
                };
                assert_eq!(outbox.send(msg).expect("send"), 1);
            }
            inbox.drain(|_| {}).expect("drain")
        }
        let p = prefix("gone");
        assert_eq!(unread_after_drop::<Shm>(&p), 0);
        assert_eq!(unread_after_drop::<Local>(&prefix("gonel")), 0);
        Shm::remove_leftovers(&p).expect("cleanup");
        assert!(Shm::leftovers(&p).is_empty());
    }

    #[test]
    fn two_prefixes_do_not_see_each_other() {
        let (a, b) = (prefix("a"), prefix("b"));
        {
            let ta = open_small(&a, "a");
            let tb = open_small(&b, "b");
            let sub_a = ta.subscriber::<StatusMsg>(Stream::Status).expect("sub a");
            let pub_b = tb.publisher::<StatusMsg>(Stream::Status).expect("pub b");
            assert_eq!(
                pub_b
                    .send(StatusMsg {
                        role: 1,
                        agent: 1,
                        kind: 1,
                        reserved: 0,
                        tick: 7
                    })
                    .expect("send"),
                0,
                "no subscriber in run b"
            );
            assert_eq!(sub_a.drain(|_| {}).expect("drain"), 0);
        }
        for p in [a, b] {
            Shm::remove_leftovers(&p).expect("cleanup");
            assert!(Shm::leftovers(&p).is_empty());
        }
    }

    #[test]
    fn prefixes_are_checked() {
        assert!(Shm::open("", "x", Sizing::new(1, 1)).is_err());
        assert!(Shm::open("a/b", "x", Sizing::new(1, 1)).is_err());
        assert!(Shm::open(
            &"p".repeat(super::super::MAX_PREFIX_LEN + 1),
            "x",
            Sizing::new(1, 1)
        )
        .is_err());
    }
}
