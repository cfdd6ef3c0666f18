//! The replayer process of `run --replay RUN_DIR`: it stands in for the agents and the attacker
//! and publishes a recorded run's tampered measurements (the attacker trace's `y`, `ẏ` per agent
//! per tick, in order) to the control center, in lockstep batches: it never runs more than
//! [`AHEAD`] ticks ahead of the torques it got back, so no buffer overflows. Its `--trace` is
//! the attacker trace it plays back (read only); it writes no trace of its own. One
//! [`Role`] of the run, in the attacker's place (its lifecycle and process shell:
//! [`fdi_runtime::role`]).

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{bail, Context, Result};
use fdi_common::engine::tick_time;
use fdi_common::records::{AttackRecord, Delivery};
use fdi_common::run_dir::{Process, RunDir};
use fdi_common::scenario::{self, Resolved, MAX_DOF};
use fdi_common::stop::Stop;
use fdi_common::trace::{TraceReader, TraceRecord, TraceWriter};
use fdi_runtime::ipc::{
    self, Bell as _, Inbox as _, MeasurementMsg, Outbox as _, Stream, TorqueMsg, Transport, Wake,
    Waker as _,
};
use fdi_runtime::process::{ProcessArgs, RoleError};
use fdi_runtime::role::{self, End, Opened, Role, Turn};

/// Ticks one agent may be ahead of its last torque (well within every stream's buffer).
const AHEAD: u64 = 64;
/// Poll period while waiting for torques (the center rings the agents, not the replayer).
const POLL: Duration = Duration::from_micros(100);

/// The attack records of `path` per agent of `resolved`, each exactly ticks `0..ticks` in
/// order; any other content (damage, a missing or extra tick) is refused, naming the file.
pub fn load_recording(resolved: &Resolved, path: &Path) -> Result<Vec<Vec<AttackRecord>>> {
    let ids: Vec<u32> = resolved.scenario.agents.iter().map(|a| a.id).collect();
    if let Some(id) = ids
        .iter()
        .find(|id| resolved.attack.attacks_torque_of(**id))
    {
        bail!(
            "{}: the recorded run attacks agent {id}'s torques; a replay stands in for the agents and the attacker on the measurement path only, so it cannot reproduce that run",
            path.display()
        );
    }
    let ticks = resolved.ticks();
    let mut per_agent: Vec<Vec<AttackRecord>> = vec![Vec::new(); ids.len()];
    let mut reader = TraceReader::open(path).context("the recording cannot be replayed")?;
    while let Some(rec) = reader.next() {
        let rec = rec.context("the recording cannot be replayed")?;
        let TraceRecord::Attack(a) = rec else {
            continue;
        };
        let at = reader.last_offset();
        let Some(i) = ids.iter().position(|id| *id == a.agent) else {
            bail!(
                "{}: the record at byte offset {at}: agent {} is not in the recorded scenario",
                path.display(),
                a.agent
            );
        };
        let want = per_agent[i].len() as u64;
        if a.k != want || a.y.as_slice().len() > MAX_DOF {
            bail!(
                "{}: the record at byte offset {at}: agent {}: tick {} where tick {want} was expected (only a complete recording can be replayed)",
                path.display(),
                a.agent,
                a.k
            );
        }
        per_agent[i].push(a);
    }
    for (id, recs) in ids.iter().zip(&per_agent) {
        if recs.len() as u64 != ticks {
            bail!(
                "{}: agent {id} has {} of {ticks} ticks (only a complete recording can be replayed)",
                path.display(),
                recs.len()
            );
        }
    }
    Ok(per_agent)
}

fn payload(j: &fdi_common::records::Joints) -> [f64; MAX_DOF] {
    let mut a = [0.0; MAX_DOF];
    for (o, x) in a.iter_mut().zip(j.as_slice()) {
        *o = *x;
    }
    a
}

/// The replayer of the recording at `recording` (an attacker trace).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Replayer {
    pub recording: PathBuf,
}

/// The replayer's ports: the tampered measurements it publishes, the torques it counts.
#[derive(Debug)]
pub struct Ports<X: Transport> {
    tampered: X::Outbox<MeasurementMsg>,
    /// Per agent in the scenario's order.
    torques: Vec<X::Inbox<TorqueMsg>>,
}

impl Role for Replayer {
    type Ports<X: Transport> = Ports<X>;
    type Running<'a, X: Transport + 'a> = Replay<'a, X>;

    fn identity(&self) -> (ipc::Role, Wake) {
        (ipc::Role::Attacker, Wake::Attacker)
    }

    fn program(&self) -> String {
        "fdi-replayer".into()
    }

    fn trace_name(&self) -> Option<String> {
        None
    }

    fn open<X: Transport>(
        &self,
        transport: &X,
        resolved: &Resolved,
    ) -> Result<Ports<X>, RoleError> {
        Ok(Ports {
            tampered: transport.publisher(Stream::Tampered)?,
            torques: (resolved.scenario.agents.iter())
                .map(|a| transport.subscriber(Stream::Torque(a.id)))
                .collect::<Result<_, _>>()?,
        })
    }

    fn prepare<'a, X: Transport + 'a>(
        &'a self,
        resolved: &'a Resolved,
        opened: &'a Opened<X, Ports<X>>,
    ) -> Result<Replay<'a, X>, RoleError> {
        let recording = load_recording(resolved, &self.recording)
            .map_err(|e| RoleError::Input(format!("{e:#}")))?;
        let n = recording.len();
        Ok(Replay {
            resolved,
            opened,
            recording,
            sent: vec![0; n],
            answered: vec![0; n],
            center: None,
        })
    }
}

/// A replay under way: per agent, the ticks sent and the ticks answered with a torque.
pub struct Replay<'a, X: Transport> {
    resolved: &'a Resolved,
    opened: &'a Opened<X, Ports<X>>,
    recording: Vec<Vec<AttackRecord>>,
    sent: Vec<u64>,
    answered: Vec<u64>,
    /// The center's bell, made at the start.
    center: Option<X::Bell>,
}

impl<X: Transport> role::Running for Replay<'_, X> {
    fn begin(&mut self, _: u64, _: &mut TraceWriter) -> Result<(), RoleError> {
        // Made once every process is ready, so that it reaches the center's listener.
        self.center = Some(self.opened.conn.transport.notifier(Wake::Center)?);
        Ok(())
    }

    /// Publishes every agent's next ticks up to [`AHEAD`] past its last torque, then counts
    /// the torques back.
    fn turn(&mut self, _: &mut TraceWriter) -> Result<Turn, RoleError> {
        let s = &self.resolved.scenario;
        let (dt, ticks) = (s.control_period_s, self.resolved.ticks());
        let mut published = false;
        for (i, recs) in self.recording.iter().enumerate() {
            while self.sent[i] < ticks && self.sent[i] < self.answered[i] + AHEAD {
                let r = &recs[self.sent[i] as usize];
                let t = tick_time(r.k, dt);
                // A tick whose input was missing is a gap marker, as the attacker sent it.
                let dof = s.agents[i].model.dof() as u32;
                self.opened
                    .ports
                    .tampered
                    .send(if r.delivery == Delivery::Delivered {
                        MeasurementMsg {
                            seq: r.k,
                            agent: r.agent,
                            dof: r.y.as_slice().len() as u32,
                            t,
                            y: payload(&r.y),
                            yd: payload(&r.yd),
                            agent_sent_ns: 0,
                            attacker_received_ns: 0,
                            attacker_sent_ns: 0,
                            flags: 0,
                            reserved: 0,
                        }
                    } else {
                        MeasurementMsg::gap(r.k, r.agent, dof, t)
                    })?;
                self.sent[i] += 1;
                published = true;
            }
        }
        if let (true, Some(center)) = (published, &self.center) {
            center.ring()?;
        }
        for (i, inbox) in self.opened.ports.torques.iter().enumerate() {
            let answered = &mut self.answered[i];
            inbox.drain(|m| *answered = (*answered).max(m.seq + 1))?;
        }
        Ok(if self.answered.iter().all(|a| *a >= ticks) {
            Turn::Done
        } else {
            Turn::Pending
        })
    }

    fn wait(&mut self) -> Result<(), RoleError> {
        self.opened.conn.waker.wait_precise(POLL)?;
        Ok(())
    }

    fn end(self, _: &mut TraceWriter) -> Result<End, RoleError> {
        Ok(End {
            ticks: self.resolved.ticks(),
            note: None,
        })
    }
}

/// The process of `fdi-launch process replayer`.
pub fn run_process(args: &ProcessArgs) -> Result<role::Ended, role::Failed> {
    role::run_process(
        &Replayer {
            recording: args.trace.clone(),
        },
        args,
    )
}

/// Checks that every trace of `path` reads to its end, naming the file otherwise.
fn check_trace(path: &Path) -> Result<()> {
    let reader = TraceReader::open(path).context("the recording cannot be replayed")?;
    for rec in reader {
        rec.context("the recording cannot be replayed")?;
    }
    Ok(())
}

/// Checks the traces of the recorded run `recorded` that a replay reads (the attacker's, played
/// back, and the agents', copied): every one must read to its end. Returns their paths.
pub fn check_recording(r: &Resolved, recorded: &RunDir) -> Result<Vec<std::path::PathBuf>> {
    fdi_report::traces::require_every_tick(recorded, "run --replay")?;
    let attacker = recorded.trace(Process::Attacker);
    load_recording(r, &attacker)?;
    let mut copies = vec![attacker];
    for a in &r.scenario.agents {
        let p = recorded.trace(Process::Agent(a.id));
        check_trace(&p)?;
        copies.push(p);
    }
    Ok(copies)
}

/// What a replay made: the replayed run's summary and directory beside the recording's digest.
#[derive(Debug)]
pub struct Replayed {
    pub summary: fdi_common::engine::RunSummary,
    pub dir: std::path::PathBuf,
    /// The trace digest of the recorded run.
    pub recorded_trace_digest: String,
}

impl Replayed {
    /// The replayed control center gave the recorded run's trace digest.
    pub fn matches(&self) -> bool {
        self.summary.trace_digest == self.recorded_trace_digest
    }
}

/// `run --replay RUN_DIR`: re-runs the recorded run's control center on its recorded tampered
/// measurements in a fresh run directory under `out`, and compares the trace digests.
pub fn replay_run(
    recorded: &Path,
    out: &Path,
    progress: &fdi_common::observe::Observer,
    stop: &Stop,
) -> Result<Replayed> {
    let summary_path = RunDir::new(recorded).summary();
    // Bounded, and only from a regular file, like scenario files.
    let text = scenario::read_limited(&summary_path).map_err(anyhow::Error::msg)?;
    let recorded_summary: fdi_common::engine::RunSummary = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a run summary", summary_path.display()))?;
    let scenario_path = RunDir::new(recorded).scenario();
    let mut r = scenario::load_written(&scenario_path)
        .with_context(|| format!("reading {}", scenario_path.display()))?;
    // The center is event-driven: the replay is lockstep whatever the recording's clock.
    r.scenario.clock = scenario::ClockMode::Lockstep;
    let copies = check_recording(&r, &RunDir::new(recorded))?;
    // Named apart from the runs of the same scenario (`<timestamp>-<name>-replay`).
    let dir =
        crate::run_dirs::create_named_run_dir(out, &r, &format!("{}-replay", r.scenario.name))?;
    let copied = copies.iter().try_for_each(|from| {
        let to = RunDir::new(&dir)
            .traces()
            .join(from.file_name().unwrap_or_default());
        std::fs::copy(from, &to)
            .map(|_| ())
            .with_context(|| format!("copying {} to {}", from.display(), to.display()))
            .map_err(crate::run::RunError::not_started)
    });
    let outcome = crate::run_dirs::discard_if_not_started(
        &dir,
        copied.and_then(|()| {
            crate::run::runtime::run_ipc(
                &r,
                &crate::run::runtime::IpcOptions {
                    run_dir: dir.clone(),
                    progress: progress.clone(),
                    replay: true,
                    placement: crate::run::runtime::Placement::default(),
                    pipes: false,
                    split: None,
                    stop: stop.clone(),
                    pace: None,
                    remote_traces: None,
                },
            )
        }),
    )?;
    let mut joined = fdi_report::join::join_run(&r, &RunDir::new(&dir), outcome.wall_s, |_| {})?;
    joined.summary.engine = "replay".into();
    for w in &joined.warnings {
        log::warn!("{w}");
    }
    fdi_report::output::write_summary(&RunDir::new(&dir), &joined.summary)?;
    Ok(Replayed {
        summary: joined.summary,
        dir,
        recorded_trace_digest: recorded_summary.trace_digest,
    })
}
