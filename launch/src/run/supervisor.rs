//! The launcher's children — a run's processes, the bench's peers — under one supervisor: each
//! spawned in a process group of its own (the terminal's Ctrl-C reaches the launcher alone, which
//! stops them in order) with its stderr relayed, reaped without blocking, described by the cause
//! it printed last when it fails, noticed when stopped (SIGSTOP, a debugger), torn down with
//! SIGTERM then SIGKILL after a grace period, and killed if still running when the supervisor is
//! dropped.

use std::os::unix::process::CommandExt;
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use fdi_runtime::process::procfs;

use crate::relay::StderrRelay;
use crate::runtime::describe_status;

/// One supervised child; `meta` is what its supervisor's user keeps about it.
#[derive(Debug)]
pub struct Child<M> {
    pub label: String,
    pub meta: M,
    /// How it ended, once reaped.
    pub status: Option<ExitStatus>,
    child: std::process::Child,
    /// Since when it has been seen stopped, for [`Supervisor::stalled`].
    stopped_since: Option<Instant>,
    /// Its stderr, relayed to ours; its last line is the cause of a failure.
    stderr: Option<StderrRelay>,
}

impl<M> Child<M> {
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// How it ended: with the cause it printed last when it exited with a status (a failure it
    /// reported), else the signal or the status alone.
    pub fn ended(&mut self, st: ExitStatus) -> String {
        let pid = self.child.id();
        let cause = match (st.code(), &mut self.stderr) {
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
#[derive(Debug)]
pub struct Supervisor<M> {
    children: Vec<Child<M>>,
}

impl<M> Default for Supervisor<M> {
    fn default() -> Self {
        Self {
            children: Vec::new(),
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
    /// Spawns `cmd` as `label`: no stdin or stdout, its stderr relayed (its lines reach ours
    /// as it prints them), in a process group of its own.
    pub fn spawn(&mut self, label: String, meta: M, mut cmd: Command) -> Result<()> {
        cmd.stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .process_group(0);
        let mut child = cmd.spawn().with_context(|| format!("spawning {label}"))?;
        let stderr = child.stderr.take().map(|e| StderrRelay::start(e, &label));
        self.push(label, meta, child, stderr);
        Ok(())
    }

    fn push(
        &mut self,
        label: String,
        meta: M,
        child: std::process::Child,
        stderr: Option<StderrRelay>,
    ) {
        self.children.push(Child {
            label,
            meta,
            status: None,
            child,
            stopped_since: None,
            stderr,
        });
    }

    /// Spawns a program outside the project (`[roles]`) as `label`: no stdin, its stdout and
    /// stderr both relayed to our stderr, each line after `label: `, in a process group of its
    /// own.
    pub fn spawn_external(&mut self, label: String, meta: M, mut cmd: Command) -> Result<()> {
        let (reader, writer) = std::io::pipe().context("making a pipe for its output")?;
        cmd.stdin(Stdio::null())
            .stdout(writer.try_clone().context("making a pipe for its output")?)
            .stderr(writer)
            .process_group(0);
        let child = cmd.spawn().with_context(|| {
            format!(
                "spawning {label} ({:?}: is the program installed and on PATH?)",
                cmd.get_program()
            )
        })?;
        // Our copies of the write end went into the command: dropped with it, so the relay
        // sees the end of the stream when the child exits.
        drop(cmd);
        let stderr = StderrRelay::start_prefixed(reader, &label, Some(label.clone()));
        self.push(label, meta, child, Some(stderr));
        Ok(())
    }

    /// Reaps the children that exited since the last call; returns their indices.
    pub fn reap(&mut self) -> Vec<usize> {
        let mut out = Vec::new();
        for (i, c) in self.children.iter_mut().enumerate() {
            if c.status.is_none() {
                if let Ok(Some(st)) = c.child.try_wait() {
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
            let stopped = procfs::state(c.child.id()).is_ok_and(|s| matches!(s, 'T' | 't'));
            match (stopped, c.stopped_since) {
                (true, None) => c.stopped_since = Some(now),
                (true, Some(since)) if now.duration_since(since) > limit => {
                    return Some(format!("{} (pid {}) has been stopped (SIGSTOP or a debugger) for {:.1} s; its peers are waiting for it", c.label, c.child.id(), now.duration_since(since).as_secs_f64()));
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
            parts.push(match c.status {
                Some(st) => format!("{} {}", c.label, describe_status(st)),
                None => format!("{} still running", c.label),
            });
        }
        parts.join(", ")
    }

    /// Sends SIGTERM to every child still running, and SIGCONT, so that a stopped one acts
    /// on it and exits on its own.
    pub fn signal_term(&self) {
        for c in &self.children {
            if c.status.is_none() {
                if let Some(pid) = rustix::process::Pid::from_raw(c.child.id() as i32) {
                    let _ = rustix::process::kill_process(pid, rustix::process::Signal::TERM);
                    let _ = rustix::process::kill_process(pid, rustix::process::Signal::CONT);
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
                    c.child.id()
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

    /// Relays what every child printed to the end (call once they all exited).
    pub fn drain_stderr(&mut self) {
        for c in &mut self.children {
            if let Some(relay) = &mut c.stderr {
                relay.last_line();
            }
        }
    }

    /// SIGKILLs every child still running and reaps it.
    pub fn kill_rest(&mut self) {
        for c in &mut self.children {
            if c.status.is_none() {
                let _ = c.child.kill();
                c.status = c.child.wait().ok();
            }
        }
    }
}

impl<M> Drop for Supervisor<M> {
    fn drop(&mut self) {
        self.kill_rest();
    }
}
