//! The three roles as threads of the test process over the in-process transport
//! ([`fdi_runtime::ipc::Local`]): the agents', the attacker's and the control center's own loops,
//! with this thread in the launcher's place (ready, start, done), and no binary spawned.
//!
//! The attacker's place may instead be taken by a test relay ([`Middle::Relay`]) that decides
//! what to forward for each measurement (duplicates, replays, forgeries), and the test may send
//! forged torques on the agents' channels before the start ([`ThreadRun::forged_torques`]).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use fdi_common::engine::{run_inproc_any, tick_time};
use fdi_common::records::{AgentRecord, AttackRecord, CenterRecord, TickRecord, TraceDigest};
use fdi_common::scenario::Resolved;
use fdi_common::trace::{TraceRecord, TraceWriter};
use fdi_runtime::ipc::{
    monotonic_ns, Bell as _, ControlMsg, Inbox as _, Local, MeasurementMsg, Outbox as _, Role,
    StatusMsg, Stream, TorqueMsg, Transport, Wake, Waker as _,
};
use fdi_runtime::process::{self, Shutdown, Start, WaitStrategy};

use crate::Scratch;

/// How long the roles may take to get ready, and the run to finish: a watchdog against hangs,
/// not a speed check.
const LIMIT: Duration = Duration::from_secs(120);

/// What stands between the agents and the control center.
pub enum Middle {
    /// The attacker role's own loop, with the scenario's attack.
    Attacker,
    /// A relay of the test: for each measurement received (in order), the messages to publish
    /// on the tampered stream.
    Relay(Box<dyn FnMut(MeasurementMsg) -> Vec<MeasurementMsg> + Send>),
}

/// What a role thread does: given the run prefix, the scenario, the traces folder and the
/// shutdown flag, run the role; its error names it.
type RoleWork = dyn FnOnce(&str, &Resolved, &Path, &Shutdown) -> Result<(), String> + Send;

/// A threaded run of `resolved`.
pub struct ThreadRun {
    pub resolved: Resolved,
    pub middle: Middle,
    /// Torques published on agent `id`'s channel before the start, as `(id, message)`.
    pub forged_torques: Vec<(u32, TorqueMsg)>,
}

/// What a threaded run left: its traces.
pub struct ThreadOutcome {
    pub dir: Scratch,
}

impl ThreadOutcome {
    pub fn trace(&self, process: &str) -> PathBuf {
        self.dir.0.join(format!("{process}.trace"))
    }

    /// The records of every process, joined in the in-process engine's order (tick, then the
    /// scenario's agent order); the attacker's are `None` when a relay stood in for it.
    pub fn joined(
        &self,
        resolved: &Resolved,
    ) -> Vec<(AgentRecord, Option<AttackRecord>, CenterRecord)> {
        let ids: Vec<u32> = resolved.scenario.agents.iter().map(|a| a.id).collect();
        let ticks = resolved.ticks() as usize;
        let slot = |agent: u32| ids.iter().position(|id| *id == agent).expect("known agent");
        let mut agents = vec![Vec::new(); ids.len()];
        for id in &ids {
            for r in crate::trace_records(&self.trace(&format!("agent-{id}"))) {
                if let TraceRecord::Agent(a) = r {
                    agents[slot(a.agent)].push(a);
                }
            }
        }
        let mut attacks = vec![Vec::new(); ids.len()];
        if self.trace("attacker").exists() {
            for r in crate::trace_records(&self.trace("attacker")) {
                if let TraceRecord::Attack(a) = r {
                    attacks[slot(a.agent)].push(a);
                }
            }
        }
        let mut centers = vec![Vec::new(); ids.len()];
        for r in crate::trace_records(&self.trace("control-center")) {
            if let TraceRecord::Center(c) = r {
                centers[slot(c.agent)].push(c);
            }
        }
        let mut out = Vec::new();
        for k in 0..ticks {
            for i in 0..ids.len() {
                let (a, c) = (agents[i][k], centers[i][k]);
                assert_eq!((a.k, c.k), (k as u64, k as u64), "agent {}", ids[i]);
                out.push((a, attacks[i].get(k).copied(), c));
            }
        }
        out
    }

    /// The digest of the joined records, as the launcher computes it for a multi-process run.
    pub fn digest(&self, resolved: &Resolved) -> String {
        let mut digest = TraceDigest::new();
        for (agent, attack, center) in self.joined(resolved) {
            digest.push(&TickRecord {
                agent,
                attack: attack.expect("the attacker's records"),
                center,
            });
        }
        digest.finish()
    }

    /// The event messages of `process`'s trace.
    pub fn events(&self, process: &str) -> Vec<String> {
        crate::trace_records(&self.trace(process))
            .into_iter()
            .filter_map(|r| match r {
                TraceRecord::Event { message, .. } => Some(message),
                _ => None,
            })
            .collect()
    }
}

/// The in-process engine's records of `resolved`.
pub fn inproc_records(resolved: &Resolved) -> (Vec<TickRecord>, String) {
    let mut recs = Vec::new();
    let summary = run_inproc_any(resolved, |r| recs.push(*r)).expect("in-process run");
    (recs, summary.trace_digest)
}

fn header(process: &str, resolved: &Resolved) -> fdi_common::trace::TraceHeader {
    process::trace_header(process, resolved)
}

fn writer(dir: &Path, process: &str, resolved: &Resolved) -> TraceWriter {
    TraceWriter::create(
        &dir.join(format!("{process}.trace")),
        &header(process, resolved),
    )
    .expect("trace")
}

/// The relay's loop: the attacker's place, with `forward` deciding what goes on.
fn relay(
    prefix: &str,
    resolved: &Resolved,
    mut forward: Box<dyn FnMut(MeasurementMsg) -> Vec<MeasurementMsg> + Send>,
    shutdown: &Shutdown,
) {
    let conn = process::connect::<Local>(
        prefix,
        Role::Attacker,
        Wake::Attacker,
        process::sizing_for(resolved),
    )
    .expect("relay node");
    let inbox = conn
        .transport
        .subscriber::<MeasurementMsg>(Stream::Measurement)
        .expect("measurements");
    let outbox = conn
        .transport
        .publisher::<MeasurementMsg>(Stream::Tampered)
        .expect("tampered");
    let center = conn.transport.notifier(Wake::Center).expect("center bell");
    match conn.launcher.ready_and_wait_start(&conn.waker, shutdown) {
        Ok(Start::Go { .. }) => {}
        other => panic!("relay: no start: {other:?}"),
    }
    let ticks = resolved.ticks();
    let mut seen = 0u64;
    let total = ticks * resolved.agent_count() as u64;
    let strategy = WaitStrategy::for_clock(resolved.scenario.clock);
    while seen < total {
        let mut any = false;
        inbox
            .drain(|m| {
                seen += 1;
                for out in forward(m) {
                    outbox.send(out).expect("relay send");
                }
                any = true;
            })
            .expect("relay receive");
        if any {
            center.ring().expect("ring");
        }
        if shutdown.requested() {
            return;
        }
        strategy.wait(&conn.waker, &inbox).expect("relay wait");
    }
    conn.launcher
        .done_and_hold(ticks, &conn.waker, shutdown)
        .expect("done");
}

/// Runs `run`: every role on a thread of its own, this thread in the launcher's place.
pub fn run(run: ThreadRun, tag: &str) -> ThreadOutcome {
    let ThreadRun {
        resolved,
        middle,
        forged_torques,
    } = run;
    let dir = Scratch::new(tag);
    let prefix = format!("fdithr{}_{tag}_", std::process::id());
    // This node creates the run's services first, with room for the forger's publishers.
    let launcher = Local::open(
        &prefix,
        "launcher",
        process::sizing_for(&resolved).with_taps(1),
    )
    .expect("launcher node");
    let control = launcher
        .publisher::<ControlMsg>(Stream::Control)
        .expect("control");
    let status = launcher
        .subscriber::<StatusMsg>(Stream::Status)
        .expect("status");
    let waker = launcher.waker(Wake::Launcher).expect("launcher waker");
    let ids: Vec<u32> = resolved.scenario.agents.iter().map(|a| a.id).collect();
    let forgers: Vec<_> = ids
        .iter()
        .map(|id| {
            launcher
                .publisher::<TorqueMsg>(Stream::Torque(*id))
                .expect("forger")
        })
        .collect();
    let shutdown = Shutdown::manual();

    let spawn = |work: Box<RoleWork>| {
        let (p, r, d, s) = (
            prefix.clone(),
            resolved.clone(),
            dir.0.clone(),
            shutdown.clone(),
        );
        std::thread::spawn(move || work(&p, &r, &d, &s))
    };
    let mut threads = vec![
        spawn(Box::new(|p, r, d, s| {
            let ports = fdi_control_center::Ports::<Local>::open(p, r).expect("center ports");
            let mut trace = writer(d, "control-center", r);
            fdi_control_center::run_any(r, &ports, s, &mut trace)
                .map(|_| ())
                .map_err(|e| format!("control center: {e}"))
        })),
        spawn(Box::new(move |p, r, d, s| match middle {
            Middle::Attacker => {
                let ports = fdi_attacker::Ports::<Local>::open(p, r).expect("attacker ports");
                let mut trace = writer(d, "attacker", r);
                fdi_attacker::run_any(r, &ports, s, &mut trace)
                    .map(|_| ())
                    .map_err(|e| format!("attacker: {e}"))
            }
            Middle::Relay(forward) => {
                relay(p, r, forward, s);
                Ok(())
            }
        })),
    ];
    for id in ids.clone() {
        threads.push(spawn(Box::new(move |p, r, d, s| {
            let ports = fdi_agent::Ports::<Local>::open(p, id, r).expect("agent ports");
            let mut trace = writer(d, &format!("agent-{id}"), r);
            fdi_agent::run_any(id, r, &ports, s, &mut trace)
                .map(|_| ())
                .map_err(|e| format!("agent {id}: {e}"))
        })));
    }

    // Ready: every role's ports exist. A role that ends before it reported (it failed) ends
    // the wait, and its error is shown by the join.
    let roles = threads.len();
    let wait_for =
        |kind: u32, what: &str, threads: &[std::thread::JoinHandle<Result<(), String>>]| {
            let began = Instant::now();
            let mut got = 0;
            while got < roles {
                assert!(began.elapsed() < LIMIT, "{got} of {roles} roles {what}");
                if kind == StatusMsg::READY && threads.iter().any(|t| t.is_finished()) {
                    return false;
                }
                waker
                    .wait(Duration::from_millis(20))
                    .expect("launcher wait");
                status
                    .drain(|m| got += usize::from(m.kind == kind))
                    .expect("status");
            }
            true
        };
    if !wait_for(StatusMsg::READY, "ready", &threads) {
        shutdown.request();
        join(threads);
        panic!("a role ended before it was ready");
    }
    for (i, (id, m)) in forged_torques.iter().enumerate() {
        let slot = ids
            .iter()
            .position(|x| x == id)
            .expect("forged torque for a known agent");
        forgers[slot]
            .send(*m)
            .unwrap_or_else(|e| panic!("forged torque {i}: {e}"));
    }
    let mut bells = vec![
        launcher.notifier(Wake::Center).expect("bell"),
        launcher.notifier(Wake::Attacker).expect("bell"),
    ];
    for id in &ids {
        bells.push(launcher.notifier(Wake::Agent(*id)).expect("bell"));
    }
    control
        .send(ControlMsg {
            command: ControlMsg::START,
            reserved: 0,
            epoch_ns: monotonic_ns(),
        })
        .expect("start");
    for b in &bells {
        b.ring().expect("ring");
    }
    wait_for(StatusMsg::DONE, "done", &threads);
    // As the launcher: the stop that lets the finished roles go.
    control
        .send(ControlMsg {
            command: ControlMsg::STOP,
            reserved: 0,
            epoch_ns: 0,
        })
        .expect("stop");
    for b in &bells {
        b.ring().expect("ring");
    }
    join(threads);
    ThreadOutcome { dir }
}

/// Joins every role thread; fails the test with the first role's error.
fn join(threads: Vec<std::thread::JoinHandle<Result<(), String>>>) {
    let errors: Vec<String> = threads
        .into_iter()
        .filter_map(|t| match t.join() {
            Ok(Ok(())) => None,
            Ok(Err(e)) => Some(e),
            Err(_) => Some("a role thread panicked".into()),
        })
        .collect();
    assert!(errors.is_empty(), "{}", errors.join("; "));
}

/// A torque for agent `agent`, tick `seq`, with every field as the control center fills it.
pub fn torque(agent: u32, dof: u32, seq: u64, dt: f64) -> TorqueMsg {
    TorqueMsg {
        seq,
        agent,
        dof,
        t_send: tick_time(seq, dt),
        u: [0.0; fdi_common::scenario::MAX_DOF],
        agent_sent_ns: 0,
        attacker_received_ns: 0,
        attacker_sent_ns: 0,
        center_received_ns: 0,
        center_sent_ns: 0,
    }
}
