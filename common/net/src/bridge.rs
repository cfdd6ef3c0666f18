//! The bridge of one host for one run: the local streams carried out to the other hosts, and
//! theirs carried in. [`Bridge`] is what the launcher and `serve` hold of it; [`ZenohBridge`]
//! is the bridge fdi-mas ships.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use fdi_runtime::ipc::{
    AlarmMsg, Bell as _, ControlMsg, ControllerInMsg, ControllerOutMsg, Inbox as _, IpcError,
    MeasurementMsg, Outbox as _, Sizing, StatusMsg, Stream, TorqueMsg, Transport, Wake, Waker as _,
};

use crate::error::{thread_error, NetError};
use crate::keys;
use crate::plan::{HostPlan, Inbound};
use crate::session::{Net, NetOutbox, Subscription};
use crate::wire::{decode, encode, frames, Carried};

/// A bridge between the hosts of a run as its holder sees it: started for one run (by its own
/// constructor, [`ZenohBridge::start`]), asked how it goes, stopped. Another way of carrying a
/// run's streams between hosts implements this trait (docs/architecture.md, "A new bridge").
pub trait Bridge: Send + std::fmt::Debug {
    /// Why it stopped early, if it did: the run cannot go on without it.
    fn failure(&self) -> Option<String>;
    /// The first frame it refused, described ([`BridgeCounts::refused`] counts them all).
    fn first_refusal(&self) -> Option<String>;
    /// The routes it sends on that no other host receives yet: a payload sent there now would
    /// be lost. Empty once every route of the run is known.
    fn unmatched(&self) -> Vec<String> {
        self.routes().unmatched()
    }
    /// Its routes, to ask [`Routes::unmatched`] from another thread.
    fn routes(&self) -> Routes;
    /// What it carried so far.
    fn counts(&self) -> BridgeCounts;
    /// Stops it (what was published locally before is still sent); the first error it met, if
    /// any.
    fn stop(self: Box<Self>) -> Result<BridgeCounts, NetError>;
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

/// The routes of a bridge, asked from any thread.
#[derive(Clone)]
pub struct Routes(Arc<dyn Fn() -> Vec<String> + Send + Sync>);

impl Routes {
    /// Routes whose unmatched ones `unmatched` names.
    pub fn new(unmatched: impl Fn() -> Vec<String> + Send + Sync + 'static) -> Self {
        Self(Arc::new(unmatched))
    }

    /// The routes no other host receives yet.
    pub fn unmatched(&self) -> Vec<String> {
        (self.0)()
    }
}

impl std::fmt::Debug for Routes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_tuple("Routes").field(&self.unmatched()).finish()
    }
}

/// The local receiving side of an outbound stream, by payload type.
enum OutPort<X: Transport> {
    Measurement(X::Inbox<MeasurementMsg>),
    Torque(X::Inbox<TorqueMsg>),
    Control(X::Inbox<ControlMsg>),
    Status(X::Inbox<StatusMsg>),
    Alarm(X::Inbox<AlarmMsg>),
    ControllerIn(X::Inbox<ControllerInMsg>),
    ControllerOut(X::Inbox<ControllerOutMsg>),
}

/// The local publishing side of an inbound stream, by payload type.
enum InPort<X: Transport> {
    Measurement(X::Outbox<MeasurementMsg>),
    Torque(X::Outbox<TorqueMsg>),
    Control(X::Outbox<ControlMsg>),
    Status(X::Outbox<StatusMsg>),
    Alarm(X::Outbox<AlarmMsg>),
    ControllerIn(X::Outbox<ControllerInMsg>),
    ControllerOut(X::Outbox<ControllerOutMsg>),
}

#[derive(Clone, Copy)]
enum Kind {
    Measurement,
    Torque,
    Control,
    Status,
    Alarm,
    ControllerIn,
    ControllerOut,
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
            Self::ControllerIn => std::mem::size_of::<ControllerInMsg>(),
            Self::ControllerOut => std::mem::size_of::<ControllerOutMsg>(),
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
        Stream::ControllerIn => Kind::ControllerIn,
        Stream::ControllerOut => Kind::ControllerOut,
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
            Kind::ControllerIn => Self::ControllerIn(t.subscriber(stream)?),
            Kind::ControllerOut => Self::ControllerOut(t.subscriber(stream)?),
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
            Self::ControllerIn(p) => p.drain(|m| encode(m, by, batch)),
            Self::ControllerOut(p) => p.drain(|m| encode(m, by, batch)),
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
            Kind::ControllerIn => Self::ControllerIn(t.publisher(stream)?),
            Kind::ControllerOut => Self::ControllerOut(t.publisher(stream)?),
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
            Self::ControllerIn(p) => {
                admit(at, bytes, by, admitted, refused, |m| p.send(m).map(drop))
            }
            Self::ControllerOut(p) => {
                admit(at, bytes, by, admitted, refused, |m| p.send(m).map(drop))
            }
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
pub struct ZenohBridge {
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

impl ZenohBridge {
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

    /// Stops the bridge; the first error a thread met, if any ([`Bridge::stop`]).
    pub fn stop_now(mut self) -> Result<BridgeCounts, NetError> {
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

impl Bridge for ZenohBridge {
    fn first_refusal(&self) -> Option<String> {
        self.shared
            .refusals
            .first
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }

    fn failure(&self) -> Option<String> {
        self.shared
            .failure
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }

    fn routes(&self) -> Routes {
        let outboxes = self.routes.clone();
        Routes::new(move || {
            (outboxes.iter())
                .filter(|o| !o.matched())
                .map(|o| o.key().to_string())
                .collect()
        })
    }

    fn counts(&self) -> BridgeCounts {
        BridgeCounts {
            sent: self.shared.sent.load(Ordering::Relaxed),
            received: self.shared.received.load(Ordering::Relaxed),
            refused: self.shared.refusals.count.load(Ordering::Relaxed),
        }
    }

    fn stop(self: Box<Self>) -> Result<BridgeCounts, NetError> {
        self.stop_now()
    }
}

impl Drop for ZenohBridge {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::plan;
    use crate::plan::tests::layout;
    use crate::session::{NetConfig, Security};
    use crate::wire::tests::encoded;

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
        use fdi_runtime::ipc::{Local, LocalShared};
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
        let control = ZenohBridge::start::<LocalShared>(
            &control_net,
            (&pc, &run, "control"),
            sizing,
            &plan(&l, "control").expect("plan"),
            0,
        )
        .expect("control bridge");
        let cell = ZenohBridge::start::<LocalShared>(
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
        let _ = cell.stop_now();
        assert!(
            control.stop_now().is_err(),
            "the refusal is the bridge's error"
        );
    }
}
