//! Joins the per-process traces of a multi-process run into tick records, in the in-process
//! engine's order (tick, then scenario agent order), and feeds the same digest and metrics.

use std::collections::{BTreeMap, VecDeque};
use std::path::Path;

use anyhow::{Context, Result};
use fdi_common::engine::{evaluator_for, summarize, RunSummary};
use fdi_common::metrics::Evaluator;
use fdi_common::records::{
    ActuationRecord, AgentRecord, AttackRecord, CenterRecord, MonitorRecord, TickRecord,
    TraceDigest,
};
use fdi_common::scenario::Resolved;
use fdi_common::trace::{TraceReader, TraceRecord};

use fdi_common::run_dir::{Process, RunDir};

/// Records that carry their tick.
trait Tick {
    fn tick(&self) -> u64;
}
impl Tick for AgentRecord {
    fn tick(&self) -> u64 {
        self.k
    }
}
impl Tick for AttackRecord {
    fn tick(&self) -> u64 {
        self.k
    }
}
impl Tick for CenterRecord {
    fn tick(&self) -> u64 {
        self.k
    }
}
impl Tick for ActuationRecord {
    fn tick(&self) -> u64 {
        self.k
    }
}
impl Tick for MonitorRecord {
    fn tick(&self) -> u64 {
        self.k
    }
}

/// The records of one trace, as they are read: from its file, or streamed from the process
/// that writes it ([`super::tap`]). An error is the damage that ends the trace.
pub type Feed = Box<dyn Iterator<Item = Result<TraceRecord, String>> + Send>;

/// The records of a trace file.
fn file_feed(path: &Path) -> Result<Feed> {
    let reader = TraceReader::open(path)?;
    Ok(Box::new(reader.map(|r| r.map_err(|e| e.to_string()))))
}

/// One trace and the records read ahead of the join, per agent.
struct Source<T> {
    reader: Feed,
    pending: BTreeMap<u32, VecDeque<T>>,
    pick: fn(TraceRecord) -> Option<(u32, T)>,
    damage: Option<String>,
}

impl<T: Tick> Source<T> {
    fn new(reader: Feed, pick: fn(TraceRecord) -> Option<(u32, T)>) -> Self {
        Self {
            reader,
            pending: BTreeMap::new(),
            pick,
            damage: None,
        }
    }

    fn open(path: &Path, pick: fn(TraceRecord) -> Option<(u32, T)>) -> Result<Self> {
        Ok(Self::new(file_feed(path)?, pick))
    }

    /// The record of `agent` for tick `k`: older records are skipped, a newer one stays for
    /// later (the tick was lost on the way). `Err(())` at the end of the trace.
    fn take(&mut self, agent: u32, k: u64) -> Result<Option<T>, ()> {
        loop {
            if let Some(q) = self.pending.get_mut(&agent) {
                while q.front().is_some_and(|r| r.tick() < k) {
                    q.pop_front();
                }
                match q.front().map(Tick::tick) {
                    Some(t) if t == k => return Ok(q.pop_front()),
                    Some(_) => return Ok(None),
                    None => {}
                }
            }
            let Some(next) = self.reader.next() else {
                return Err(());
            };
            match next {
                Ok(rec) => {
                    if let Some((a, r)) = (self.pick)(rec) {
                        self.pending.entry(a).or_default().push_back(r);
                    }
                }
                Err(e) => {
                    self.damage = Some(e);
                    return Err(());
                }
            }
        }
    }
}

impl<T> Source<T> {
    /// Reads what the join did not need (records after the last tick, the closing events) to
    /// its end, so that damage there is reported too.
    fn finish(&mut self) {
        if self.damage.is_some() {
            return;
        }
        for rec in self.reader.by_ref() {
            if let Err(e) = rec {
                self.damage = Some(e);
                return;
            }
        }
    }
}

fn pick_agent(r: TraceRecord) -> Option<(u32, AgentRecord)> {
    match r {
        TraceRecord::Agent(a) => Some((a.agent, a)),
        _ => None,
    }
}
fn pick_attack(r: TraceRecord) -> Option<(u32, AttackRecord)> {
    match r {
        TraceRecord::Attack(a) => Some((a.agent, a)),
        _ => None,
    }
}
fn pick_actuation(r: TraceRecord) -> Option<(u32, ActuationRecord)> {
    match r {
        TraceRecord::Actuation(a) => Some((a.agent, a)),
        _ => None,
    }
}
fn pick_monitor(r: TraceRecord) -> Option<(u32, MonitorRecord)> {
    match r {
        TraceRecord::Monitor(m) => Some((m.agent, m)),
        _ => None,
    }
}
fn pick_center(r: TraceRecord) -> Option<(u32, CenterRecord)> {
    match r {
        TraceRecord::Center(c) => Some((c.agent, c)),
        _ => None,
    }
}

/// Result of a join.
#[derive(Debug)]
pub struct Joined {
    pub summary: RunSummary,
    /// Problems met while joining (damaged or short traces).
    pub warnings: Vec<String>,
}

/// Joins the traces in `run_dir` and summarizes them.
pub fn join_run(
    resolved: &Resolved,
    run: &RunDir,
    wall_s: f64,
    sink: impl FnMut(&TickRecord),
) -> Result<Joined> {
    join_run_until(resolved, run.path(), wall_s, sink, || Ok(()))
}

/// The traces of a run's processes, each read ahead as the join needs.
pub struct Sources {
    agents: Vec<(u32, Source<AgentRecord>)>,
    attacker: Source<AttackRecord>,
    /// The attacker's torque records (a second reader of its trace), when the run attacks
    /// some agent's torques.
    actuation: Option<Source<ActuationRecord>>,
    center: Source<CenterRecord>,
    /// The monitor's verdicts as the control center recorded them (a second reader of its
    /// trace), when the run has a monitor (`[roles.monitor]`).
    monitor: Option<Source<MonitorRecord>>,
}

impl Sources {
    fn open(resolved: &Resolved, run_dir: &Path) -> Result<Self> {
        let mut agents = Vec::with_capacity(resolved.scenario.agents.len());
        for a in &resolved.scenario.agents {
            let p = RunDir::new(run_dir).trace(Process::Agent(a.id));
            // A split run whose host became unreachable keeps a note instead of the trace: the
            // agent's ticks count as missing, and the note is the join's warning.
            let lost = p.with_extension("lost");
            let source = match std::fs::read_to_string(&lost) {
                Ok(note) if !p.exists() => {
                    let mut s = Source::new(Box::new(std::iter::empty()), pick_agent);
                    s.damage = Some(format!("{note}: its ticks count as missing"));
                    s
                }
                _ => Source::open(&p, pick_agent)
                    .with_context(|| format!("opening the trace of agent {}", a.id))?,
            };
            agents.push((a.id, source));
        }
        let attacker = RunDir::new(run_dir).trace(Process::Attacker);
        let routed = resolved
            .scenario
            .agents
            .iter()
            .any(|a| resolved.attack.attacks_torque_of(a.id));
        let center = RunDir::new(run_dir).trace(Process::Center);
        Ok(Self {
            agents,
            monitor: match resolved.scenario.roles.monitor {
                Some(_) => Some(
                    Source::open(&center, pick_monitor)
                        .context("opening the control-center trace")?,
                ),
                None => None,
            },
            actuation: if routed {
                Some(
                    Source::open(&attacker, pick_actuation)
                        .context("opening the attacker trace")?,
                )
            } else {
                None
            },
            attacker: Source::open(&attacker, pick_attack).context("opening the attacker trace")?,
            center: Source::open(&center, pick_center)
                .context("opening the control-center trace")?,
        })
    }

    /// The sources of streamed traces: per agent (scenario order) its feed, the attacker's
    /// measurement records, its torque records (when the run attacks some agent's torques), the
    /// control center's, and its record of the monitor's verdicts (when the run has a monitor).
    pub fn from_feeds(
        agents: Vec<(u32, Feed)>,
        attacker: Feed,
        actuation: Option<Feed>,
        center: Feed,
        monitor: Option<Feed>,
    ) -> Self {
        Self {
            agents: agents
                .into_iter()
                .map(|(id, f)| (id, Source::new(f, pick_agent)))
                .collect(),
            attacker: Source::new(attacker, pick_attack),
            actuation: actuation.map(|f| Source::new(f, pick_actuation)),
            center: Source::new(center, pick_center),
            monitor: monitor.map(|f| Source::new(f, pick_monitor)),
        }
    }

    /// Reads every trace to its end and adds what damage they showed to `warnings`.
    fn finish(mut self, warnings: &mut Vec<String>) {
        for (_, src) in &mut self.agents {
            src.finish();
        }
        self.attacker.finish();
        self.center.finish();
        if let Some(a) = &mut self.actuation {
            a.finish();
        }
        if let Some(m) = &mut self.monitor {
            m.finish();
        }
        for (id, src) in &self.agents {
            if let Some(d) = &src.damage {
                warnings.push(format!("agent {id}: {d}"));
            }
        }
        // The second reader of the attacker trace sees the same damage: reported once.
        for d in [&self.attacker.damage, &self.center.damage]
            .into_iter()
            .flatten()
        {
            warnings.push(d.clone());
        }
    }
}

/// [`join_run`], calling `stop` every few thousand ticks: its error (an interrupt) ends the
/// join at once.
pub fn join_run_until(
    resolved: &Resolved,
    run_dir: &Path,
    wall_s: f64,
    sink: impl FnMut(&TickRecord),
    stop: impl Fn() -> Result<()>,
) -> Result<Joined> {
    let sources = Sources::open(resolved, run_dir)?;
    Ok(walk(resolved, sources, 1, sink, stop)?.summarize(resolved, wall_s))
}

/// The join of traces that keep every `every`-th tick (`--traces decimate=K`): the kept ticks
/// into `sink`. Its metrics and digest cover those ticks only (the run's summary covers them
/// all).
pub fn join_decimated(
    resolved: &Resolved,
    run_dir: &Path,
    every: u32,
    sink: impl FnMut(&TickRecord),
    stop: impl Fn() -> Result<()>,
) -> Result<Joined> {
    let sources = Sources::open(resolved, run_dir)?;
    Ok(walk(resolved, sources, u64::from(every.max(1)), sink, stop)?.summarize(resolved, f64::NAN))
}

/// What a walk over a run's ticks gathered: the digest and the metrics of every tick joined.
pub struct Walked {
    joined: u64,
    digest: TraceDigest,
    evaluator: Evaluator,
    warnings: Vec<String>,
}

impl Walked {
    /// What the join found wrong with the traces (a damaged or short one).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// The run's summary (engine `ipc`), and the warnings of the join.
    pub fn summarize(self, resolved: &Resolved, wall_s: f64) -> Joined {
        Joined {
            summary: summarize(
                resolved,
                "ipc",
                self.joined,
                wall_s,
                self.digest,
                self.evaluator,
            ),
            warnings: self.warnings,
        }
    }
}

/// Walks the ticks of a run over its sources, in the in-process engine's order, feeding the
/// digest, the metrics and `sink`; `stop` is called every few thousand ticks. `stride` 1 walks
/// every tick; K the ticks 0, K, 2K, … of decimated traces.
pub fn walk(
    resolved: &Resolved,
    mut traces: Sources,
    stride: u64,
    mut sink: impl FnMut(&TickRecord),
    stop: impl Fn() -> Result<()>,
) -> Result<Walked> {
    let mut join = Join::new(resolved);
    let mut joined = 0;
    // An agent whose trace ends early (lost in a realtime run) leaves the join; the others go on.
    let mut ended = vec![false; traces.agents.len()];
    'ticks: for (i, k) in (0..join.ticks).step_by(stride.max(1) as usize).enumerate() {
        if i % 4096 == 4095 {
            stop()?;
        }
        for n in 0..traces.agents.len() {
            if ended[n] {
                continue;
            }
            if !join.agent_tick(&mut traces, n, k, &mut sink) {
                ended[n] = true;
                if ended.iter().all(|e| *e) {
                    break 'ticks;
                }
            }
        }
        // The ticks joined: up to the last one that some robot was still controlled on (each
        // robot's metrics say how many of its own ticks they cover).
        if join.control_ended.iter().any(|ended| !ended) {
            joined = k + 1;
        }
    }
    join.warn_uncontrolled();
    let Join {
        digest,
        evaluator,
        mut warnings,
        ..
    } = join;
    traces.finish(&mut warnings);
    Ok(Walked {
        joined,
        digest,
        evaluator,
        warnings,
    })
}

/// What a join has gathered while it walks the ticks.
struct Join {
    digest: TraceDigest,
    evaluator: Evaluator,
    warnings: Vec<String>,
    /// The run's planned ticks.
    ticks: u64,
    /// Agent-ticks whose measurement never reached the control center.
    lost: u64,
    /// Per agent (scenario order): its torques go through the attacker.
    routed: Vec<bool>,
    /// Agent-ticks of such agents without the attacker's torque record.
    actuation_lost: u64,
    /// Ticks the agents recorded after the attacker or control-center trace ended for them:
    /// they ran on without control, and their own records (deadline misses) still count.
    after_control: u64,
    /// Per agent (scenario order): the attacker's or the control center's records of it have
    /// ended. Each robot's control ends where its own records end: the center computes each
    /// robot's tick as its measurement arrives, so an interrupted run leaves the robots at
    /// different ticks.
    control_ended: Vec<bool>,
}

impl Join {
    fn new(resolved: &Resolved) -> Self {
        Self {
            digest: TraceDigest::new(),
            evaluator: evaluator_for(resolved),
            warnings: Vec::new(),
            ticks: resolved.ticks(),
            lost: 0,
            routed: resolved
                .scenario
                .agents
                .iter()
                .map(|a| resolved.attack.attacks_torque_of(a.id))
                .collect(),
            actuation_lost: 0,
            after_control: 0,
            control_ended: vec![false; resolved.scenario.agents.len()],
        }
    }

    /// Tick `k` of the `n`-th agent: its record joined with the attacker's and the control
    /// center's into the digest, the metrics and `sink`, or counted uncontrolled when they lack
    /// it. `false` when the agent's trace has ended (with a warning).
    fn agent_tick(
        &mut self,
        traces: &mut Sources,
        n: usize,
        k: u64,
        sink: &mut impl FnMut(&TickRecord),
    ) -> bool {
        let ticks = self.ticks;
        let (id, src) = &mut traces.agents[n];
        let Ok(Some(a)) = src.take(*id, k) else {
            self.warnings
                .push(format!("agent {id}: its trace ends at tick {k} of {ticks}"));
            return false;
        };
        if self.control_ended[n] {
            self.after_control += 1;
            self.evaluator.push_uncontrolled(&a);
            return true;
        }
        let (x, c) = match (traces.attacker.take(*id, k), traces.center.take(*id, k)) {
            (Ok(Some(x)), Ok(Some(c))) => (x, c),
            // The measurement of this tick never reached the control center (realtime
            // overflow, a stalled process, an agent given up as lost): the agent held its
            // last command, uncontrolled.
            (Ok(_), Ok(_)) => {
                self.lost += 1;
                self.evaluator.push_uncontrolled(&a);
                return true;
            }
            _ => {
                self.warnings.push(format!(
                    "the attacker or control-center trace ends at tick {k} of {ticks} (agent {id})"
                ));
                self.control_ended[n] = true;
                self.after_control += 1;
                self.evaluator.push_uncontrolled(&a);
                return true;
            }
        };
        let actuation = match (&mut traces.actuation, self.routed[n]) {
            (Some(src), true) => {
                let r = src.take(*id, k).ok().flatten();
                self.actuation_lost += u64::from(r.is_none());
                r
            }
            _ => None,
        };
        // A tick the monitor gave no verdict on has none: the metrics count it as missing.
        let monitor = traces
            .monitor
            .as_mut()
            .and_then(|src| src.take(*id, k).ok().flatten());
        let rec = TickRecord {
            agent: a,
            attack: x,
            center: c,
            actuation,
            monitor,
        };
        self.digest.push(&rec);
        self.evaluator.push(&rec);
        sink(&rec);
        true
    }

    /// The warnings of the agent-ticks that ran uncontrolled (lost, or after the control ended).
    fn warn_uncontrolled(&mut self) {
        let (lost, after_control) = (self.lost, self.after_control);
        if self.actuation_lost > 0 {
            self.warnings.push(format!(
                "{} agent-ticks of robots whose torques go through the attacker have no record of the torque's way (it never reached the attacker)",
                self.actuation_lost
            ));
        }
        if lost > 0 {
            self.warnings.push(format!(
                "{lost} agent-ticks never reached the control center (the robots ran uncontrolled): left out of the metrics but their deadline misses"
            ));
        }
        if after_control > 0 {
            self.warnings.push(format!(
                "{after_control} agent-ticks were recorded after the control stopped (the robots ran uncontrolled): left out of the metrics but their deadline misses"
            ));
        }
    }
}
