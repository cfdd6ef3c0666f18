//! fdi-live: a run watched while it runs (`fdi-launch run --live`). The run's records are
//! served over the Foxglove WebSocket protocol by the `foxglove` crate's server, on the topics,
//! encodings and schemas of the MCAP export ([`fdi_report::topics`]: one definition for both),
//! stamped with the simulated time of their tick, which the server also broadcasts so that a
//! viewer's timeline follows the run.
//!
//! The run never waits for it. The joined ticks (from the launcher's join of the traces, or from
//! the in-process engine when it keeps less than whole traces) go through a bounded queue
//! ([`Feed`]) to a thread of its own that makes the messages; a record that finds the queue full
//! is dropped and counted. The stream is decimated to what a viewer can draw (about
//! [`Options::rate_hz`] ticks a second of wall time; [`Decimation`]). A message is made only for
//! a channel some client subscribed to. Viewers connect to the server's [`door`], which relays
//! each to the SDK's server on loopback under any name of the protocol, and keeps a bounded
//! outbox per client whose oldest messages a slow client loses, counted. Its threads run at the
//! least priority ([`yield_to_the_run`]).

pub mod door;
pub mod layout;

use std::collections::BTreeMap;
use std::net::{Ipv4Addr, SocketAddr};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{bail, Context as _, Result};
use fdi_common::engine::{tick_time, LiveStats};
use fdi_common::records::TickRecord;
use fdi_common::scenario::Resolved;
use fdi_common::stop::Stop;
use fdi_common::trace::TraceRecord;
use fdi_report::topics::{self, detectors, json_schema, topic_name, RunInfo, Schema, Sink};
use foxglove::websocket::{Capability, Client, ServerListener};
use foxglove::{ChannelBuilder, Context, PartialMetadata, RawChannel, WebSocketServer};
use serde_json::Value;

/// How a run is served live.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    /// Where the server listens.
    pub addr: SocketAddr,
    /// Ticks published per second of wall time, at most.
    pub rate_hz: f64,
    /// The run's ticks per second of wall time when the run is paced (a lockstep run at
    /// `--pace`, a realtime run): the stream then keeps every K-th tick, K fixed. `None`: an
    /// unpaced lockstep run ([`Decimation::Adaptive`]).
    pub ticks_per_s: Option<f64>,
    /// The run's processes stamp each torque's hops (`/agent<id>/latency`).
    pub stamped: bool,
}

impl Options {
    /// The address `--live` serves without one.
    pub const DEFAULT_ADDR: &'static str = "127.0.0.1:8765";
    /// Ticks a second the stream keeps at most, by default (`--live-rate`): a plot in Foxglove or
    /// PlotJuggler redraws at most 60 times a second; 50 ticks of the paper's four robots are
    /// about 2600 messages a second.
    pub const DEFAULT_RATE_HZ: f64 = 50.0;
}

/// Which ticks the stream keeps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Decimation {
    /// Ticks 0, K, 2K, … (a run of known pace).
    Every(u64),
    /// An unpaced run: every K-th tick, K measured again every [`WINDOW`] from the ticks the run
    /// made meanwhile so that about `rate_hz` are kept a second.
    Adaptive { rate_hz: f64 },
}

/// How often an unpaced run's K is measured again.
pub const WINDOW: Duration = Duration::from_millis(500);
/// The longest burst of kept ticks: `rate_hz` × this, at most [`MAX_BURST`], whatever the
/// decimation. The records come in bursts as the trace writers flush (a file every 64 KiB: up to
/// a second of a paced run's ticks at once), and all at once to a viewer that joins a run late;
/// each kept tick is also a time message, and the server disconnects a client whose 1024 control
/// messages wait.
pub const BURST: Duration = Duration::from_secs(5);
/// The most ticks kept at once.
pub const MAX_BURST: f64 = 500.0;

impl Decimation {
    /// The decimation of `opts`.
    pub fn of(opts: &Options) -> Self {
        match opts.ticks_per_s {
            Some(rate) => Self::Every(((rate / opts.rate_hz).ceil() as u64).max(1)),
            None => Self::Adaptive {
                rate_hz: opts.rate_hz,
            },
        }
    }
}

/// Which ticks a stream keeps, decided as the run hands them over: every K-th
/// ([`Decimation`]), and never more than `rate_hz` a second over [`BURST`] (a token bucket).
#[derive(Debug, Clone)]
struct Gate {
    decimation: Decimation,
    rate_hz: f64,
    /// The tick last judged, and whether it is kept.
    last: Option<(u64, bool)>,
    /// [`Decimation::Adaptive`]: K and the window it is measured over (its start and first tick).
    every: u64,
    window: Option<(Instant, u64)>,
    /// The ticks that may still be kept, and when they were last counted.
    tokens: f64,
    refilled: Option<Instant>,
}

impl Gate {
    fn new(decimation: Decimation, rate_hz: f64) -> Self {
        let every = match decimation {
            Decimation::Every(k) => k,
            Decimation::Adaptive { .. } => 1,
        };
        Self {
            decimation,
            rate_hz,
            last: None,
            every,
            window: None,
            tokens: Self::cap(rate_hz),
            refilled: None,
        }
    }

    fn cap(rate_hz: f64) -> f64 {
        (rate_hz * BURST.as_secs_f64()).clamp(1.0, MAX_BURST)
    }

    /// Whether tick `k` is kept (every record of a tick is judged alike).
    fn keeps(&mut self, k: u64) -> bool {
        if let Some((last, keep)) = self.last {
            if last == k {
                return keep;
            }
        }
        let now = Instant::now();
        if let Decimation::Adaptive { rate_hz } = self.decimation {
            self.measure(k, rate_hz, now);
        }
        if let Some(t) = self.refilled {
            let more = now.duration_since(t).as_secs_f64() * self.rate_hz;
            self.tokens = (self.tokens + more).min(Self::cap(self.rate_hz));
        }
        self.refilled = Some(now);
        let keep = k.is_multiple_of(self.every) && self.tokens >= 1.0;
        if keep {
            self.tokens -= 1.0;
        }
        self.last = Some((k, keep));
        keep
    }

    /// K of an unpaced run, from the ticks it made over the last [`WINDOW`].
    fn measure(&mut self, k: u64, rate_hz: f64, now: Instant) {
        match self.window {
            Some((t0, k0)) if now.duration_since(t0) >= WINDOW => {
                let ticks_per_s =
                    k.saturating_sub(k0) as f64 / now.duration_since(t0).as_secs_f64();
                self.every = ((ticks_per_s / rate_hz).ceil() as u64).max(1);
                self.window = Some((now, k));
            }
            Some(_) => {}
            None => self.window = Some((now, k)),
        }
    }
}

/// What goes to the server's thread.
enum Item {
    /// Joined ticks, each with whether the stream keeps it.
    Ticks(Vec<(TickRecord, bool)>),
    /// An event or latency record of a process's trace (named by its file stem).
    Record(String, Box<TraceRecord>),
}

/// How long a viewer's subscriptions must rest before [`Live::wait_for_viewer`] lets the run
/// start.
pub const SETTLED: Duration = Duration::from_millis(300);

/// How long the server stays up after the run's last message while clients are connected: what
/// their queues hold is sent meanwhile (the server drops it when it stops).
pub const LINGER: Duration = Duration::from_secs(3);
/// How long the door then has to send its clients what their outboxes hold and close them.
pub const CLOSING: Duration = Duration::from_millis(500);

/// Records per batch handed to the server's thread.
const BATCH: usize = 256;
/// Batches that may wait: 65 536 records, 16 384 ticks of the paper's four robots (16 s in
/// realtime).
const QUEUED: usize = 256;
/// A batch is handed over with the first record that comes this long after its first (or when
/// it is full, or at the end).
const LATENCY: Duration = Duration::from_millis(20);

/// The run's side of the queue: hands records to the server's thread, never waits.
pub struct Feed {
    tx: SyncSender<Item>,
    gate: Gate,
    batch: Vec<(TickRecord, bool)>,
    since: Instant,
    /// Joined ticks' records dropped; events and latency stamps dropped.
    dropped: Arc<AtomicU64>,
    events_dropped: Arc<AtomicU64>,
}

impl Feed {
    /// The joined tick `r` (in the join's order: tick, then robot).
    pub fn tick(&mut self, r: &TickRecord) {
        if self.batch.is_empty() {
            self.since = Instant::now();
        }
        let kept = self.gate.keeps(r.center.k);
        self.batch.push((*r, kept));
        if self.batch.len() >= BATCH || self.since.elapsed() >= LATENCY {
            self.flush();
        }
    }

    /// Hands over the records held back.
    pub fn flush(&mut self) {
        if self.batch.is_empty() {
            return;
        }
        let batch = std::mem::replace(&mut self.batch, Vec::with_capacity(BATCH));
        let n = batch.len() as u64;
        if let Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) =
            self.tx.try_send(Item::Ticks(batch))
        {
            self.dropped.fetch_add(n, Ordering::Relaxed);
        }
    }

    /// A second feed for the records of processes (events, latency stamps).
    pub fn records(&self) -> RecordFeed {
        RecordFeed {
            tx: self.tx.clone(),
            gate: Gate::new(self.gate.decimation, self.gate.rate_hz),
            dropped: self.events_dropped.clone(),
        }
    }
}

impl Drop for Feed {
    fn drop(&mut self) {
        self.flush();
    }
}

/// The events and latency stamps of one process's trace (a clone per process: the latency
/// stamps of each agent are decimated as its ticks are).
#[derive(Clone)]
pub struct RecordFeed {
    tx: SyncSender<Item>,
    gate: Gate,
    dropped: Arc<AtomicU64>,
}

impl RecordFeed {
    /// `rec` of the trace `stem` (`agent-3`, `control-center`, …); records other than events
    /// and latency stamps are the joined ticks' ([`Feed::tick`]) and ignored here.
    pub fn record(&mut self, stem: &str, rec: &TraceRecord) {
        match rec {
            TraceRecord::Event { .. } => {}
            TraceRecord::Latency { k, .. } if self.gate.keeps(*k) => {}
            _ => return,
        }
        if self
            .tx
            .try_send(Item::Record(stem.to_string(), Box::new(rec.clone())))
            .is_err()
        {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// Counts kept by the server's listener.
#[derive(Default)]
struct Clients {
    connected: AtomicU64,
    /// Subscriptions made so far, waited for by [`Live::wait_for_viewer`].
    subscribed: Mutex<u64>,
    changed: Condvar,
}

impl ServerListener for Clients {
    fn on_client_connect(&self) {
        self.connected.fetch_add(1, Ordering::Relaxed);
    }

    fn on_subscribe(&self, _client: Client, _channel: foxglove::websocket::ChannelView) {
        let mut n = self
            .subscribed
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        *n += 1;
        self.changed.notify_all();
    }
}

/// Puts the calling thread (and the threads it starts) under SCHED_IDLE
/// ([`fdi_runtime::process::use_idle`]): the live view's threads give way to the run's
/// processes and the launcher's own. Best effort: a system that refuses leaves the thread as it
/// was.
pub fn yield_to_the_run() {
    let _ = fdi_runtime::process::use_idle();
}

/// Whether a viewer of a live server subscribed to a topic.
#[derive(Clone)]
pub struct Watcher(Arc<Clients>);

impl Watcher {
    /// Waits until a viewer subscribed to a topic (at any time since the start), at most
    /// `timeout`; whether one did.
    pub fn wait(&self, timeout: Duration) -> bool {
        let n = self
            .0
            .subscribed
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        let (n, _) = self
            .0
            .changed
            .wait_timeout_while(n, timeout, |n| *n == 0)
            .unwrap_or_else(PoisonError::into_inner);
        *n > 0
    }
}

/// The channels of a run of `resolved` in `ctx`: every topic it has, advertised from the start.
fn channels(
    resolved: &Resolved,
    opts: &Options,
    ctx: &Arc<Context>,
) -> Result<BTreeMap<(u32, &'static str), Arc<RawChannel>>> {
    let mut channels = BTreeMap::new();
    for (agent, name, schema) in topics::run_topics(resolved, opts.stamped) {
        let text = serde_json::to_vec(&json_schema(schema)).context("a schema")?;
        let topic = topic_name(agent, name);
        let c = ChannelBuilder::new(topic.as_str())
            .message_encoding("json")
            .schema(foxglove::Schema::new(schema.name, "jsonschema", text))
            .context(ctx)
            .build_raw()
            .with_context(|| format!("the live channel {topic}"))?;
        channels.insert((agent, name), c);
    }
    Ok(channels)
}

/// A running live server.
pub struct Live {
    addr: SocketAddr,
    clients: Arc<Clients>,
    door: Arc<door::Counts>,
    thread: JoinHandle<Published>,
    dropped: Arc<AtomicU64>,
    events_dropped: Arc<AtomicU64>,
}

impl std::fmt::Debug for Live {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Live").field("addr", &self.addr).finish()
    }
}

/// What the server's thread did.
#[derive(Debug, Default)]
struct Published {
    ticks: u64,
    messages: u64,
    error: Option<String>,
}

impl Live {
    /// Starts the server of a run of `resolved` at `opts.addr`, its channels advertised, and
    /// its thread; the feed the run hands its records to.
    pub fn start(resolved: &Resolved, opts: &Options) -> Result<(Self, Feed)> {
        if !(opts.rate_hz.is_finite() && opts.rate_hz > 0.0) {
            bail!(
                "--live-rate {}: a rate of ticks a second, > 0",
                opts.rate_hz
            );
        }
        let ctx = Context::new();
        let channels = channels(resolved, opts, &ctx)?;
        let clients = Arc::new(Clients::default());
        // The SDK's server listens on loopback; viewers connect to the door (module `door`).
        let server = WebSocketServer::new()
            .name(format!("fdi-mas {}", resolved.scenario.name))
            .bind(Ipv4Addr::LOCALHOST.to_string(), 0)
            .capabilities([Capability::Time])
            .message_backlog_size(door::UPSTREAM_BACKLOG)
            .listener(clients.clone())
            .context(&ctx);
        let (tx, rx) = mpsc::sync_channel(QUEUED);
        let dropped = Arc::new(AtomicU64::new(0));
        let events_dropped = Arc::new(AtomicU64::new(0));
        let counts = Arc::new(door::Counts::default());
        let info = RunInfo::of(resolved.clone());
        let publisher = Publisher {
            detectors: Some(detectors::Stats::new(&info)),
            info,
            out: Out {
                channels,
                published: Published::default(),
                buf: Vec::with_capacity(1 << 10),
            },
            dropped: dropped.clone(),
            last_kept: None,
            door: counts.clone(),
        };
        let (thread, addr) =
            serve_on_a_thread(server, (opts.addr, counts.clone()), publisher, (rx, ctx))?;
        let feed = Feed {
            tx,
            gate: Gate::new(Decimation::of(opts), opts.rate_hz),
            batch: Vec::with_capacity(BATCH),
            since: Instant::now(),
            dropped: dropped.clone(),
            events_dropped: events_dropped.clone(),
        };
        Ok((
            Self {
                addr,
                clients,
                door: counts,
                thread,
                dropped,
                events_dropped,
            },
            feed,
        ))
    }

    /// Waits until a viewer subscribed to a topic and made no further subscription for
    /// [`SETTLED`] (its first subscriptions come one by one), at most `timeout`, and no longer
    /// than `stop` is raised. Whether one did.
    pub fn wait_for_viewer(&self, timeout: Duration, stop: &Stop) -> bool {
        /// How often the wait looks at `stop`.
        const SLICE: Duration = Duration::from_millis(100);
        let end = Instant::now() + timeout;
        let clients = &self.clients;
        let mut n = clients
            .subscribed
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        // The subscriptions counted at the last look, and since when.
        let mut seen: Option<(u64, Instant)> = None;
        loop {
            let now = Instant::now();
            if *n > 0 {
                match seen {
                    Some((m, since)) if m == *n && now.duration_since(since) >= SETTLED => {
                        return true;
                    }
                    Some((m, _)) if m == *n => {}
                    _ => seen = Some((*n, now)),
                }
            }
            if now >= end || stop.pending().is_some() {
                return *n > 0;
            }
            n = clients
                .changed
                .wait_timeout(n, SLICE.min(end - now))
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    /// Whether a viewer subscribed, for another thread.
    pub fn watcher(&self) -> Watcher {
        Watcher(self.clients.clone())
    }

    /// The address it listens on (the port the system gave for port 0).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Waits for the thread to publish what the run handed over and stop the server (every
    /// [`Feed`] must be dropped first), and says what it did.
    pub fn finish(self) -> LiveStats {
        let published = self.thread.join().unwrap_or_else(|_| Published {
            error: Some("the live server's thread panicked".into()),
            ..Published::default()
        });
        LiveStats {
            address: format!("ws://{}", self.addr),
            clients: self.clients.connected.load(Ordering::Relaxed),
            ticks_published: published.ticks,
            messages_published: published.messages,
            records_dropped: self.dropped.load(Ordering::Relaxed),
            events_dropped: self.events_dropped.load(Ordering::Relaxed),
            client_messages_dropped: self.door.dropped.load(Ordering::Relaxed),
            clients_let_go: self.door.let_go.load(Ordering::Relaxed),
            clients_outside_the_door: self
                .clients
                .connected
                .load(Ordering::Relaxed)
                .saturating_sub(self.door.relayed.load(Ordering::Relaxed)),
            error: published.error,
        }
    }
}

/// Starts the thread that starts the servers (the SDK's `server`, the door at `at`) and then
/// publishes what `rx` brings; the thread, and the door's address once they listen.
fn serve_on_a_thread(
    server: WebSocketServer,
    (at, door): (SocketAddr, Arc<door::Counts>),
    publisher: Publisher,
    (rx, ctx): (Receiver<Item>, Arc<Context>),
) -> Result<(JoinHandle<Published>, SocketAddr)> {
    // The servers are started on the thread, which gives way to the run: the threads of their
    // runtime, made there, inherit that.
    let (ready_tx, ready) = mpsc::sync_channel(1);
    let thread = std::thread::Builder::new()
        .name("live".into())
        .spawn(move || {
            yield_to_the_run();
            match open(server, at, door) {
                Ok((runtime, server, addr)) => {
                    let _ = ready_tx.send(Ok(addr));
                    let published = publisher.run(&rx, server, ctx);
                    runtime.shutdown_background();
                    published
                }
                Err(e) => {
                    let _ = ready_tx.send(Err(e));
                    Published::default()
                }
            }
        })
        .context("starting the live server's thread")?;
    let addr = ready
        .recv()
        .context("the live server's thread ended before the server started")??;
    Ok((thread, addr))
}

/// Starts the SDK's `server` and the door at `addr` in front of it, on a runtime of one thread;
/// the runtime, the server, and the door's address (the port the system gave for port 0).
fn open(
    server: WebSocketServer,
    addr: SocketAddr,
    counts: Arc<door::Counts>,
) -> Result<(
    tokio::runtime::Runtime,
    foxglove::WebSocketServerHandle,
    SocketAddr,
)> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("live-io")
        .enable_all()
        .build()
        .context("the live server's runtime")?;
    let server = runtime
        .block_on(server.start())
        .context("the live server (Foxglove SDK) on loopback")?;
    let upstream = SocketAddr::new(Ipv4Addr::LOCALHOST.into(), server.port());
    let listener = runtime
        .block_on(tokio::net::TcpListener::bind(addr))
        .with_context(|| format!("--live: serving at {addr}"))?;
    let addr = listener
        .local_addr()
        .with_context(|| format!("--live: the address served at {addr}"))?;
    runtime.spawn(door::serve(listener, upstream, counts));
    Ok((runtime, server, addr))
}

/// The channels of the run and what was published on them.
struct Out {
    channels: BTreeMap<(u32, &'static str), Arc<RawChannel>>,
    published: Published,
    buf: Vec<u8>,
}

impl Out {
    /// Whether any channel has a subscriber.
    fn watched(&self) -> bool {
        self.channels.values().any(|c| c.has_sinks())
    }
}

impl Sink for Out {
    fn message(
        &mut self,
        agent: u32,
        name: &'static str,
        _schema: &Schema,
        t: f64,
        msg: &Value,
    ) -> Result<()> {
        let Some(c) = self.channels.get(&(agent, name)) else {
            bail!(
                "a message on {}, which the run's topics do not have",
                topic_name(agent, name)
            );
        };
        if !c.has_sinks() {
            return Ok(());
        }
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, msg).context("a message")?;
        c.log_with_meta(
            &self.buf,
            PartialMetadata {
                log_time: Some(topics::log_time_ns(t)?),
            },
        );
        self.published.messages += 1;
        Ok(())
    }
}

/// The server's thread: makes the messages of the ticks it keeps, for the channels a client
/// subscribed to.
struct Publisher {
    info: RunInfo,
    out: Out,
    /// The detectors, fed every tick; `None` once a record was dropped.
    detectors: Option<detectors::Stats>,
    dropped: Arc<AtomicU64>,
    /// The kept tick last published (its time broadcast).
    last_kept: Option<u64>,
    /// The door's connections.
    door: Arc<door::Counts>,
}

impl Publisher {
    fn run(
        mut self,
        rx: &Receiver<Item>,
        server: foxglove::WebSocketServerHandle,
        ctx: Arc<Context>,
    ) -> Published {
        for item in rx {
            let done = match item {
                Item::Ticks(batch) => {
                    if self.dropped.load(Ordering::Relaxed) > 0 {
                        self.detectors = None;
                    }
                    batch
                        .iter()
                        .try_for_each(|(r, kept)| self.tick(r, *kept, &server))
                }
                Item::Record(stem, rec) => self.record(&stem, &rec),
            };
            if let Err(e) = done {
                self.out.published.error.get_or_insert(format!("{e:#}"));
            }
        }
        // The clients' queues are sent before the server stops (it drops what they hold).
        // While the door has connections, at most `longest`.
        let while_open = |longest: Duration| {
            let end = Instant::now() + longest;
            while self.door.open.load(Ordering::Relaxed) > 0 && Instant::now() < end {
                std::thread::sleep(Duration::from_millis(10));
            }
        };
        while_open(LINGER);
        // Stopped without waiting for its connections' tasks: one that never finished its
        // handshake, or a client that reads nothing, would hold the launcher for good. The door
        // then closes its clients' connections once their outboxes are sent, at most CLOSING.
        drop(server.stop());
        while_open(CLOSING);
        drop(ctx);
        self.out.published
    }

    /// Joined tick `r`: its detector statistics, and when `kept` and watched, its messages (the
    /// first record of a kept tick broadcasts its time).
    fn tick(
        &mut self,
        r: &TickRecord,
        kept: bool,
        server: &foxglove::WebSocketServerHandle,
    ) -> Result<()> {
        let k = r.center.k;
        let kept = kept && self.out.watched();
        if kept && self.last_kept != Some(k) {
            self.last_kept = Some(k);
            self.out.published.ticks += 1;
            server.broadcast_time(topics::log_time_ns(tick_time(k, self.info.dt))?);
        }
        let Self {
            info,
            out,
            detectors,
            ..
        } = self;
        if let Some(stats) = detectors {
            // Every tick, kept or not: a statistic follows every tick.
            if let Some(tick) = stats.observe(info, r) {
                if kept {
                    detectors::message(out, &tick)?;
                }
            }
        }
        if !kept {
            return Ok(());
        }
        let recs = [
            Some(TraceRecord::Agent(r.agent)),
            Some(TraceRecord::Attack(r.attack)),
            Some(TraceRecord::Center(r.center)),
            r.actuation.map(TraceRecord::Actuation),
            r.monitor.map(TraceRecord::Monitor),
        ];
        for rec in recs.iter().flatten() {
            topics::record(out, info, Path::new("live"), "live", rec)?;
        }
        Ok(())
    }

    fn record(&mut self, stem: &str, rec: &TraceRecord) -> Result<()> {
        topics::record(&mut self.out, &self.info, Path::new(stem), stem, rec)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(ticks_per_s: Option<f64>, rate_hz: f64) -> Options {
        Options {
            addr: "127.0.0.1:0".parse().expect("an address"),
            rate_hz,
            ticks_per_s,
            stamped: false,
        }
    }

    #[test]
    fn a_paced_stream_keeps_every_k_th_tick_k_from_the_pace_and_the_rate() {
        assert_eq!(
            Decimation::of(&opts(Some(1000.0), 50.0)),
            Decimation::Every(20)
        );
        assert_eq!(
            Decimation::of(&opts(Some(1000.0), 30.0)),
            Decimation::Every(34)
        );
        assert_eq!(
            Decimation::of(&opts(Some(10.0), 50.0)),
            Decimation::Every(1)
        );
        let mut g = Gate::new(Decimation::Every(5), 50.0);
        let kept: Vec<u64> = (0..23).filter(|k| g.keeps(*k)).collect();
        assert_eq!(kept, [0, 5, 10, 15, 20]);
        // Every record of a tick is judged alike (four robots' records of tick 5).
        let mut g = Gate::new(Decimation::Every(5), 50.0);
        assert!((0..4).all(|_| g.keeps(5)));
        assert!((0..4).all(|_| !g.keeps(6)));
    }

    #[test]
    fn no_stream_keeps_more_than_its_burst_at_once() {
        let rate = 50.0;
        let cap = (rate * BURST.as_secs_f64()).min(MAX_BURST);
        // 100 000 ticks handed over at once (a viewer that joins late, a trace writer's flush):
        // the burst, and what the time spent judging them refilled.
        for d in [Decimation::of(&opts(None, rate)), Decimation::Every(2)] {
            let mut g = Gate::new(d, rate);
            let began = Instant::now();
            let kept = (0..100_000u64).filter(|k| g.keeps(*k)).count() as f64;
            let most = cap + rate * began.elapsed().as_secs_f64() + 1.0;
            assert!(
                kept <= most,
                "{d:?}: {kept} ticks kept at once, at most {most}"
            );
            assert!(
                kept >= cap,
                "{d:?}: {kept} kept, the whole burst {cap} allowed"
            );
        }
    }
}
