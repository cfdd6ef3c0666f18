//! The processes of a program outside the project (`[roles]`): it is started in a process group
//! of its own, and whatever it starts stays in that group unless it leaves it (`setsid`,
//! `setpgid`). At the end of the run the launcher ends the whole group, and with it the
//! processes that left the group: the program's descendants while it lives, and any process
//! whose environment still holds every variable the program was given (docs/protocol.md: the
//! run's prefix, the launcher's pid, …), which finds a process that detached twice. The launcher
//! is its descendants' subreaper ([`contain_descendants`]): a process that detached twice (its
//! own session, its environment cleared) is the launcher's child then, not init's, and every
//! child of the launcher that the launcher did not start itself is ended with the program too
//! (issue 51: one that also cleared its environment outlived the run).

use std::collections::{BTreeSet, HashMap};
use std::os::unix::process::CommandExt;
use std::process::Command;
use std::time::{Duration, Instant};

use fdi_runtime::process::procfs;
use rustix::process::{Pid, Signal};

/// How often the processes of a program are looked up while they are given time to exit.
const POLL: Duration = Duration::from_millis(50);

/// The children this process started itself (the run's processes, the programs of roles):
/// any other child of it is a process orphaned below it ([`contain_descendants`]).
static STARTED: std::sync::Mutex<BTreeSet<u32>> = std::sync::Mutex::new(BTreeSet::new());

/// Makes this process the subreaper of its descendants: a process orphaned anywhere below it
/// (its parent exited: a double fork, `setsid`, …) becomes its child rather than init's, so
/// that a run can find and end whatever its programs started, whatever they did. Called once
/// by the command line at its start.
pub fn contain_descendants() -> std::io::Result<()> {
    rustix::process::set_child_subreaper(Some(rustix::process::getpid())).map_err(Into::into)
}

fn started() -> std::sync::MutexGuard<'static, BTreeSet<u32>> {
    STARTED
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Spawns `cmd` as a child this process started: the only way the launcher starts a process.
/// The child is noted under the same lock [`reap_orphans`] holds, so a child that exits at
/// once is never taken for an orphan and reaped behind its owner's back (its `wait` would
/// then fail with "No child processes").
pub fn spawn_noted(cmd: &mut Command) -> std::io::Result<std::process::Child> {
    let mut s = started();
    let child = cmd.spawn()?;
    s.insert(child.id());
    Ok(child)
}

/// Has the kernel send the program `cmd` starts SIGTERM when the launcher dies, however it
/// dies: a SIGKILL leaves the launcher no time to end its programs, and a program that does not
/// watch its parent (the project's roles do, `fdi_runtime::process::shutdown`) would run on,
/// orphaned. The signal comes when the thread that starts the program ends: the launcher's
/// threads that start programs outlive their runs.
#[allow(unsafe_code)]
pub fn ends_with_the_launcher(cmd: &mut Command) {
    let launcher = rustix::process::getpid();
    // SAFETY: the closure runs in the child between fork and exec, where only
    // async-signal-safe calls are allowed: it makes two system calls (prctl, getppid) and
    // allocates nothing (an `Errno` becomes an `io::Error` without allocating).
    unsafe {
        cmd.pre_exec(move || {
            rustix::process::set_parent_process_death_signal(Some(rustix::process::Signal::TERM))?;
            // The launcher died before the call: the signal would never come.
            if rustix::process::getppid() != Some(launcher) {
                return Err(rustix::io::Errno::SRCH.into());
            }
            Ok(())
        });
    }
}

/// Notes that the child `pid` this process started was reaped by its owner.
pub fn note_reaped(pid: u32) {
    started().remove(&pid);
}

/// What identifies the processes of one program.
#[derive(Debug, Clone)]
pub struct Program {
    /// Its pid, which is also its process group.
    leader: u32,
    /// `KEY=VALUE` of every variable its command set: a process whose environment holds them
    /// all descends from it (they name this run).
    marks: Vec<Vec<u8>>,
}

/// A process of a program, as `/proc` showed it.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct Member {
    pub pid: u32,
    /// Its command name.
    pub comm: String,
    /// In the program's process group (else it left it).
    pub in_group: bool,
}

impl Program {
    /// The program `cmd` started as `leader` in a process group of its own
    /// (`CommandExt::process_group(0)`).
    pub fn new(leader: u32, cmd: &Command) -> Self {
        let marks = cmd
            .get_envs()
            .filter_map(|(k, v)| {
                let mut entry = k.as_encoded_bytes().to_vec();
                entry.push(b'=');
                entry.extend_from_slice(v?.as_encoded_bytes());
                Some(entry)
            })
            .collect();
        Self { leader, marks }
    }

    /// The live processes of the program, the leader included while it runs: its process
    /// group, its descendants, and the processes its environment marks. Never this process.
    /// Zombies are left out (dead, only not yet reaped by their parent).
    pub fn members(&self) -> Vec<Member> {
        let me = std::process::id();
        let Ok(pids) = procfs::pids() else {
            return Vec::new();
        };
        let stats: HashMap<u32, procfs::Stat> = pids
            .into_iter()
            .filter(|&p| p != me)
            .filter_map(|p| procfs::stat(p).ok().map(|s| (p, s)))
            .filter(|(_, s)| !matches!(s.state, 'Z' | 'X' | 'x'))
            .collect();
        // Orphans below this process (its subreaper's children it did not start).
        let started = STARTED
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone();
        let orphan = |s: &procfs::Stat| s.ppid == me && !started.contains(&s.pid);
        let descends = |mut pid: u32| {
            // A chain of parents ends at 0 (init's parent); a bound against a changing tree.
            for _ in 0..stats.len().min(4096) {
                if pid == self.leader {
                    return true;
                }
                match stats.get(&pid) {
                    Some(s) if orphan(s) => return true,
                    Some(s) if s.ppid != pid => pid = s.ppid,
                    _ => return false,
                }
            }
            false
        };
        let mut out: Vec<Member> = stats
            .values()
            .filter_map(|s| {
                let in_group = s.pgrp() == Some(self.leader);
                let ours = in_group || descends(s.pid) || self.marked(s.pid);
                ours.then(|| Member {
                    pid: s.pid,
                    comm: s.comm.clone(),
                    in_group,
                })
            })
            .collect();
        out.sort();
        out
    }

    /// Whether the environment of `pid` holds every mark.
    fn marked(&self, pid: u32) -> bool {
        if self.marks.is_empty() {
            return false;
        }
        let Ok(env) = procfs::environ(pid) else {
            return false;
        };
        let entries: BTreeSet<&[u8]> = env.split(|&b| b == 0).collect();
        self.marks.iter().all(|m| entries.contains(m.as_slice()))
    }

    /// Sends `sig` to the program's process group and to each of `members` outside it, with
    /// SIGCONT after a SIGTERM so that a stopped process acts on it.
    fn signal(&self, members: &[Member], sig: Signal) {
        let send = |group: bool, pid: u32| {
            let Some(pid) = Pid::from_raw(pid as i32) else {
                return;
            };
            let kill = |s| {
                if group {
                    rustix::process::kill_process_group(pid, s)
                } else {
                    rustix::process::kill_process(pid, s)
                }
            };
            let _ = kill(sig);
            if sig == Signal::TERM {
                let _ = kill(Signal::CONT);
            }
        };
        send(true, self.leader);
        for m in members.iter().filter(|m| !m.in_group) {
            send(false, m.pid);
        }
    }

    /// Ends every process of the program: SIGTERM to its group and to those outside it, then
    /// SIGKILL to those still running after `grace`. Returns the processes it found running
    /// but `spare` (its leader, which its supervisor reaps and names itself): none when the
    /// program left nothing behind.
    pub fn end(&self, grace: Duration, spare: Option<u32>) -> Vec<Member> {
        let others = |all: Vec<Member>| -> Vec<Member> {
            all.into_iter().filter(|m| Some(m.pid) != spare).collect()
        };
        let found = others(self.members());
        if found.is_empty() {
            return found;
        }
        self.signal(&found, Signal::TERM);
        let began = Instant::now();
        let mut left = found.clone();
        while !left.is_empty() && began.elapsed() < grace {
            std::thread::sleep(POLL.min(grace.saturating_sub(began.elapsed())));
            left = others(self.members());
        }
        if !left.is_empty() {
            self.signal(&left, Signal::KILL);
            // One more look: a process forked while the signals went out.
            let late = others(self.members());
            if !late.is_empty() {
                self.signal(&late, Signal::KILL);
            }
        }
        reap_orphans();
        found
    }

    /// SIGKILLs every process of the program at once (no grace: the launcher is going).
    pub fn kill(&self) {
        let members = self.members();
        self.signal(&members, Signal::KILL);
        reap_orphans();
    }
}

/// Reaps the orphans below this process that have exited (they became its children as their
/// subreaper, and nothing else waits for them).
pub fn reap_orphans() {
    let me = std::process::id();
    // Held while the orphans are reaped: no child is started (and not yet noted) meanwhile.
    let started = started();
    let Ok(pids) = procfs::pids() else {
        return;
    };
    for pid in pids.into_iter().filter(|p| !started.contains(p)) {
        let dead_orphan = procfs::stat(pid).is_ok_and(|s| s.ppid == me && s.state == 'Z');
        if let (true, Some(p)) = (dead_orphan, Pid::from_raw(pid as i32)) {
            let _ = rustix::process::waitpid(Some(p), rustix::process::WaitOptions::NOHANG);
        }
    }
}

/// `pid 123 (sleep), pid 124 (sh)`: processes, named.
pub fn describe(members: &[Member]) -> String {
    members
        .iter()
        .map(|m| {
            let outside = if m.in_group {
                ""
            } else {
                ", outside its group"
            };
            format!("pid {} ({}{outside})", m.pid, m.comm)
        })
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::process::CommandExt;
    use std::process::Stdio;

    /// A program started as the launcher starts one, running `script` under `sh`, with a
    /// variable that marks its processes.
    fn start(script: &str, mark: &str) -> (std::process::Child, Program) {
        let mut cmd = Command::new("sh");
        cmd.args(["-c", script])
            .env("FDI_TEST_MARK", mark)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .process_group(0);
        let child = spawn_noted(&mut cmd).expect("sh");
        let program = Program::new(child.id(), &cmd);
        (child, program)
    }

    fn wait_for(mut cond: impl FnMut() -> bool) {
        let began = Instant::now();
        while !cond() {
            assert!(began.elapsed() < Duration::from_secs(30), "never happened");
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    fn alive(pid: u32) -> bool {
        procfs::state(pid).is_ok_and(|s| !matches!(s, 'Z' | 'X' | 'x'))
    }

    /// A value no other test's processes have.
    fn mark(tag: &str) -> String {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        format!("{tag}-{}-{nanos}", std::process::id())
    }

    #[test]
    fn a_child_in_the_group_and_one_that_left_it_twice_are_found_and_ended() {
        let dir = std::env::temp_dir().join(mark("fdi-program"));
        std::fs::create_dir_all(&dir).expect("dir");
        let (kept, gone) = (dir.join("kept"), dir.join("detached"));
        let script = format!(
            "sleep 300 & echo $! > {kept}; (setsid sleep 301 & echo $! > {gone}); exec sleep 302",
            kept = kept.display(),
            gone = gone.display()
        );
        let (mut child, program) = start(&script, &mark("both"));
        let pid_in = |p: &std::path::Path| {
            std::fs::read_to_string(p)
                .ok()
                .and_then(|s| s.trim().parse::<u32>().ok())
        };
        wait_for(|| pid_in(&kept).is_some() && pid_in(&gone).is_some());
        let (kept, gone) = (pid_in(&kept).unwrap_or(0), pid_in(&gone).unwrap_or(0));
        // `setsid` is found in the group until it has called setsid(2): wait for that.
        wait_for(|| {
            let m = program.members();
            m.len() == 3 && m.iter().any(|m| m.pid == gone && !m.in_group)
        });
        let members = program.members();
        assert!(
            members.iter().any(|m| m.pid == kept && m.in_group),
            "{members:?}"
        );
        assert!(
            members.iter().any(|m| m.pid == gone && !m.in_group),
            "{members:?}"
        );

        let ended = program.end(Duration::from_secs(5), Some(child.id()));
        assert_eq!(ended.len(), 2, "{ended:?}");
        assert!(!alive(kept) && !alive(gone), "{:?}", program.members());
        // The leader, in the group, got the SIGTERM too.
        assert!(!child.wait().expect("wait").success());
        assert!(program.members().is_empty());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_process_that_ignores_sigterm_is_killed_after_the_grace() {
        let (mut child, program) = start("trap '' TERM; sleep 300 & wait", &mark("stubborn"));
        wait_for(|| program.members().len() == 2);
        let ended = program.end(Duration::from_millis(200), None);
        assert_eq!(ended.len(), 2, "{ended:?}");
        child.wait().expect("wait");
        wait_for(|| program.members().is_empty());
    }

    #[test]
    fn nothing_else_is_a_member() {
        let (mut child, program) = start("exit 0", &mark("none"));
        child.wait().expect("wait");
        assert_eq!(program.members(), Vec::new());
        assert!(program.end(Duration::from_secs(1), None).is_empty());
    }
}
