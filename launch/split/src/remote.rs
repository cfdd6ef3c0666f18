//! The coordinating host's side of a split run (`fdi-launch run --hosts FILE`): it reaches
//! each host's `fdi-launch serve`, asks it to run its share of the processes, bridges the
//! run's services with its own, supervises the remote processes through what their hosts
//! report, notices a host that is gone, and at the end fetches the remote traces into the run
//! directory and releases the hosts (each removes everything the run left there).

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use fdi_common::run_dir::Process;
use fdi_net::{
    self as net, keys, Answering, Bridge, Net, NetConfig, Subscription, Token, ZenohBridge,
};
use fdi_runtime::ipc::{ShmShared, Sizing, Wake};

use crate::hosts::{
    wake_word, Deployment, Host, HostCommand, HostEvent, Released, RemoteProcess, RunReply,
    RunRequest,
};
use fdi_orchestrator::run::relay::lock;
use fdi_orchestrator::run::split::{self, Hosts, LostHost, Refusals, Subscribed};
use fdi_orchestrator::run::supervisor::{Remote as RemoteChild, RemoteState, Stopper};

/// After how long without every host's serve the coordinator says it is waiting (it waits
/// [`Deployment::reach_timeout`] in all).
const SAY_WAITING: Duration = Duration::from_secs(5);
/// How long a host may take to start its processes (their ports open).
const START_TIMEOUT: Duration = Duration::from_secs(30);
/// How long a host may take to send one piece of a trace.
const TRACE_TIMEOUT: Duration = Duration::from_secs(60);
/// The pieces a trace is fetched in: each answer within one of Zenoh's batches (64 KiB). The
/// end of a query is sent on the serve's Zenoh thread, the one that empties its queue
/// ([`fdi_net::ONE_RUNTIME_THREAD`]): an answer that fills the queue can leave it
/// waiting for room only it can make (seen with pieces asked during a run,
/// [`crate::trace_stream`]).
pub const TRACE_PIECE: u64 = crate::trace_stream::CHUNK as u64;
/// How long every route between the hosts may take to be known before the start.
const ROUTES_TIMEOUT: Duration = Duration::from_secs(10);

/// One host of the run, as the coordinator follows it.
struct HostLink {
    host: Host,
    /// Its serve's liveliness token is seen (false once it is gone).
    alive: Arc<AtomicBool>,
    /// Its loss was acted on.
    lost_reported: bool,
    processes: Vec<(RemoteProcess, Wake)>,
    states: Arc<Mutex<BTreeMap<String, Arc<Mutex<RemoteState>>>>>,
    reply: Option<RunReply>,
    /// What the host said made it fail.
    failed: Arc<Mutex<Option<String>>>,
    /// Frames its bridge refused, and the first, as it last said.
    refused: Arc<Mutex<(u64, String)>>,
    _watch: Subscription,
    _events: Subscription,
}

impl HostLink {
    /// Follows host `h` in the run `prefix`: whether its serve is alive, and what it says of
    /// its processes (lines, exits, stalls, failures, refused frames).
    fn follow(net: &Net, prefix: &str, h: &Host) -> Result<Self> {
        let alive = Arc::new(AtomicBool::new(false));
        let a = alive.clone();
        let watch = net.watch(&keys::serve(&h.name), move |up| {
            a.store(up, Ordering::SeqCst)
        })?;
        let states: Arc<Mutex<BTreeMap<String, Arc<Mutex<RemoteState>>>>> = Arc::default();
        let st = states.clone();
        let failed: Arc<Mutex<Option<String>>> = Arc::default();
        let fl = failed.clone();
        let refused: Arc<Mutex<(u64, String)>> = Arc::default();
        let rf = refused.clone();
        let name = h.name.clone();
        let events = net.subscribe(&keys::said(&h.name, prefix, "events"), move |_, bytes| {
            match serde_json::from_slice::<HostEvent>(&bytes) {
                Ok(HostEvent::Line { text }) => {
                    log::info!(target: fdi_common::observe::VERBATIM, "{name}: {text}");
                }
                Ok(HostEvent::Exited { label, raw, ended }) => {
                    if let Some(s) = lock(&st).get(&label) {
                        lock(s).exit = Some((raw, ended));
                    }
                }
                Ok(HostEvent::Stalled { label, text }) => {
                    if let Some(s) = lock(&st).get(&label) {
                        lock(s).stalled = Some(text);
                    }
                }
                Ok(HostEvent::Failed { text }) => {
                    lock(&fl).get_or_insert(text);
                }
                Ok(HostEvent::Refused { count, first }) => {
                    *lock(&rf) = (count, first);
                }
                Err(e) => log::warn!("host `{name}` sent an event that is not one ({e})"),
            }
        })?;
        Ok(Self {
            host: h.clone(),
            alive,
            lost_reported: false,
            processes: Vec::new(),
            states,
            reply: None,
            failed,
            refused,
            _watch: watch,
            _events: events,
        })
    }

    /// Started, and not lost: a host lost once keeps nothing of the run even if it is heard
    /// from again (its serve stopped and cleaned up when it lost the coordinator).
    fn reachable(&self) -> bool {
        self.reply.is_some() && !self.lost_reported && self.alive.load(Ordering::SeqCst)
    }
}

/// The traces of a run's processes on other hosts, as the live view subscribes to their
/// streams ([`crate::trace_stream`]) during the run.
#[derive(Debug, Clone)]
pub struct RemoteTraces {
    net: Net,
    prefix: String,
    /// The host of each process that runs on another host than the coordinating one.
    hosts: BTreeMap<Process, String>,
}

impl split::RemoteTraces for RemoteTraces {
    fn processes(&self) -> std::collections::BTreeSet<Process> {
        self.hosts.keys().copied().collect()
    }

    /// The stream of the trace of `process` its host sends once subscribed
    /// ([`crate::trace_stream`]).
    fn subscribe(&self, process: Process, readers: usize) -> Result<Subscribed> {
        let host = self
            .hosts
            .get(&process)
            .with_context(|| format!("{process} runs on no other host"))?;
        crate::trace_stream::subscribe(&self.net, (host, &self.prefix), process, readers)
    }
}

/// The coordinator's link to the other hosts of a run.
pub struct Remote {
    pub deployment: Deployment,
    prefix: String,
    net: Net,
    hosts: Vec<HostLink>,
    bridge: Option<Box<dyn Bridge>>,
    _token: Token,
    _clock: Answering,
}

impl std::fmt::Debug for Remote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Remote")
            .field("prefix", &self.prefix)
            .finish_non_exhaustive()
    }
}

/// The processes host `link` says it started (`reply`), each stopped through the host's
/// command key (`cmd`): their wake-up events, labels and handles.
fn adopted(
    link: &HostLink,
    reply: &RunReply,
    cmd: &Arc<fdi_net::NetOutbox>,
) -> Result<Vec<(Wake, String, RemoteChild)>> {
    let mut adopted = Vec::new();
    for (p, wake) in &link.processes {
        let pid = reply
            .pids
            .iter()
            .find(|(l, _)| *l == p.label)
            .map(|(_, pid)| *pid)
            .with_context(|| {
                format!(
                    "host `{}` did not say it started {}",
                    link.host.name, p.label
                )
            })?;
        let state = lock(&link.states)
            .get(&p.label)
            .cloned()
            .unwrap_or_default();
        let cmd = cmd.clone();
        let stop = Stopper(Arc::new(move |kill| {
            let c = if kill {
                HostCommand::Kill
            } else {
                HostCommand::Term
            };
            if let Ok(body) = serde_json::to_vec(&c) {
                let _ = cmd.put(&body);
            }
        }));
        adopted.push((
            *wake,
            p.label.clone(),
            RemoteChild {
                host: link.host.name.clone(),
                pid,
                state,
                stop,
            },
        ));
    }
    Ok(adopted)
}

impl Remote {
    /// Opens the coordinator's Zenoh session for the run `prefix` and waits until every
    /// host's serve is seen; names each host that is not.
    pub fn connect(deployment: Deployment, prefix: &str) -> Result<Self> {
        let me = deployment.coordinator.name.clone();
        let config = NetConfig {
            listen: vec![deployment.coordinator.endpoint.clone()],
            connect: deployment
                .others
                .iter()
                .map(|h| h.endpoint.clone())
                .collect(),
            security: deployment.lab.security_of(&me)?,
        };
        let net = Net::open(&config).with_context(|| {
            format!(
                "host `{}` (the coordinator, {})",
                deployment.coordinator.name, deployment.lab.source
            )
        })?;
        if let Some(warning) = net.unfiltered() {
            log::warn!("{warning}");
        }
        let token = net.token(&keys::said(&me, prefix, "coordinator"))?;
        let clock = net.answer_clock(&keys::asked(&me, "*", prefix, "clock"))?;
        let hosts = deployment
            .others
            .iter()
            .map(|h| HostLink::follow(&net, prefix, h))
            .collect::<Result<Vec<_>>>()?;
        let began = Instant::now();
        let limit = deployment.reach_timeout;
        let mut said = false;
        while hosts.iter().any(|h| !h.alive.load(Ordering::SeqCst)) {
            if !said && began.elapsed() > SAY_WAITING && limit > SAY_WAITING {
                said = true;
                let missing: Vec<String> = hosts
                    .iter()
                    .filter(|h| !h.alive.load(Ordering::SeqCst))
                    .map(|h| format!("`{}`", h.host.name))
                    .collect();
                log::info!(
                    "waiting for the serve of host {} (at most {:.0} s: a serve whose \
                     network was cut may take up to 30 s to hear a new coordinator; \
                     docs/multi-host.md)",
                    missing.join(", "),
                    limit.as_secs_f64()
                );
            }
            if began.elapsed() > limit {
                let missing: Vec<String> = hosts
                    .iter()
                    .filter(|h| !h.alive.load(Ordering::SeqCst))
                    .map(|h| format!("`{}` ({})", h.host.name, h.host.endpoint))
                    .collect();
                bail!(
                    "no `fdi-launch serve` answers on host {} within {:.0} s (is it running \
                     there as `fdi-launch serve --hosts FILE --name NAME` with this deployment \
                     file and the same lab's certificates, and is its port open (UDP for \
                     `quic/`, TCP for `tcp/`)? docs/multi-host.md)",
                    missing.join(", "),
                    limit.as_secs_f64()
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        Ok(Self {
            deployment,
            prefix: prefix.into(),
            net,
            hosts,
            bridge: None,
            _token: token,
            _clock: clock,
        })
    }

    /// The key the coordinator asks `what` of `host` on.
    fn ask(&self, host: &str, what: &str) -> String {
        keys::asked(host, &self.deployment.coordinator.name, &self.prefix, what)
    }

    /// Starts the coordinator's bridge: before the local processes, so that none of what
    /// they send to other hosts is lost.
    pub fn start_bridge(&mut self, sizing: Sizing) -> Result<()> {
        let plan = net::plan(&self.deployment.layout, &self.deployment.coordinator.name)
            .map_err(anyhow::Error::msg)?;
        self.bridge = Some(
            ZenohBridge::start::<ShmShared>(
                &self.net,
                (
                    &self.prefix,
                    &self.prefix,
                    &self.deployment.coordinator.name,
                ),
                sizing,
                &plan,
                0,
            )
            .map(Box::new)?,
        );
        Ok(())
    }

    /// Fetches the trace `name` of host `l` into `path`, piece by piece.
    fn fetch_trace(&self, l: &HostLink, name: &str, path: &Path) -> Result<()> {
        use std::io::Write as _;
        let key = self.ask(&l.host.name, "traces");
        let mut file = std::io::BufWriter::new(
            std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?,
        );
        let mut offset = 0u64;
        loop {
            let ask = format!("{name} {offset}");
            let piece = self.net.request(&key, ask.as_bytes(), TRACE_TIMEOUT)?;
            file.write_all(&piece)
                .with_context(|| format!("writing {}", path.display()))?;
            offset += piece.len() as u64;
            if (piece.len() as u64) < TRACE_PIECE {
                break;
            }
        }
        file.flush()
            .with_context(|| format!("writing {}", path.display()))?;
        Ok(())
    }
}

impl Hosts for Remote {
    /// The traces of the run's processes on the other hosts, for the live view.
    fn traces(&self) -> Arc<dyn split::RemoteTraces> {
        let coordinator = &self.deployment.coordinator.name;
        let hosts = self
            .deployment
            .layout
            .host_of
            .iter()
            .filter(|(_, h)| *h != coordinator)
            .filter_map(|(w, h)| Some((RemoteProcess::of(*w)?.process, h.clone())))
            .collect();
        Arc::new(RemoteTraces {
            net: self.net.clone(),
            prefix: self.prefix.clone(),
            hosts,
        })
    }

    /// Asks each host to run its processes (`procs`: the run's processes that are not on
    /// this host, with how messages name them), and gives each back once its host says it is
    /// started. A process that only the coordinating host can run is refused, named.
    fn start_hosts(
        &mut self,
        scenario: &str,
        procs: Vec<(Wake, String)>,
    ) -> Result<Vec<(Wake, String, RemoteChild)>> {
        let layout: Vec<(String, String)> = self
            .deployment
            .layout
            .host_of
            .iter()
            .map(|(w, h)| (wake_word(*w), h.clone()))
            .collect();
        for (wake, label) in procs {
            let p = RemoteProcess::of(wake).with_context(|| {
                format!("{label} cannot run on a host other than the coordinating one")
            })?;
            let host = self.deployment.host_of(wake).to_string();
            let link = (self.hosts.iter_mut())
                .find(|l| l.host.name == host)
                .with_context(|| format!("{label}: its host `{host}` is not one of the run's"))?;
            link.processes.push((p, wake));
        }
        let mut started = Vec::new();
        for link in &mut self.hosts {
            let request = RunRequest {
                version: env!("CARGO_PKG_VERSION").into(),
                prefix: self.prefix.clone(),
                coordinator: self.deployment.coordinator.name.clone(),
                host: link.host.name.clone(),
                scenario: scenario.into(),
                layout: layout.clone(),
            };
            for (p, _) in &link.processes {
                lock(&link.states).insert(p.label.clone(), Arc::default());
            }
            let body = serde_json::to_vec(&request).context("encoding a run request")?;
            let answer = self
                .net
                .request(
                    &keys::run_request(&link.host.name, &self.deployment.coordinator.name),
                    &body,
                    START_TIMEOUT,
                )
                .with_context(|| {
                    format!(
                        "host `{}` ({}) did not start its processes",
                        link.host.name, link.host.endpoint
                    )
                })?;
            let reply: RunReply = serde_json::from_slice(&answer)
                .with_context(|| format!("host `{}` answered with no run reply", link.host.name))?;
            let cmd = Arc::new(self.net.outbox(&keys::said(
                &self.deployment.coordinator.name,
                &self.prefix,
                &format!("cmd/{}", link.host.name),
            ))?);
            started.extend(adopted(link, &reply, &cmd)?);
            link.reply = Some(reply);
        }
        Ok(started)
    }

    /// Why the run cannot go on across hosts, if it cannot: the coordinator's bridge stopped, or
    /// a host said its own did.
    fn failure(&self) -> Option<String> {
        if let Some(f) = self.bridge.as_ref().and_then(|b| b.failure()) {
            return Some(format!(
                "host `{}` (the coordinator): {f}",
                self.deployment.coordinator.name
            ));
        }
        self.hosts.iter().find_map(|l| {
            lock(&l.failed)
                .as_ref()
                .map(|f| format!("host `{}` ({}): {f}", l.host.name, l.host.endpoint))
        })
    }

    /// The frames refused so far on the network path, per host that refused any: (host,
    /// count, the first described).
    fn refusals(&self) -> Vec<Refusals> {
        let mut all = Vec::new();
        if let Some(b) = &self.bridge {
            let count = b.counts().refused;
            if count > 0 {
                all.push(Refusals {
                    host: self.deployment.coordinator.name.clone(),
                    count,
                    first: b.first_refusal().unwrap_or_default(),
                });
            }
        }
        for l in &self.hosts {
            let (count, first) = lock(&l.refused).clone();
            if count > 0 {
                all.push(Refusals {
                    host: l.host.name.clone(),
                    count,
                    first,
                });
            }
        }
        all
    }

    /// A host that is gone since the last call (each reported once).
    fn lost_host(&mut self) -> Option<LostHost> {
        let link = self
            .hosts
            .iter_mut()
            .find(|l| !l.lost_reported && !l.alive.load(Ordering::SeqCst))?;
        link.lost_reported = true;
        for s in lock(&link.states).values() {
            lock(s).host_lost = true;
        }
        let labels: Vec<&str> = link.processes.iter().map(|(p, _)| &*p.label).collect();
        Some(LostHost {
            name: link.host.name.clone(),
            endpoint: link.host.endpoint.clone(),
            agents: link
                .processes
                .iter()
                .filter_map(|(p, _)| p.process.agent())
                .collect(),
            message: format!(
                "host `{}` ({}) is unreachable: its `fdi-launch serve` died or the network to \
                 it was cut (nothing heard from it for the {:.1} s Zenoh lease); it ran {}",
                link.host.name,
                link.host.endpoint,
                net::LEASE.as_secs_f64(),
                labels.join(", ")
            ),
        })
    }

    /// The coordinating host's line for the report: the processes it ran.
    fn describe_coordinator(&self) -> String {
        let here = &self.deployment.coordinator;
        let procs: Vec<String> = self
            .deployment
            .layout
            .host_of
            .iter()
            .filter(|(_, h)| **h == here.name)
            .map(|(w, _)| match w {
                Wake::Agent(id) => format!("agent {id}"),
                Wake::Center => fdi_common::run_dir::Process::CENTER.into(),
                w => wake_word(*w),
            })
            .collect();
        format!(
            "host `{}` ({}, the coordinator): {}",
            here.name,
            here.endpoint,
            procs.join(", ")
        )
    }

    /// Lines for the report: each host, its processes and its clock against ours.
    fn describe(&self) -> Vec<String> {
        self.hosts
            .iter()
            .map(|l| {
                let procs: Vec<&str> = l.processes.iter().map(|(p, _)| p.label.as_str()).collect();
                match &l.reply {
                    Some(r) => format!(
                        "host `{}` ({}): {}; its clock {:+.3} ms from the coordinator's, \
                         measured in a round trip of {:.3} ms",
                        l.host.name,
                        l.host.endpoint,
                        procs.join(", "),
                        -(r.offset_ns as f64) / 1e6,
                        r.rtt_ns as f64 / 1e6
                    ),
                    None => format!("host `{}` ({}): not started", l.host.name, l.host.endpoint),
                }
            })
            .collect()
    }

    /// Fetches the traces of every reachable host into `run_dir/traces`. A host that is gone
    /// keeps its traces: for each of its agents a `<name>.lost` note says so, which the join
    /// reads (those agents' ticks count as missing). Problems are returned, one per trace.
    fn fetch_traces(&mut self, run_dir: &Path) -> Vec<String> {
        // A host gone by now is one lost, whether or not it was noticed during the run.
        while self.lost_host().is_some() {}
        let mut problems = Vec::new();
        for l in &self.hosts {
            if l.reply.is_none() {
                continue;
            }
            for (p, _) in &l.processes {
                let path = fdi_common::run_dir::RunDir::new(run_dir).trace(p.process);
                if !l.reachable() {
                    let note = format!(
                        "its trace stayed on host `{}` ({}), which became unreachable during \
                         the run",
                        l.host.name, l.host.endpoint
                    );
                    let lost = path.with_extension("lost");
                    if let Err(e) = std::fs::write(&lost, &note) {
                        problems.push(format!("writing {}: {e}", lost.display()));
                    }
                    problems.push(format!("{}: {note}", p.label));
                    continue;
                }
                if let Err(e) = self.fetch_trace(l, &p.process.to_string(), &path) {
                    problems.push(format!(
                        "the trace of {} from host `{}`: {e:#}",
                        p.label, l.host.name
                    ));
                }
            }
        }
        problems
    }

    /// Waits until every route of the run is known to Zenoh (each host's bridge has a
    /// subscriber for every key it sends on): a sample sent before would be lost. Names the
    /// host and the keys still unmatched after [`ROUTES_TIMEOUT`].
    fn await_routes(&self) -> Result<()> {
        let began = Instant::now();
        loop {
            let mut unmatched: Vec<(String, Vec<String>)> = Vec::new();
            if let Some(b) = &self.bridge {
                let u = b.unmatched();
                if !u.is_empty() {
                    unmatched.push((self.deployment.coordinator.name.clone(), u));
                }
            }
            for l in self.hosts.iter().filter(|l| l.reply.is_some()) {
                let key = self.ask(&l.host.name, "routes");
                let u: Vec<String> = self
                    .net
                    .request(&key, &[], Duration::from_secs(5))
                    .map_err(anyhow::Error::from)
                    .and_then(|b| Ok(serde_json::from_slice(&b)?))
                    .with_context(|| format!("asking host `{}` for its routes", l.host.name))?;
                if !u.is_empty() {
                    unmatched.push((l.host.name.clone(), u));
                }
            }
            if unmatched.is_empty() {
                return Ok(());
            }
            if began.elapsed() > ROUTES_TIMEOUT {
                let said: Vec<String> = unmatched
                    .iter()
                    .map(|(h, keys)| {
                        format!("host `{h}` sends on {} with no receiver", keys.join(", "))
                    })
                    .collect();
                bail!(
                    "the hosts do not all reach one another after {:.0} s: {} (can every host \
                     connect to every other's endpoint? docs/multi-host.md, Ports)",
                    ROUTES_TIMEOUT.as_secs_f64(),
                    said.join("; ")
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Releases every reachable host (each removes what the run left there) and stops the
    /// bridge. Returns what could not be removed (`host:path`), problems, and the run's
    /// network path.
    fn release(self: Box<Self>) -> split::Released {
        let mut this = *self;
        let (mut leftovers, mut problems) = (Vec::new(), Vec::new());
        for l in this.hosts.iter().filter(|l| l.reachable()) {
            let key = this.ask(&l.host.name, "release");
            match this
                .net
                .request(&key, &[], Duration::from_secs(10))
                .map_err(anyhow::Error::from)
                .and_then(|b| Ok(serde_json::from_slice::<Released>(&b)?))
            {
                Ok(r) => {
                    leftovers.extend(r.leftovers.iter().map(|p| format!("{}:{p}", l.host.name)));
                    *lock(&l.refused) = (r.refused, r.first_refusal.unwrap_or_default());
                }
                Err(e) => problems.push(format!("releasing host `{}`: {e}", l.host.name)),
            }
        }
        // Counted before the bridge stops (its counts go with it).
        let refusals = this.refusals();
        if let Some(b) = this.bridge.take() {
            if let Err(e) = b.stop() {
                problems.push(format!("the coordinator's bridge: {e}"));
            }
        }
        let network = fdi_common::engine::NetworkPath {
            authenticated: this.deployment.lab.authenticated(),
            refused_frames: refusals.iter().map(|r| r.count).sum(),
            refusals: refusals.iter().map(Refusals::to_string).collect(),
        };
        // Closing the session waits for its connectors, and one still trying an unreachable
        // host waits for the network's timeout (seconds): the session is closed aside, the run
        // has nothing more to say on it.
        let _ = std::thread::Builder::new()
            .name("zenoh close".into())
            .spawn(move || drop(this));
        split::Released {
            leftovers,
            problems,
            network,
        }
    }
}

impl split::Split for Deployment {
    fn is_local(&self, wake: Wake) -> bool {
        Deployment::is_local(self, wake)
    }

    fn stall_timeout(&self) -> Option<Duration> {
        self.stall_timeout
    }

    fn connect(&self, prefix: &str, sizing: Sizing) -> Result<Box<dyn Hosts>> {
        let mut remote = Remote::connect(self.clone(), prefix)?;
        remote.start_bridge(sizing)?;
        Ok(Box::new(remote))
    }
}
