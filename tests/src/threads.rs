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
use fdi_runtime::role;

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
        for r in crate::trace_records(&self.trace(fdi_common::run_dir::Process::CENTER)) {
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
                // Not in the digest.
                actuation: None,
                monitor: None,
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

fn writer(dir: &Path, process: &str, resolved: &Resolved) -> TraceWriter {
    TraceWriter::create(
        &dir.join(format!("{process}.trace")),
        &process::trace_header(process, resolved),
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

type RoleThread = std::thread::JoinHandle<Result<(), String>>;

/// The launcher's side of a threaded run: its node creates the run's services first, with
/// room for the forger's publishers on the agents' torque channels.
struct Coordinator {
    control: <Local as Transport>::Outbox<ControlMsg>,
    status: <Local as Transport>::Inbox<StatusMsg>,
    waker: <Local as Transport>::Waker,
    forgers: Vec<(u32, <Local as Transport>::Outbox<TorqueMsg>)>,
    bells: Vec<<Local as Transport>::Bell>,
    node: Local,
}

impl Coordinator {
    fn open(prefix: &str, resolved: &Resolved) -> Self {
        let node = Local::open(
            prefix,
            "launcher",
            process::sizing_for(resolved).with_taps(1),
        )
        .expect("launcher node");
        let forgers = resolved
            .scenario
            .agents
            .iter()
            .map(|a| {
                let port = node
                    .publisher::<TorqueMsg>(Stream::Torque(a.id))
                    .expect("forger");
                (a.id, port)
            })
            .collect();
        Self {
            control: node
                .publisher::<ControlMsg>(Stream::Control)
                .expect("control"),
            status: node
                .subscriber::<StatusMsg>(Stream::Status)
                .expect("status"),
            waker: node.waker(Wake::Launcher).expect("launcher waker"),
            forgers,
            bells: Vec::new(),
            node,
        }
    }

    /// Waits until every role of `threads` reported `kind`; false when, waiting for ready, a
    /// role ended first (it failed: the join shows why).
    fn wait_for(&self, kind: u32, what: &str, threads: &[RoleThread]) -> bool {
        let began = Instant::now();
        let mut got = 0;
        while got < threads.len() {
            assert!(
                began.elapsed() < LIMIT,
                "{got} of {} roles {what}",
                threads.len()
            );
            if kind == StatusMsg::READY && threads.iter().any(|t| t.is_finished()) {
                return false;
            }
            self.waker
                .wait(Duration::from_millis(20))
                .expect("launcher wait");
            self.status
                .drain(|m| got += usize::from(m.kind == kind))
                .expect("status");
        }
        true
    }

    /// Sends `command` to every role and wakes them (the bells are made at the start, once
    /// every role's waker exists).
    fn broadcast(&mut self, command: u32, ids: &[u32]) {
        if self.bells.is_empty() {
            for wake in [Wake::Center, Wake::Attacker]
                .into_iter()
                .chain(ids.iter().map(|id| Wake::Agent(*id)))
            {
                self.bells.push(self.node.notifier(wake).expect("bell"));
            }
        }
        self.control
            .send(ControlMsg {
                command,
                reserved: 0,
                epoch_ns: monotonic_ns(),
            })
            .expect("control message");
        for b in &self.bells {
            b.ring().expect("ring");
        }
    }

    fn forge(&self, forged: &[(u32, TorqueMsg)]) {
        for (i, (id, m)) in forged.iter().enumerate() {
            let (_, port) = self
                .forgers
                .iter()
                .find(|(a, _)| a == id)
                .expect("forged torque for a known agent");
            port.send(*m)
                .unwrap_or_else(|e| panic!("forged torque {i}: {e}"));
        }
    }
}

/// Starts every role on a thread of its own (the attacker's place taken by `middle`).
fn spawn_roles(
    prefix: &str,
    resolved: &Resolved,
    dir: &Path,
    shutdown: &Shutdown,
    middle: Middle,
) -> Vec<RoleThread> {
    let spawn = |work: Box<RoleWork>| {
        let (p, r, d, s) = (
            prefix.to_string(),
            resolved.clone(),
            dir.to_path_buf(),
            shutdown.clone(),
        );
        std::thread::spawn(move || work(&p, &r, &d, &s))
    };
    let mut threads = vec![
        spawn(Box::new(|p, r, d, s| {
            let center = fdi_control_center::ControlCenter;
            let opened = role::open::<_, Local>(&center, p, r).expect("center ports");
            let mut trace = writer(d, fdi_common::run_dir::Process::CENTER, r);
            role::drive(&center, r, &opened, s, &mut trace)
                .map(|_| ())
                .map_err(|e| format!("control center: {e}"))
        })),
        spawn(Box::new(move |p, r, d, s| match middle {
            Middle::Attacker => {
                let attacker = fdi_attacker::Attacker;
                let opened = role::open::<_, Local>(&attacker, p, r).expect("attacker ports");
                let mut trace = writer(d, "attacker", r);
                role::drive(&attacker, r, &opened, s, &mut trace)
                    .map(|_| ())
                    .map_err(|e| format!("attacker: {e}"))
            }
            Middle::Relay(forward) => {
                relay(p, r, forward, s);
                Ok(())
            }
        })),
    ];
    for a in &resolved.scenario.agents {
        let id = a.id;
        threads.push(spawn(Box::new(move |p, r, d, s| {
            let agent = fdi_agent::Agent { id, pace: None };
            let opened = role::open::<_, Local>(&agent, p, r).expect("agent ports");
            let mut trace = writer(d, &format!("agent-{id}"), r);
            role::drive(&agent, r, &opened, s, &mut trace)
                .map(|_| ())
                .map_err(|e| format!("agent {id}: {e}"))
        })));
    }
    threads
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
    let mut coordinator = Coordinator::open(&prefix, &resolved);
    let shutdown = Shutdown::manual();
    let threads = spawn_roles(&prefix, &resolved, &dir.0, &shutdown, middle);
    if !coordinator.wait_for(StatusMsg::READY, "ready", &threads) {
        shutdown.request();
        join(threads);
        panic!("a role ended before it was ready");
    }
    let ids: Vec<u32> = resolved.scenario.agents.iter().map(|a| a.id).collect();
    coordinator.forge(&forged_torques);
    coordinator.broadcast(ControlMsg::START, &ids);
    coordinator.wait_for(StatusMsg::DONE, "done", &threads);
    // As the launcher: the stop that lets the finished roles go.
    coordinator.broadcast(ControlMsg::STOP, &ids);
    join(threads);
    ThreadOutcome { dir }
}

/// Joins every role thread; fails the test with the first role's error.
fn join(threads: Vec<RoleThread>) {
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
        held_s: 0.0,
        flags: 0,
        reserved: 0,
    }
}
