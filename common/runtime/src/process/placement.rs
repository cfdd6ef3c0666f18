//! Where and how a run's processes are scheduled: CPU affinity and SCHED_FIFO.

/// Where and how a run's processes are scheduled (`--rt-priority`, `--cpus`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct Placement {
    /// Realtime runs: every process of the run under SCHED_FIFO at this priority (1–99)
    /// instead of the time-sharing default. Needs CAP_SYS_NICE or an RLIMIT_RTPRIO of at least
    /// the priority.
    #[cfg_attr(feature = "clap", arg(long, value_name = "PRIORITY", value_parser = clap::value_parser!(u8).range(1..=99)))]
    pub rt_priority: Option<u8>,
    /// Every process of the run only on these CPUs (a list such as `1`, `0,2` or `0-3`).
    #[cfg_attr(feature = "clap", arg(long, value_name = "LIST"))]
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

/// Puts the calling thread under SCHED_IDLE at nice 19: it runs only when nothing else wants
/// its CPU, and any other thread that wakes takes the CPU from it at once (a nice value alone
/// still lets it hold the CPU for a scheduler slice). Threads it starts later inherit the
/// policy. The error says why not.
pub fn use_idle() -> Result<(), String> {
    use thread_priority::unix::{
        set_thread_priority_and_policy, thread_native_id, NormalThreadSchedulePolicy,
        ThreadSchedulePolicy,
    };
    use thread_priority::ThreadPriority;
    let idle = set_thread_priority_and_policy(
        thread_native_id(),
        ThreadPriority::Min,
        ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Idle),
    )
    .map_err(|e| format!("SCHED_IDLE: {e:?}"));
    // Nice 19 whether or not SCHED_IDLE was allowed (a container may refuse it).
    let nice = rustix::process::setpriority_process(None, 19).map_err(|e| format!("nice 19: {e}"));
    idle.and(nice)
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
