//! The launcher's children — a run's processes, the bench's peers — under one supervisor: each
//! spawned in a process group of its own (the terminal's Ctrl-C reaches the launcher alone, which
//! stops them in order) with its stderr relayed, reaped without blocking, described by the cause
//! it printed last when it fails, noticed when stopped (SIGSTOP, a debugger), torn down with
//! SIGTERM then SIGKILL after a grace period, and killed if still running when the supervisor is
//! dropped. A program outside the project is ended with its whole process group and what it
//! started ([`crate::run::program`]); its output is awaited for a bounded time only.

use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::process::{Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use fdi_runtime::process::procfs;

use crate::run::program::{self, Program};
use crate::run::relay::{lock, StderrRelay};

/// One supervised child; `meta` is what its supervisor's user keeps about it.
#[derive(Debug)]
pub struct Child<M> {
    pub label: String,
    pub meta: M,
    /// How it ended, once reaped.
    pub status: Option<ExitStatus>,
    child: Handle,
    /// Since when it has been seen stopped, for [`Supervisor::stalled`].
    stopped_since: Option<Instant>,
    /// Its stderr, relayed to ours; its last line is the cause of a failure.
    stderr: Option<StderrRelay>,
    /// A program outside the project: its process group and what it started.
    program: Option<Program>,
}

/// A child on this host, or one that the `fdi-launch serve` of another host runs for us.
#[derive(Debug)]
enum Handle {
    Local(std::process::Child),
    Remote(Remote),
}

/// A process another host runs for this run: what its serve reported of it.
#[derive(Debug, Clone)]
pub struct Remote {
    pub host: String,
    pub pid: u32,
    pub state: Arc<Mutex<RemoteState>>,
    /// Asks its host to stop it: `true` SIGKILL, `false` SIGTERM.
    pub stop: Stopper,
}

/// How a remote child is stopped: a message to its host.
#[derive(Clone)]
pub struct Stopper(pub Arc<dyn Fn(bool) + Send + Sync>);

impl std::fmt::Debug for Stopper {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Stopper")
    }
}

/// What the serve of a remote child's host said of it.
#[derive(Debug, Default)]
pub struct RemoteState {
    /// Its wait status and how its host described its end, once it exited.
    pub exit: Option<(i32, String)>,
    /// Its host reported it stopped (SIGSTOP, a debugger): the message.
    pub stalled: Option<String>,
    /// Its host is unreachable: nothing more will be heard of it.
    pub host_lost: bool,
}

impl<M> Child<M> {
    pub fn pid(&self) -> u32 {
        match &self.child {
            Handle::Local(c) => c.id(),
            Handle::Remote(r) => r.pid,
        }
    }

    /// Nothing more will be heard of it: it runs on a host that is unreachable.
    pub fn unreachable(&self) -> bool {
        matches!(&self.child, Handle::Remote(r) if lock(&r.state).host_lost)
    }

    /// The host it runs on, when that is not this one.
    pub fn host(&self) -> Option<&str> {
        match &self.child {
            Handle::Local(_) => None,
            Handle::Remote(r) => Some(&r.host),
        }
    }

    /// How it ended: with the cause it printed last when it exited with a status (a failure it
    /// reported), else the signal or the status alone.
    pub fn ended(&mut self, st: ExitStatus) -> String {
        if let Handle::Remote(r) = &self.child {
            let said = lock(&r.state).exit.as_ref().map(|(_, s)| s.clone());
            return match said {
                Some(s) => format!("{s} on host `{}`", r.host),
                None => format!(
                    "{} (pid {}) {} on host `{}`",
                    self.label,
                    r.pid,
                    describe_status(st),
                    r.host
                ),
            };
        }
        let pid = self.pid();
        let cause = match (st.code(), &self.stderr) {
            (Some(_), Some(relay)) => relay.cause(),
            _ => None,
        };
        match cause {
            Some(c) => format!(
                "{} (pid {pid}) failed: {c} ({})",
                self.label,
                describe_status(st)
            ),
            None => format!("{} (pid {pid}) {}", self.label, describe_status(st)),
        }
    }
}

/// The children of one run (or one bench case).
pub struct Supervisor<M> {
    children: Vec<Child<M>>,
    /// Where the lines the children print also go (`fdi-launch serve`: to the coordinator).
    tee: Option<crate::run::relay::Tee>,
}

impl<M: std::fmt::Debug> std::fmt::Debug for Supervisor<M> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Supervisor")
            .field("children", &self.children)
            .finish_non_exhaustive()
    }
}

impl<M> Default for Supervisor<M> {
    fn default() -> Self {
        Self {
            children: Vec::new(),
            tee: None,
        }
    }
}

impl<M> std::ops::Deref for Supervisor<M> {
    type Target = [Child<M>];
    fn deref(&self) -> &[Child<M>] {
        &self.children
    }
}

impl<M> std::ops::DerefMut for Supervisor<M> {
    fn deref_mut(&mut self) -> &mut [Child<M>] {
        &mut self.children
    }
}

impl<M> Supervisor<M> {
    /// A supervisor that also hands every line its children print to `tee`.
    pub fn with_tee(tee: crate::run::relay::Tee) -> Self {
        Self {
            children: Vec::new(),
            tee: Some(tee),
        }
    }

    /// Spawns `cmd` as `label`: no stdin or stdout, its stderr relayed (its lines reach ours
    /// as it prints them), in a process group of its own.
    pub fn spawn(&mut self, label: String, meta: M, mut cmd: Command) -> Result<()> {
        cmd.stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .process_group(0);
        let mut child = crate::run::program::spawn_noted(&mut cmd)
            .with_context(|| format!("spawning {label}"))?;
        let tee = self.tee.clone();
        let stderr = child
            .stderr
            .take()
            .map(|e| StderrRelay::start_teed(e, &label, None, tee));
        self.push(label, meta, Handle::Local(child), stderr, None);
        Ok(())
    }

    /// Supervises `label`, a process the serve of another host runs for this run.
    pub fn adopt_remote(&mut self, label: String, meta: M, remote: Remote) {
        self.push(label, meta, Handle::Remote(remote), None, None);
    }

    fn push(
        &mut self,
        label: String,
        meta: M,
        child: Handle,
        stderr: Option<StderrRelay>,
        program: Option<Program>,
    ) {
        self.children.push(Child {
            label,
            meta,
            status: None,
            child,
            stopped_since: None,
            stderr,
            program,
        });
    }

    /// Spawns a program outside the project (`[roles]`) as `label`: no stdin, its stdout and
    /// stderr both relayed to our stderr, each line after `label: `, in a process group of its
    /// own, which [`Self::end_programs`] ends with whatever it started.
    pub fn spawn_external(&mut self, label: String, meta: M, mut cmd: Command) -> Result<()> {
        let (reader, writer) = std::io::pipe().context("making a pipe for its output")?;
        cmd.stdin(Stdio::null())
            .stdout(writer.try_clone().context("making a pipe for its output")?)
            .stderr(writer)
            .process_group(0);
        crate::run::program::ends_with_the_launcher(&mut cmd);
        let child = match crate::run::program::spawn_noted(&mut cmd) {
            Ok(child) => child,
            // The check before exec: the launcher was dying as it started the program.
            Err(e) if e.raw_os_error() == Some(rustix::io::Errno::SRCH.raw_os_error()) => {
                return Err(e).with_context(|| {
                    format!("spawning {label}: the launcher is ending (its parent is gone)")
                })
            }
            Err(e) => {
                return Err(e).with_context(|| {
                    format!(
                        "spawning {label} ({:?}: is the program installed and on PATH?)",
                        cmd.get_program()
                    )
                })
            }
        };
        let program = Program::new(child.id(), &cmd);
        // Our copies of the write end went into the command: dropped with it, so the relay
        // sees the end of the stream when the child (and whatever it started) exits.
        drop(cmd);
        let stderr = StderrRelay::start_prefixed(reader, &label, Some(label.clone()));
        self.push(
            label,
            meta,
            Handle::Local(child),
            Some(stderr),
            Some(program),
        );
        Ok(())
    }

    /// Reaps the children that exited since the last call; returns their indices.
    pub fn reap(&mut self) -> Vec<usize> {
        let mut out = Vec::new();
        for (i, c) in self.children.iter_mut().enumerate() {
            if c.status.is_none() {
                let exited = match &mut c.child {
                    Handle::Local(child) => child.try_wait().ok().flatten(),
                    Handle::Remote(r) => lock(&r.state)
                        .exit
                        .as_ref()
                        .map(|(raw, _)| ExitStatus::from_raw(*raw)),
                };
                if let Some(st) = exited {
                    if let Handle::Local(child) = &c.child {
                        crate::run::program::note_reaped(child.id());
                    }
                    c.status = Some(st);
                    out.push(i);
                }
            }
        }
        out
    }

    /// A child stopped (SIGSTOP, or traced) for longer than `limit`, named.
    pub fn stalled(&mut self, limit: Duration) -> Option<String> {
        let now = Instant::now();
        for c in &mut self.children {
            if c.status.is_some() {
                continue;
            }
            let pid = match &c.child {
                Handle::Local(child) => child.id(),
                Handle::Remote(r) => {
                    // Its host watches it and says so.
                    if let Some(said) = lock(&r.state).stalled.take() {
                        return Some(format!("{said} on host `{}`", r.host));
                    }
                    continue;
                }
            };
            let stopped = procfs::state(pid).is_ok_and(|s| matches!(s, 'T' | 't'));
            match (stopped, c.stopped_since) {
                (true, None) => c.stopped_since = Some(now),
                (true, Some(since)) if now.duration_since(since) > limit => {
                    return Some(format!("{} (pid {pid}) has been stopped (SIGSTOP or a debugger) for {:.1} s; its peers are waiting for it", c.label, now.duration_since(since).as_secs_f64()));
                }
                (false, _) => c.stopped_since = None,
                _ => {}
            }
        }
        None
    }

    /// How the children ended, e.g. `6 exited 0` or `5 exited 0, agent 2 killed by signal 9`.
    pub fn exits(&self) -> String {
        let clean = self
            .children
            .iter()
            .filter(|c| c.status.is_some_and(|s| s.success()))
            .count();
        let mut parts = vec![format!("{clean} exited 0")];
        for c in self
            .children
            .iter()
            .filter(|c| !c.status.is_some_and(|s| s.success()))
        {
            let lost = match &c.child {
                Handle::Remote(r) => lock(&r.state).host_lost.then(|| r.host.clone()),
                Handle::Local(_) => None,
            };
            parts.push(match (c.status, lost) {
                (Some(st), _) => format!("{} {}", c.label, describe_status(st)),
                (None, Some(host)) => format!("{} unknown (host `{host}` unreachable)", c.label),
                (None, None) => format!("{} still running", c.label),
            });
        }
        parts.join(", ")
    }

    /// Sends SIGTERM to every child still running, and SIGCONT, so that a stopped one acts
    /// on it and exits on its own. A program outside the project gets them through its whole
    /// process group.
    pub fn signal_term(&self) {
        use rustix::process::{kill_process, kill_process_group, Signal};
        for c in &self.children {
            if c.status.is_none() {
                match &c.child {
                    Handle::Local(child) => {
                        if let Some(pid) = rustix::process::Pid::from_raw(child.id() as i32) {
                            let kill = |sig| match c.program {
                                Some(_) => kill_process_group(pid, sig),
                                None => kill_process(pid, sig),
                            };
                            let _ = kill(Signal::TERM);
                            let _ = kill(Signal::CONT);
                        }
                    }
                    Handle::Remote(r) => (r.stop.0)(false),
                }
            }
        }
    }

    /// Waits for every child to exit, successfully, within `timeout`.
    pub fn wait_all(&mut self, timeout: Duration) -> Result<()> {
        let began = Instant::now();
        while let Some(c) = self.children.iter().find(|c| c.status.is_none()) {
            if began.elapsed() > timeout {
                bail!(
                    "{} (pid {}) did not exit within {timeout:?}",
                    c.label,
                    c.pid()
                );
            }
            self.reap();
            std::thread::sleep(Duration::from_millis(1));
        }
        for c in &mut self.children {
            if let Some(st) = c.status.filter(|st| !st.success()) {
                bail!("{}", c.ended(st));
            }
        }
        Ok(())
    }

    /// Ends what the programs outside the project left running once they exited or were
    /// stopped (children that kept their output open or detached): their whole process group
    /// and the processes that left it, SIGTERM then SIGKILL after `grace`. Call it once the
    /// children themselves are reaped. Returns what it ended, one line per program that left
    /// something, naming the program.
    pub fn end_programs(&mut self, grace: Duration) -> Vec<String> {
        let mut out = Vec::new();
        for c in &self.children {
            let Some(program) = &c.program else { continue };
            let spare = c.status.is_none().then(|| c.pid());
            let left = program.end(grace, spare);
            if !left.is_empty() {
                out.push(format!(
                    "{} (pid {}) left {} process{} running, ended: {}",
                    c.label,
                    c.pid(),
                    left.len(),
                    if left.len() == 1 { "" } else { "es" },
                    program::describe(&left)
                ));
            }
        }
        out
    }

    /// Relays what every child printed to the end (call once they all exited, and
    /// [`Self::end_programs`]), waiting at most `limit` in all for the ends of their output:
    /// a process that left a program's process group and outlived it may hold the program's
    /// output open. Returns a line for each output no longer awaited, naming its program.
    pub fn drain_stderr(&mut self, limit: Duration) -> Vec<String> {
        let deadline = Instant::now() + limit;
        let mut open = Vec::new();
        for c in &self.children {
            if let Some(relay) = &c.stderr {
                if !relay.wait_end(deadline.saturating_duration_since(Instant::now())) {
                    open.push(format!(
                        "the output of {} (pid {}) was still open {:.1} s after its end (a \
                         process outside its process group holds it): no longer relayed",
                        c.label,
                        c.pid(),
                        limit.as_secs_f64()
                    ));
                }
            }
        }
        open
    }

    /// SIGKILLs every child still running and reaps it. A remote child's host is asked to, and its exit awaited for at most
    /// [`REMOTE_KILL_WAIT`] in all (none when its host is lost).
    pub fn kill_rest(&mut self) {
        let mut remote = false;
        for c in &mut self.children {
            if c.status.is_none() {
                match &mut c.child {
                    Handle::Local(child) => {
                        let _ = child.kill();
                        c.status = child.wait().ok();
                    }
                    Handle::Remote(r) => {
                        if !lock(&r.state).host_lost {
                            (r.stop.0)(true);
                            remote = true;
                        }
                    }
                }
            }
        }
        let began = Instant::now();
        while remote && began.elapsed() < REMOTE_KILL_WAIT {
            self.reap();
            remote = self.children.iter().any(|c| {
                c.status.is_none()
                    && matches!(&c.child, Handle::Remote(r) if !lock(&r.state).host_lost)
            });
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

/// How long [`Supervisor::kill_rest`] waits for the hosts of remote children to report them
/// gone.
pub const REMOTE_KILL_WAIT: Duration = Duration::from_secs(3);

impl<M> Drop for Supervisor<M> {
    fn drop(&mut self) {
        self.kill_rest();
        for program in self.children.iter().filter_map(|c| c.program.as_ref()) {
            program.kill();
        }
    }
}

/// Describes how a child ended, naming the signal.
pub fn describe_status(status: ExitStatus) -> String {
    if let Some(sig) = status.signal() {
        match signal_hook::low_level::signal_name(sig) {
            Some(name) => format!("was killed by signal {sig} {name}"),
            None => format!("was killed by signal {sig}"),
        }
    } else {
        format!("exited with status {}", status.code().unwrap_or(-1))
    }
}
