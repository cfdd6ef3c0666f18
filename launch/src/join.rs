//! Joins the per-process traces of a multi-process run into tick records, in the in-process
//! engine's order (tick, then scenario agent order), and feeds the same digest and metrics.

use std::collections::{BTreeMap, VecDeque};
use std::path::Path;

use anyhow::{Context, Result};
use fdi_common::engine::{evaluator_for, summarize, RunSummary};
use fdi_common::records::{AgentRecord, AttackRecord, CenterRecord, TickRecord, TraceDigest};
use fdi_common::scenario::Resolved;
use fdi_common::trace::{TraceReader, TraceRecord};

use crate::runtime::trace_path;

/// One trace and the records read ahead of the join, per agent.
struct Source<T> {
    reader: TraceReader,
    pending: BTreeMap<u32, VecDeque<T>>,
    pick: fn(TraceRecord) -> Option<(u32, T)>,
    damage: Option<String>,
}

impl<T> Source<T> {
    fn open(path: &Path, pick: fn(TraceRecord) -> Option<(u32, T)>) -> Result<Self> {
        Ok(Self {
            reader: TraceReader::open(path)?,
            pending: BTreeMap::new(),
            pick,
            damage: None,
        })
    }

    /// The next record of `agent`, reading ahead as needed; `None` at the end of the trace.
    fn next_for(&mut self, agent: u32) -> Option<T> {
        loop {
            if let Some(r) = self.pending.get_mut(&agent).and_then(VecDeque::pop_front) {
                return Some(r);
            }
            match self.reader.next()? {
                Ok(rec) => {
                    if let Some((a, r)) = (self.pick)(rec) {
                        self.pending.entry(a).or_default().push_back(r);
                    }
                }
                Err(e) => {
                    self.damage = Some(e.to_string());
                    return None;
                }
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
    run_dir: &Path,
    wall_s: f64,
    mut sink: impl FnMut(&TickRecord),
) -> Result<Joined> {
    let s = &resolved.scenario;
    let mut agents = Vec::with_capacity(s.agents.len());
    for a in &s.agents {
        let p = trace_path(run_dir, &format!("agent-{}", a.id));
        agents.push((
            a.id,
            Source::open(&p, pick_agent)
                .with_context(|| format!("opening the trace of agent {}", a.id))?,
        ));
    }
    let mut attacker = Source::open(&trace_path(run_dir, "attacker"), pick_attack)
        .context("opening the attacker trace")?;
    let mut center = Source::open(&trace_path(run_dir, "control-center"), pick_center)
        .context("opening the control-center trace")?;
    let mut digest = TraceDigest::new();
    let mut evaluator = evaluator_for(resolved);
    let mut warnings = Vec::new();
    let ticks = resolved.ticks();
    let mut joined = 0;
    'ticks: for k in 0..ticks {
        for (id, src) in &mut agents {
            let (Some(a), Some(x), Some(c)) = (
                src.next_for(*id),
                attacker.next_for(*id),
                center.next_for(*id),
            ) else {
                warnings.push(format!("traces end at tick {k} of {ticks} (agent {id})"));
                break 'ticks;
            };
            if a.k != k || x.k != k || c.k != k {
                warnings.push(format!("agent {id}: records out of step at tick {k} (agent {}, attacker {}, center {})", a.k, x.k, c.k));
                break 'ticks;
            }
            let rec = TickRecord {
                agent: a,
                attack: x,
                center: c,
            };
            digest.push(&rec);
            evaluator.push::<2>(&rec);
            sink(&rec);
        }
        joined = k + 1;
    }
    for (id, src) in &agents {
        if let Some(d) = &src.damage {
            warnings.push(format!("agent {id}: {d}"));
        }
    }
    for d in [&attacker.damage, &center.damage].into_iter().flatten() {
        warnings.push(d.clone());
    }
    Ok(Joined {
        summary: summarize(resolved, "ipc", joined, wall_s, digest, evaluator),
        warnings,
    })
}
