//! `fdi-launch serve`: the other hosts' side of a split run. It waits for runs; for each it
//! runs the processes the coordinating host gives it on its own shared memory, bridges the
//! run's services with the other hosts (`fdi_runtime::net::Bridge`), reports what its
//! processes print and how they end, hands their traces to the coordinator, and removes
//! everything the run left once it is released, or at once when the coordinator is gone.

use fdi_common::run_dir::{Process, RunDir};
use fdi_common::stop::Stop;
use std::os::unix::process::ExitStatusExt;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use fdi_runtime::ipc::{check_prefix, Shm, Transport as _};
use fdi_runtime::net::{self, keys, Bridge, Layout, Net, NetConfig, NetOutbox, Request, Requests};
use fdi_runtime::process::{sizing_for, Placement, ProcessArgs};

use crate::run::hosts::{
    parse_wake, put_json, HostCommand, HostEvent, Released, RunReply, RunRequest,
};
use crate::run::supervisor::Supervisor;

/// `fdi-launch serve`.
#[derive(Debug, Clone, clap::Args)]
pub struct ServeArgs {
    /// This host's name, as the deployment file names it (`hosts.<name>`).
    #[arg(long)]
    pub name: String,
    /// The Zenoh endpoint to listen on, as the deployment file gives it:
    /// `tcp/<address>:<port>`.
    #[arg(long)]
    pub listen: String,
    /// Where a run's processes keep their traces until the coordinator has them (a folder per
    /// run, removed at its release). Default: the system's temporary folder.
    #[arg(long)]
    pub work_dir: Option<PathBuf>,
    /// Serve this many runs, then exit (default: until interrupted).
    #[arg(long)]
    pub runs: Option<u64>,
}

/// How long the coordinator's liveliness may stay unseen once a run is taken.
const COORDINATOR_SEEN_TIMEOUT: Duration = Duration::from_secs(5);
use crate::run::runtime::{GRACE, STALL_LIMIT};

pub fn serve(args: &ServeArgs, stop: &Stop) -> Result<ExitCode> {
    net::check_host_name(&args.name).map_err(|e| anyhow::anyhow!("--name: {e}"))?;
    net::check_endpoint(&args.listen).map_err(|e| anyhow::anyhow!("--listen: {e}"))?;
    let net = Net::open(&NetConfig {
        listen: vec![args.listen.clone()],
        connect: Vec::new(),
    })
    .with_context(|| format!("host `{}`", args.name))?;
    let _token = net.token(&keys::host(&args.name))?;
    let requests = net.requests(&keys::host_run(&args.name))?;
    eprintln!(
        "fdi-launch serve: host `{}` listens on {}; waiting for runs (Ctrl-C stops)",
        args.name, args.listen
    );
    let mut served = 0u64;
    while stop.pending().is_none() {
        let Some(request) = requests.next(Duration::from_millis(200))? else {
            continue;
        };
        match serve_run(&net, args, request, &requests, stop) {
            Ok(said) => eprintln!("fdi-launch serve: {said}"),
            Err(e) => eprintln!(
                "fdi-launch serve: {}",
                fdi_report::output::describe_error(&e)
            ),
        }
        served += 1;
        if args.runs.is_some_and(|n| served >= n) {
            break;
        }
    }
    if let Some(sig) = stop.take() {
        eprintln!(
            "fdi-launch serve: host `{}` stops ({})",
            args.name,
            crate::run::runtime::signal_name(sig)
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Takes one run request: starts the processes and answers, then follows the run to its
/// release (or the coordinator's loss). Returns what happened, in a line.
fn serve_run(
    net: &Net,
    args: &ServeArgs,
    request: Request,
    queue: &Requests,
    stop: &Stop,
) -> Result<String> {
    let parsed = serde_json::from_slice::<RunRequest>(&request.body())
        .map_err(|e| anyhow::anyhow!("not a run request: {e}"))
        .and_then(|r| {
            if r.host != args.name {
                bail!(
                    "the request is for host `{}`, this is `{}`",
                    r.host,
                    args.name
                );
            }
            if r.version != env!("CARGO_PKG_VERSION") {
                bail!(
                    "the coordinator runs fdi-mas {}, this host {}: both must run the same \
                     (the payloads travel as their layouts)",
                    r.version,
                    env!("CARGO_PKG_VERSION")
                );
            }
            check_prefix(&r.prefix)?;
            Ok(r)
        });
    let r = match parsed {
        Ok(r) => r,
        Err(e) => {
            let _ = request.answer(Err(format!("host `{}`: {e:#}", args.name)));
            return Err(e);
        }
    };
    let result = match HostRun::start(net, args, &r, stop) {
        Ok(run) => match serde_json::to_vec(&run.reply) {
            Ok(reply) => match request.answer(Ok(reply)) {
                Ok(()) => run.follow(net, args, queue),
                Err(e) => Err(e.into()),
            },
            Err(e) => Err(e.into()),
        },
        Err(e) => {
            let _ = request.answer(Err(format!(
                "host `{}`: {}",
                args.name,
                fdi_report::output::describe_error(&e)
            )));
            Err(e)
        }
    };
    // However the run ended here (its processes and bridge are gone by now), nothing of it
    // stays on this host.
    if let Err(e) = Shm::remove_leftovers(&r.prefix) {
        eprintln!(
            "fdi-launch serve: run {}: removing its files: {e}",
            r.prefix
        );
    }
    result.map_err(|e| e.context(format!("run {}", r.prefix)))
}

/// A run's share on this host.
struct HostRun {
    prefix: String,
    coordinator: String,
    reply: RunReply,
    procs: Supervisor<()>,
    bridge: Option<Bridge>,
    events: Arc<NetOutbox>,
    /// Per child: its end was reported.
    reported: Vec<bool>,
    /// The trace names of its processes (`agent-3`, ...).
    names: Vec<String>,
    dir: tempfile::TempDir,
    /// The serve's stop (SIGINT, SIGTERM).
    stop: Stop,
}

impl HostRun {
    fn start(net: &Net, args: &ServeArgs, r: &RunRequest, stop: &Stop) -> Result<Self> {
        let base = args.work_dir.clone().unwrap_or_else(std::env::temp_dir);
        std::fs::create_dir_all(&base)
            .with_context(|| format!("creating the work folder {}", base.display()))?;
        let dir = tempfile::Builder::new()
            .prefix(&format!("fdi-serve-{}-", r.prefix))
            .tempdir_in(&base)
            .with_context(|| format!("making a run folder in {}", base.display()))?;
        let run_dir = RunDir::new(dir.path());
        let scenario = run_dir.scenario();
        std::fs::write(&scenario, &r.scenario).context("writing the run's scenario")?;
        std::fs::create_dir_all(run_dir.traces()).context("making traces/")?;
        let resolved = fdi_common::scenario::load_file(&scenario)
            .map_err(|e| anyhow::anyhow!("the run's scenario: {e}"))?;
        let mut host_of = std::collections::BTreeMap::new();
        for (i, (word, host)) in r.layout.iter().enumerate() {
            let wake =
                parse_wake(word).with_context(|| format!("the run request's layout[{i}]"))?;
            host_of.insert(wake, host.clone());
        }
        let layout = Layout::new(host_of, &resolved);
        let plan = net::plan(&layout, &args.name).map_err(anyhow::Error::msg)?;
        let clock = net
            .clock_offset(&keys::run(&r.prefix, "clock"), 16)
            .context("measuring the clock against the coordinator's")?;
        let bridge = Bridge::start::<Shm>(
            net,
            &r.prefix,
            &r.prefix,
            sizing_for(&resolved),
            &plan,
            clock.offset_ns,
        )?;
        let events = Arc::new(net.outbox(&keys::run(&r.prefix, &format!("events/{}", args.name)))?);
        let tee_events = events.clone();
        let mut procs = Supervisor::with_tee(Arc::new(move |line: &str| {
            put_json(&tee_events, &HostEvent::Line { text: line.into() });
        }));
        let mut pids = Vec::new();
        for p in &r.processes {
            let mut cmd = crate::run::runtime::role_command(&p.role)?;
            let child = ProcessArgs {
                prefix: r.prefix.clone(),
                scenario: scenario.clone(),
                trace: run_dir.trace(p.name.parse::<Process>()?),
                agent: p.agent,
                launcher_pid: Some(std::process::id()),
                placement: Placement::default(),
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
            bridge: Some(bridge),
            events,
            reported: vec![false; n],
            names: r.processes.iter().map(|p| p.name.clone()).collect(),
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
    fn follow(mut self, net: &Net, args: &ServeArgs, queue: &Requests) -> Result<String> {
        let (cmd_tx, cmd_rx) = mpsc::channel();
        let _commands = net.subscribe(
            &keys::run(&self.prefix, &format!("cmd/{}", args.name)),
            move |bytes| {
                if let Ok(c) = serde_json::from_slice::<HostCommand>(&bytes) {
                    let _ = cmd_tx.send(c);
                }
            },
        )?;
        let (seen, alive) = (
            Arc::new(AtomicBool::new(false)),
            Arc::new(AtomicBool::new(false)),
        );
        let (s, a) = (seen.clone(), alive.clone());
        let _watch = net.watch(&keys::run(&self.prefix, "coordinator"), move |up| {
            if up {
                s.store(true, Ordering::SeqCst);
            }
            a.store(up, Ordering::SeqCst);
        })?;
        let traces = fdi_common::run_dir::RunDir::new(self.dir.path()).traces();
        let names = self.names.clone();
        let _traces = net.answer(
            &keys::run(&self.prefix, &format!("traces/{}", args.name)),
            move |ask| {
                let ask = String::from_utf8_lossy(ask).into_owned();
                let (name, offset) = ask
                    .split_once(' ')
                    .and_then(|(n, o)| Some((n.to_string(), o.parse::<u64>().ok()?)))
                    .ok_or_else(|| format!("`{ask}` does not ask for a piece of a trace"))?;
                if !names.contains(&name) {
                    return Err(format!("no process `{name}` ran on this host"));
                }
                let path = traces.join(format!("{name}.trace"));
                read_piece(&path, offset).map_err(|e| format!("reading {}: {e}", path.display()))
            },
        )?;
        let bridge_routes = self.bridge.as_ref().map(Bridge::routes);
        let _routes = net.answer(
            &keys::run(&self.prefix, &format!("routes/{}", args.name)),
            move |_| {
                let unmatched = bridge_routes
                    .as_ref()
                    .map(|r| r.unmatched())
                    .unwrap_or_default();
                serde_json::to_vec(&unmatched).map_err(|e| e.to_string())
            },
        )?;
        let release = net.requests(&keys::run(&self.prefix, &format!("release/{}", args.name)))?;
        let began = Instant::now();
        let mut failed = false;
        loop {
            self.report_exits();
            if let Some(text) = self.bridge.as_ref().and_then(Bridge::failure) {
                if !std::mem::replace(&mut failed, true) {
                    eprintln!("fdi-launch serve: run {}: {text}", self.prefix);
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
            // One run at a time: another coordinator is told at once, not left to time out.
            while let Some(other) = queue.next(Duration::ZERO)? {
                let _ = other.answer(Err(format!(
                    "host `{}` is busy with run {} of `{}`",
                    args.name, self.prefix, self.coordinator
                )));
            }
            for c in cmd_rx.try_iter() {
                match c {
                    HostCommand::Term => self.procs.signal_term(),
                    HostCommand::Kill => self.procs.kill_rest(),
                }
            }
            if let Some(req) = release.next(Duration::from_millis(20))? {
                self.stop_processes();
                let (removed, leftovers, counts) = self.clean_up();
                let carried = match counts {
                    Ok(c) => format!("{} payloads sent, {} received", c.sent, c.received),
                    Err(ref e) => format!("its bridge failed: {e}"),
                };
                let counts = counts.unwrap_or_default();
                let released = Released {
                    removed,
                    leftovers: leftovers.clone(),
                    sent: counts.sent,
                    received: counts.received,
                };
                req.answer(Ok(serde_json::to_vec(&released)?))?;
                return Ok(format!(
                    "run {} released by `{}`: {}; {}",
                    self.prefix,
                    self.coordinator,
                    carried,
                    left_behind(&leftovers)
                ));
            }
            let lost = if seen.load(Ordering::SeqCst) {
                !alive.load(Ordering::SeqCst)
            } else {
                began.elapsed() > COORDINATOR_SEEN_TIMEOUT
            };
            let interrupted = self.stop.pending();
            if lost || interrupted.is_some() {
                let labels: Vec<String> = self.procs.iter().map(|c| c.label.clone()).collect();
                self.stop_processes();
                let (_, leftovers, _) = self.clean_up();
                let why = match interrupted {
                    Some(sig) => {
                        format!("interrupted by {}", crate::run::runtime::signal_name(sig))
                    }
                    None => format!(
                        "the coordinator `{}` is unreachable (nothing heard for the {:.1} s \
                         lease)",
                        self.coordinator,
                        net::LEASE.as_secs_f64()
                    ),
                };
                return Ok(format!(
                    "run {}: {why}: stopped {}; {}",
                    self.prefix,
                    labels.join(", "),
                    left_behind(&leftovers)
                ));
            }
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
        for line in self.procs.drain_stderr(crate::run::runtime::OUTPUT_WAIT) {
            eprintln!("fdi-launch serve: warning: {line}");
        }
    }

    /// Stops the bridge and removes the run's files here: (removed, left, what the bridge
    /// carried or why it failed).
    fn clean_up(&mut self) -> (usize, Vec<String>, Result<net::BridgeCounts, String>) {
        let counts = match self.bridge.take().map(Bridge::stop) {
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

/// The piece of `path` from `offset` on, at most [`crate::run::remote::TRACE_PIECE`] bytes.
fn read_piece(path: &std::path::Path, offset: u64) -> std::io::Result<Vec<u8>> {
    use std::io::{Read as _, Seek as _};
    let mut f = std::fs::File::open(path)?;
    f.seek(std::io::SeekFrom::Start(offset))?;
    let mut piece = Vec::new();
    f.take(crate::run::remote::TRACE_PIECE)
        .read_to_end(&mut piece)?;
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
