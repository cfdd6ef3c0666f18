//! What `/proc` says about processes (Linux): which exist, their state letter, parent and
//! process group from `/proc/PID/stat`, their command line and environment. The stat line is
//! parsed here and nowhere else.

use std::path::{Path, PathBuf};

const PROC: &str = "/proc";

/// A file of `/proc` that could not be read or parsed; both name the file.
#[derive(Debug, thiserror::Error)]
pub enum ProcError {
    #[error("reading {}: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: not a stat line (`PID (COMMAND) STATE PPID …`)", path.display())]
    Malformed { path: PathBuf },
}

/// `/proc/PID/stat`: `pid (comm) state ppid …` (proc(5)).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stat {
    pub pid: u32,
    /// The command name, as the kernel writes it between the parentheses: it may hold spaces
    /// and parentheses itself, so it ends at the line's last `)`.
    pub comm: String,
    /// `R` running, `S` sleeping, `D` disk sleep, `T` stopped, `t` tracing stop, `Z` zombie, …
    pub state: char,
    pub ppid: u32,
    /// Everything after the command name, from the state on.
    rest: String,
}

impl Stat {
    /// Parses a stat line; `None` when it is not one.
    pub fn parse(line: &str) -> Option<Self> {
        let (head, rest) = line.rsplit_once(')')?;
        let (pid, comm) = head.split_once('(')?;
        let mut fields = rest.split_whitespace();
        let state = fields.next()?;
        let mut letters = state.chars();
        let state = letters.next().filter(|_| letters.next().is_none())?;
        Some(Self {
            pid: pid.trim().parse().ok()?,
            comm: comm.to_string(),
            state,
            ppid: fields.next()?.parse().ok()?,
            rest: rest.trim().to_string(),
        })
    }

    /// The process group (field 5).
    pub fn pgrp(&self) -> Option<u32> {
        self.field(5)?.parse().ok()
    }

    /// Field `n` as proc(5) numbers them, from 3 (the state) on: 4 is the parent, 40 the
    /// real-time priority, 41 the scheduling policy. `None` for 1, 2 and past the end.
    pub fn field(&self, n: usize) -> Option<&str> {
        self.rest.split_whitespace().nth(n.checked_sub(3)?)
    }
}

fn path_of(pid: u32, file: &str) -> PathBuf {
    Path::new(PROC).join(pid.to_string()).join(file)
}

/// `/proc/PID/stat` of `pid`.
pub fn stat(pid: u32) -> Result<Stat, ProcError> {
    let path = path_of(pid, "stat");
    let line = std::fs::read_to_string(&path).map_err(|source| ProcError::Read {
        path: path.clone(),
        source,
    })?;
    Stat::parse(&line).ok_or(ProcError::Malformed { path })
}

/// The state letter of `pid` (see [`Stat::state`]).
pub fn state(pid: u32) -> Result<char, ProcError> {
    stat(pid).map(|s| s.state)
}

/// The parent of `pid`.
pub fn parent(pid: u32) -> Result<u32, ProcError> {
    stat(pid).map(|s| s.ppid)
}

/// Whether `/proc/PID` exists: the process lives, or is a zombie not yet reaped.
pub fn exists(pid: u32) -> bool {
    Path::new(PROC).join(pid.to_string()).exists()
}

/// The pids of `/proc` (its entries named by a number; an entry that cannot be read is left
/// out: a process that ends while the folder is listed).
pub fn pids() -> Result<Vec<u32>, ProcError> {
    let entries = std::fs::read_dir(PROC).map_err(|source| ProcError::Read {
        path: PROC.into(),
        source,
    })?;
    Ok(entries
        .flatten()
        .filter_map(|e| e.file_name().to_str()?.parse().ok())
        .collect())
}

/// The command line of `pid` as the kernel keeps it: every argument followed by a NUL byte
/// (empty for a zombie or a kernel thread).
pub fn cmdline(pid: u32) -> Result<Vec<u8>, ProcError> {
    let path = path_of(pid, "cmdline");
    std::fs::read(&path).map_err(|source| ProcError::Read { path, source })
}

/// The environment `pid` was started with, as the kernel keeps it: `KEY=VALUE` entries, each
/// followed by a NUL byte (readable for the processes of the same user, or by root).
pub fn environ(pid: u32) -> Result<Vec<u8>, ProcError> {
    let path = path_of(pid, "environ");
    std::fs::read(&path).map_err(|source| ProcError::Read { path, source })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_command_name_with_spaces_and_parentheses_ends_at_the_last_paren() {
        let line = "4242 (my (odd) name) ) T 17 4242 17 0 -1 4194560 120 0 0 0 3 1 0 0 20 0 1 0 \
                    99 4096 100 18446744073709551615 1 1 0 0 0 0 0 0 0 0 0 0 17 1 7 1 0 0 0\n";
        let s = Stat::parse(line).expect("a stat line");
        assert_eq!(s.pid, 4242);
        assert_eq!(s.comm, "my (odd) name) ");
        assert_eq!(s.state, 'T');
        assert_eq!(s.ppid, 17);
        assert_eq!(s.field(3), Some("T"));
        assert_eq!(s.field(4), Some("17"));
        assert_eq!((s.field(40), s.field(41)), (Some("7"), Some("1")));
        assert_eq!((s.field(2), s.field(45)), (None, None));
        assert_eq!(s.pgrp(), Some(4242));
    }

    #[test]
    fn lines_that_are_no_stat_line_are_refused() {
        for line in [
            "",
            "4242 (name S 1",
            "4242 name) S 1",
            "(name) S 1",
            "x (name) S 1",
            "4242 (name)",
            "4242 (name) S",
            "4242 (name) S x",
            "4242 (name) SR 1",
        ] {
            assert_eq!(Stat::parse(line), None, "{line:?}");
        }
    }

    #[test]
    fn this_process_is_read_from_proc() {
        let me = std::process::id();
        assert!(exists(me));
        assert!(pids().expect("/proc listed").contains(&me));
        let s = stat(me).expect("own stat");
        assert_eq!(s.pid, me);
        assert!(matches!(s.state, 'R' | 'S'), "{s:?}");
        assert_eq!(
            parent(me).expect("own parent"),
            std::os::unix::process::parent_id()
        );
        let exe = std::env::current_exe().expect("exe");
        let name = exe.file_name().expect("exe name").to_string_lossy();
        let cmd = cmdline(me).expect("own cmdline");
        assert!(cmd.ends_with(b"\0"), "{cmd:?}");
        assert!(String::from_utf8_lossy(&cmd).contains(&*name), "{cmd:?}");
        assert_eq!(
            s.pgrp(),
            Some(rustix::process::getpgrp().as_raw_nonzero().get() as u32)
        );
        if let Ok(path) = std::env::var("PATH") {
            let env = environ(me).expect("own environment");
            let entry = format!("PATH={path}\0");
            assert!(
                env.windows(entry.len()).any(|w| w == entry.as_bytes()),
                "{entry:?}"
            );
        }
    }

    #[test]
    fn a_missing_process_is_an_error_naming_its_file() {
        // Above the kernel's largest pid (2^22).
        let pid = 4_194_305;
        assert!(!exists(pid));
        let e = state(pid).expect_err("no such process");
        assert!(e.to_string().contains("/proc/4194305/stat"), "{e}");
        let e = cmdline(pid).expect_err("no such process");
        assert!(e.to_string().contains("/proc/4194305/cmdline"), "{e}");
    }
}
