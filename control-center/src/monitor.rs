//! The control center's side of a monitor program (`[roles.monitor]`, docs/protocol.md): it
//! takes the monitor's verdicts on `fdi/alarm` (one per agent and tick, in tick order), records
//! them, and in lockstep computes tick `k` of an agent only once it holds the verdict on tick
//! `k − MONITOR_LAG` (so a slow monitor slows the run instead of losing what it taps).

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use fdi_common::records::MonitorRecord;
use fdi_common::roles::ExternalRole;
use fdi_common::trace::{TraceRecord, TraceWriter};
use fdi_runtime::ipc::{
    monotonic_ns, AlarmMsg, Inbox as _, IpcError, MeasurementMsg, Stream, Transport, Wake,
};
use fdi_runtime::process::external::{LateBell, MONITOR_LAG};
use fdi_runtime::process::RoleError;

/// The ports towards the monitor program.
#[derive(Debug)]
pub struct MonitorPorts<X: Transport> {
    pub alarms: X::Inbox<AlarmMsg>,
    /// The monitor's wake-up event.
    pub bell: LateBell<X>,
}

impl<X: Transport> MonitorPorts<X> {
    pub fn open(transport: &X) -> Result<Self, IpcError> {
        Ok(Self {
            alarms: transport.subscriber(Stream::Alarm)?,
            bell: LateBell::open(transport, Wake::Monitor)?,
        })
    }

    /// Rings the monitor after a batch of measurements came or ticks were computed.
    pub fn ring(&self, transport: &X) -> Result<(), IpcError> {
        self.bell.ring(transport)
    }
}

/// What the control center keeps about the monitor.
#[derive(Debug)]
pub struct Monitor {
    label: String,
    ids: Vec<u32>,
    /// Per agent (scenario order): the next tick whose verdict is due.
    next: Vec<u64>,
    /// Lockstep: per agent, measurements held until the monitor's verdicts catch up.
    held: Vec<VecDeque<MeasurementMsg>>,
    lockstep: bool,
    timeout: Duration,
    deadline_ns: u64,
    dt: f64,
    epoch_ns: u64,
    /// The last verdict (or the start): the lockstep timeout counts from it.
    progress: Instant,
    /// Realtime: when the wait for the last verdicts ends (set once every agent is done).
    verdicts_until: Option<Instant>,
    /// Realtime: verdicts later than the deadline after their tick's time.
    late: u64,
    verdicts: u64,
}

impl Monitor {
    pub fn new(role: &ExternalRole, ids: &[u32], dt: f64, lockstep: bool, epoch_ns: u64) -> Self {
        Self {
            label: role.label(),
            ids: ids.to_vec(),
            next: vec![0; ids.len()],
            held: vec![VecDeque::new(); ids.len()],
            lockstep,
            timeout: role.timeout(),
            deadline_ns: role.deadline_ns(),
            dt,
            epoch_ns,
            progress: Instant::now(),
            verdicts_until: None,
            late: 0,
            verdicts: 0,
        }
    }

    fn violation(&self, what: String) -> RoleError {
        RoleError::External(format!("monitor `{}`: {what}", self.label))
    }

    /// Lockstep: holds `m` back until the monitor caught up with its agent (or passes it on at
    /// once); realtime: passes it on. `ready` gets each measurement that may be computed now.
    pub fn admit(&mut self, m: MeasurementMsg, ready: &mut Vec<MeasurementMsg>) {
        let Some(i) = self.ids.iter().position(|&a| a == m.agent) else {
            ready.push(m); // the center refuses it
            return;
        };
        if !self.lockstep {
            ready.push(m);
            return;
        }
        if !self.holding() {
            self.progress = Instant::now();
        }
        self.held[i].push_back(m);
        self.release(i, ready);
    }

    /// Passes on agent `i`'s held measurements that the monitor's verdicts allow.
    fn release(&mut self, i: usize, ready: &mut Vec<MeasurementMsg>) {
        while let Some(m) = self.held[i].front() {
            if m.seq >= MONITOR_LAG && self.next[i] <= m.seq - MONITOR_LAG {
                break;
            }
            ready.extend(self.held[i].pop_front());
        }
    }

    /// Takes every verdict waiting: checks it, records it, and passes on to `ready` what it
    /// releases.
    pub fn take_verdicts<X: Transport>(
        &mut self,
        ports: &MonitorPorts<X>,
        trace: &mut TraceWriter,
        ready: &mut Vec<MeasurementMsg>,
    ) -> Result<(), RoleError> {
        let mut got = Vec::new();
        ports.alarms.drain(|a| got.push(a))?;
        let now = monotonic_ns();
        for a in got {
            let Some(i) = self.ids.iter().position(|&id| id == a.agent) else {
                return Err(self.violation(format!(
                    "verdict for agent {}, which the run does not have (tick {})",
                    a.agent, a.seq
                )));
            };
            if a.seq != self.next[i] {
                return Err(self.violation(format!(
                    "agent {}: verdict on tick {} where tick {} was due (one verdict per tick, in \
                     tick order)",
                    a.agent, a.seq, self.next[i]
                )));
            }
            if a.alarm > 1 {
                return Err(self.violation(format!(
                    "agent {}, tick {}: alarm {} is neither 0 nor 1",
                    a.agent, a.seq, a.alarm
                )));
            }
            self.next[i] += 1;
            self.verdicts += 1;
            self.progress = Instant::now();
            let t = fdi_common::engine::tick_time(a.seq, self.dt);
            let late = !self.lockstep && now > self.epoch_ns + (t * 1e9) as u64 + self.deadline_ns;
            self.late += u64::from(late);
            trace.write(&TraceRecord::Monitor(MonitorRecord {
                k: a.seq,
                agent: a.agent,
                alarm: a.alarm == 1,
                statistic: a.statistic,
                late,
            }))?;
        }
        for i in 0..self.ids.len() {
            self.release(i, ready);
        }
        Ok(())
    }

    /// Whether the run may end as far as the monitor goes, once `controlled` (every agent
    /// done): every verdict of the run's `ticks` came, or, in realtime, the grace of its
    /// deadline + 200 ms after the control's end passed. In lockstep it fails once the run has
    /// waited for the monitor for its timeout (held measurements, or the last verdicts).
    pub fn judged(&mut self, ticks: u64, controlled: bool) -> Result<bool, RoleError> {
        if self.next.iter().all(|&n| n >= ticks) {
            return Ok(true);
        }
        if self.lockstep {
            self.check_timeout(controlled)?;
            return Ok(false);
        }
        if !controlled {
            return Ok(false);
        }
        let grace = Duration::from_nanos(self.deadline_ns) + Duration::from_millis(200);
        let until = *self
            .verdicts_until
            .get_or_insert_with(|| Instant::now() + grace);
        Ok(Instant::now() >= until)
    }

    /// Lockstep: fails once the run has waited for the monitor's verdicts for the timeout
    /// (measurements held back, or the last verdicts at the end: `waiting`).
    fn check_timeout(&self, waiting: bool) -> Result<(), RoleError> {
        if self.lockstep && (self.holding() || waiting) && self.progress.elapsed() > self.timeout {
            let (i, n) = self
                .next
                .iter()
                .enumerate()
                .min_by_key(|(_, n)| **n)
                .map_or((0, 0), |(i, n)| (i, *n));
            return Err(self.violation(format!(
                "no verdict on tick {n} of agent {} within {:?} (lockstep waits for the \
                 monitor; `[roles.monitor] timeout_s` sets the limit)",
                self.ids.get(i).copied().unwrap_or(0),
                self.timeout
            )));
        }
        Ok(())
    }

    /// Whether measurements are held back for the monitor.
    fn holding(&self) -> bool {
        self.held.iter().any(|h| !h.is_empty())
    }

    /// The closing note: verdicts received, missing and late.
    pub fn summary(&self, ticks: u64) -> String {
        let expected = ticks * self.ids.len() as u64;
        let mut s = format!(
            "monitor `{}`: {} of {expected} verdicts",
            self.label, self.verdicts
        );
        if !self.lockstep {
            s.push_str(&format!(
                ", {} later than the {:.3} ms deadline after their tick",
                self.late,
                self.deadline_ns as f64 / 1e6
            ));
        }
        s
    }
}
