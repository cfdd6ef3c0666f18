//! The transport floor: the lowest per-hop latency the runtime's transport gives on this machine,
//! measured with the runtime's own wait strategy ([`WaitStrategy`]: poll the wake-up event,
//! yielding the CPU between polls, for `spin`; then block on it).
//!
//! Three cases, each a ring of processes passing one message of the size of a
//! [`MeasurementMsg`] around, one message in flight at a time:
//!
//! | case | processes | hops | transport |
//! |---|---|---|---|
//! | `ipc_ping_pong` | 2 | 2 | iceoryx2 publish–subscribe plus an event notify per hop, as the runtime |
//! | `ipc_chain` | 3 | 3 | the same, A → B → C → A like agent → attacker → control center → agent |
//! | `uds_ping_pong` | 2 | 2 | [`UnixDatagram`] sockets bound to paths in a temporary folder |
//!
//! This process is A: per iteration it stamps the clock, publishes, waits until the message comes
//! back and records `round trip / hops` into a histogram (warm-up iterations are not recorded).
//! The other processes are this executable again, in the hidden `bench-peer` mode
//! ([`peer_main`] gets the arguments after `bench-peer`):
//!
//! ```text
//! bench-peer <KIND> <ROLE> [--prefix PREFIX] [--dir DIR] [--spin-us N] [--parent-pid PID]
//!
//!   KIND ROLE            what the peer does
//!   ipc-pair pong        Measurement → Tampered, wakes on the attacker's event (needs --prefix)
//!   ipc-chain attacker   Measurement → Tampered, wakes on the attacker's event (needs --prefix)
//!   ipc-chain center     Tampered → Torque(1), wakes on the center's event (needs --prefix)
//!   uds-pair pong        echoes on DIR/b.sock to DIR/a.sock (needs --dir)
//!   --spin-us            spin budget of the wait strategy, µs (default: DEFAULT_SPIN_US)
//!   --parent-pid         stop when this process is no longer the parent
//! ```
//!
//! Each iceoryx2 case runs in its own run prefix (a fresh `ipc::RunPrefix`, the launcher's
//! format, so a killed launcher's leftovers are reaped by the next run), and uses the runtime's own service
//! names, all carrying [`MeasurementMsg`]. A peer relays every message it receives and exits
//! after relaying the stop message; it also exits when its parent dies (the kernel sends SIGTERM)
//! or when nothing arrives for [`PEER_IDLE_TIMEOUT`].

use std::io;
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use fdi_common::scenario::MAX_DOF;
use fdi_runtime::ipc::{
    monotonic_ns, Bell as _, Inbox as _, MeasurementMsg, Outbox as _, Shm, Sizing, Stream,
    Transport, Wake, Waker as _,
};
use fdi_runtime::process::{WaitStrategy, DEFAULT_SPIN_US, WAIT_SLICE};

use fdi_orchestrator::run::supervisor::Supervisor;
use hdrhistogram::Histogram;
use serde::Serialize;

/// What [`run_floor`] measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FloorOptions {
    /// Round trips recorded per case.
    pub iterations: u64,
    /// Round trips before those, not recorded.
    pub warmup: u64,
    /// Spin budget of the wait strategy (as `FDI_SPIN_US` for the runtime).
    pub spin: Duration,
    /// Start one round trip per period (on absolute period boundaries) instead of back to back:
    /// the processes then sleep between messages, as the runtime's do between ticks.
    pub pace: Option<Duration>,
}

impl Default for FloorOptions {
    fn default() -> Self {
        Self {
            iterations: 20_000,
            warmup: 1_000,
            spin: Duration::from_micros(DEFAULT_SPIN_US),
            pace: None,
        }
    }
}

/// The iceoryx2 3-hop chain with one round trip per `opts.pace` period.
pub fn run_paced_chain(opts: &FloorOptions) -> Result<FloorCase> {
    if opts.pace.is_none() {
        bail!("a paced chain needs a period");
    }
    ipc_case(opts, PeerKind::IpcChain, &self_command).context("iceoryx2 3-hop chain, paced")
}

/// Per-hop latency percentiles, µs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct HopLatency {
    pub p50_us: f64,
    pub p90_us: f64,
    pub p99_us: f64,
    pub p999_us: f64,
    pub max_us: f64,
    pub mean_us: f64,
}

/// One case of the floor.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FloorCase {
    /// What was measured, e.g. `iceoryx2 ping-pong`.
    pub transport: &'static str,
    pub processes: u32,
    /// Hops per round trip; each iteration records `round trip / hops`.
    pub hops: u32,
    pub per_hop: HopLatency,
}

/// The transport floor.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FloorResult {
    /// Round trips recorded per case.
    pub iterations: u64,
    /// Round trips run before, not recorded.
    pub warmup: u64,
    /// Spin budget of the wait strategy, µs (0: block at once).
    pub spin_us: u64,
    /// Bytes per message.
    pub payload_bytes: usize,
    pub ipc_ping_pong: FloorCase,
    pub ipc_chain: FloorCase,
    pub uds_ping_pong: FloorCase,
}

impl FloorResult {
    pub fn cases(&self) -> [&FloorCase; 3] {
        [&self.ipc_ping_pong, &self.ipc_chain, &self.uds_ping_pong]
    }

    /// A markdown table of the per-hop latencies.
    pub fn to_markdown(&self) -> String {
        let mut s = format!(
            "transport floor: {} round trips (+{} warm-up) per case, spin {} µs, {}-byte messages; per hop = round trip / hops\n\n",
            self.iterations, self.warmup, self.spin_us, self.payload_bytes
        );
        s.push_str("| transport | processes | hops | p50 (µs) | p90 (µs) | p99 (µs) | p99.9 (µs) | max (µs) |\n");
        s.push_str("|---|---|---|---|---|---|---|---|\n");
        for c in self.cases() {
            let h = &c.per_hop;
            s.push_str(&format!(
                "| {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |\n",
                c.transport, c.processes, c.hops, h.p50_us, h.p90_us, h.p99_us, h.p999_us, h.max_us
            ));
        }
        s
    }
}

/// Measures the floor; spawns the peers as `current_exe() bench-peer ...`.
pub fn run_floor(opts: &FloorOptions) -> Result<FloorResult> {
    run_floor_with(opts, &self_command)
}

/// The peer side (`bench-peer`, see the module documentation).
pub fn peer_main(a: &PeerSpec) -> Result<()> {
    if a.parent_pid.is_some() {
        rustix::process::set_parent_process_death_signal(Some(rustix::process::Signal::TERM))
            .context("asking for SIGTERM on the parent's death")?;
    }
    let parent = ParentWatch(a.parent_pid);
    // The parent may have died before the request above.
    parent.check()?;
    let strategy = WaitStrategy {
        spin: Duration::from_micros(a.spin_us),
    };
    match (a.kind, a.role) {
        (PeerKind::IpcPair | PeerKind::IpcChain, _) => {
            let route = Route::of(a.kind, a.role).ok_or_else(|| {
                anyhow!(
                    "bench-peer: no role `{}` in `{}`",
                    a.role.name(),
                    a.kind.name()
                )
            })?;
            let prefix = a
                .prefix
                .as_deref()
                .context("bench-peer: --prefix is required")?;
            ipc_peer(prefix, a.role, route, strategy, &parent)
        }
        (PeerKind::UdsPair, PeerRole::Pong) => {
            let dir = a.dir.as_deref().context("bench-peer: --dir is required")?;
            uds_peer(dir, strategy, &parent)
        }
        (k, r) => bail!("bench-peer: no role `{}` in `{}`", r.name(), k.name()),
    }
}

/// A peer with no message for this long gives up (the parent stalls far shorter than this).
pub const PEER_IDLE_TIMEOUT: Duration = Duration::from_secs(30);
/// How long the peers may take to connect.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(20);
/// How long a round trip may take before the run is declared stalled.
const STALL_TIMEOUT: Duration = Duration::from_secs(10);
/// How long the peers may take to exit after the stop message.
const EXIT_TIMEOUT: Duration = Duration::from_secs(5);
/// Resend period of the connection probe.
const PROBE_PERIOD: Duration = Duration::from_millis(20);

/// Sequence number of the stop message; peers relay it, then exit.
const STOP: u64 = u64::MAX;
/// Sequence number of the Unix-socket peer's greeting.
const HELLO: u64 = u64::MAX - 1;
/// Connection probes: this bit plus the attempt number.
const PROBE: u64 = 1 << 62;

/// One agent, in-flight batch of one: every service the floor opens fits.
const SIZING: Sizing = Sizing::new(1, 1);

/// Bytes of one message.
const PAYLOAD_BYTES: usize = std::mem::size_of::<MeasurementMsg>();

/// Highest latency the histograms track, ns (larger values are recorded as this).
const HIGHEST_NS: u64 = 60_000_000_000;

/// What a peer process of the floor measures with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PeerKind {
    IpcPair,
    IpcChain,
    UdsPair,
}

impl PeerKind {
    pub const ALL: [Self; 3] = [Self::IpcPair, Self::IpcChain, Self::UdsPair];

    pub fn name(self) -> &'static str {
        match self {
            Self::IpcPair => "ipc-pair",
            Self::IpcChain => "ipc-chain",
            Self::UdsPair => "uds-pair",
        }
    }
}

/// Which process of its case a peer is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PeerRole {
    Pong,
    Attacker,
    Center,
}

impl PeerRole {
    pub const ALL: [Self; 3] = [Self::Pong, Self::Attacker, Self::Center];

    pub fn name(self) -> &'static str {
        match self {
            Self::Pong => "pong",
            Self::Attacker => "attacker",
            Self::Center => "center",
        }
    }
}

/// What a peer process does: the arguments of `bench-peer` ([`PeerSpec::to_args`]), which the
/// command line parses back into this.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PeerSpec {
    pub kind: PeerKind,
    pub role: PeerRole,
    /// iceoryx2 run prefix (ipc kinds).
    pub prefix: Option<String>,
    /// Folder of the sockets (uds-pair).
    pub dir: Option<PathBuf>,
    /// Spin budget of the wait strategy, µs.
    pub spin_us: u64,
    /// Stop when this process is no longer the parent.
    pub parent_pid: Option<u32>,
}

impl PeerSpec {
    /// The arguments after `bench-peer`: `KIND ROLE [--prefix P] [--dir D] --spin-us N
    /// [--parent-pid PID]`.
    pub fn to_args(&self) -> Vec<String> {
        let mut out = vec![self.kind.name().to_string(), self.role.name().to_string()];
        if let Some(p) = &self.prefix {
            out.extend(["--prefix".into(), p.clone()]);
        }
        if let Some(d) = &self.dir {
            out.extend(["--dir".into(), d.display().to_string()]);
        }
        out.extend(["--spin-us".into(), self.spin_us.to_string()]);
        if let Some(pid) = self.parent_pid {
            out.extend(["--parent-pid".into(), pid.to_string()]);
        }
        out
    }
}

/// Where one iceoryx2 process reads, writes and wakes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Route {
    input: Stream,
    output: Stream,
    /// This process's wake-up event.
    own: Wake,
    /// The next process's wake-up event.
    next: Wake,
}

impl Route {
    /// The initiator (this process, in the agent's place).
    fn initiator(kind: PeerKind) -> Self {
        Self {
            input: if kind == PeerKind::IpcChain {
                Stream::Torque(1)
            } else {
                Stream::Tampered
            },
            output: Stream::Measurement,
            own: Wake::Agent(1),
            next: Wake::Attacker,
        }
    }

    fn of(kind: PeerKind, role: PeerRole) -> Option<Self> {
        match (kind, role) {
            (PeerKind::IpcPair, PeerRole::Pong) => Some(Self {
                input: Stream::Measurement,
                output: Stream::Tampered,
                own: Wake::Attacker,
                next: Wake::Agent(1),
            }),
            (PeerKind::IpcChain, PeerRole::Attacker) => Some(Self {
                input: Stream::Measurement,
                output: Stream::Tampered,
                own: Wake::Attacker,
                next: Wake::Center,
            }),
            (PeerKind::IpcChain, PeerRole::Center) => Some(Self {
                input: Stream::Tampered,
                output: Stream::Torque(1),
                own: Wake::Center,
                next: Wake::Agent(1),
            }),
            _ => None,
        }
    }
}

/// A message of the runtime's measurement size.
fn payload(seq: u64) -> MeasurementMsg {
    MeasurementMsg {
        seq,
        agent: 1,
        dof: 2,
        t: 0.0,
        y: [0.0; MAX_DOF],
        yd: [0.0; MAX_DOF],
        agent_sent_ns: monotonic_ns(),
        attacker_received_ns: 0,
        attacker_sent_ns: 0,
        flags: 0,
        reserved: 0,
    }
}

/// Per-hop latency histogram of one case.
#[derive(Debug)]
struct HopRecorder {
    hist: Histogram<u64>,
    hops: u32,
}

impl HopRecorder {
    fn new(hops: u32) -> Result<Self> {
        Ok(Self {
            hist: Histogram::new_with_bounds(1, HIGHEST_NS, 3).context("creating a histogram")?,
            hops: hops.max(1),
        })
    }

    /// Records one round trip of `round_trip_ns` as `round_trip_ns / hops`.
    fn record(&mut self, round_trip_ns: u64) {
        self.hist
            .saturating_record((round_trip_ns / u64::from(self.hops)).max(1));
    }

    fn count(&self) -> u64 {
        self.hist.len()
    }

    fn summary(&self) -> HopLatency {
        let us = |ns: u64| ns as f64 / 1_000.0;
        let q = |quantile: f64| us(self.hist.value_at_quantile(quantile));
        HopLatency {
            p50_us: q(0.50),
            p90_us: q(0.90),
            p99_us: q(0.99),
            p999_us: q(0.999),
            max_us: us(self.hist.max()),
            mean_us: self.hist.mean() / 1_000.0,
        }
    }
}

/// A spin budget in whole µs (saturating).
fn spin_us(spin: Duration) -> u64 {
    u64::try_from(spin.as_micros()).unwrap_or(u64::MAX)
}

/// How peers are started: a command running `bench-peer` with `args`.
type PeerCommand<'a> = &'a dyn Fn(&[String]) -> Result<Command>;

fn self_command(args: &[String]) -> Result<Command> {
    let me = std::env::current_exe().context("locating the executable")?;
    let mut c = Command::new(me);
    c.arg("bench-peer").args(args);
    Ok(c)
}

fn run_floor_with(opts: &FloorOptions, peer: PeerCommand<'_>) -> Result<FloorResult> {
    if opts.iterations == 0 {
        bail!("the transport floor needs at least one iteration");
    }
    let ipc_ping_pong = ipc_case(opts, PeerKind::IpcPair, peer).context("iceoryx2 ping-pong")?;
    let ipc_chain = ipc_case(opts, PeerKind::IpcChain, peer).context("iceoryx2 3-hop chain")?;
    let uds_ping_pong = uds_case(opts, peer).context("Unix datagram ping-pong")?;
    Ok(FloorResult {
        iterations: opts.iterations,
        warmup: opts.warmup,
        spin_us: spin_us(opts.spin),
        payload_bytes: PAYLOAD_BYTES,
        ipc_ping_pong,
        ipc_chain,
        uds_ping_pong,
    })
}

/// A fresh run prefix in the launcher's format, so that the launcher's reaping of dead runs
/// also covers a floor whose process was killed.
fn new_prefix() -> String {
    fdi_runtime::ipc::RunPrefix::fresh().to_string()
}

/// Removes a run prefix's resources when dropped (declare it before anything that opens them).
struct PrefixCleanup(String);

impl Drop for PrefixCleanup {
    fn drop(&mut self) {
        if let Err(e) = Shm::remove_leftovers(&self.0) {
            log::warn!("cleaning up run prefix {}: {e}", self.0);
        }
    }
}

/// The peers of one case, under the launcher's supervisor: any still running when dropped are
/// killed.
#[derive(Default)]
struct Peers(Supervisor<()>);

impl Peers {
    fn spawn(&mut self, peer: PeerCommand<'_>, args: &[String]) -> Result<()> {
        let label = args.iter().take(2).cloned().collect::<Vec<_>>().join(" ");
        self.0.spawn(format!("the peer `{label}`"), (), peer(args)?)
    }

    /// Fails when a peer has ended.
    fn check_alive(&mut self) -> Result<()> {
        self.0.reap();
        for c in self.0.iter_mut() {
            if let Some(st) = c.status {
                bail!("{} before the end", c.ended(st));
            }
        }
        Ok(())
    }

    /// While message `i`, sent at `sent`, has not come back: fails when a peer has ended or
    /// the message is overdue.
    fn check_waiting(&mut self, i: u64, sent: Instant) -> Result<()> {
        self.check_alive()?;
        if sent.elapsed() > STALL_TIMEOUT {
            bail!("message {i} did not come back within {STALL_TIMEOUT:?}");
        }
        Ok(())
    }

    /// Waits for every peer to exit, successfully, within `timeout`.
    fn finish(&mut self, timeout: Duration) -> Result<()> {
        self.0.wait_all(timeout)
    }
}

/// In a peer: fails once the process that started it is gone.
struct ParentWatch(Option<u32>);

impl ParentWatch {
    fn check(&self) -> Result<()> {
        if let Some(pid) = self.0 {
            let parent = rustix::process::getppid().map(|p| p.as_raw_nonzero().get());
            if parent != i32::try_from(pid).ok() {
                bail!("bench-peer: the parent process {pid} is gone");
            }
        }
        Ok(())
    }
}

/// One process's ports on the ring.
struct IpcPorts<X: Transport> {
    inbox: X::Inbox<MeasurementMsg>,
    outbox: X::Outbox<MeasurementMsg>,
    bell: X::Bell,
    waker: X::Waker,
}

impl<X: Transport> IpcPorts<X> {
    /// Opens the ports of `route`; the waker first, so no ring for a message this process can
    /// receive goes unheard.
    fn open(transport: &X, route: Route) -> Result<Self> {
        let waker = transport.waker(route.own)?;
        let inbox = transport.subscriber(route.input)?;
        let outbox = transport.publisher(route.output)?;
        let bell = transport.notifier(route.next)?;
        Ok(Self {
            inbox,
            outbox,
            bell,
            waker,
        })
    }

    fn send(&self, m: MeasurementMsg) -> Result<()> {
        self.outbox.send(m)?;
        self.bell.ring()?;
        Ok(())
    }

    /// True when a message `seq` was among those waiting (the others are dropped).
    fn take(&self, seq: u64) -> Result<bool> {
        let mut got = false;
        self.inbox.drain(|m| got |= m.seq == seq)?;
        Ok(got)
    }
}

fn ipc_case(opts: &FloorOptions, kind: PeerKind, peer: PeerCommand<'_>) -> Result<FloorCase> {
    let (roles, transport_name): (&[PeerRole], _) = match (kind, opts.pace) {
        (PeerKind::IpcChain, None) => (
            &[PeerRole::Attacker, PeerRole::Center],
            "iceoryx2 3-hop chain",
        ),
        (PeerKind::IpcChain, Some(_)) => (
            &[PeerRole::Attacker, PeerRole::Center],
            "iceoryx2 3-hop chain, one round trip per period",
        ),
        _ => (&[PeerRole::Pong], "iceoryx2 ping-pong"),
    };
    let hops = u32::try_from(roles.len() + 1).unwrap_or(u32::MAX);
    let prefix = new_prefix();
    let _cleanup = PrefixCleanup(prefix.clone());
    let mut rec = HopRecorder::new(hops)?;
    let strategy = WaitStrategy { spin: opts.spin };
    {
        let transport = Shm::open(&prefix, "floor", SIZING)?;
        let ports = IpcPorts::open(&transport, Route::initiator(kind))?;
        let mut peers = Peers::default();
        for role in roles {
            let spec = PeerSpec {
                kind,
                role: *role,
                prefix: Some(prefix.clone()),
                dir: None,
                spin_us: spin_us(opts.spin),
                parent_pid: Some(std::process::id()),
            };
            peers.spawn(peer, &spec.to_args())?;
        }
        ipc_connect(&ports, &mut peers)?;
        let paced_from = monotonic_ns();
        for i in 0..opts.warmup + opts.iterations {
            if let Some(period) = opts.pace {
                let due = paced_from + (i + 1) * u64::try_from(period.as_nanos()).unwrap_or(0);
                fdi_runtime::ipc::sleep_until_ns(due);
            }
            let t0 = monotonic_ns();
            ports.send(payload(i))?;
            // As the agent waits for its torque: wait on the event, then look.
            let began = Instant::now();
            loop {
                let rung = strategy.wait(&ports.waker, &ports.inbox)?;
                if ports.take(i)? {
                    break;
                }
                if !rung {
                    peers.check_waiting(i, began)?;
                }
            }
            let rtt = monotonic_ns().saturating_sub(t0);
            if i >= opts.warmup {
                rec.record(rtt);
            }
        }
        ports.send(payload(STOP))?;
        peers.finish(EXIT_TIMEOUT)?;
    }
    debug_assert_eq!(rec.count(), opts.iterations);
    Ok(FloorCase {
        transport: transport_name,
        processes: hops,
        hops,
        per_hop: rec.summary(),
    })
}

/// Sends probes around the ring until one comes back: then every port is connected.
fn ipc_connect<X: Transport>(ports: &IpcPorts<X>, peers: &mut Peers) -> Result<()> {
    let began = Instant::now();
    let mut attempt = 0;
    loop {
        let seq = PROBE | attempt;
        attempt += 1;
        ports.send(payload(seq))?;
        let sent = Instant::now();
        while sent.elapsed() < PROBE_PERIOD {
            ports.waker.wait(Duration::from_millis(5))?;
            if ports.take(seq)? {
                return Ok(());
            }
        }
        peers.check_alive()?;
        if began.elapsed() > CONNECT_TIMEOUT {
            bail!("the peers did not connect within {CONNECT_TIMEOUT:?}");
        }
    }
}

/// A relay: takes every message of `route.input`, publishes it on `route.output`, rings the next
/// process; the loop of the runtime's attacker.
fn ipc_peer(
    prefix: &str,
    role: PeerRole,
    route: Route,
    strategy: WaitStrategy,
    parent: &ParentWatch,
) -> Result<()> {
    let transport = Shm::open(prefix, &format!("floor-{}", role.name()), SIZING)?;
    let ports = IpcPorts::open(&transport, route)?;
    let mut last = Instant::now();
    loop {
        let (mut relayed, mut stop, mut failure) = (0u64, false, None);
        ports.inbox.drain(|m| {
            if let Err(e) = ports.outbox.send(m) {
                failure.get_or_insert(e);
            }
            relayed += 1;
            stop |= m.seq == STOP;
        })?;
        if let Some(e) = failure {
            return Err(e.into());
        }
        if relayed > 0 {
            ports.bell.ring()?;
            last = Instant::now();
        }
        if stop {
            return Ok(());
        }
        if !strategy.wait(&ports.waker, &ports.inbox)? {
            parent.check()?;
            if last.elapsed() > PEER_IDLE_TIMEOUT {
                bail!("bench-peer: nothing arrived for {PEER_IDLE_TIMEOUT:?}");
            }
        }
    }
}

fn write_seq(buf: &mut [u8; PAYLOAD_BYTES], seq: u64) {
    buf[..8].copy_from_slice(&seq.to_le_bytes());
}

fn read_seq(buf: &[u8]) -> Option<u64> {
    Some(u64::from_le_bytes(buf.get(..8)?.try_into().ok()?))
}

/// Receives on a Unix datagram socket with the runtime's wait strategy: non-blocking receives
/// with `sched_yield` between them for the spin budget, then a blocking receive of at most
/// [`WAIT_SLICE`] (the socket's receive timeout). Switches the socket's mode only when needed.
struct UdsReceiver<'a> {
    sock: &'a UnixDatagram,
    spin: Duration,
    nonblocking: bool,
}

impl<'a> UdsReceiver<'a> {
    fn new(sock: &'a UnixDatagram, spin: Duration) -> io::Result<Self> {
        sock.set_read_timeout(Some(WAIT_SLICE))?;
        sock.set_nonblocking(false)?;
        Ok(Self {
            sock,
            spin,
            nonblocking: false,
        })
    }

    fn set_nonblocking(&mut self, on: bool) -> io::Result<()> {
        if self.nonblocking != on {
            self.sock.set_nonblocking(on)?;
            self.nonblocking = on;
        }
        Ok(())
    }

    /// A datagram's length, or `None` after the wait slice passed without one.
    fn recv(&mut self, buf: &mut [u8]) -> io::Result<Option<usize>> {
        if !self.spin.is_zero() {
            self.set_nonblocking(true)?;
            let began = Instant::now();
            while began.elapsed() < self.spin {
                match self.sock.recv(buf) {
                    Ok(n) => return Ok(Some(n)),
                    Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                    Err(e) => return Err(e),
                }
                std::thread::yield_now();
            }
            self.set_nonblocking(false)?;
        }
        match self.sock.recv(buf) {
            Ok(n) => Ok(Some(n)),
            Err(e) if nothing_yet(&e) => Ok(None),
            Err(e) => Err(e),
        }
    }
}

/// A receive that found nothing (yet): timed out, would block, or was interrupted.
fn nothing_yet(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
    )
}

fn uds_case(opts: &FloorOptions, peer: PeerCommand<'_>) -> Result<FloorCase> {
    let dir = tempfile::Builder::new()
        .prefix("fdi-floor-")
        .tempdir()
        .context("creating a temporary folder for the sockets")?;
    let (a, b) = (dir.path().join("a.sock"), dir.path().join("b.sock"));
    let mut rec = HopRecorder::new(2)?;
    let sock = UnixDatagram::bind(&a).with_context(|| format!("binding {}", a.display()))?;
    let mut peers = Peers::default();
    let spec = PeerSpec {
        kind: PeerKind::UdsPair,
        role: PeerRole::Pong,
        prefix: None,
        dir: Some(dir.path().to_path_buf()),
        spin_us: spin_us(opts.spin),
        parent_pid: Some(std::process::id()),
    };
    peers.spawn(peer, &spec.to_args())?;
    let mut buf = [0u8; PAYLOAD_BYTES];
    // The peer greets once its socket is bound; it is connected to ours already.
    {
        sock.set_read_timeout(Some(WAIT_SLICE))?;
        let began = Instant::now();
        loop {
            match sock.recv(&mut buf) {
                Ok(n) if read_seq(&buf[..n]) == Some(HELLO) => break,
                Ok(_) => {}
                Err(e) if nothing_yet(&e) => {
                    peers.check_alive()?;
                    if began.elapsed() > CONNECT_TIMEOUT {
                        bail!("the peer did not connect within {CONNECT_TIMEOUT:?}");
                    }
                }
                Err(e) => return Err(e).context("receiving the peer's greeting"),
            }
        }
    }
    sock.connect(&b)
        .with_context(|| format!("connecting to {}", b.display()))?;
    let mut rx = UdsReceiver::new(&sock, opts.spin)?;
    let mut out = [0u8; PAYLOAD_BYTES];
    for i in 0..opts.warmup + opts.iterations {
        let t0 = monotonic_ns();
        write_seq(&mut out, i);
        sock.send(&out).context("sending")?;
        let began = Instant::now();
        loop {
            match rx.recv(&mut buf).context("receiving")? {
                Some(n) if read_seq(&buf[..n]) == Some(i) => break,
                Some(_) => {}
                None => peers.check_waiting(i, began)?,
            }
        }
        let rtt = monotonic_ns().saturating_sub(t0);
        if i >= opts.warmup {
            rec.record(rtt);
        }
    }
    rx.set_nonblocking(false)?;
    write_seq(&mut out, STOP);
    sock.send(&out).context("sending the stop")?;
    peers.finish(EXIT_TIMEOUT)?;
    Ok(FloorCase {
        transport: "Unix datagram ping-pong",
        processes: 2,
        hops: 2,
        per_hop: rec.summary(),
    })
}

/// The Unix-socket echo: binds `dir/b.sock`, greets `dir/a.sock`, echoes every datagram back.
fn uds_peer(dir: &Path, strategy: WaitStrategy, parent: &ParentWatch) -> Result<()> {
    let (a, b) = (dir.join("a.sock"), dir.join("b.sock"));
    let sock = UnixDatagram::bind(&b).with_context(|| format!("binding {}", b.display()))?;
    sock.connect(&a)
        .with_context(|| format!("connecting to {}", a.display()))?;
    let mut buf = [0u8; PAYLOAD_BYTES];
    write_seq(&mut buf, HELLO);
    sock.send(&buf).context("greeting")?;
    let mut rx = UdsReceiver::new(&sock, strategy.spin)?;
    let mut last = Instant::now();
    loop {
        match rx.recv(&mut buf).context("receiving")? {
            Some(n) => {
                // A send on the non-blocking socket cannot find the one-deep queue full.
                sock.send(&buf[..n]).context("echoing")?;
                last = Instant::now();
                if read_seq(&buf[..n]) == Some(STOP) {
                    return Ok(());
                }
            }
            None => {
                parent.check()?;
                if last.elapsed() > PEER_IDLE_TIMEOUT {
                    bail!("bench-peer: nothing arrived for {PEER_IDLE_TIMEOUT:?}");
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn per_hop_percentiles_divide_the_round_trip_by_the_hops() {
        let mut rec = HopRecorder::new(2).expect("histogram");
        // Round trips of 2..=2000 µs: per hop 1..=1000 µs, uniformly.
        for us in 1..=1000u64 {
            rec.record(2 * us * 1_000);
        }
        assert_eq!(rec.count(), 1000);
        let h = rec.summary();
        // Three significant digits: within 0.1 % (plus the bucket's upper edge).
        let near = |got: f64, want: f64| (got - want).abs() <= want * 0.002 + 0.001;
        assert!(near(h.p50_us, 500.0), "{h:?}");
        assert!(near(h.p90_us, 900.0), "{h:?}");
        assert!(near(h.p99_us, 990.0), "{h:?}");
        assert!(near(h.p999_us, 999.0), "{h:?}");
        assert!(near(h.max_us, 1000.0), "{h:?}");
        assert!(near(h.mean_us, 500.5), "{h:?}");
        assert!(
            h.p50_us <= h.p90_us
                && h.p90_us <= h.p99_us
                && h.p99_us <= h.p999_us
                && h.p999_us <= h.max_us
        );
    }

    #[test]
    fn the_histogram_keeps_extremes_instead_of_failing() {
        let mut rec = HopRecorder::new(3).expect("histogram");
        rec.record(0); // below the lowest trackable value: counted as 1 ns
        rec.record(u64::MAX); // above the highest: counted as the highest
        assert_eq!(rec.count(), 2);
        let h = rec.summary();
        assert!(h.p50_us > 0.0);
        assert!(h.max_us >= HIGHEST_NS as f64 / 1_000.0 * 0.999, "{h:?}");
    }

    #[test]
    fn peer_routes_close_their_rings() {
        // The ring closes: each process's output is the next one's input, and it wakes that one.
        let ring = [
            Route::initiator(PeerKind::IpcChain),
            Route::of(PeerKind::IpcChain, PeerRole::Attacker).expect("attacker"),
            Route::of(PeerKind::IpcChain, PeerRole::Center).expect("center"),
        ];
        for (i, r) in ring.iter().enumerate() {
            let next = &ring[(i + 1) % ring.len()];
            assert_eq!(r.output, next.input);
            assert_eq!(r.next, next.own);
        }
        let pair = [
            Route::initiator(PeerKind::IpcPair),
            Route::of(PeerKind::IpcPair, PeerRole::Pong).expect("pong"),
        ];
        assert_eq!((pair[0].output, pair[0].next), (pair[1].input, pair[1].own));
        assert_eq!((pair[1].output, pair[1].next), (pair[0].input, pair[0].own));
        assert!(Route::of(PeerKind::IpcPair, PeerRole::Center).is_none());
        // A role its kind has not is refused.
        assert!(peer_main(&PeerSpec {
            kind: PeerKind::IpcPair,
            role: PeerRole::Center,
            prefix: Some("p_".into()),
            dir: None,
            spin_us: 0,
            parent_pid: None,
        })
        .is_err());
    }

    #[test]
    fn payload_is_the_runtime_measurement() {
        assert_eq!(PAYLOAD_BYTES, std::mem::size_of::<MeasurementMsg>());
        let mut b = [0u8; PAYLOAD_BYTES];
        write_seq(&mut b, 0x0102_0304_0506_0708);
        assert_eq!(read_seq(&b), Some(0x0102_0304_0506_0708));
        assert_eq!(read_seq(&b[..7]), None);
    }
}
