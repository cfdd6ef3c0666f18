//! `fdi-launch serve`: the other hosts' side of a split run. It waits for runs; for each it
//! runs the processes the coordinating host gives it on its own shared memory, bridges the
//! run's services with the other hosts (`fdi_net::Bridge`), reports what its
//! processes print and how they end, hands their traces to the coordinator, and removes
//! everything the run left once it is released, or at once when the coordinator is gone.

use fdi_common::run_dir::{Process, RunDir};
use fdi_common::stop::Stop;
use std::collections::BTreeMap;
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use fdi_common::limits::MAX_FILE_BYTES;
use fdi_net::{
    self as net, keys, Bridge, Layout, Net, NetConfig, NetOutbox, Request, Requests, ZenohBridge,
};
use fdi_runtime::ipc::{check_prefix, Shm, ShmShared, Transport as _, Wake};
use fdi_runtime::process::{sizing_for, Placement, ProcessArgs};
use serde::{Deserialize, Serialize};

use crate::hosts::{
    parse_wake, put_json, HostCommand, HostEvent, Lab, Released, RemoteProcess, RunReply,
    RunRequest,
};
use crate::trace_stream::Streamer;
use fdi_orchestrator::run::supervisor::Supervisor;

/// A host's share of split runs (`fdi-launch serve`).
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// The deployment file: the lab's hosts, their endpoints and certificates. The serve
    /// listens on its own host's endpoint and takes runs only from the lab's hosts.
    pub hosts: PathBuf,
    /// This host's name, as the deployment file names it (`hosts.<name>`).
    pub name: String,
    /// Where a run's processes keep their traces until the coordinator has them (a folder per
    /// run, removed at its release, or by the next serve if this one is killed). `None`: the
    /// system's temporary folder.
    pub work_dir: Option<PathBuf>,
    /// Serve this many runs, then return (`None`: until the stop is raised).
    pub runs: Option<u64>,
}

/// How long the coordinator's liveliness may stay unseen once a run is taken.
const COORDINATOR_SEEN_TIMEOUT: Duration = Duration::from_secs(5);
use fdi_orchestrator::run::runtime::{GRACE, STALL_LIMIT};

/// The largest run request taken: a scenario file of the largest size and its layout.
pub const MAX_REQUEST_BYTES: usize = MAX_FILE_BYTES as usize + (64 << 10);

/// The name of a run's work folder starts with this (then the host's name and the run's
/// prefix).
const WORK_PREFIX: &str = "fdi-serve-";
/// The note in a run's work folder saying which serve made it, for the reaping of a serve
/// that was killed.
const OWNER: &str = "serve.json";

/// Who made a work folder.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Owner {
    pid: u32,
    prefix: String,
}

/// Serves split runs until `stop` is raised (or `runs` were served); says what it does
/// (`log`).
pub fn serve(args: &ServeOptions, stop: &Stop) -> Result<()> {
    net::check_host_name(&args.name).map_err(|e| anyhow::anyhow!("--name: {e}"))?;
    let lab = Lab::load(&args.hosts)?;
    let me = lab.host(&args.name)?.clone();
    let base = args.work_dir.clone().unwrap_or_else(std::env::temp_dir);
    std::fs::create_dir_all(&base)
        .with_context(|| format!("creating the work folder {}", base.display()))?;
    for line in reap_stale(&base) {
        log::info!("{line}");
    }
    let net = Net::open(&NetConfig {
        listen: vec![me.endpoint.clone()],
        connect: Vec::new(),
        security: lab.security_of(&me.name)?,
    })
    .with_context(|| format!("host `{}`", me.name))?;
    if let Some(warning) = net.unfiltered() {
        log::warn!("{warning}");
    }
    let _token = net.token(&keys::serve(&me.name))?;
    let requests = net.requests(&keys::run_requests(&me.name))?;
    log::info!(
        "host `{}` listens on {} ({}); waiting for runs (Ctrl-C stops)",
        me.name,
        me.endpoint,
        if lab.authenticated() {
            "TLS, the lab's certificates"
        } else {
            "plain TCP: NOT authenticated, as the deployment file says"
        }
    );
    let serving = Serving {
        net: &net,
        lab: &lab,
        base: &base,
        name: &me.name,
    };
    let mut served = 0u64;
    while stop.pending().is_none() {
        let Some(request) = requests.next(Duration::from_millis(200))? else {
            continue;
        };
        match serving.run(request, &requests, stop) {
            Ok(said) => log::info!("{said}"),
            Err(e) => log::info!("{}", fdi_report::output::describe_error(&e)),
        }
        served += 1;
        if args.runs.is_some_and(|n| served >= n) {
            break;
        }
    }
    if let Some(sig) = stop.take() {
        log::info!(
            "host `{}` stops ({})",
            me.name,
            fdi_orchestrator::run::runtime::signal_name(sig)
        );
    }
    Ok(())
}

/// Removes the work folders in `base` of runs whose serve is gone (killed before it could
/// clean up), with their shared memory; says what it removed.
fn reap_stale(base: &Path) -> Vec<String> {
    let mut said = Vec::new();
    let Ok(entries) = std::fs::read_dir(base) else {
        return said;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let is_ours = entry
            .file_name()
            .to_str()
            .is_some_and(|n| n.starts_with(WORK_PREFIX));
        // A folder of its own only (never a link to somewhere else).
        if !is_ours || !entry.file_type().is_ok_and(|t| t.is_dir()) {
            continue;
        }
        let owner = std::fs::read(path.join(OWNER))
            .ok()
            .and_then(|b| serde_json::from_slice::<Owner>(&b).ok());
        let stale = match &owner {
            Some(o) => !fdi_runtime::process::procfs::exists(o.pid),
            // A folder a serve is making right now has no note for a moment.
            None => entry
                .metadata()
                .and_then(|m| m.modified())
                .is_ok_and(|t| t.elapsed().is_ok_and(|age| age > Duration::from_secs(60))),
        };
        if !stale {
            continue;
        }
        if let Some(o) = &owner {
            if check_prefix(&o.prefix).is_ok() {
                let _ = Shm::remove_leftovers(&o.prefix);
            }
        }
        match std::fs::remove_dir_all(&path) {
            Ok(()) => said.push(format!(
                "removed {}, left by a serve that is gone{}",
                path.display(),
                owner.map_or(String::new(), |o| format!(
                    " (pid {}, run {})",
                    o.pid, o.prefix
                ))
            )),
            Err(e) => said.push(format!(
                "warning: {} was left by a serve that is gone and cannot be removed: {e}",
                path.display()
            )),
        }
    }
    said
}

/// A serve's standing: its session, its lab, its work folder, its name.
struct Serving<'a> {
    net: &'a Net,
    lab: &'a Lab,
    base: &'a Path,
    name: &'a str,
}

impl Serving<'_> {
    /// Takes one run request: checks it, starts the processes and answers, then follows the
    /// run to its release (or the coordinator's loss). Returns what happened, in a line.
    fn run(&self, request: Request, queue: &Requests, stop: &Stop) -> Result<String> {
        let r = match self.admit(&request) {
            Ok(r) => r,
            Err(e) => {
                let _ = request.answer(Err(format!("host `{}`: {e:#}", self.name)));
                return Err(e);
            }
        };
        let started = HostRun::start(self, &r, stop).and_then(|run| {
            let reply = serde_json::to_vec(&run.reply)?;
            Ok((run, reply))
        });
        let result = match started {
            Ok((run, reply)) => {
                let labels: Vec<&str> = run.reply.pids.iter().map(|(l, _)| l.as_str()).collect();
                log::info!(
                    "run {} of `{}`: started {}",
                    r.prefix,
                    r.coordinator,
                    labels.join(", ")
                );
                match request.answer(Ok(reply)) {
                    Ok(()) => run.follow(self, queue),
                    Err(e) => Err(e.into()),
                }
            }
            Err(e) => {
                let _ = request.answer(Err(format!(
                    "host `{}`: {}",
                    self.name,
                    fdi_report::output::describe_error(&e)
                )));
                Err(e)
            }
        };
        // However the run ended here (its processes and bridge are gone by now), nothing of it
        // stays on this host.
        if let Err(e) = Shm::remove_leftovers(&r.prefix) {
            log::info!("run {}: removing its files: {e}", r.prefix);
        }
        result.map_err(|e| e.context(format!("run {}", r.prefix)))
    }

    /// A run request, checked before anything is written: its size, its form, that it is for
    /// this host and this version, and that it comes from the coordinator it names, a host of
    /// the lab (with TLS the asker is the certificate's).
    fn admit(&self, request: &Request) -> Result<RunRequest> {
        let body = request.body();
        if body.len() > MAX_REQUEST_BYTES {
            bail!(
                "a run request of {} bytes, more than the {MAX_REQUEST_BYTES} a run can need",
                body.len()
            );
        }
        let r: RunRequest =
            serde_json::from_slice(&body).map_err(|e| anyhow::anyhow!("not a run request: {e}"))?;
        if r.host != self.name {
            bail!(
                "the request is for host `{}`, this is `{}`",
                r.host,
                self.name
            );
        }
        if r.version != env!("CARGO_PKG_VERSION") {
            bail!(
                "the coordinator runs fdi-mas {}, this host {}: both must run the same (the \
                 payloads travel as their layouts)",
                r.version,
                env!("CARGO_PKG_VERSION")
            );
        }
        check_prefix(&r.prefix)?;
        let asker = request.asker().unwrap_or_default();
        if asker != r.coordinator || self.lab.host(&asker).is_err() || asker == self.name {
            bail!(
                "a run request that names `{}` as its coordinator came from `{asker}`: only a \
                 host of {} other than this one may coordinate a run here",
                r.coordinator,
                self.lab.source
            );
        }
        // Another host of the lab (the attacker's, say) would hold this host's robots for as
        // long as it liked: only the coordinator the file names starts runs.
        if asker != self.lab.coordinator {
            bail!(
                "a run request came from `{asker}`, which {} does not name as the coordinator \
                 (`{}`): only the coordinator starts runs on this host",
                self.lab.source,
                self.lab.coordinator
            );
        }
        if r.scenario.len() as u64 > MAX_FILE_BYTES {
            bail!(
                "a scenario of {} bytes, more than the {MAX_FILE_BYTES} byte limit of scenario \
                 files",
                r.scenario.len()
            );
        }
        Ok(r)
    }
}

/// The processes of a run request's layout that run on `here`, checked against the scenario
/// and the lab: every process named once, on a host of the lab, the agents those of the
/// scenario, the launcher on the coordinator, and only agents, the attacker and the control
/// center here. Returns the layout with them.
fn share(
    r: &RunRequest,
    here: &str,
    lab: &Lab,
    resolved: &fdi_common::scenario::Resolved,
) -> Result<(BTreeMap<Wake, String>, Vec<RemoteProcess>)> {
    let agents: std::collections::BTreeSet<u32> =
        resolved.scenario.agents.iter().map(|a| a.id).collect();
    let mut host_of = BTreeMap::new();
    for (i, (word, host)) in r.layout.iter().enumerate() {
        let at = || format!("the run request's layout[{i}]");
        let wake = parse_wake(word).with_context(at)?;
        lab.host(host).with_context(at)?;
        if let Wake::Agent(id) = wake {
            if !agents.contains(&id) {
                bail!("{}: agent {id} is not an agent of the run's scenario", at());
            }
        }
        if host_of.insert(wake, host.clone()).is_some() {
            bail!("{}: `{word}` is placed twice", at());
        }
    }
    if host_of.get(&Wake::Launcher) != Some(&r.coordinator) {
        bail!("the run request's layout does not put the launcher on its coordinator");
    }
    if let Some(id) = agents
        .iter()
        .find(|id| !host_of.contains_key(&Wake::Agent(**id)))
    {
        bail!("the run request's layout places no agent {id}");
    }
    let mut mine = Vec::new();
    for (wake, host) in &host_of {
        if host != here {
            continue;
        }
        let p = RemoteProcess::of(*wake).with_context(|| {
            format!(
                "the run request places `{}` on this host: it runs on the coordinating host only",
                crate::hosts::wake_word(*wake)
            )
        })?;
        mine.push(p);
    }
    if mine.is_empty() {
        bail!("the run request places no process on this host");
    }
    Ok((host_of, mine))
}

/// The services a host's bridge carries, by name: out (published here for processes on other
/// hosts) and in (published elsewhere for processes here).
struct Carried {
    outbound: Vec<String>,
    inbound: Vec<String>,
}

impl Carried {
    /// The services of `plan`, each list sorted (the plan's order is not the reader's).
    fn of(plan: &net::HostPlan) -> Self {
        let sorted = |mut v: Vec<String>| {
            v.sort();
            v.dedup();
            v
        };
        Self {
            outbound: sorted(plan.outbound.iter().map(|s| s.service_name()).collect()),
            inbound: sorted(
                plan.inbound
                    .iter()
                    .map(|i| i.stream.service_name())
                    .collect(),
            ),
        }
    }

    /// What the bridge carried, in words: the payloads sent and let in are of different
    /// services (this host's processes' out, the other hosts' in), so the two counts differ
    /// by what the processes of each side publish.
    fn describe(&self, c: net::BridgeCounts) -> String {
        let names = |v: &[String]| match v {
            [] => "none".to_string(),
            v => v.join(", "),
        };
        format!(
            "its bridge sent {} payloads to the other hosts (on {}: what this host's processes \
             publish for theirs) and let in {} from them (on {}){}; the two counts are of \
             different services, so they need not match",
            c.sent,
            names(&self.outbound),
            c.received,
            names(&self.inbound),
            match c.refused {
                0 => String::new(),
                n => format!(", refusing {n} frames"),
            }
        )
    }
}

/// A run's share on this host.
struct HostRun {
    prefix: String,
    coordinator: String,
    reply: RunReply,
    procs: Supervisor<()>,
    bridge: Option<Box<dyn Bridge>>,
    events: Arc<NetOutbox>,
    /// Per child: its end was reported.
    reported: Vec<bool>,
    /// Its processes.
    processes: Vec<Process>,
    /// Frames its bridge refused, as last told to the coordinator.
    refused_told: u64,
    /// The first frame its bridge refused, kept when the bridge stops.
    bridge_refusal: Option<String>,
    /// The services its bridge carries out to the other hosts and in from them, by name.
    carried: Carried,
    dir: tempfile::TempDir,
    /// The serve's stop (SIGINT, SIGTERM).
    stop: Stop,
}

impl HostRun {
    fn start(serving: &Serving, r: &RunRequest, stop: &Stop) -> Result<Self> {
        let (net, here) = (serving.net, serving.name);
        let dir = tempfile::Builder::new()
            .prefix(&format!("{WORK_PREFIX}{here}-{}-", r.prefix))
            .tempdir_in(serving.base)
            .with_context(|| format!("making a run folder in {}", serving.base.display()))?;
        let owner = Owner {
            pid: std::process::id(),
            prefix: r.prefix.clone(),
        };
        std::fs::write(dir.path().join(OWNER), serde_json::to_vec(&owner)?)
            .context("writing the run folder's owner")?;
        let run_dir = RunDir::new(dir.path());
        let scenario = run_dir.scenario();
        std::fs::write(&scenario, &r.scenario).context("writing the run's scenario")?;
        std::fs::create_dir_all(run_dir.traces()).context("making traces/")?;
        let resolved = fdi_common::scenario::load_written(&scenario)
            .map_err(|e| anyhow::anyhow!("the run's scenario: {e}"))?;
        let (host_of, mine) = share(r, here, serving.lab, &resolved)?;
        let layout = Layout::new(host_of, &resolved);
        let plan = net::plan(&layout, here).map_err(anyhow::Error::msg)?;
        let clock = net
            .clock_offset(&keys::asked(&r.coordinator, here, &r.prefix, "clock"), 16)
            .context("measuring the clock against the coordinator's")?;
        let bridge = ZenohBridge::start::<ShmShared>(
            net,
            (&r.prefix, &r.prefix, here),
            sizing_for(&resolved),
            &plan,
            clock.offset_ns,
        )?;
        let events = Arc::new(net.outbox(&keys::said(here, &r.prefix, "events"))?);
        let tee_events = events.clone();
        let mut procs = Supervisor::with_tee(Arc::new(move |line: &str| {
            put_json(&tee_events, &HostEvent::Line { text: line.into() });
        }));
        let mut pids = Vec::new();
        for p in &mine {
            let trace = run_dir.trace(p.process);
            // Derived from a closed type: inside the run's folder, whatever the request said.
            if !trace.starts_with(dir.path()) {
                bail!("{} would be outside the run's folder", trace.display());
            }
            let mut cmd = fdi_orchestrator::run::runtime::role_command(p.role)?;
            let child = ProcessArgs {
                prefix: r.prefix.clone(),
                scenario: scenario.clone(),
                trace,
                agent: p.process.agent(),
                launcher_pid: Some(std::process::id()),
                placement: Placement::default(),
                pace: None,
            };
            cmd.args(child.to_args());
            procs.spawn(p.label.clone(), (), cmd)?;
            if let Some(c) = procs.last() {
                pids.push((p.label.clone(), c.pid()));
            }
        }
        let n = procs.len();
        Ok(Self {
            prefix: r.prefix.clone(),
            coordinator: r.coordinator.clone(),
            reply: RunReply {
                pids,
                offset_ns: clock.offset_ns,
                rtt_ns: clock.rtt_ns,
            },
            procs,
            bridge: Some(Box::new(bridge)),
            events,
            reported: vec![false; n],
            processes: mine.iter().map(|p| p.process).collect(),
            refused_told: 0,
            bridge_refusal: None,
            carried: Carried::of(&plan),
            stop: stop.clone(),
            dir,
        })
    }

    fn send(&self, event: &HostEvent) {
        put_json(&self.events, event);
    }

    /// Reports the children that ended since the last call.
    fn report_exits(&mut self) {
        self.procs.reap();
        for i in 0..self.procs.len() {
            let Some(st) = self.procs[i].status else {
                continue;
            };
            if std::mem::replace(&mut self.reported[i], true) {
                continue;
            }
            let ended = if st.success() {
                format!(
                    "{} (pid {}) exited 0",
                    self.procs[i].label,
                    self.procs[i].pid()
                )
            } else {
                self.procs[i].ended(st)
            };
            let event = HostEvent::Exited {
                label: self.procs[i].label.clone(),
                raw: st.into_raw(),
                ended,
            };
            self.send(&event);
        }
    }

    /// Follows the run until the coordinator releases it or is gone; then removes what the
    /// run left on this host.
    fn follow(mut self, serving: &Serving, queue: &Requests) -> Result<String> {
        let (net, here) = (serving.net, serving.name);
        // Only the run's coordinator commands: with TLS no other host may put or ask on its
        // keys.
        let said = |what: &str| keys::said(&self.coordinator, &self.prefix, what);
        let asked = |what: &str| keys::asked(here, &self.coordinator, &self.prefix, what);
        let (cmd_tx, cmd_rx) = mpsc::channel();
        let _commands = net.subscribe(&said(&format!("cmd/{here}")), move |_, bytes| {
            if let Ok(c) = serde_json::from_slice::<HostCommand>(&bytes) {
                let _ = cmd_tx.send(c);
            }
        })?;
        let (seen, alive) = (
            Arc::new(AtomicBool::new(false)),
            Arc::new(AtomicBool::new(false)),
        );
        let (s, a) = (seen.clone(), alive.clone());
        let _watch = net.watch(&said("coordinator"), move |up| {
            if up {
                s.store(true, Ordering::SeqCst);
            }
            a.store(up, Ordering::SeqCst);
        })?;
        let run_dir = RunDir::new(self.dir.path());
        // The live view's streams of the traces, sent only once the coordinator subscribed.
        let streamed: Vec<(Process, PathBuf)> = (self.processes.iter())
            .map(|p| (*p, run_dir.trace(*p)))
            .collect();
        let _stream = Streamer::start(net, (here, &self.prefix), &streamed)?;
        let processes = self.processes.clone();
        let _traces = net.answer(&asked("traces"), move |ask| {
            let (process, offset) = trace_piece_asked(ask, &processes)?;
            let path = run_dir.trace(process);
            read_piece(&path, offset).map_err(|e| format!("reading the trace of {process}: {e}"))
        })?;
        let bridge_routes = self.bridge.as_ref().map(|b| b.routes());
        let _routes = net.answer(&asked("routes"), move |_| {
            let unmatched = bridge_routes
                .as_ref()
                .map(|r| r.unmatched())
                .unwrap_or_default();
            serde_json::to_vec(&unmatched).map_err(|e| e.to_string())
        })?;
        let release = net.requests(&asked("release"))?;
        let began = Instant::now();
        let mut failed = false;
        loop {
            self.report_exits();
            self.tell_refusals();
            self.tell_trouble(&mut failed);
            // One run at a time: another coordinator is told at once, not left to time out.
            while let Some(other) = queue.next(Duration::ZERO)? {
                let _ = other.answer(Err(format!(
                    "host `{here}` is busy with run {} of `{}`",
                    self.prefix, self.coordinator
                )));
            }
            for c in cmd_rx.try_iter() {
                match c {
                    HostCommand::Term => self.procs.signal_term(),
                    HostCommand::Kill => self.procs.kill_rest(),
                }
            }
            if let Some(req) = release.next(Duration::from_millis(20))? {
                return self.release(req);
            }
            let lost = if seen.load(Ordering::SeqCst) {
                !alive.load(Ordering::SeqCst)
            } else {
                began.elapsed() > COORDINATOR_SEEN_TIMEOUT
            };
            let interrupted = self.stop.pending();
            if lost || interrupted.is_some() {
                return Ok(self.abandon(interrupted));
            }
        }
    }

    /// Tells the coordinator that the bridge failed (once) or that a process is stopped.
    fn tell_trouble(&mut self, failed: &mut bool) {
        if let Some(text) = self.bridge.as_ref().and_then(|b| b.failure()) {
            if !std::mem::replace(failed, true) {
                log::info!("run {}: {text}", self.prefix);
                self.send(&HostEvent::Failed { text });
            }
        }
        if let Some(text) = self.procs.stalled(STALL_LIMIT) {
            // The supervisor's message starts with `<label> (pid <pid>)`.
            let label = self
                .procs
                .iter()
                .find(|c| text.starts_with(&format!("{} (pid {})", c.label, c.pid())))
                .map(|c| c.label.clone())
                .unwrap_or_default();
            self.send(&HostEvent::Stalled { label, text });
        }
    }

    /// The coordinator releases the run: its processes stop, its files go, and the answer says
    /// what the bridge carried and refused and what is left. Returns the serve's line.
    fn release(&mut self, req: Request) -> Result<String> {
        self.stop_processes();
        let (removed, leftovers, counts) = self.clean_up();
        let carried = match counts {
            Ok(c) => self.carried.describe(c),
            Err(ref e) => format!("its bridge failed: {e}"),
        };
        let first_refusal = self.bridge_refusal.take();
        let counts = counts.unwrap_or_default();
        let released = Released {
            removed,
            leftovers: leftovers.clone(),
            sent: counts.sent,
            received: counts.received,
            refused: counts.refused,
            first_refusal,
        };
        req.answer(Ok(serde_json::to_vec(&released)?))?;
        Ok(format!(
            "run {} released by `{}`: {}; {}",
            self.prefix,
            self.coordinator,
            carried,
            left_behind(&leftovers)
        ))
    }

    /// The coordinator is gone, or the serve was interrupted: the run's processes stop and its
    /// files go. Returns the serve's line.
    fn abandon(&mut self, interrupted: Option<i32>) -> String {
        let labels: Vec<String> = self.procs.iter().map(|c| c.label.clone()).collect();
        self.stop_processes();
        let (_, leftovers, _) = self.clean_up();
        let why = match interrupted {
            Some(sig) => format!(
                "interrupted by {}",
                fdi_orchestrator::run::runtime::signal_name(sig)
            ),
            None => format!(
                "the coordinator `{}` is unreachable (nothing heard for the {:.1} s lease)",
                self.coordinator,
                net::LEASE.as_secs_f64()
            ),
        };
        format!(
            "run {}: {why}: stopped {}; {}",
            self.prefix,
            labels.join(", "),
            left_behind(&leftovers)
        )
    }

    /// Tells the coordinator how many frames the bridge refused, when that changed.
    fn tell_refusals(&mut self) {
        let Some(b) = &self.bridge else {
            return;
        };
        let count = b.counts().refused;
        if count != self.refused_told {
            self.refused_told = count;
            let first = b.first_refusal().unwrap_or_default();
            self.send(&HostEvent::Refused { count, first });
        }
    }

    /// SIGTERM to what still runs, SIGKILL after the grace.
    fn stop_processes(&mut self) {
        self.procs.signal_term();
        let began = Instant::now();
        while self.procs.iter().any(|c| c.status.is_none()) && began.elapsed() < GRACE {
            self.report_exits();
            std::thread::sleep(Duration::from_millis(10));
        }
        self.procs.kill_rest();
        self.report_exits();
        for line in self
            .procs
            .drain_stderr(fdi_orchestrator::run::runtime::OUTPUT_WAIT)
        {
            log::warn!("{line}");
        }
    }

    /// Stops the bridge and removes the run's files here: (removed, left, what the bridge
    /// carried or why it failed).
    fn clean_up(&mut self) -> (usize, Vec<String>, Result<net::BridgeCounts, String>) {
        if let Some(b) = &self.bridge {
            self.bridge_refusal = b.first_refusal();
        }
        let counts = match self.bridge.take().map(|b| b.stop()) {
            Some(Ok(c)) => Ok(c),
            Some(Err(e)) => Err(e.to_string()),
            None => Ok(net::BridgeCounts::default()),
        };
        let removed = Shm::remove_leftovers(&self.prefix).unwrap_or(0);
        let leftovers = Shm::leftovers(&self.prefix)
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        (removed, leftovers, counts)
    }
}

/// The trace piece asked for by `ask` (`<process> <offset>`): a process of `processes` (this
/// host's share of the run) and an offset.
fn trace_piece_asked(ask: &[u8], processes: &[Process]) -> Result<(Process, u64), String> {
    let ask =
        std::str::from_utf8(ask).map_err(|_| "a trace asked for in bytes that are not text")?;
    let (name, offset) = ask
        .split_once(' ')
        .and_then(|(n, o)| Some((n, o.parse::<u64>().ok()?)))
        .ok_or_else(|| format!("`{ask}` does not ask for a piece of a trace"))?;
    let process = name
        .parse::<Process>()
        .ok()
        .filter(|p| processes.contains(p))
        .ok_or_else(|| format!("no process `{name}` of this run ran on this host"))?;
    Ok((process, offset))
}

/// The piece of `path` from `offset` on, at most [`crate::remote::TRACE_PIECE`] bytes.
fn read_piece(path: &std::path::Path, offset: u64) -> std::io::Result<Vec<u8>> {
    use std::io::{Read as _, Seek as _};
    let mut f = std::fs::File::open(path)?;
    f.seek(std::io::SeekFrom::Start(offset))?;
    let mut piece = Vec::new();
    f.take(crate::remote::TRACE_PIECE).read_to_end(&mut piece)?;
    Ok(piece)
}

fn left_behind(leftovers: &[String]) -> String {
    if leftovers.is_empty() {
        "nothing is left on this host".into()
    } else {
        format!(
            "{} files could not be removed: {}",
            leftovers.len(),
            leftovers.join(", ")
        )
    }
}
