//! The multi-process engine: spawns the agents, the attacker and the control center, supervises
//! them, and tears everything down (processes and shared memory) however the run ends.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use fdi_common::engine::LostAgent;
use fdi_common::observe::{Finish, Observer, Progress, Work};

pub use super::error::{RunError, DID_NOT_START};
use fdi_common::run_dir::{Process, RunDir};
use fdi_common::scenario::{ClockMode, Resolved};
use fdi_common::stop::{Interrupted, Stop, BEFORE_THE_START};
use fdi_runtime::ipc::{
    self, monotonic_ns, Bell as _, ControlMsg, Inbox as _, Outbox as _, Role, Shm, StatusMsg,
    Stream, Transport, Wake, Waker as _,
};
use fdi_runtime::process::procfs;

use crate::run::split::{Hosts, Split};
use crate::run::supervisor::{Child, Supervisor};
use fdi_control_center::controller::{Asker, AskerPorts};

/// Grace period between SIGTERM and SIGKILL when a run is torn down.
pub const GRACE: Duration = Duration::from_secs(2);
/// How long the end of the children's output is awaited once they are gone (the output of a
/// program outside the project may be held open by a process that left its group).
pub const OUTPUT_WAIT: Duration = Duration::from_secs(1);
/// How long the processes may take to report ready.
const READY_TIMEOUT: Duration = Duration::from_secs(30);
/// A process stopped (SIGSTOP) this long stalls the run: the launcher stops it with a message.
pub const STALL_LIMIT: Duration = Duration::from_secs(1);
/// A started run that makes no progress for this long (no report of the control center, which
/// reports every 500 ticks, and no process done) is stopped, named: whatever holds it (a lost
/// or forged frame between hosts, a process that waits for what never comes).
pub const STALL_TIMEOUT: Duration = Duration::from_secs(10);
/// Realtime runs start this long after the start message, so every process sees it in time.
const REALTIME_LEAD: Duration = Duration::from_millis(50);

/// What the launcher keeps about each of its children.
#[derive(Debug)]
struct Slot {
    wake: Wake,
    ready: bool,
    /// A program outside the project (`[roles]`): how long it may take to be ready, and to be
    /// done once the run's own processes are.
    external: Option<Duration>,
}

type Proc = Child<Slot>;

/// The role binaries: the sibling `fdi-agent` etc. when they are at least as new as this
/// executable, else this executable in the hidden multi-call mode (`fdi-launch process ROLE`),
/// which is always consistent with the launcher.
pub fn role_command(role: &str) -> Result<Command> {
    let me = std::env::current_exe().context("locating fdi-launch")?;
    let sibling = me.with_file_name(format!("fdi-{role}"));
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    if let (Some(s), Some(m)) = (modified(&sibling), modified(&me)) {
        if s >= m {
            return Ok(Command::new(sibling));
        }
    }
    let mut c = Command::new(me);
    c.args(["process", role]);
    Ok(c)
}

/// `SIGINT`, `SIGKILL`, ...: the name of signal `sig`, or its number.
pub fn signal_name(sig: i32) -> String {
    signal_hook::low_level::signal_name(sig).map_or_else(|| format!("signal {sig}"), Into::into)
}

/// A unique run prefix (short: iceoryx2 puts it into socket paths).
pub fn new_prefix() -> String {
    ipc::RunPrefix::fresh().to_string()
}

/// True while a process of the run `prefix` may still use its files: its launcher `pid` lives,
/// or some process names the prefix on its command line (a child outliving a killed launcher
/// for the moment it takes to exit).
fn run_alive(prefix: &str, pid: u32) -> bool {
    if procfs::exists(pid) {
        return true;
    }
    let Ok(pids) = procfs::pids() else {
        return true; // cannot tell: leave it
    };
    let needle = prefix.as_bytes();
    pids.into_iter()
        .any(|p| procfs::cmdline(p).is_ok_and(|c| c.windows(needle.len()).any(|w| w == needle)))
}

/// Removes the resources of runs whose launcher is dead (a killed launcher cannot clean up),
/// wherever iceoryx2 left them. Every command but the runtime's own processes calls it first.
pub fn reap_stale_runs() -> usize {
    let mut n = 0;
    let parse = |name: &str| ipc::RunPrefix::parse_start(name).map(|p| p.to_string());
    for p in Shm::runs_with_leftovers(parse) {
        let Some(pid) = ipc::RunPrefix::parse_start(&p).map(|p| p.launcher_pid()) else {
            continue;
        };
        if !run_alive(&p, pid) {
            n += Shm::remove_leftovers(&p).unwrap_or(0);
        }
    }
    n
}

/// What the caller needs after the processes ended.
#[derive(Debug)]
pub struct IpcOutcome {
    pub wall_s: f64,
    pub prefix: String,
    pub leftovers: Vec<PathBuf>,
    /// Realtime agents that died or fell silent while the run went on.
    pub lost: Vec<LostAgent>,
    /// The signal (SIGINT, SIGTERM) that interrupted the run after its start; the traces hold
    /// the run up to that point.
    pub interrupted: Option<i32>,
    /// How the processes ended, when interrupted.
    pub exits: String,
    /// A run split over hosts: one line per host (`RunSummary::hosts`).
    pub hosts: Vec<String>,
    /// A run split over hosts: its network path (`RunSummary::network`).
    pub network: Option<fdi_common::engine::NetworkPath>,
}

/// How the supervision of a started run ended.
struct Supervised {
    wall_s: f64,
    interrupted: Option<i32>,
}

/// Options of one multi-process run.
#[derive(Debug, Clone)]
pub struct IpcOptions {
    /// The run directory: `scenario.toml` is read from it, traces go to `traces/`.
    pub run_dir: PathBuf,
    /// Told the run's ticks as the control center reports them.
    pub progress: Observer,
    /// Replay mode (`run --replay`): only the control center runs, fed by a replayer process
    /// that plays back `traces/attacker.trace` of `run_dir` (already copied there).
    pub replay: bool,
    /// Where and how the run's processes are scheduled.
    pub placement: Placement,
    /// The processes write their traces into the named pipes of [`crate::run::tap`]
    /// (`traces/<process>.pipe`) instead of the trace files.
    pub pipes: bool,
    /// The run is split over hosts (`--hosts FILE`): where each process runs.
    pub split: Option<std::sync::Arc<dyn Split>>,
    /// The launcher's stop.
    pub stop: Stop,
    /// A lockstep run paced for watching (`--pace FACTOR`): the agents' argument.
    pub pace: Option<f64>,
    /// Where a split run leaves the way to its remote traces once it reached the other hosts
    /// (the live view's follower reads them as they grow).
    pub remote_traces: Option<crate::run::follow::RemoteSlot>,
}

pub use fdi_runtime::process::{Placement, ProcessArgs};

struct Launcher<X: Transport> {
    realtime: bool,
    lost: Vec<LostAgent>,
    procs: Supervisor<Slot>,
    bells: Vec<X::Bell>,
    control: X::Outbox<ControlMsg>,
    status: X::Inbox<StatusMsg>,
    waker: X::Waker,
    /// The launcher's stop: raised by SIGINT/SIGTERM (or a library caller).
    stop: Stop,
    /// The start was broadcast: from then on the run records.
    started: bool,
    /// The other hosts of a split run.
    remote: Option<Box<dyn Hosts>>,
    /// The last tick the control center reported, and when any process last said it moved
    /// on (or the start).
    progress: (u64, Instant),
    /// The agents that reported done (their last tick run), by id: a later "rejoined" of the
    /// control center, which lags behind robots that ran ahead of it on an overloaded machine,
    /// leaves them done.
    said_done: std::collections::BTreeSet<u32>,
}

impl<X: Transport> Launcher<X> {
    /// The signal (SIGINT, SIGTERM) the launcher received, if any.
    fn interrupt(&self) -> Option<i32> {
        self.stop.pending()
    }

    /// A host of a split run that is gone: before the start or in lockstep it ends the run
    /// (its message); in a started realtime run its agents are lost and the run goes on.
    fn host_lost(&mut self, done: &mut [bool], bar: &dyn Progress) -> Option<String> {
        if let Some(failed) = self.remote.as_ref()?.failure() {
            return Some(failed);
        }
        let lost = self.remote.as_mut()?.lost_host()?;
        let ran_only_agents = self
            .procs
            .iter()
            .filter(|p| p.host() == Some(lost.name.as_str()))
            .all(|p| matches!(p.meta.wake, Wake::Agent(_)));
        if !(self.realtime && self.started && ran_only_agents) {
            return Some(lost.message);
        }
        let reason = format!("host `{}` ({}) unreachable", lost.name, lost.endpoint);
        for (i, p) in self.procs.iter().enumerate() {
            if p.host() == Some(lost.name.as_str()) {
                done[i] = true;
            }
        }
        for &agent in &lost.agents {
            match self.lost.iter_mut().find(|x| x.agent == agent) {
                Some(x) => x.reason = reason.clone(),
                None => self.lost.push(LostAgent {
                    agent,
                    t_s: None,
                    reason: reason.clone(),
                    rejoined_t_s: None,
                }),
            }
        }
        bar.line(&format!(
            "{}; its agents are lost, the run goes on",
            lost.message
        ));
        None
    }

    /// Reaps exited children; returns the first abnormal exit that ends the run. Once a realtime
    /// run has started, an agent's abnormal exit does not end the run (the control center keeps controlling the
    /// others): it is recorded in `self.lost` instead.
    fn poll_children(&mut self) -> Option<String> {
        let mut failure = None;
        for i in self.procs.reap() {
            let p = &mut self.procs[i];
            let Some(st) = p.status.filter(|st| !st.success()) else {
                continue;
            };
            let what = p.ended(st);
            match (self.realtime && self.started, p.meta.wake) {
                (true, Wake::Agent(id)) => {
                    // The control center may have reported it silent first: one entry per
                    // agent, with the exit as its reason.
                    match self.lost.iter_mut().find(|x| x.agent == id) {
                        Some(x) => x.reason = what,
                        None => self.lost.push(LostAgent {
                            agent: id,
                            t_s: None,
                            reason: what,
                            rejoined_t_s: None,
                        }),
                    }
                }
                _ => {
                    failure.get_or_insert(what);
                }
            }
        }
        failure
    }

    /// The run has made no progress (no report of the control center, no process done) for
    /// `timeout`: says where it stopped and what the network path refused, if anything.
    fn no_progress(&self, resolved: &Resolved, timeout: Duration) -> Option<String> {
        let (tick, at) = self.progress;
        if at.elapsed() <= timeout {
            return None;
        }
        let refusals = self
            .remote
            .as_ref()
            .map(|r| r.refusals())
            .unwrap_or_default();
        let network = if self.remote.is_none() {
            String::new()
        } else if refusals.is_empty() {
            "; no frame was refused on the network path".into()
        } else {
            let said: Vec<String> = refusals.iter().map(ToString::to_string).collect();
            format!(
                "; frames were refused on the network path ({}): a forged, duplicated or \
                 reordered frame stops a lockstep run",
                said.join("; ")
            )
        };
        Some(format!(
            "no progress for {:.1} s (the stall timeout): the control center reported tick {tick} \
             of {} last{network}",
            at.elapsed().as_secs_f64(),
            resolved.ticks()
        ))
    }

    /// Once the run's own processes are all done, a program taking a role that has not
    /// reported done within its timeout after them (`since`: when they were), named.
    fn external_late(&self, done: &[bool], since: &mut Option<Instant>) -> Option<String> {
        let finished = |i: usize, p: &Proc| done[i] || p.status.is_some_and(|st| !st.success());
        let own = |(i, p): (usize, &Proc)| p.meta.external.is_some() || finished(i, p);
        if !self.procs.iter().enumerate().all(own) {
            return None;
        }
        let since = *since.get_or_insert_with(Instant::now);
        let (_, p) = self.procs.iter().enumerate().find(|(i, p)| {
            !finished(*i, p) && p.meta.external.is_some_and(|t| since.elapsed() > t)
        })?;
        Some(format!(
            "{} (pid {}) did not report done within {:.1} s after the run's other processes (a \
             program that takes a role reports done on `fdi/status` after its last message: \
             docs/protocol.md)",
            p.label,
            p.pid(),
            since.elapsed().as_secs_f64()
        ))
    }

    /// The processes that have not reported done (and not failed), named.
    fn not_done(&self, done: &[bool]) -> String {
        let names: Vec<&str> = self
            .procs
            .iter()
            .enumerate()
            .filter(|(i, p)| !(done[*i] || p.status.is_some_and(|st| !st.success())))
            .map(|(_, p)| p.label.as_str())
            .collect();
        names.join(", ")
    }

    /// A child stopped (SIGSTOP, or traced) for longer than [`STALL_LIMIT`], named.
    fn stalled(&mut self) -> Option<String> {
        self.procs.stalled(STALL_LIMIT)
    }

    /// How the children ended, e.g. `6 exited 0` or `5 exited 0, agent 2 killed by signal 9`.
    fn exits(&self) -> String {
        self.procs.exits()
    }

    /// Reads the processes' status reports: progress (the control center's), done, agents
    /// lost and rejoined (realtime).
    fn take_status(&mut self, done: &mut [bool], bar: &dyn Progress, dt: f64) -> Result<()> {
        let (mut lost, mut rejoined) = (Vec::new(), Vec::new());
        let procs = &self.procs;
        let progress = &mut self.progress;
        let said_done = &mut self.said_done;
        self.status.drain(|m| {
            // Progress: anything the control center says, and any process's progress or done
            // (a realtime robot that fell behind its clock still ticks after the center is
            // done). The tick kept is the center's.
            let center = Role::from_code(m.role) == Some(Role::Center);
            if center {
                *progress = (progress.0.max(m.tick), Instant::now());
            } else if m.kind == StatusMsg::DONE || m.kind == StatusMsg::PROGRESS {
                progress.1 = Instant::now();
            }
            if Role::from_code(m.role) == Some(Role::Center) {
                bar.at(m.tick);
            }
            if m.kind == StatusMsg::DONE {
                if let Some(i) = procs.iter().position(|p| matches_status(p.meta.wake, &m)) {
                    done[i] = true;
                    if let Wake::Agent(id) = procs[i].meta.wake {
                        said_done.insert(id);
                    }
                }
            }
            if m.kind == StatusMsg::LOST {
                lost.push((m.agent, m.tick as f64 * dt));
            }
            if m.kind == StatusMsg::REJOINED {
                rejoined.push((m.agent, m.tick as f64 * dt));
            }
        })?;
        let slot = |procs: &Supervisor<Slot>, agent| {
            procs.iter().position(|p| p.meta.wake == Wake::Agent(agent))
        };
        for (agent, t) in lost {
            if let Some(i) = slot(&self.procs, agent) {
                done[i] = true; // a lost agent will not report done
            }
            match self.lost.iter_mut().find(|x| x.agent == agent) {
                Some(x) => x.t_s = Some(t),
                None => self.lost.push(LostAgent {
                    agent,
                    t_s: Some(t),
                    reason: "fell silent".into(),
                    rejoined_t_s: None,
                }),
            }
            bar.line(&format!(
                "agent {agent} lost at t = {t:.3} s; the run goes on"
            ));
        }
        for (agent, t) in rejoined {
            let Some(x) = self.lost.iter_mut().find(|x| x.agent == agent) else {
                continue;
            };
            x.rejoined_t_s = Some(t);
            // It is controlled again and will report done itself, unless its process ended or
            // it reported done already (issue 51: a robot that ran ahead of an overloaded
            // center was done when the center found it again, and the run was taken for
            // stalled).
            if let Some(i) = slot(&self.procs, agent) {
                done[i] = self.procs[i].status.is_some() || self.said_done.contains(&agent);
            }
            let gap = x.t_s.map_or(String::new(), |from| {
                format!(" after a gap of {:.3} s", t - from)
            });
            bar.line(&format!("agent {agent} rejoined at t = {t:.3} s{gap}"));
        }
        Ok(())
    }

    /// A process that exited cleanly without reporting done (SIGTERM sent to it alone) ends the
    /// run too: its peers would wait for it. Its done may have raced its exit: the reports are
    /// read once more before deciding. Names it.
    fn ended_early(&mut self, done: &mut [bool]) -> Result<Option<String>> {
        let early = |done: &[bool], procs: &[Proc]| {
            procs
                .iter()
                .enumerate()
                .position(|(i, p)| p.status.is_some_and(|st| st.success()) && !done[i])
        };
        if early(done, &self.procs).is_none() {
            return Ok(None);
        }
        let procs = &self.procs;
        self.status.drain(|m| {
            if m.kind == StatusMsg::DONE {
                if let Some(i) = procs.iter().position(|p| matches_status(p.meta.wake, &m)) {
                    done[i] = true;
                }
            }
        })?;
        Ok(early(done, &self.procs).map(|i| {
            let p = &self.procs[i];
            format!(
                "{} (pid {}) exited before the end of the run",
                p.label,
                p.pid()
            )
        }))
    }

    fn broadcast(&self, msg: ControlMsg) {
        let _ = self.control.send(msg);
        for b in &self.bells {
            let _ = b.ring();
        }
    }

    /// Stops every child still running: STOP message, SIGTERM, then SIGKILL after the grace.
    fn teardown(&mut self) {
        self.broadcast(ControlMsg {
            command: ControlMsg::STOP,
            reserved: 0,
            epoch_ns: 0,
        });
        // A stopped process (SIGSTOP) acts on the SIGTERM only once continued: it then exits on
        // its own with its trace flushed, not SIGKILLed after the grace.
        self.procs.signal_term();
        let began = Instant::now();
        while self
            .procs
            .iter()
            .any(|p| p.status.is_none() && !p.unreachable())
            && began.elapsed() < GRACE
        {
            self.poll_children();
            std::thread::sleep(Duration::from_millis(10));
        }
        self.procs.kill_rest();
        // What the programs outside the project started goes with them, named.
        for line in self.procs.end_programs(GRACE) {
            log::info!("{line}");
        }
    }
}

/// Runs the resolved scenario in `opts.run_dir` (which must already hold `scenario.toml`).
pub fn run_ipc(resolved: &Resolved, opts: &IpcOptions) -> Result<IpcOutcome, RunError> {
    reap_stale_runs();
    let prefix = new_prefix();
    let run_dir = RunDir::new(&opts.run_dir);
    let scenario_path = run_dir.scenario();
    std::fs::create_dir_all(run_dir.traces()).context("creating the traces folder")?;
    opts.stop
        .check(BEFORE_THE_START)
        .map_err(RunError::not_started)?;
    let sizing = check_machine(resolved, &prefix).map_err(RunError::not_started)?;

    let ended = {
        let (transport, mut launcher) =
            open_launcher(resolved, &opts.stop, &prefix, sizing).map_err(RunError::not_started)?;
        run_and_tear_down(
            resolved,
            opts,
            &prefix,
            &scenario_path,
            &transport,
            &mut launcher,
        )
        // ports and node dropped here, before the files are removed
    };
    let Ended {
        result,
        lost,
        exits,
        remote_left,
        hosts,
        network,
    } = ended;
    Shm::remove_leftovers(&prefix).ok();
    let mut leftovers = Shm::leftovers(&prefix);
    leftovers.extend(remote_left.into_iter().map(PathBuf::from));
    let Supervised {
        wall_s,
        interrupted,
    } = result?;
    if interrupted.is_some() {
        // Acted on: from here on (the join, the report) only a new signal interrupts.
        opts.stop.take();
    }
    Ok(IpcOutcome {
        wall_s,
        prefix,
        leftovers,
        lost,
        interrupted,
        exits,
        hosts,
        network,
    })
}

/// The controller program of an in-process run (`[roles.controller]`, lockstep): started on a
/// node of the launcher's own in the run directory `run_dir` and its ports opened first, as
/// the control center opens them; once it is ready, `body` runs the engine and asks it through
/// an [`Asker`] (a stop, or the program's exit, ends the wait for an answer); then the program
/// is let go once it reported done, and everything it started is ended. Returns `body`'s result
/// and the program's closing note.
pub fn with_controller_program<T>(
    resolved: &Resolved,
    run_dir: &Path,
    stop: &Stop,
    body: impl FnOnce(&mut Asker<'_, Shm>) -> Result<T>,
) -> Result<(T, String), RunError> {
    let Some(role) = &resolved.scenario.roles.controller else {
        return Err(anyhow::anyhow!("the scenario has no `[roles.controller]`").into());
    };
    reap_stale_runs();
    let prefix = new_prefix();
    stop.check(BEFORE_THE_START)
        .map_err(RunError::not_started)?;
    let sizing = check_machine(resolved, &prefix).map_err(RunError::not_started)?;
    let result = {
        let (transport, mut l) =
            open_launcher(resolved, stop, &prefix, sizing).map_err(RunError::not_started)?;
        let r = host_and_ask(
            resolved,
            (run_dir, &prefix),
            (&transport, &mut l),
            role,
            body,
        );
        l.teardown();
        for line in l.procs.drain_stderr(OUTPUT_WAIT) {
            log::warn!("{line}");
        }
        match r {
            Err(e) if !l.started => Err(RunError::not_started(e)),
            r => r.map_err(RunError::Failed),
        }
        // ports and node dropped here, before the files are removed
    };
    Shm::remove_leftovers(&prefix).ok();
    result
}

/// [`with_controller_program`] on the launcher `l`'s node `transport`.
fn host_and_ask<T>(
    resolved: &Resolved,
    (run_dir, prefix): (&Path, &str),
    (transport, l): (&Shm, &mut Launcher<Shm>),
    role: &fdi_common::roles::ExternalRole,
    body: impl FnOnce(&mut Asker<'_, Shm>) -> Result<T>,
) -> Result<(T, String)> {
    let ports = AskerPorts::open(transport)?;
    let scenario = RunDir::new(run_dir).scenario();
    spawn_externals(resolved, (false, run_dir), prefix, &scenario, l)?;
    await_ready(l)?;
    start_run(resolved, transport, l)?;
    let ids: Vec<u32> = resolved.scenario.agents.iter().map(|a| a.id).collect();
    let (out, note) = {
        let mut watch = || -> Result<(), fdi_runtime::process::RoleError> {
            let failed = match l.interrupt() {
                Some(signal) => Some(format!("interrupted by {}", signal_name(signal))),
                None => l.poll_children(),
            };
            failed.map_or(Ok(()), |f| {
                Err(fdi_runtime::process::RoleError::External(f))
            })
        };
        let mut asker = Asker::new((transport, ports), role, &ids, &mut watch);
        let out = body(&mut asker)?;
        (out, asker.summary())
    };
    // Interrupted: the engine stopped where it was; the program is ended with the run.
    if l.interrupt().is_none() {
        let stall_timeout = stall_timeout_of(resolved, None, None);
        supervise(
            resolved,
            l,
            &fdi_common::observe::Quiet,
            Instant::now(),
            stall_timeout,
        )?;
        release_and_reap(l)?;
    }
    Ok((out, note))
}

/// The sizing of the run's services, once the machine is known to carry them.
fn check_machine(resolved: &Resolved, prefix: &str) -> Result<ipc::Sizing> {
    let sizing = fdi_runtime::process::sizing_for(resolved);
    // A full shared-memory folder, a read-only iceoryx2 folder or a low open-file limit is
    // named now, with its fix: past this point iceoryx2 reports them as a SIGBUS or an
    // internal error.
    let external = resolved.has_external_roles();
    ipc::machine::check(sizing, external, prefix).context("the machine cannot carry this run")?;
    Ok(sizing)
}

/// Opens the launcher's node and ports, and makes the launcher that owns them.
fn open_launcher(
    resolved: &Resolved,
    stop: &Stop,
    prefix: &str,
    sizing: ipc::Sizing,
) -> Result<(Shm, Launcher<Shm>)> {
    // What a failed node or port creation made is the run's: removed.
    let opened = Shm::open(prefix, "launcher", sizing).and_then(|transport| {
        let ports = (
            transport.publisher(Stream::Control)?,
            transport.subscriber(Stream::Status)?,
            transport.waker(Wake::Launcher)?,
        );
        Ok((transport, ports))
    });
    let (transport, (control, status, waker)) = match opened {
        Ok(opened) => opened,
        Err(e) => {
            Shm::remove_leftovers(prefix).ok();
            return Err(anyhow::Error::new(e));
        }
    };
    let launcher = Launcher {
        realtime: resolved.scenario.clock == ClockMode::Realtime,
        lost: Vec::new(),
        procs: Supervisor::default(),
        bells: Vec::new(),
        control,
        status,
        waker,
        stop: stop.clone(),
        started: false,
        remote: None,
        progress: (0, Instant::now()),
        said_done: std::collections::BTreeSet::new(),
    };
    Ok((transport, launcher))
}

/// How a run ended, once its processes are torn down.
struct Ended {
    result: Result<Supervised, RunError>,
    lost: Vec<LostAgent>,
    exits: String,
    /// Files of the run left on the other hosts.
    remote_left: Vec<String>,
    /// One line per host of a split run.
    hosts: Vec<String>,
    network: Option<fdi_common::engine::NetworkPath>,
}

/// Connects the other hosts (if any), spawns and supervises the run, and tears it down
/// however it ended.
fn run_and_tear_down<X: Transport>(
    resolved: &Resolved,
    opts: &IpcOptions,
    prefix: &str,
    scenario_path: &Path,
    transport: &X,
    launcher: &mut Launcher<X>,
) -> Ended {
    // A failure to reach the other hosts goes the way of every other failure: through the
    // teardown and the removal of the run's files below.
    let connected = connect_remote(resolved, opts, prefix, launcher);
    let r = connected.and_then(|()| {
        spawn_and_supervise(resolved, opts, prefix, scenario_path, transport, launcher)
    });
    launcher.teardown();
    // Every child has exited: what they printed is relayed whole before we go on, unless
    // a process that left a program's group still holds its output.
    for line in launcher.procs.drain_stderr(OUTPUT_WAIT) {
        log::warn!("{line}");
    }
    let (remote_left, hosts, network) = release_remote(opts, launcher);
    let r = match r {
        Err(e) if !launcher.started => Err(RunError::not_started(e)),
        Err(e) => Err(RunError::Failed(e)),
        Ok(supervised) => Ok(supervised),
    };
    Ended {
        result: r,
        lost: std::mem::take(&mut launcher.lost),
        exits: launcher.exits(),
        remote_left,
        hosts,
        network,
    }
}

/// Reaches the other hosts of a split run and starts the bridge to them.
fn connect_remote<X: Transport>(
    resolved: &Resolved,
    opts: &IpcOptions,
    prefix: &str,
    launcher: &mut Launcher<X>,
) -> Result<()> {
    match &opts.split {
        Some(split) => split
            .connect(prefix, fdi_runtime::process::sizing_for(resolved))
            .map(|r| {
                if let Some(slot) = &opts.remote_traces {
                    *crate::run::relay::lock(slot) = Some(r.traces());
                }
                launcher.remote = Some(r)
            }),
        None => Ok(()),
    }
}

/// Describes the other hosts, fetches their traces (of a started run) and releases them:
/// the files left on them, and one line per host.
fn release_remote<X: Transport>(
    opts: &IpcOptions,
    launcher: &mut Launcher<X>,
) -> (
    Vec<String>,
    Vec<String>,
    Option<fdi_common::engine::NetworkPath>,
) {
    let mut remote_left = Vec::new();
    let mut hosts = Vec::new();
    let mut network = None;
    if let Some(slot) = &opts.remote_traces {
        // The live view reads the rest from the fetched copies.
        *crate::run::relay::lock(slot) = None;
    }
    if let Some(mut remote) = launcher.remote.take() {
        hosts.push(remote.describe_coordinator());
        hosts.extend(remote.describe());
        if launcher.started {
            for p in remote.fetch_traces(&opts.run_dir) {
                log::warn!("{p}");
            }
        }
        let released = remote.release();
        for p in released.problems {
            log::warn!("{p}");
        }
        remote_left = released.leftovers;
        network = Some(released.network);
    }
    (remote_left, hosts, network)
}

/// Spawns the processes, waits until they are ready, starts the run and supervises it to
/// its end.
fn spawn_and_supervise<X: Transport>(
    resolved: &Resolved,
    opts: &IpcOptions,
    prefix: &str,
    scenario_path: &Path,
    transport: &X,
    l: &mut Launcher<X>,
) -> Result<Supervised> {
    spawn_roles(resolved, opts, prefix, scenario_path, l)?;
    await_ready(l)?;
    spawn_externals(
        resolved,
        (opts.replay, &opts.run_dir),
        prefix,
        scenario_path,
        l,
    )?;
    await_ready(l)?;
    let bar = &*opts.progress;
    bar.begin(Work::Ticks {
        total: resolved.ticks(),
        period_s: resolved.scenario.control_period_s,
    });
    if let Some(remote) = &l.remote {
        remote.await_routes()?;
    }
    let started = start_run(resolved, transport, l)?;
    let stall_timeout = stall_timeout_of(resolved, opts.split.as_deref(), opts.pace);
    let (wall_s, interrupted) = supervise(resolved, l, bar, started, stall_timeout)?;
    if interrupted.is_some() {
        return Ok(Supervised {
            wall_s,
            interrupted,
        });
    }
    bar.finish(Finish::Done);
    release_and_reap(l)?;
    Ok(Supervised {
        wall_s,
        interrupted: None,
    })
}

/// One process of the run's own: its role binary, its name, its wake-up event, its agent.
struct RoleProcess {
    role: String,
    process: Process,
    wake: Wake,
    agent: Option<u32>,
}

/// Spawns the run's processes: the control center, the attacker (or the replayer) and the
/// agents.
fn spawn_roles<X: Transport>(
    resolved: &Resolved,
    opts: &IpcOptions,
    prefix: &str,
    scenario_path: &Path,
    l: &mut Launcher<X>,
) -> Result<()> {
    let mut remote_procs = Vec::new();
    for rp in roles_of_run(resolved, opts) {
        let label = match rp.agent {
            Some(id) => format!("agent {id}"),
            None => rp.role.clone(),
        };
        if let Some(split) = &opts.split {
            if !split.is_local(rp.wake) {
                remote_procs.push((rp.wake, label));
                continue;
            }
        }
        spawn_local(&rp, label, opts, prefix, scenario_path, l)?;
    }
    if let Some(remote) = &mut l.remote {
        let scenario = std::fs::read_to_string(scenario_path)
            .with_context(|| format!("reading {}", scenario_path.display()))?;
        for (wake, label, child) in remote.start_hosts(&scenario, remote_procs)? {
            let slot = Slot {
                wake,
                ready: false,
                external: None,
            };
            l.procs.adopt_remote(label, slot, child);
        }
        for line in remote.describe() {
            log::info!("{line}");
        }
    }
    Ok(())
}

/// The run's own processes: the control center, then the attacker and the agents, or the
/// replayer alone in replay mode.
fn roles_of_run(resolved: &Resolved, opts: &IpcOptions) -> Vec<RoleProcess> {
    let role = |role: &str, process: Process, wake: Wake, agent: Option<u32>| RoleProcess {
        role: role.into(),
        process,
        wake,
        agent,
    };
    let mut roles = vec![role(Process::CENTER, Process::Center, Wake::Center, None)];
    if opts.replay {
        // The replayer stands in for the attacker (and the agents); its `--trace` is the
        // attacker trace it plays back.
        roles.push(role("replayer", Process::Attacker, Wake::Attacker, None));
    } else {
        roles.push(role(
            Process::ATTACKER,
            Process::Attacker,
            Wake::Attacker,
            None,
        ));
        for a in &resolved.scenario.agents {
            roles.push(role(
                "agent",
                Process::Agent(a.id),
                Wake::Agent(a.id),
                Some(a.id),
            ));
        }
    }
    roles
}

/// Spawns one of the run's own processes on this host, unless the launcher was interrupted.
fn spawn_local<X: Transport>(
    rp: &RoleProcess,
    label: String,
    opts: &IpcOptions,
    prefix: &str,
    scenario_path: &Path,
    l: &mut Launcher<X>,
) -> Result<()> {
    if let Some(signal) = l.interrupt() {
        return Err(Interrupted {
            signal,
            phase: BEFORE_THE_START,
        }
        .into());
    }
    let run_dir = RunDir::new(&opts.run_dir);
    let mut cmd = role_command(&rp.role)?;
    let args = ProcessArgs {
        prefix: prefix.to_string(),
        scenario: scenario_path.to_path_buf(),
        trace: if opts.pipes {
            run_dir.pipe(rp.process)
        } else {
            run_dir.trace(rp.process)
        },
        agent: rp.agent,
        launcher_pid: Some(std::process::id()),
        placement: opts.placement.clone(),
        pace: opts.pace,
    };
    cmd.args(args.to_args());
    if opts.pace.is_some() {
        // Paced, the processes wait most of each tick: spinning before they block would only
        // burn the CPUs.
        cmd.env("FDI_SPIN_US", "0");
    }
    l.procs.spawn(
        label,
        Slot {
            wake: rp.wake,
            ready: false,
            external: None,
        },
        cmd,
    )?;
    Ok(())
}

/// Spawns the programs that take a role (`[roles]`), once the run's own processes are ready:
/// every service they open exists by then. Each gets the run's prefix and parameters in its
/// environment (docs/protocol.md). In replay mode the attacker program does not run (the
/// replayer stands in for the attacker).
fn spawn_externals<X: Transport>(
    resolved: &Resolved,
    (replay, run_dir): (bool, &Path),
    prefix: &str,
    scenario_path: &Path,
    l: &mut Launcher<X>,
) -> Result<()> {
    use fdi_runtime::process::external::{environment, ExternalKind};
    let roles = &resolved.scenario.roles;
    let attacker = roles.attacker.as_ref().filter(|_| !replay);
    for (kind, role, wake, what) in [
        (
            ExternalKind::Attacker,
            attacker,
            Wake::ExternalAttacker,
            "external attacker",
        ),
        (
            ExternalKind::Monitor,
            roles.monitor.as_ref(),
            Wake::Monitor,
            "monitor",
        ),
        (
            ExternalKind::Controller,
            roles.controller.as_ref(),
            Wake::ExternalController,
            "controller",
        ),
    ] {
        let Some(role) = role else { continue };
        let label = format!("{what} `{}`", role.label());
        let Some((program, args)) = role.command.split_first() else {
            bail!("{label}: `command` names no program");
        };
        let mut cmd = Command::new(program);
        cmd.args(args)
            .envs(environment(kind, prefix, resolved, scenario_path, run_dir));
        let slot = Slot {
            wake,
            ready: false,
            external: Some(role.timeout()),
        };
        l.procs.spawn_external(label, slot, cmd)?;
    }
    Ok(())
}

/// Waits until every process reported ready (its ports exist; only then can nothing sent be
/// lost), naming the first that fails, stalls or never gets there.
fn await_ready<X: Transport>(l: &mut Launcher<X>) -> Result<()> {
    let began = Instant::now();
    while l.procs.iter().any(|p| !p.meta.ready) {
        if let Some(signal) = l.interrupt() {
            return Err(Interrupted {
                signal,
                phase: BEFORE_THE_START,
            }
            .into());
        }
        if let Some(failed) = l.poll_children() {
            // A signal to the process group reaches the launcher in the same kill() as the
            // child: if the child died of it, the launcher's flag is set by now.
            if let Some(signal) = l.interrupt() {
                return Err(Interrupted {
                    signal,
                    phase: BEFORE_THE_START,
                }
                .into());
            }
            bail!("{failed} before the start");
        }
        // A process that ended cleanly before it was ready (SIGTERM sent to it alone) will
        // never be: named at once, as during the run.
        if let Some(p) = l
            .procs
            .iter()
            .find(|p| !p.meta.ready && p.status.is_some_and(|st| st.success()))
        {
            bail!(
                "{} (pid {}) exited before it was ready (before the start)",
                p.label,
                p.pid()
            );
        }
        if let Some(stall) = l.stalled() {
            bail!("{stall} (before the start)");
        }
        if let Some(lost) = l.host_lost(&mut [], &fdi_common::observe::Quiet) {
            bail!("{lost} (before the start)");
        }
        // The run's own processes get READY_TIMEOUT; a program outside the project its
        // role's timeout.
        let late: Vec<&str> = l
            .procs
            .iter()
            .filter(|p| !p.meta.ready && began.elapsed() > p.meta.external.unwrap_or(READY_TIMEOUT))
            .map(|p| p.label.as_str())
            .collect();
        if !late.is_empty() {
            let external = l
                .procs
                .iter()
                .any(|p| !p.meta.ready && p.meta.external.is_some());
            let hint = if external {
                " (a program that takes a role reports ready on `fdi/status` once its ports are \
                 open: docs/protocol.md)"
            } else {
                ""
            };
            bail!(
                "not ready after {:.1} s: {}{hint}",
                began.elapsed().as_secs_f64(),
                late.join(", ")
            );
        }
        l.waker.wait(Duration::from_millis(20))?;
        let procs = &mut l.procs;
        l.status.drain(|m| {
            if m.kind == StatusMsg::READY {
                if let Some(p) = procs.iter_mut().find(|p| matches_status(p.meta.wake, &m)) {
                    p.meta.ready = true;
                }
            }
        })?;
    }

    Ok(())
}

/// Broadcasts the start (realtime: sim time zero a short lead ahead); returns when.
fn start_run<X: Transport>(
    resolved: &Resolved,
    transport: &X,
    l: &mut Launcher<X>,
) -> Result<Instant> {
    // Notifiers are created once every listener exists: a notifier created earlier may not
    // reach a listener that appears later, and the start would then wait for a timeout.
    for p in l.procs.iter() {
        l.bells.push(transport.notifier(p.meta.wake)?);
    }
    let lead = if resolved.scenario.clock == ClockMode::Realtime {
        REALTIME_LEAD
    } else {
        Duration::ZERO
    };
    let started = Instant::now();
    l.started = true;
    l.broadcast(ControlMsg {
        command: ControlMsg::START,
        reserved: 0,
        epoch_ns: monotonic_ns() + lead.as_nanos() as u64,
    });
    Ok(started)
}

/// Supervises the started run until every process is done (or an interrupt, a failure, a
/// stall). Returns the run's wall time and the interrupting signal, if any.
fn supervise<X: Transport>(
    resolved: &Resolved,
    l: &mut Launcher<X>,
    bar: &dyn Progress,
    started: Instant,
    stall_timeout: Duration,
) -> Result<(f64, Option<i32>)> {
    let dt = resolved.scenario.control_period_s;
    l.progress = (0, started);
    let mut done = vec![false; l.procs.len()];
    // When the run's own processes were all done: the programs taking roles must be done
    // within their timeout after it.
    let mut own_done: Option<Instant> = None;
    let interrupted = |l: &mut Launcher<X>| {
        l.interrupt().map(|signal| {
            bar.finish(Finish::Stopped);
            l.teardown();
            (started.elapsed().as_secs_f64(), Some(signal))
        })
    };
    loop {
        l.waker.wait(Duration::from_millis(50))?;
        // An interrupt comes first: whatever a child did after it is part of the stop.
        if let Some(end) = interrupted(l) {
            return Ok(end);
        }
        l.take_status(&mut done, bar, dt)?;
        if let Some(lost) = l.host_lost(&mut done, bar) {
            bar.finish(Finish::Stopped);
            bail!("run stopped: {lost}");
        }
        if let Some(failed) = l.poll_children() {
            // A child killed by the signal that interrupted the launcher (the same kill() of the
            // process group) is part of the interrupt, not a failure.
            if let Some(end) = interrupted(l) {
                return Ok(end);
            }
            bar.finish(Finish::Stopped);
            bail!("run stopped: {failed}");
        }
        if let Some(early) = l.ended_early(&mut done)? {
            bar.finish(Finish::Stopped);
            bail!("run stopped: {early}");
        }
        // The simulation ends when every process has reported done (its trace is flushed by
        // then); process exit is teardown and not part of the run's wall time.
        let finished = |i: usize, p: &Proc| done[i] || p.status.is_some_and(|st| !st.success());
        if l.procs.iter().enumerate().all(|(i, p)| finished(i, p))
            || l.procs.iter().all(|p| p.status.is_some())
        {
            return Ok((started.elapsed().as_secs_f64(), None));
        }
        if let Some(late) = l.external_late(&done, &mut own_done) {
            bar.finish(Finish::Stopped);
            bail!("run stopped: {late}");
        }
        if let Some(stall) = l.stalled() {
            bar.finish(Finish::Stopped);
            l.teardown();
            bail!("run stalled: {stall} (processes: {})", l.exits());
        }
        if let Some(stall) = l.no_progress(resolved, stall_timeout) {
            bar.finish(Finish::Stopped);
            let waiting = l.not_done(&done);
            l.teardown();
            bail!(
                "run stalled: {stall}; not done: {waiting} (processes: {})",
                l.exits()
            );
        }
    }
}

/// How long a started run may go without progress before it is stopped as stalled: the
/// deployment's `stall_timeout_s` (split runs) or [`STALL_TIMEOUT`], and never less than what a
/// program that takes a role may take to answer, plus a second.
fn stall_timeout_of(resolved: &Resolved, split: Option<&dyn Split>, pace: Option<f64>) -> Duration {
    let roles = &resolved.scenario.roles;
    let mut base = split
        .and_then(Split::stall_timeout)
        .unwrap_or(STALL_TIMEOUT);
    // A paced or realtime run reports its progress every `PROGRESS_EVERY` ticks (or once, at
    // its end, when it has fewer) at its pace: twice that long without a report is a stall (a
    // realtime run of one 40 s tick was stopped as stalled after 10 s).
    let realtime = resolved.scenario.clock == fdi_common::scenario::ClockMode::Realtime;
    if let Some(p) = pace.or(realtime.then_some(1.0)) {
        base = base.max(STALL_TIMEOUT + reports_apart(resolved, p).saturating_mul(2));
    }
    [
        roles.attacker.as_ref(),
        roles.monitor.as_ref(),
        roles.controller.as_ref(),
    ]
    .into_iter()
    .flatten()
    .map(|r| r.timeout() + Duration::from_secs(1))
    .fold(base, Duration::max)
}

/// How much wall time passes between two progress reports of a run of `resolved` at `pace` ×
/// real time: [`PROGRESS_EVERY`](fdi_runtime::process::PROGRESS_EVERY) ticks, or the whole
/// run when it has fewer.
fn reports_apart(resolved: &Resolved, pace: f64) -> Duration {
    let ticks = fdi_runtime::process::PROGRESS_EVERY.min(resolved.ticks().max(1));
    let s = ticks as f64 * resolved.scenario.control_period_s / pace;
    Duration::try_from_secs_f64(s).unwrap_or(Duration::MAX)
}

/// Every process is done: the stop lets them go (each keeps its ports until then, so that no
/// last message leaves with its sender); their exits are reaped, and a process that fails on
/// its way out still fails the run.
fn release_and_reap<X: Transport>(l: &mut Launcher<X>) -> Result<()> {
    l.broadcast(ControlMsg {
        command: ControlMsg::STOP,
        reserved: 0,
        epoch_ns: 0,
    });
    let began = Instant::now();
    while l
        .procs
        .iter()
        .any(|p| p.status.is_none() && !p.unreachable())
        && began.elapsed() < GRACE
    {
        if let Some(failed) = l.poll_children() {
            bail!("run stopped: {failed}");
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    Ok(())
}

fn matches_status(wake: Wake, m: &StatusMsg) -> bool {
    match (wake, Role::from_code(m.role)) {
        (Wake::Agent(id), Some(Role::Agent)) => id == m.agent,
        (Wake::Attacker, Some(Role::Attacker))
        | (Wake::Center, Some(Role::Center))
        | (Wake::ExternalAttacker, Some(Role::ExternalAttacker))
        | (Wake::Monitor, Some(Role::Monitor))
        | (Wake::ExternalController, Some(Role::ExternalController)) => true,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    /// Regression (issue 51): a valid realtime run of one 40 s tick reports its progress once,
    /// at its end, and was stopped as stalled by the 10 s watchdog. A realtime run's stall
    /// timeout is at least twice the wall time between two of its reports, plus the 10 s.
    #[test]
    fn the_stall_timeout_of_a_realtime_run_outlasts_the_time_between_its_reports() {
        use fdi_common::scenario::ClockMode;
        use std::time::Duration;
        let mut r = fdi_common::scenario::paper().expect("paper");
        let timeout =
            |r: &fdi_common::scenario::Resolved, pace| super::stall_timeout_of(r, None, pace);
        assert_eq!(timeout(&r, None), super::STALL_TIMEOUT, "lockstep");
        r.scenario.clock = ClockMode::Realtime;
        // 500 ticks of 1 ms apart: 10 s + 2 × 0.5 s.
        assert_eq!(timeout(&r, None), Duration::from_secs(11));
        r.scenario.control_period_s = 40.0;
        r.scenario.duration_s = 40.0;
        assert_eq!(r.ticks(), 1);
        assert_eq!(timeout(&r, None), Duration::from_secs(90));
        // Lockstep paced at a tenth of real time: the same rule at its pace.
        r.scenario.clock = ClockMode::Lockstep;
        assert_eq!(timeout(&r, Some(0.1)), Duration::from_secs(810));
    }
}
