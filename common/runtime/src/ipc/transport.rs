//! The transport's vocabulary: its errors, streams, wake-up events, sizing, clocks and the
//! traits every transport implements (`Transport`, `Outbox`, `Inbox`, `Bell`, `Waker`).

use std::path::PathBuf;
use std::time::Duration;

/// Longest run prefix: iceoryx2 puts it into Unix socket paths (108 bytes in all).
pub const MAX_PREFIX_LEN: usize = 40;

/// The error an iceoryx2 call (or a check of ours) returned, kept as the source.
pub type Source = Box<dyn std::error::Error + Send + Sync>;

/// Transport errors name the service or port concerned and keep the underlying error.
#[derive(Debug, thiserror::Error)]
pub enum IpcError {
    #[error("run prefix `{prefix}`: {source}")]
    Prefix {
        prefix: String,
        #[source]
        source: Source,
    },
    #[error("creating the iceoryx2 node `{name}`: {source}")]
    Node {
        name: String,
        #[source]
        source: Source,
    },
    #[error("service `{service}`: {source}")]
    Service {
        service: String,
        #[source]
        source: Source,
    },
    #[error("port on `{service}`: {source}")]
    Port {
        service: String,
        #[source]
        source: Source,
    },
    #[error("sending on `{service}`: {source}")]
    Send {
        service: String,
        #[source]
        source: Source,
    },
    #[error("receiving on `{service}`: {source}")]
    Receive {
        service: String,
        #[source]
        source: Source,
    },
    #[error("waiting on `{service}`: {source}")]
    Wait {
        service: String,
        #[source]
        source: Source,
    },
}

/// Publish–subscribe streams of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Stream {
    Measurement,
    Tampered,
    Torque(u32),
    /// Control center → attacker: the torques of the agents whose torques a run attacks.
    Actuation,
    Control,
    Status,
    /// Attacker → the external program that takes the attacker role: the clean measurements.
    ExternalIn,
    /// The external attacker program → attacker: what the control center is to receive.
    ExternalOut,
    /// The monitor program → control center: one verdict per agent and tick.
    Alarm,
    /// Control center → the controller program: what it is shown of each tick.
    ControllerIn,
    /// The controller program → control center: the torque of each tick.
    ControllerOut,
}

impl Stream {
    /// The one place service names are built.
    pub fn service_name(self) -> String {
        match self {
            Self::Measurement => "fdi/measurement".into(),
            Self::Tampered => "fdi/tampered".into(),
            Self::Torque(id) => format!("fdi/torque/{id}"),
            Self::Actuation => "fdi/actuation".into(),
            Self::Control => "fdi/control".into(),
            Self::Status => "fdi/status".into(),
            Self::ExternalIn => "fdi/external/attacker/in".into(),
            Self::ExternalOut => "fdi/external/attacker/out".into(),
            Self::Alarm => "fdi/alarm".into(),
            Self::ControllerIn => "fdi/external/controller/in".into(),
            Self::ControllerOut => "fdi/external/controller/out".into(),
        }
    }
}

/// Wake-up event services, one per process.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Wake {
    Agent(u32),
    Attacker,
    Center,
    Launcher,
    /// The external program that takes the attacker role (the attacker process relays for it).
    ExternalAttacker,
    /// The monitor program (detectors outside the project).
    Monitor,
    /// The controller program (the control center's torques decided outside the project).
    ExternalController,
}

impl Wake {
    pub fn service_name(self) -> String {
        match self {
            Self::Agent(id) => format!("fdi/wake/agent/{id}"),
            Self::Attacker => "fdi/wake/attacker".into(),
            Self::Center => "fdi/wake/center".into(),
            Self::Launcher => "fdi/wake/launcher".into(),
            Self::ExternalAttacker => "fdi/wake/external/attacker".into(),
            Self::Monitor => "fdi/wake/monitor".into(),
            Self::ExternalController => "fdi/wake/external/controller".into(),
        }
    }
}

/// Periods of receiver stall that realtime buffers absorb without loss.
pub const STALL_TICKS: usize = 256;

/// Sizes every process must agree on (iceoryx2 checks them when a service is opened).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sizing {
    /// Agents of the run.
    pub agents: usize,
    /// Messages one agent may have in flight on a stream (lockstep batch).
    pub in_flight: usize,
    /// Extra publishers and subscribers on every stream, beyond the run's own, for a node
    /// that taps or forges messages (tests). The node that creates a run's services first
    /// decides; a run's processes (0 taps) open them as created.
    pub taps: usize,
}

impl Sizing {
    /// The sizing of a run of `agents` with `in_flight` messages per agent, without taps.
    pub const fn new(agents: usize, in_flight: usize) -> Self {
        Self {
            agents,
            in_flight,
            taps: 0,
        }
    }

    /// This sizing with `taps` extra publishers and subscribers on every stream.
    pub const fn with_taps(self, taps: usize) -> Self {
        Self { taps, ..self }
    }

    /// (max publishers, max subscribers, subscriber buffer) of `stream`.
    pub(super) fn qos(self, stream: Stream) -> (usize, usize, usize) {
        let n = self.agents.max(1);
        // Lockstep needs `in_flight`; realtime must ride out a stall of a receiver (start-up page
        // faults, a descheduled process) of up to STALL_TICKS periods without losing data.
        let burst = (self.in_flight.max(1) * 4).max(STALL_TICKS);
        let (pubs, subs, buffer) = match stream {
            Stream::Measurement => (n, 2, burst),
            Stream::Tampered => (1, 2, n * burst),
            Stream::Torque(_) => (1, 2, burst),
            Stream::Actuation => (1, 2, n * burst),
            Stream::Control => (1, n + 6, 8),
            Stream::Status => (n + 6, 2, 256),
            Stream::ExternalIn
            | Stream::ExternalOut
            | Stream::Alarm
            | Stream::ControllerIn
            | Stream::ControllerOut => (1, 2, n * burst),
        };
        (pubs + self.taps, subs + self.taps, buffer)
    }
}

/// Monotonic clock shared by every process of the machine, ns.
pub fn monotonic_ns() -> u64 {
    let ts = rustix::time::clock_gettime(rustix::time::ClockId::Monotonic);
    u64::try_from(ts.tv_sec).unwrap_or(0) * 1_000_000_000 + u64::try_from(ts.tv_nsec).unwrap_or(0)
}

/// Sleeps until CLOCK_MONOTONIC reads `due_ns` (an absolute deadline, as [`monotonic_ns`]
/// counts); a sleep interrupted by a signal sleeps again.
pub fn sleep_until_ns(due_ns: u64) {
    let request = rustix::time::Timespec {
        tv_sec: i64::try_from(due_ns / 1_000_000_000).unwrap_or(i64::MAX),
        tv_nsec: i64::try_from(due_ns % 1_000_000_000).unwrap_or(0),
    };
    while let Err(rustix::io::Errno::INTR) =
        rustix::thread::clock_nanosleep_absolute(rustix::thread::ClockId::Monotonic, &request)
    {}
}

/// Checks a run prefix: 1 to [`MAX_PREFIX_LEN`] bytes of ASCII letters, digits, `_` and `-`
/// (it becomes part of file names).
pub fn check_prefix(prefix: &str) -> Result<(), IpcError> {
    let bad = |source: Source| IpcError::Prefix {
        prefix: prefix.into(),
        source,
    };
    if prefix.is_empty() || prefix.len() > MAX_PREFIX_LEN {
        return Err(bad(format!("must be 1..={MAX_PREFIX_LEN} bytes").into()));
    }
    if !prefix
        .bytes()
        .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
    {
        return Err(bad(
            "only ASCII letters, digits, `_` and `-` are allowed".into()
        ));
    }
    Ok(())
}

/// Payload types the transport carries: `#[repr(C)]` plain data, copied in and out whole.
pub trait Payload: iceoryx2::prelude::ZeroCopySend + Copy + std::fmt::Debug + 'static {}
impl<T: iceoryx2::prelude::ZeroCopySend + Copy + std::fmt::Debug + 'static> Payload for T {}

/// Sending side of a stream.
pub trait Outbox<T: Payload> {
    /// Publishes `value`; returns the number of subscribers reached.
    fn send(&self, value: T) -> Result<usize, IpcError>;
}

/// Receiving side of a stream.
pub trait Inbox<T: Payload> {
    /// True when a message is waiting (no system call on the shared-memory transport).
    fn has_messages(&self) -> Result<bool, IpcError>;
    /// Hands every waiting message to `f`, oldest first; returns how many.
    fn drain(&self, f: impl FnMut(T)) -> Result<usize, IpcError>;
}

/// Rings a peer's wake-up event.
pub trait Bell {
    fn ring(&self) -> Result<(), IpcError>;
}

/// A process's own wake-up event.
pub trait Waker {
    /// Blocks until a peer rings or `timeout` passes (a signal also ends the wait early).
    /// Returns whether it was rung. Every pending notification is consumed.
    fn wait(&self, timeout: Duration) -> Result<bool, IpcError>;
    /// Like [`Waker::wait`], with nanosecond timeout resolution, for realtime processes that
    /// must both keep a deadline and notice an arrival the moment it happens.
    fn wait_precise(&self, timeout: Duration) -> Result<bool, IpcError>;
}

/// What a run's processes talk over: one handle per process (a node of the run).
///
/// Ports are dropped before the handle that made them (declare them before it in a struct).
pub trait Transport: Sized + std::fmt::Debug {
    type Outbox<T: Payload>: Outbox<T> + std::fmt::Debug;
    type Inbox<T: Payload>: Inbox<T> + std::fmt::Debug;
    type Bell: Bell + std::fmt::Debug;
    type Waker: Waker + std::fmt::Debug;

    /// Opens this process's node `name` in the run `prefix` ([`check_prefix`]).
    fn open(prefix: &str, name: &str, sizing: Sizing) -> Result<Self, IpcError>;
    /// The run prefix it was opened with.
    fn prefix(&self) -> &str;
    /// A publisher on `stream`.
    fn publisher<T: Payload>(&self, stream: Stream) -> Result<Self::Outbox<T>, IpcError>;
    /// A subscriber on `stream`.
    fn subscriber<T: Payload>(&self, stream: Stream) -> Result<Self::Inbox<T>, IpcError>;
    /// A bell that wakes the process behind `wake`. Create it once that process's waker
    /// exists: an earlier one may not reach it.
    fn notifier(&self, wake: Wake) -> Result<Self::Bell, IpcError>;
    /// The waker this process blocks on.
    fn waker(&self, wake: Wake) -> Result<Self::Waker, IpcError>;
    /// One waker on the events of several processes (the bridge between hosts waits, in
    /// place of the processes of other hosts, for whatever the local ones send them).
    fn waker_any(&self, wakes: &[Wake]) -> Result<Self::Waker, IpcError>;
    /// Number of subscribers currently connected to `stream`.
    fn subscribers_of<T: Payload>(&self, stream: Stream) -> Result<usize, IpcError>;
    /// Reclaims what the dead nodes of this run (crashed processes) hold; returns how many.
    fn reap_dead_nodes(&self) -> usize;

    /// What the run `prefix` left behind (files), for checks after a run.
    fn leftovers(prefix: &str) -> Vec<PathBuf>;
    /// Removes everything the run `prefix` left behind. Only call it when no process of the
    /// run is alive. Returns the number of items removed.
    fn remove_leftovers(prefix: &str) -> Result<usize, IpcError>;
    /// The run prefixes that left something behind: `parse` gets each candidate name and
    /// returns the prefix it starts with, if it is one of the caller's. Sorted, without
    /// duplicates. For finding what dead runs left.
    fn runs_with_leftovers(parse: impl Fn(&str) -> Option<String>) -> Vec<String>;
}
