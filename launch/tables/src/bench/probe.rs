//! The machine's own deadline floor, measured beside a realtime run: a thread of the launcher
//! sleeps until every period boundary (absolute CLOCK_MONOTONIC deadlines, like the agents)
//! and records how late it woke. A stall that delays this thread by milliseconds is the
//! machine's (the hypervisor taking the vCPU, a kernel thread, another process), not the
//! runtime's; deadline misses that fall in such a stall are reported as such.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;

use anyhow::{anyhow, Result};
use fdi_runtime::ipc::{monotonic_ns, sleep_until_ns};
use fdi_runtime::process::CpuList;

use fdi_orchestrator::run::runtime::Placement;
use hdrhistogram::Histogram;

/// Wake-ups at least this late are kept as stalls, ns.
pub const STALL_NS: u64 = 500_000;

/// One wake-up of the timer probe: `(due, woke)`, CLOCK_MONOTONIC ns.
type Wakeup = (u64, u64);

/// Every wake-up of the timer probe.
#[derive(Debug, Default)]
pub struct Wakeups(Vec<Wakeup>);

impl Wakeups {
    /// What the probe saw of the wake-ups due in `[from, to]` (the run itself: not its start-up
    /// or its teardown).
    pub fn within(&self, from: u64, to: u64) -> Result<ProbeResult> {
        let mut late = Histogram::<u64>::new(3)?;
        let mut stalls = Vec::new();
        for &(due, woke) in self.0.iter().filter(|(due, _)| (from..=to).contains(due)) {
            let l = woke.saturating_sub(due);
            late.record(l.max(1))?;
            if l >= STALL_NS {
                stalls.push((due, woke));
            }
        }
        stalls.sort_unstable();
        Ok(ProbeResult { late, stalls })
    }
}

/// What the timer probe saw during a run.
#[derive(Debug)]
pub struct ProbeResult {
    /// Lateness of every wake-up, ns.
    pub late: Histogram<u64>,
    /// Wake-ups at least [`STALL_NS`] late: `(due, woke)`, CLOCK_MONOTONIC ns, sorted.
    pub stalls: Vec<(u64, u64)>,
}

impl ProbeResult {
    /// Wake-ups at least `ns` late.
    pub fn stalls_over(&self, ns: u64) -> usize {
        self.stalls
            .iter()
            .filter(|(due, woke)| woke - due >= ns)
            .count()
    }
}

/// A running timer probe: one thread per CPU this process may use, each pinned to its CPU, so
/// that a stall of one CPU (a vCPU the hypervisor took away) shows even when the other runs.
#[derive(Debug)]
pub struct TimerProbe {
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<Result<Vec<Wakeup>, String>>>,
}

impl TimerProbe {
    /// Starts waking every `period_ns` on every CPU of the run it sits beside (its `--cpus`,
    /// or every CPU this process may use), scheduled like that run.
    pub fn start(period_ns: u64, placement: &Placement) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let rt_priority = placement.rt_priority;
        let cpus: Vec<Option<CpuList>> =
            match placement.cpus.clone().map_or_else(CpuList::allowed, Ok) {
                Ok(list) => list
                    .cpus()
                    .iter()
                    .map(|&c| Some(CpuList::single(c)))
                    .collect(),
                Err(_) => vec![None],
            };
        let threads = cpus
            .into_iter()
            .map(|cpu| {
                let flag = Arc::clone(&stop);
                std::thread::spawn(move || probe_loop(cpu, period_ns, rt_priority, &flag))
            })
            .collect();
        Self { stop, threads }
    }

    /// Stops the probe and returns every wake-up it had on every CPU.
    pub fn finish(self) -> Result<Wakeups> {
        self.stop.store(true, Ordering::Relaxed);
        let mut all = Vec::new();
        for t in self.threads {
            all.extend(
                t.join()
                    .map_err(|_| anyhow!("the timer probe panicked"))?
                    .map_err(|e| anyhow!("timer probe: {e}"))?,
            );
        }
        Ok(Wakeups(all))
    }
}

fn probe_loop(
    cpu: Option<CpuList>,
    period_ns: u64,
    rt_priority: Option<u8>,
    stop: &AtomicBool,
) -> Result<Vec<Wakeup>, String> {
    Placement {
        rt_priority,
        cpus: cpu,
    }
    .apply()?;
    let mut wakeups = Vec::new();
    let period = period_ns.max(1);
    let mut due = monotonic_ns() + period;
    while !stop.load(Ordering::Relaxed) {
        sleep_until_ns(due);
        let woke = monotonic_ns();
        wakeups.push((due, woke));
        // After a stall, the next boundary still ahead (no burst of catch-up wake-ups).
        due += period * (1 + woke.saturating_sub(due) / period);
    }
    Ok(wakeups)
}

/// How many of the `windows` (`[from, to]`, ns) overlap at least one of the `stalls`
/// (`[due, woke]`, ns; several CPUs' stalls may overlap each other).
pub fn overlapping(windows: &[(u64, u64)], stalls: &[(u64, u64)]) -> usize {
    let mut sorted = stalls.to_vec();
    sorted.sort_unstable();
    // Latest end among the stalls that begin at or before each one.
    let reach: Vec<u64> = sorted
        .iter()
        .scan(0u64, |m, &(_, woke)| {
            *m = (*m).max(woke);
            Some(*m)
        })
        .collect();
    windows
        .iter()
        .filter(|(from, to)| {
            let began = sorted.partition_point(|(due, _)| due <= to);
            began > 0 && reach[began - 1] >= *from
        })
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_count_when_they_touch_a_stall() {
        // Two CPUs' stalls, overlapping each other.
        let stalls = [(100, 200), (1_000, 1_500), (1_200, 1_300), (5_000, 9_000)];
        let windows = [
            (0, 99),        // before everything
            (0, 100),       // touches the first stall's start
            (150, 160),     // inside the first
            (201, 999),     // between two stalls
            (1_400, 1_600), // straddles the second's end
            (9_001, 9_500), // after everything
            (4_000, 10_000),
        ];
        assert_eq!(overlapping(&windows, &stalls), 4);
        assert_eq!(overlapping(&windows, &[]), 0);
        assert_eq!(overlapping(&[], &stalls), 0);
    }

    #[test]
    fn the_probe_records_one_lateness_per_wake_up() {
        let probe = TimerProbe::start(1_000_000, &Placement::default());
        std::thread::sleep(std::time::Duration::from_millis(30));
        let all = probe.finish().expect("probe");
        assert!(all.0.iter().all(|(due, woke)| woke >= due));
        let r = all.within(0, u64::MAX).expect("window");
        assert_eq!(r.late.len(), all.0.len() as u64);
        // Nothing is due before the probe started.
        assert!(all.within(0, 1).expect("window").late.is_empty());
        // A count, not a speed: wake-ups happened (one thread per CPU), and every stall was
        // recorded in the histogram too.
        assert!(!r.late.is_empty());
        assert!(r.late.len() >= r.stalls.len() as u64);
        assert!(r.stalls.iter().all(|(due, woke)| woke - due >= STALL_NS));
        assert_eq!(r.stalls_over(u64::MAX), 0);
    }
}
