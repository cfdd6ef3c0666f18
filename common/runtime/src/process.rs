//! What every runtime process shares around its main loop: arguments from the launcher,
//! shutdown on SIGINT/SIGTERM or on the launcher's death, the start handshake and status reports.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::ipc::{
    Bell, ControlMsg, Inbox, IpcError, Outbox, Role, StatusMsg, Waker, ZeroCopySendCopy,
};

/// Arguments the launcher passes to every process: the child parses them (clap), the launcher
/// builds a child's command line from the same struct ([`ProcessArgs::to_args`]).
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct ProcessArgs {
    /// Run prefix (iceoryx2 `global.prefix`): isolates this run's services.
    #[arg(long)]
    pub prefix: String,
    /// Resolved scenario file of the run.
    #[arg(long)]
    pub scenario: PathBuf,
    /// Trace file this process writes.
    #[arg(long)]
    pub trace: PathBuf,
    /// Agent id (agents only).
    #[arg(long)]
    pub agent: Option<u32>,
    /// Pid of the launcher: the process stops when it dies.
    #[arg(long)]
    pub launcher_pid: Option<u32>,
    #[command(flatten)]
    pub placement: Placement,
}

impl ProcessArgs {
    /// The command line that parses back into `self`: what the launcher passes to a child.
    /// Checked against the parser by `process_args_round_trip_through_the_command_line`.
    pub fn to_args(&self) -> Vec<std::ffi::OsString> {
        let mut out: Vec<std::ffi::OsString> = vec![
            "--prefix".into(),
            self.prefix.clone().into(),
            "--scenario".into(),
            self.scenario.clone().into(),
            "--trace".into(),
            self.trace.clone().into(),
        ];
        if let Some(id) = self.agent {
            out.extend(["--agent".into(), id.to_string().into()]);
        }
        if let Some(pid) = self.launcher_pid {
            out.extend(["--launcher-pid".into(), pid.to_string().into()]);
        }
        if let Some(priority) = self.placement.rt_priority {
            out.extend(["--rt-priority".into(), priority.to_string().into()]);
        }
        if let Some(cpus) = &self.placement.cpus {
            out.extend(["--cpus".into(), cpus.to_string().into()]);
        }
        out
    }
}

/// Where and how a run's processes are scheduled (`--rt-priority`, `--cpus`).
#[derive(Debug, Clone, Default, PartialEq, Eq, clap::Args)]
pub struct Placement {
    /// Realtime runs: every process of the run under SCHED_FIFO at this priority (1–99)
    /// instead of the time-sharing default. Needs CAP_SYS_NICE or an RLIMIT_RTPRIO of at least
    /// the priority.
    #[arg(long, value_name = "PRIORITY", value_parser = clap::value_parser!(u8).range(1..=99))]
    pub rt_priority: Option<u8>,
    /// Every process of the run only on these CPUs (a list such as `1`, `0,2` or `0-3`).
    #[arg(long, value_name = "LIST")]
    pub cpus: Option<CpuList>,
}

impl Placement {
    /// Applies it to the calling thread (and the threads it starts later). The error names the
    /// option that could not be honoured and why.
    pub fn apply(&self) -> Result<(), String> {
        if let Some(cpus) = &self.cpus {
            cpus.pin().map_err(|e| format!("--cpus {cpus}: {e}"))?;
        }
        if let Some(priority) = self.rt_priority {
            use_fifo(priority).map_err(|e| format!("--rt-priority {priority}: {e}"))?;
        }
        Ok(())
    }

    /// Checks, before anything starts, that every CPU asked for is available and (on a
    /// throw-away thread) that this user may do what is asked.
    pub fn check(&self) -> Result<(), String> {
        if let Some(cpus) = &self.cpus {
            let allowed = CpuList::allowed()?;
            if let Some(c) = cpus.cpus().iter().find(|c| !allowed.cpus().contains(c)) {
                return Err(format!(
                    "--cpus {cpus}: CPU {c} is not available (this process may use CPUs {allowed})"
                ));
            }
        }
        let p = self.clone();
        std::thread::spawn(move || p.apply())
            .join()
            .map_err(|_| "checking --rt-priority / --cpus: the check panicked".to_string())?
    }

    /// `SCHED_OTHER` or `SCHED_FIFO <priority>`, and the CPUs when confined.
    pub fn describe(&self) -> String {
        let policy = self
            .rt_priority
            .map_or("SCHED_OTHER".into(), |p| format!("SCHED_FIFO {p}"));
        match &self.cpus {
            Some(c) => format!("{policy} on CPUs {c}"),
            None => policy,
        }
    }
}

/// A set of CPUs, written as a list of numbers and ranges: `1`, `0,2`, `0-3`, `0,2-3`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CpuList(Vec<usize>);

impl CpuList {
    /// Just `cpu`.
    pub fn single(cpu: usize) -> Self {
        Self(vec![cpu])
    }

    /// The CPUs, ascending, each once.
    pub fn cpus(&self) -> &[usize] {
        &self.0
    }

    /// The CPUs this thread may run on.
    pub fn allowed() -> Result<Self, String> {
        let set = rustix::thread::sched_getaffinity(None)
            .map_err(|e| format!("reading the CPU affinity: {e}"))?;
        Ok(Self(
            (0..rustix::thread::CpuSet::MAX_CPU)
                .filter(|&c| set.is_set(c))
                .collect(),
        ))
    }

    /// Confines the calling thread (and the threads it starts later) to these CPUs.
    pub fn pin(&self) -> Result<(), String> {
        let mut set = rustix::thread::CpuSet::new();
        for &c in &self.0 {
            set.set(c);
        }
        rustix::thread::sched_setaffinity(None, &set)
            .map_err(|e| format!("pinning to CPUs {self}: {e}"))
    }
}

impl std::str::FromStr for CpuList {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let cpu = |x: &str| -> Result<usize, String> {
            let c: usize = x
                .trim()
                .parse()
                .map_err(|_| format!("`{x}` is not a CPU number (in CPU list `{s}`)"))?;
            if c >= rustix::thread::CpuSet::MAX_CPU {
                return Err(format!("CPU {c} is out of range (in CPU list `{s}`)"));
            }
            Ok(c)
        };
        let mut cpus = Vec::new();
        for part in s.split(',') {
            match part.split_once('-') {
                Some((a, b)) => {
                    let (a, b) = (cpu(a)?, cpu(b)?);
                    if a > b {
                        return Err(format!("range `{part}` runs backwards (in CPU list `{s}`)"));
                    }
                    cpus.extend(a..=b);
                }
                None => cpus.push(cpu(part)?),
            }
        }
        cpus.sort_unstable();
        cpus.dedup();
        Ok(Self(cpus))
    }
}

impl std::fmt::Display for CpuList {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let list: Vec<String> = self.0.iter().map(ToString::to_string).collect();
        f.write_str(&list.join(","))
    }
}

/// Puts the calling thread under SCHED_FIFO at `priority` (1–99); threads it starts later
/// inherit the policy. The error says why not, in words a user can act on.
pub fn use_fifo(priority: u8) -> Result<(), String> {
    use thread_priority::unix::{
        set_thread_priority_and_policy, thread_native_id, RealtimeThreadSchedulePolicy,
        ThreadSchedulePolicy,
    };
    use thread_priority::{ThreadPriority, ThreadPriorityValue};
    let value =
        ThreadPriorityValue::try_from(priority).map_err(|e| format!("priority {priority}: {e}"))?;
    set_thread_priority_and_policy(
        thread_native_id(),
        ThreadPriority::Crossplatform(value),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    )
    .map_err(|e| match e {
        thread_priority::Error::OS(code) if code == rustix::io::Errno::PERM.raw_os_error() => {
            format!(
                "SCHED_FIFO priority {priority} is not permitted for this user (it needs \
                 CAP_SYS_NICE, or an RLIMIT_RTPRIO of at least {priority}: `ulimit -r`)"
            )
        }
        other => format!("SCHED_FIFO priority {priority}: {other:?}"),
    })
}

/// Set when the process must stop: SIGINT, SIGTERM, or the launcher died.
#[derive(Debug, Clone)]
pub struct Shutdown {
    flag: Arc<AtomicBool>,
    launcher_pid: Option<u32>,
}

impl Shutdown {
    /// Registers SIGINT/SIGTERM handlers that only set a flag, and asks the kernel to send
    /// SIGTERM when the parent dies.
    pub fn install(launcher_pid: Option<u32>) -> std::io::Result<Self> {
        let flag = Arc::new(AtomicBool::new(false));
        signal_hook::flag::register(signal_hook::consts::SIGTERM, Arc::clone(&flag))?;
        signal_hook::flag::register(signal_hook::consts::SIGINT, Arc::clone(&flag))?;
        if launcher_pid.is_some() {
            rustix::process::set_parent_process_death_signal(Some(rustix::process::Signal::TERM))
                .map_err(std::io::Error::from)?;
        }
        Ok(Self { flag, launcher_pid })
    }

    /// A handle that is never triggered by signals (tests, in-process use).
    pub fn manual() -> Self {
        Self {
            flag: Arc::new(AtomicBool::new(false)),
            launcher_pid: None,
        }
    }

    pub fn request(&self) {
        self.flag.store(true, Ordering::SeqCst);
    }

    /// True once a stop was requested or the launcher is gone.
    pub fn requested(&self) -> bool {
        if self.flag.load(Ordering::Relaxed) {
            return true;
        }
        if let Some(pid) = self.launcher_pid {
            let parent = rustix::process::getppid().map(|p| p.as_raw_nonzero().get());
            if parent != i32::try_from(pid).ok() {
                self.request();
                return true;
            }
        }
        false
    }
}

/// How long a process waits for the launcher's start before giving up.
pub const START_TIMEOUT: Duration = Duration::from_secs(60);
/// Longest single block on a wake-up event; shutdown is checked at least this often.
pub const WAIT_SLICE: Duration = Duration::from_millis(50);

/// How a lockstep process waits for its peers: poll its wake-up event (yielding the CPU between
/// polls) for up to `spin`, then block on it. Blocking costs a scheduler wake-up (tens of µs on
/// the 2-vCPU machines); polling with `sched_yield` hands the CPU to whichever process has work.
/// A zero `spin` blocks at once. Set by `FDI_SPIN_US` (the launcher passes it on).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WaitStrategy {
    pub spin: Duration,
}

/// Default bounded spin before blocking, µs (chosen by measurement, see docs/performance.md).
pub const DEFAULT_SPIN_US: u64 = 200;

impl WaitStrategy {
    /// Lockstep spins `FDI_SPIN_US` (default [`DEFAULT_SPIN_US`]) before blocking; realtime
    /// never spins (the attacker and the center are purely event-driven there, so that the
    /// agents keep the CPU for their deadlines) unless `FDI_SPIN_US` says otherwise.
    pub fn for_clock(clock: fdi_common::scenario::ClockMode) -> Self {
        let env = std::env::var("FDI_SPIN_US")
            .ok()
            .and_then(|v| v.parse().ok());
        let us = match clock {
            fdi_common::scenario::ClockMode::Lockstep => env.unwrap_or(DEFAULT_SPIN_US),
            fdi_common::scenario::ClockMode::Realtime => env.unwrap_or(0),
        };
        Self {
            spin: Duration::from_micros(us),
        }
    }

    /// Returns once `inbox` holds a message (or `waker` was rung), or after [`WAIT_SLICE`]. The
    /// spin polls the inbox's shared-memory queue (no system call) and yields between polls;
    /// the pending notification is consumed once work is found.
    pub fn wait<T: ZeroCopySendCopy>(
        &self,
        waker: &Waker,
        inbox: &crate::ipc::Inbox<T>,
    ) -> Result<bool, IpcError> {
        if !self.spin.is_zero() {
            let began = Instant::now();
            while began.elapsed() < self.spin {
                if inbox.has_messages()? {
                    waker.wait(Duration::ZERO)?;
                    return Ok(true);
                }
                std::thread::yield_now();
            }
        }
        // The realtime processes' own blocking wait, so that the transport floor measured with
        // this strategy waits exactly as they do.
        waker.wait_precise(WAIT_SLICE)
    }
}

/// Why a process stopped early.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    #[error(transparent)]
    Ipc(#[from] IpcError),
    #[error("no start from the launcher within {0:?}")]
    NoStart(Duration),
    #[error("stopped by the launcher before the start")]
    StoppedBeforeStart,
}

/// Why a runtime process (agent, attacker, control center) failed: one type for all of them.
#[derive(Debug, thiserror::Error)]
pub enum RoleError {
    #[error(transparent)]
    Process(#[from] ProcessError),
    #[error(transparent)]
    Ipc(#[from] IpcError),
    #[error(transparent)]
    Trace(#[from] fdi_common::trace::TraceError),
    #[error(transparent)]
    Scenario(#[from] fdi_common::scenario::ScenarioError),
    #[error("installing signal handlers: {0}")]
    Signals(std::io::Error),
    #[error("agent {0} is not in the scenario")]
    NotInScenario(u32),
    #[error("--agent is required")]
    MissingId,
    #[error("agent {0}: its model has another number of links than the run's first agent")]
    Dof(u32),
    #[error("{0}")]
    Scheduling(String),
}

/// Outcome of waiting for the start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Start {
    /// Go; sim time zero is this CLOCK_MONOTONIC instant, ns.
    Go { epoch_ns: u64 },
    /// A signal or the launcher's death arrived first.
    Shutdown,
}

/// The process's link to the launcher.
#[derive(Debug)]
pub struct LauncherLink {
    pub role: Role,
    pub agent: u32,
    pub control: Inbox<ControlMsg>,
    pub status: Outbox<StatusMsg>,
    pub bell: Bell,
}

impl LauncherLink {
    pub fn report(&self, kind: u32, tick: u64) -> Result<(), IpcError> {
        self.status.send(StatusMsg {
            role: self.role.code(),
            agent: self.agent,
            kind,
            reserved: 0,
            tick,
        })?;
        self.bell.ring()
    }

    /// Tells the launcher that `agent`, declared lost, is heard from again at `tick`.
    pub fn report_rejoined(&self, agent: u32, tick: u64) -> Result<(), IpcError> {
        self.status.send(StatusMsg {
            role: self.role.code(),
            agent,
            kind: StatusMsg::REJOINED,
            reserved: 0,
            tick,
        })?;
        self.bell.ring()
    }

    /// Tells the launcher that `agent` was declared lost after `tick`.
    pub fn report_lost(&self, agent: u32, tick: u64) -> Result<(), IpcError> {
        self.status.send(StatusMsg {
            role: self.role.code(),
            agent,
            kind: StatusMsg::LOST,
            reserved: 0,
            tick,
        })?;
        self.bell.ring()
    }

    /// True when the launcher has sent a stop.
    pub fn stop_requested(&self) -> Result<bool, IpcError> {
        let mut stop = false;
        self.control
            .drain(|m| stop |= m.command == ControlMsg::STOP)?;
        Ok(stop)
    }

    /// Reports ready, then blocks on `waker` until the launcher's start.
    pub fn ready_and_wait_start(
        &self,
        waker: &Waker,
        shutdown: &Shutdown,
    ) -> Result<Start, ProcessError> {
        self.report(StatusMsg::READY, 0)?;
        let began = Instant::now();
        loop {
            let mut start = None;
            let mut stop = false;
            self.control.drain(|m| match m.command {
                ControlMsg::START => start = Some(m.epoch_ns),
                ControlMsg::STOP => stop = true,
                _ => {}
            })?;
            if stop {
                return Err(ProcessError::StoppedBeforeStart);
            }
            if let Some(epoch_ns) = start {
                return Ok(Start::Go { epoch_ns });
            }
            if shutdown.requested() {
                return Ok(Start::Shutdown);
            }
            if began.elapsed() > START_TIMEOUT {
                return Err(ProcessError::NoStart(START_TIMEOUT));
            }
            waker.wait(WAIT_SLICE)?;
        }
    }
}

/// Everything a process opens on the transport at start-up.
#[derive(Debug)]
pub struct Connection {
    pub transport: crate::ipc::Transport,
    pub launcher: LauncherLink,
    /// This process's own wake-up event.
    pub waker: Waker,
}

/// Opens the node, the launcher link and this process's waker.
pub fn connect(
    args: &ProcessArgs,
    role: Role,
    wake: crate::ipc::Wake,
    sizing: crate::ipc::Sizing,
) -> Result<Connection, IpcError> {
    use crate::ipc::{Stream, Transport, Wake};
    let name = match wake {
        Wake::Agent(id) => format!("agent-{id}"),
        Wake::Attacker => "attacker".into(),
        Wake::Center => "control-center".into(),
        Wake::Launcher => "launcher".into(),
    };
    let transport = Transport::open(&args.prefix, &name, sizing)?;
    let launcher = LauncherLink {
        role,
        agent: args.agent.unwrap_or(0),
        control: transport.subscriber(Stream::Control)?,
        status: transport.publisher(Stream::Status)?,
        bell: transport.notifier(Wake::Launcher)?,
    };
    let waker = transport.waker(wake)?;
    Ok(Connection {
        transport,
        launcher,
        waker,
    })
}

/// The start-up every process shell shares: SIGINT/SIGTERM and parent-death handling, the
/// run's scenario, and the transport with its launcher link and waker.
pub fn start(
    args: &ProcessArgs,
    role: Role,
    wake: crate::ipc::Wake,
) -> Result<(Shutdown, fdi_common::scenario::Resolved, Connection), RoleError> {
    let shutdown = Shutdown::install(args.launcher_pid).map_err(RoleError::Signals)?;
    args.placement.apply().map_err(RoleError::Scheduling)?;
    let resolved = fdi_common::scenario::load_file(&args.scenario)?;
    let conn = connect(args, role, wake, sizing_for(&resolved))?;
    Ok((shutdown, resolved, conn))
}

/// Sizing of a run's services: every process computes the same from the scenario.
pub fn sizing_for(resolved: &fdi_common::scenario::Resolved) -> crate::ipc::Sizing {
    // Lookahead lets an agent run up to τ_max/Δ ticks ahead of its commands.
    let s = &resolved.scenario;
    let tau_max = s.agents.iter().map(|a| a.delay.max()).fold(0.0, f64::max);
    let ahead = (tau_max / s.control_period_s).ceil() as usize + 2;
    crate::ipc::Sizing {
        agents: resolved.agent_count(),
        in_flight: ahead,
    }
}

/// Header of the trace a process writes.
pub fn trace_header(
    process: &str,
    resolved: &fdi_common::scenario::Resolved,
) -> fdi_common::trace::TraceHeader {
    fdi_common::trace::TraceHeader {
        format_version: fdi_common::trace::FORMAT_VERSION,
        process: process.into(),
        scenario_toml: resolved.to_toml(),
        seed: resolved.scenario.seed,
        clock: resolved.scenario.clock.as_str().into(),
    }
}

/// Silence after which a realtime peer is declared lost, ns. With a liveness check every
/// [`LIVENESS_CHECK`] the loss is reported within 45 ms of the last message.
pub const LOST_AFTER_NS: u64 = 40_000_000;

/// Prints a child process's failure on its stderr, which the launcher relays. A write error
/// is ignored: the launcher that read the pipe may be gone (killed), and `eprintln!` would then
/// panic on the broken pipe instead of exiting with the failure's status.
pub fn print_failure(message: std::fmt::Arguments<'_>) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr(), "{message}");
}

/// The wall-clock instant after which a realtime peer that is still lost stays lost: the run's
/// end (epoch + duration) plus the loss limit.
pub fn realtime_end_ns(epoch_ns: u64, duration_s: f64) -> u64 {
    epoch_ns + (duration_s * 1e9) as u64 + LOST_AFTER_NS
}
/// How often a realtime event-driven process checks liveness while idle.
pub const LIVENESS_CHECK: Duration = Duration::from_millis(5);

/// Which peers (agents) are still heard from. Pure bookkeeping on monotonic-clock stamps.
#[derive(Debug, Clone)]
pub struct Liveness {
    last_seen_ns: Vec<u64>,
    lost_at_ns: Vec<Option<u64>>,
    after_ns: u64,
}

impl Liveness {
    /// `n` peers, all heard from at `now_ns`.
    pub fn new(n: usize, now_ns: u64, after_ns: u64) -> Self {
        Self {
            last_seen_ns: vec![now_ns; n],
            lost_at_ns: vec![None; n],
            after_ns,
        }
    }

    /// Peer `i` was heard from at `now_ns` (never moves its stamp back: a message sent before
    /// the realtime epoch does not shorten the grace the epoch gives). A peer declared lost
    /// rejoins: returns how long it had been silent, ns.
    pub fn seen(&mut self, i: usize, now_ns: u64) -> Option<u64> {
        let s = self.last_seen_ns.get_mut(i)?;
        let silent = now_ns.saturating_sub(*s);
        *s = (*s).max(now_ns);
        self.lost_at_ns.get_mut(i)?.take().map(|_| silent)
    }

    /// Whether peer `i` is done with: finished normally, or lost and the run's wall-clock end
    /// (`end_ns`: epoch + duration + the loss limit) has passed, so it can no longer rejoin.
    pub fn settled(&self, i: usize, finished: bool, now_ns: u64, end_ns: u64) -> bool {
        finished || (self.is_lost(i) && now_ns >= end_ns)
    }

    /// Peers silent for longer than the limit and not yet declared lost; declares them lost.
    /// `finished(i)` excludes peers that ended normally.
    pub fn newly_lost(&mut self, now_ns: u64, finished: impl Fn(usize) -> bool) -> Vec<usize> {
        let mut out = Vec::new();
        for (i, (seen, lost)) in self
            .last_seen_ns
            .iter()
            .zip(self.lost_at_ns.iter_mut())
            .enumerate()
        {
            if lost.is_none() && !finished(i) && now_ns.saturating_sub(*seen) > self.after_ns {
                *lost = Some(now_ns);
                out.push(i);
            }
        }
        out
    }

    /// How long peer `i` has been silent at `now_ns`.
    pub fn silence_ns(&self, i: usize, now_ns: u64) -> u64 {
        self.last_seen_ns
            .get(i)
            .map_or(0, |s| now_ns.saturating_sub(*s))
    }

    pub fn is_lost(&self, i: usize) -> bool {
        self.lost_at_ns.get(i).is_some_and(Option::is_some)
    }
}

/// What a receiver of measurements (attacker, control center) does with one message: structure
/// first (dof within the payload before any indexing, the expected dof, a finite time stamp),
/// then the sequence (`sequence`, limit = the run's tick count). A gap is recorded as an event; a
/// refusal (duplicate, replay, forged far-future number, malformed) is recorded and never moves
/// the stream on. Returns whether to use the message.
pub fn admit_measurement(
    m: &crate::ipc::MeasurementMsg,
    dof: usize,
    sequence: &mut crate::ipc::msg::SequenceTracker,
    control_period_s: f64,
    trace: &mut fdi_common::trace::TraceWriter,
) -> bool {
    use crate::ipc::msg::{validate_measurement, SeqRule, SeqVerdict};
    use fdi_common::engine::tick_time;
    use fdi_common::trace::TraceRecord;
    let structure = validate_measurement(m, dof, |_| true, SeqRule::Tracked).map(|_| ());
    let verdict = structure
        .as_ref()
        .ok()
        .map(|()| sequence.observe(m.agent, m.seq));
    // Events are diagnostics: a failing trace write surfaces on the next record write.
    if let Some(SeqVerdict::Gap { missing }) = verdict {
        let message = format!(
            "agent {}: {missing} measurements missing before tick {}",
            m.agent, m.seq
        );
        let _ = trace.write(&TraceRecord::Event {
            t: tick_time(m.seq, control_period_s),
            message,
        });
    }
    if verdict.is_some_and(SeqVerdict::is_accepted) {
        return true;
    }
    let message = match (structure, verdict) {
        (Err(e), _) => e.to_string(),
        (_, v) => format!("agent {}, sequence {}: refused ({v:?})", m.agent, m.seq),
    };
    let _ = trace.write(&TraceRecord::Event { t: m.t, message });
    false
}

/// What the agent does with one torque message on its own channel: it must name this agent,
/// carry `N` links, a finite stamp, and a sequence number no older than `next_seq` (the one
/// after the last admitted; a later one means the ones between never came). Returns the torque
/// to take into the delay line, which refuses non-finite values and stamps that do not increase.
pub fn admit_torque<const N: usize>(
    m: &crate::ipc::TorqueMsg,
    own_agent: u32,
    next_seq: u64,
) -> Result<fdi_common::model::Vector<N>, crate::ipc::msg::MsgError> {
    use crate::ipc::msg::{to_vector, validate_torque, SeqRule};
    validate_torque(m, N, own_agent, SeqRule::AtLeast(next_seq))?;
    Ok(to_vector::<N>(&m.u))
}

#[cfg(test)]
mod liveness_tests {
    use super::Liveness;

    #[test]
    fn a_peer_is_lost_once_after_the_silence_limit_and_finished_peers_never() {
        let mut l = Liveness::new(3, 0, 40);
        l.seen(0, 30);
        assert!(l.newly_lost(40, |_| false).is_empty());
        assert_eq!(l.newly_lost(41, |i| i == 2), vec![1]);
        assert!(l.is_lost(1) && !l.is_lost(0) && !l.is_lost(2));
        assert_eq!(l.newly_lost(71, |i| i == 2), vec![0]);
        assert!(l.newly_lost(1000, |i| i == 2).is_empty(), "reported once");
        // A stamp older than the start (a message sent before the epoch) keeps the start.
        let mut e = Liveness::new(1, 100, 40);
        e.seen(0, 50);
        assert!(e.newly_lost(130, |_| false).is_empty());
    }
}

#[cfg(test)]
mod args_tests {
    use super::{CpuList, Placement, ProcessArgs};
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Child {
        #[command(flatten)]
        args: ProcessArgs,
    }

    #[test]
    fn process_args_round_trip_through_the_command_line() {
        let base = ProcessArgs {
            prefix: "fdi12_ab_".into(),
            scenario: "run dir/scenario.toml".into(),
            trace: "run dir/traces/agent-3.trace".into(),
            agent: None,
            launcher_pid: None,
            placement: Placement::default(),
        };
        let full = ProcessArgs {
            agent: Some(3),
            launcher_pid: Some(4242),
            placement: Placement {
                rt_priority: Some(20),
                cpus: Some("0,2-3".parse::<CpuList>().expect("list")),
            },
            ..base.clone()
        };
        for args in [base, full] {
            let mut line = vec![std::ffi::OsString::from("fdi-agent")];
            line.extend(args.to_args());
            let parsed = Child::try_parse_from(line).expect("parses").args;
            assert_eq!(parsed, args);
        }
    }
}

#[cfg(test)]
mod cpu_list_tests {
    use super::CpuList;

    fn parse(s: &str) -> Result<Vec<usize>, String> {
        s.parse::<CpuList>().map(|c| c.cpus().to_vec())
    }

    #[test]
    fn lists_and_ranges_parse_sorted_and_once() {
        assert_eq!(parse("1"), Ok(vec![1]));
        assert_eq!(parse("0,2"), Ok(vec![0, 2]));
        assert_eq!(parse("0-3"), Ok(vec![0, 1, 2, 3]));
        assert_eq!(parse("3,0-1,1"), Ok(vec![0, 1, 3]));
        assert_eq!(parse(" 2 - 3 "), Ok(vec![2, 3]));
        let list: CpuList = "2-3,0".parse().expect("list");
        assert_eq!(list.to_string(), "0,2,3");
        assert_eq!(list.to_string().parse::<CpuList>(), Ok(list));
    }

    #[test]
    fn bad_lists_say_what_is_wrong() {
        for (s, says) in [
            ("", "not a CPU number"),
            ("a", "`a` is not a CPU number"),
            ("1,", "not a CPU number"),
            ("3-1", "runs backwards"),
            ("-1", "not a CPU number"),
            ("99999", "out of range"),
        ] {
            let e = parse(s).expect_err(s);
            assert!(e.contains(says), "{s}: {e}");
        }
    }

    #[test]
    fn this_thread_may_run_somewhere() {
        let allowed = CpuList::allowed().expect("affinity");
        assert!(!allowed.cpus().is_empty());
        // Pinning to what is allowed already changes nothing and succeeds.
        std::thread::spawn(move || allowed.pin())
            .join()
            .expect("thread")
            .expect("pin");
    }
}
