//! The topics of a run, one definition for the MCAP export ([`crate::export`]) and the live
//! view (`fdi-live`): one topic per agent and stream (`/agent<id>/state`, `/agent<id>/attack`,
//! …, listed in [`topics`] and docs/traces.md), JSON messages (`json` encoding) with a
//! `jsonschema` schema per message type ([`json_schema`]), stamped with the simulated time of
//! the tick. Each message also carries its tick `k` and `t_s`. JSON has no NaN or infinity: a
//! non-finite number (a corrupt attack, a diverged robot) is written as `null`.
//!
//! [`record`] turns one trace record into its messages and [`detectors::Stats`] one joined
//! tick into its detector statistics; both hand them to a [`Sink`] (the MCAP writer, the live
//! server), so that a layout made on a recording works live and back.

pub mod detectors;

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::LazyLock;

use anyhow::{Context, Result};
use fdi_common::detect;
use fdi_common::engine::tick_time;
use fdi_common::records::true_s;
use fdi_common::records::{AgentRecord, AttackRecord, CenterRecord};
use fdi_common::scenario::{self, Resolved, MAX_DOF};
use fdi_common::trace::{TraceHeader, TraceRecord};
use fdi_common::trajectory::TrajectoryConfig;
use serde_json::{json, Map, Value};

/// The type of a message field, as its JSON schema says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ty {
    /// An unsigned integer (a tick, an agent, a time stamp in ns).
    Int,
    /// A number (`null` when it is not finite).
    Num,
    /// An array of numbers, one per link.
    Nums,
    Bool,
    Str,
}

/// One field of a message: name, type, meaning with its unit.
pub type Field = (&'static str, Ty, &'static str);

/// One message type: its schema name and fields (every field is always present).
#[derive(Debug)]
pub struct Schema {
    pub name: &'static str,
    pub description: &'static str,
    pub fields: &'static [Field],
}

const K: Field = ("k", Ty::Int, "control tick k");
const T: Field = (
    "t_s",
    Ty::Num,
    "tick time t_k = k·Δ, s (the log and publish time, in ns)",
);

macro_rules! schema {
    ($id:ident, $name:literal, $desc:literal, [$($f:expr),* $(,)?]) => {
        pub const $id: Schema = Schema { name: $name, description: $desc, fields: &[$($f),*] };
    };
}

schema!(
    STATE,
    "fdi_mas.State",
    "True joint state of the robot at t_k (agent trace).",
    [
        K,
        T,
        ("q_rad", Ty::Nums, "true joint angles q, rad"),
        ("q_dot_rad_s", Ty::Nums, "true joint velocities q̇, rad/s"),
        (
            "q_ddot_rad_s2",
            Ty::Nums,
            "joint accelerations q̈ of the step from t_k, rad/s²"
        ),
    ]
);
schema!(
    DESIRED,
    "fdi_mas.Desired",
    "Desired trajectory of the scenario at t_k (the paper's q_d).",
    [
        K,
        T,
        ("q_des_rad", Ty::Nums, "desired joint angles q_d, rad"),
        (
            "q_dot_des_rad_s",
            Ty::Nums,
            "desired joint velocities q̇_d, rad/s"
        ),
        (
            "q_ddot_des_rad_s2",
            Ty::Nums,
            "desired joint accelerations q̈_d, rad/s²"
        ),
    ]
);
schema!(
    TRACKING,
    "fdi_mas.TrackingError",
    "Tracking error e = q_d − q with the true state (the paper's Figs. 3 and 4).",
    [
        K,
        T,
        ("e_rad", Ty::Nums, "position error q_d − q, rad"),
        ("e_dot_rad_s", Ty::Nums, "velocity error q̇_d − q̇, rad/s"),
    ]
);
schema!(
    CLEAN,
    "fdi_mas.CleanMeasurement",
    "Measurement the agent published: with sensor noise, before any attack (agent trace).",
    [
        K,
        T,
        ("y_rad", Ty::Nums, "measured joint angles, rad"),
        ("y_dot_rad_s", Ty::Nums, "measured joint velocities, rad/s"),
    ]
);
schema!(TAMPERED, "fdi_mas.TamperedMeasurement", "Measurement the control center took as the tick's input, after the attack (attacker trace); empty arrays when the input was missing.", [
    K, T,
    ("y_rad", Ty::Nums, "joint angles as received, rad"),
    ("y_dot_rad_s", Ty::Nums, "joint velocities as received, rad/s"),
    ("delivery", Ty::Str, "delivered, missing, forged or replayed"),
]);
schema!(ATTACK, "fdi_mas.Attack", "Injected false data of the tick (attacker trace) and the true attack term S the estimate Ŝ tracks.", [
    K, T,
    ("alpha_pos_rad", Ty::Nums, "injected position α₁ (S₁), rad"),
    ("alpha_vel_rad_s", Ty::Nums, "injected velocity α₂ (S₂), rad/s"),
    ("s_true_rad_s", Ty::Nums, "true S = S₂ + β S₁, rad/s"),
    ("active", Ty::Bool, "the attack on the measurement was in force"),
    ("delivery", Ty::Str, "delivered, missing, forged or replayed"),
]);
schema!(
    ESTIMATE,
    "fdi_mas.Estimate",
    "Control center's estimates after the tick (control-center trace).",
    [
        K,
        T,
        (
            "s_hat_rad_s",
            Ty::Nums,
            "attack estimate Ŝ used in the tick, rad/s"
        ),
        ("q_hat_rad", Ty::Nums, "observer's joint angles q̂, rad"),
        (
            "q_dot_hat_rad_s",
            Ty::Nums,
            "observer's joint velocities, rad/s"
        ),
        (
            "q_ddot_hat_rad_s2",
            Ty::Nums,
            "observer's joint accelerations, rad/s²"
        ),
    ]
);
schema!(
    SENT,
    "fdi_mas.TorqueSent",
    "Torque the control center sent, stamped t_k (control-center trace).",
    [K, T, ("u_nm", Ty::Nums, "joint torques, N·m"),]
);
schema!(
    APPLIED,
    "fdi_mas.TorqueApplied",
    "Torque the robot applied at t_k: u(t_k − τ(t_k)) (agent trace).",
    [
        K,
        T,
        ("u_nm", Ty::Nums, "joint torques, N·m"),
        (
            "missed",
            Ty::Bool,
            "the due command was missing: the last one was held"
        ),
    ]
);
schema!(
    DELAY,
    "fdi_mas.Delay",
    "Known input delay of the torque channel at t_k (agent trace).",
    [K, T, ("tau_s", Ty::Num, "delay τ(t_k), s"),]
);
schema!(
    ALARM,
    "fdi_mas.Alarm",
    "Control center's alarm and input flags of the tick (control-center trace).",
    [
        K,
        T,
        ("alarm", Ty::Bool, "the ‖Ŝ‖ detection alarm"),
        (
            "rejected_input",
            Ty::Bool,
            "the measurement was rejected (non-finite or absurd)"
        ),
        (
            "rejected_torque",
            Ty::Bool,
            "the computed torque was non-finite; the last good one was sent"
        ),
        (
            "state_reset",
            Ty::Bool,
            "non-finite observer or estimator state was reset"
        ),
        (
            "history_miss",
            Ty::Bool,
            "the torque history did not reach back to t − τ(t)"
        ),
        (
            "missing_input",
            Ty::Bool,
            "the tick's measurement was missing: the last good one was used"
        ),
    ]
);
/// The per-tick statistic of each detector: the paper's alarm, then every detector of
/// [`detect::RESIDUAL`] with its own fields (made once, from the list).
pub static DETECTORS: LazyLock<Schema> = LazyLock::new(|| {
    const VERDICT: &str = "watched, calibrating, non-finite, missing or uncalibrated";
    const ALARM: &str = "its alarm at the configured threshold";
    let mut fields: Vec<Field> = vec![
        K,
        T,
        (
            "in_force",
            Ty::Bool,
            "an attack was in force on the measurement or the torque",
        ),
        (
            "s_hat_norm",
            Ty::Num,
            "‖Ŝ‖ held over the hold time, rad/s (null without a verdict)",
        ),
        (
            "s_hat_norm_threshold",
            Ty::Num,
            "its configured threshold, rad/s",
        ),
        ("s_hat_norm_verdict", Ty::Str, VERDICT),
        ("s_hat_norm_alarm", Ty::Bool, ALARM),
    ];
    // Made once per process: the names and descriptions live as long as the schema.
    let leak = |s: String| -> &'static str { Box::leak(s.into_boxed_str()) };
    for k in detect::RESIDUAL {
        let [_, threshold, verdict, alarm] = fields_of(k.name);
        fields.extend([
            (
                k.name,
                Ty::Num,
                leak(format!("{} (null without a verdict)", k.statistic)),
            ),
            (leak(threshold), Ty::Num, k.threshold_doc),
            (leak(verdict), Ty::Str, VERDICT),
            (leak(alarm), Ty::Bool, ALARM),
        ]);
    }
    Schema {
        name: "fdi_mas.Detectors",
        description: "Per-tick statistic of each detector, as `fdi-launch detect` computes it from the joined traces (docs/detectors.md).",
        fields: Vec::leak(fields),
    }
});
schema!(LATENCY, "fdi_mas.Latency", "Monotonic-clock stamps of the torque message of the tick, ns (0 = not stamped; realtime runs).", [
    K, T,
    ("agent_sent_ns", Ty::Int, "agent sent the measurement"),
    ("attacker_received_ns", Ty::Int, "attacker received it"),
    ("attacker_sent_ns", Ty::Int, "attacker sent it on"),
    ("center_received_ns", Ty::Int, "control center received it"),
    ("center_sent_ns", Ty::Int, "control center sent the torque"),
    ("agent_received_ns", Ty::Int, "agent received the torque"),
]);
schema!(
    ACTUATION,
    "fdi_mas.Actuation",
    "The torque's way through the attacker (attacker trace; runs that attack the torque path).",
    [
        K,
        T,
        ("alpha_u_nm", Ty::Nums, "injected torque α_u, N·m"),
        (
            "u_nm",
            Ty::Nums,
            "torque the agent took as the tick's command (empty when missing), N·m"
        ),
        (
            "held_s",
            Ty::Num,
            "how much later than τ it took effect (a delay attack), s"
        ),
        (
            "active",
            Ty::Bool,
            "the attack on the torque path was in force"
        ),
        (
            "delivery",
            Ty::Str,
            "delivered, missing, forged or replayed"
        ),
    ]
);
schema!(
    MONITOR,
    "fdi_mas.Monitor",
    "A monitor program's verdict on the tick (`[roles.monitor]`, control-center trace).",
    [
        K,
        T,
        ("alarm", Ty::Bool, "the monitor's alarm at this tick"),
        (
            "statistic",
            Ty::Num,
            "its statistic, in its own unit (null when it gave none)"
        ),
        (
            "late",
            Ty::Bool,
            "realtime: it came later than the monitor's deadline after the tick's time"
        ),
    ]
);
schema!(
    EVENT,
    "fdi_mas.Event",
    "Something a process put on record (a lost peer, a rejected message, the shutdown reason).",
    [
        (
            "t_s",
            Ty::Num,
            "the process's time of the event, s (the log time, in ns)"
        ),
        ("process", Ty::Str, "the trace it comes from"),
        ("message", Ty::Str, "what happened"),
    ]
);

/// Every per-agent topic (`/agent<id>/<name>`) and its message type; `/events` is the one
/// topic of the whole run ([`EVENT`]).
pub fn topics() -> [(&'static str, &'static Schema); 15] {
    [
        ("state", &STATE),
        ("desired", &DESIRED),
        ("tracking_error", &TRACKING),
        ("measurement/clean", &CLEAN),
        ("measurement/tampered", &TAMPERED),
        ("attack", &ATTACK),
        ("estimate", &ESTIMATE),
        ("torque/sent", &SENT),
        ("torque/applied", &APPLIED),
        ("delay", &DELAY),
        ("alarm", &ALARM),
        ("detectors", &*DETECTORS),
        ("latency", &LATENCY),
        ("actuation", &ACTUATION),
        ("monitor", &MONITOR),
    ]
}

/// The fields of detector `name` in both exports and the live view, in the order of [`Statistic`]'s: statistic,
/// configured threshold, verdict, alarm.
pub fn fields_of(name: &str) -> [String; 4] {
    [
        name.to_string(),
        format!("{name}_threshold"),
        format!("{name}_verdict"),
        format!("{name}_alarm"),
    ]
}

/// The topics a run of `resolved` has, each once: `(agent, name, schema)`, agent 0 for
/// `/events`. `stamped`: its processes stamp each torque's hops (`latency`: realtime runs of the
/// ipc engine). `actuation` for an agent whose torques are attacked, `monitor` with a monitor
/// program (`[roles.monitor]`).
pub fn run_topics(resolved: &Resolved, stamped: bool) -> Vec<(u32, &'static str, &'static Schema)> {
    let s = &resolved.scenario;
    let mut out = Vec::new();
    for a in &s.agents {
        for (name, schema) in topics() {
            let has = match name {
                "latency" => stamped,
                "actuation" => resolved.attack.attacks_torque_of(a.id),
                "monitor" => s.roles.monitor.is_some(),
                _ => true,
            };
            if has {
                out.push((a.id, name, schema));
            }
        }
    }
    out.push((0, "/events", &EVENT));
    out
}

/// The topic name of `name` for agent `agent`.
pub fn topic(agent: u32, name: &str) -> String {
    format!("/agent{agent}/{name}")
}

/// The JSON schema of a message type.
pub fn json_schema(s: &Schema) -> Value {
    let mut props = Map::new();
    for (name, ty, desc) in s.fields {
        let number = json!({"type": "number"});
        let t = match ty {
            Ty::Int => json!({"type": "integer", "minimum": 0}),
            Ty::Num => number,
            Ty::Nums => json!({"type": "array", "items": number}),
            Ty::Bool => json!({"type": "boolean"}),
            Ty::Str => json!({"type": "string"}),
        };
        let mut t = t;
        t["description"] = Value::from(*desc);
        props.insert((*name).to_string(), t);
    }
    json!({
        "$schema": "http://json-schema.org/draft-07/schema#",
        "title": s.name,
        "description": format!("{} Non-finite numbers are null (JSON has no NaN).", s.description),
        "type": "object",
        "properties": props,
        "required": s.fields.iter().map(|f| f.0).collect::<Vec<_>>(),
        "additionalProperties": false,
    })
}

/// `(q_d, q̇_d, q̈_d)` of one tick, rad, rad/s, rad/s², and how many of their entries are links.
pub type Desired = ([f64; MAX_DOF], [f64; MAX_DOF], [f64; MAX_DOF], usize);

/// One agent as the scenario of a trace describes it.
#[derive(Debug, Clone)]
pub struct AgentInfo {
    pub dof: usize,
    pub trajectory: TrajectoryConfig,
}

/// What the scenario in a trace's header says that the exported columns need.
#[derive(Debug, Clone)]
pub struct RunInfo {
    pub resolved: Resolved,
    /// Δ, s.
    pub dt: f64,
    pub beta: f64,
    pub agents: BTreeMap<u32, AgentInfo>,
    /// The largest number of links of an agent: the vector columns of a CSV.
    pub dof: usize,
}

impl RunInfo {
    /// From the header of the trace at `path`; an error naming the file when its scenario
    /// does not parse (the tick times, the desired trajectory and `S` come from it).
    pub fn from_header(path: &Path, header: &TraceHeader) -> Result<Self> {
        let resolved = scenario::load_str(&header.scenario_toml, &path.display().to_string(), None)
            .map_err(|e| anyhow::anyhow!("{e}"))
            .with_context(|| {
                format!(
                    "{}: the scenario in the trace header does not parse: the tick times, the desired trajectory and S cannot be derived",
                    path.display()
                )
            })?;
        Ok(Self::of(resolved))
    }

    /// What `resolved` says.
    pub fn of(resolved: Resolved) -> Self {
        let s = &resolved.scenario;
        let agents: BTreeMap<u32, AgentInfo> = s
            .agents
            .iter()
            .map(|a| {
                (
                    a.id,
                    AgentInfo {
                        dof: a.model.dof().min(MAX_DOF),
                        trajectory: a.trajectory.clone(),
                    },
                )
            })
            .collect();
        let dof = agents.values().map(|a| a.dof).max().unwrap_or(0);
        Self {
            dt: s.control_period_s,
            beta: s.controller.beta,
            agents,
            dof,
            resolved,
        }
    }

    /// `t_k`, s: the engine's own function of the tick.
    pub fn t(&self, k: u64) -> f64 {
        tick_time(k, self.dt)
    }

    /// The agent `id`; an error naming the trace when its scenario has no such agent.
    pub fn agent(&self, path: &Path, id: u32) -> Result<&AgentInfo> {
        self.agents.get(&id).with_context(|| {
            format!(
                "{}: a record of agent {id}, which the scenario in its header does not have",
                path.display()
            )
        })
    }

    /// `(q_d, q̇_d, q̈_d)` of agent `id` at tick `k`, rad, rad/s, rad/s².
    pub fn desired(&self, path: &Path, id: u32, k: u64) -> Result<Desired> {
        let a = self.agent(path, id)?;
        let r = a.trajectory.reference::<MAX_DOF>(self.t(k));
        let arr = |v: &fdi_common::model::Vector<MAX_DOF>| {
            let mut out = [0.0; MAX_DOF];
            out.copy_from_slice(v.as_slice());
            out
        };
        Ok((arr(&r.q), arr(&r.qd), arr(&r.qdd), a.dof))
    }
}

/// The log time of a message stamped `t` s: ns; an error for a time no log time can hold.
pub fn log_time_ns(t: f64) -> Result<u64> {
    let x = (t * 1e9).round();
    if !(x.is_finite() && x >= 0.0 && x < u64::MAX as f64) {
        anyhow::bail!("time {t} s is not a log time (finite, ≥ 0)");
    }
    Ok(x as u64)
}

/// Where the messages of a run go: the MCAP file, the live server.
pub trait Sink {
    /// `msg` of type `schema` on topic `name` of `agent` (agent 0 with `name` a whole topic:
    /// `/events`), stamped `t` s.
    fn message(
        &mut self,
        agent: u32,
        name: &'static str,
        schema: &Schema,
        t: f64,
        msg: &Value,
    ) -> Result<()>;
}

/// The topic's name of `name` for `agent` (agent 0: `name` is the whole topic).
pub fn topic_name(agent: u32, name: &str) -> String {
    if agent == 0 {
        name.to_string()
    } else {
        topic(agent, name)
    }
}

fn nums(v: &[f64]) -> Value {
    Value::from(v)
}

/// The messages of one record.
pub fn record(
    w: &mut impl Sink,
    info: &RunInfo,
    path: &Path,
    stem: &str,
    rec: &TraceRecord,
) -> Result<()> {
    match rec {
        TraceRecord::Agent(a) => agent_messages(w, info, path, a),
        TraceRecord::Attack(a) => attack_messages(w, info, path, a),
        TraceRecord::Center(c) => center_messages(w, info, path, c),
        TraceRecord::Latency { k, agent, stamps } => {
            let t = info.t(*k);
            info.agent(path, *agent)?;
            w.message(
                *agent,
                "latency",
                &LATENCY,
                t,
                &json!({"k": k, "t_s": t,
                "agent_sent_ns": stamps.agent_sent_ns,
                "attacker_received_ns": stamps.attacker_received_ns,
                "attacker_sent_ns": stamps.attacker_sent_ns,
                "center_received_ns": stamps.center_received_ns,
                "center_sent_ns": stamps.center_sent_ns,
                "agent_received_ns": stamps.agent_received_ns}),
            )
        }
        TraceRecord::Actuation(a) => {
            let t = info.t(a.k);
            info.agent(path, a.agent)?;
            w.message(
                a.agent,
                "actuation",
                &ACTUATION,
                t,
                &json!({"k": a.k, "t_s": t,
                "alpha_u_nm": nums(a.alpha_u.as_slice()), "u_nm": nums(a.u.as_slice()),
                "held_s": a.held_s, "active": a.active, "delivery": a.delivery.as_str()}),
            )
        }
        TraceRecord::Event { t, message } => w.message(
            0,
            "/events",
            &EVENT,
            *t,
            &json!({
            "t_s": t, "process": stem, "message": message}),
        ),
        TraceRecord::Monitor(m) => {
            let t = info.t(m.k);
            info.agent(path, m.agent)?;
            w.message(
                m.agent,
                "monitor",
                &MONITOR,
                t,
                &json!({"k": m.k, "t_s": t, "alarm": m.alarm,
                "statistic": m.statistic, "late": m.late}),
            )
        }
    }
}

/// An agent's state, desired trajectory, tracking error, clean measurement, applied torque
/// and delay.
fn agent_messages(w: &mut impl Sink, info: &RunInfo, path: &Path, a: &AgentRecord) -> Result<()> {
    let t = info.t(a.k);
    let (q, qd, qdd, dof) = info.desired(path, a.agent, a.k)?;
    let (q, qd, qdd) = (&q[..dof], &qd[..dof], &qdd[..dof]);
    let diff = |d: &[f64], x: &[f64]| -> Vec<f64> { d.iter().zip(x).map(|(d, x)| d - x).collect() };
    let id = a.agent;
    w.message(
        id,
        "state",
        &STATE,
        t,
        &json!({"k": a.k, "t_s": t,
            "q_rad": nums(a.q.as_slice()), "q_dot_rad_s": nums(a.qd.as_slice()),
            "q_ddot_rad_s2": nums(a.qdd.as_slice())}),
    )?;
    w.message(
        id,
        "desired",
        &DESIRED,
        t,
        &json!({"k": a.k, "t_s": t,
            "q_des_rad": nums(q), "q_dot_des_rad_s": nums(qd), "q_ddot_des_rad_s2": nums(qdd)}),
    )?;
    w.message(
        id,
        "tracking_error",
        &TRACKING,
        t,
        &json!({"k": a.k, "t_s": t,
            "e_rad": diff(q, a.q.as_slice()), "e_dot_rad_s": diff(qd, a.qd.as_slice())}),
    )?;
    w.message(
        id,
        "measurement/clean",
        &CLEAN,
        t,
        &json!({"k": a.k, "t_s": t,
            "y_rad": nums(a.y.as_slice()), "y_dot_rad_s": nums(a.yd.as_slice())}),
    )?;
    w.message(
        id,
        "torque/applied",
        &APPLIED,
        t,
        &json!({"k": a.k, "t_s": t,
            "u_nm": nums(a.u_applied.as_slice()), "missed": a.missed}),
    )?;
    w.message(
        id,
        "delay",
        &DELAY,
        t,
        &json!({"k": a.k, "t_s": t, "tau_s": a.tau}),
    )
}

/// The attack on a measurement and the tampered measurement.
fn attack_messages(w: &mut impl Sink, info: &RunInfo, path: &Path, a: &AttackRecord) -> Result<()> {
    let t = info.t(a.k);
    info.agent(path, a.agent)?;
    let s: Vec<f64> = a
        .alpha_position
        .as_slice()
        .iter()
        .zip(a.alpha_velocity.as_slice())
        .map(|(p, v)| true_s(*p, *v, info.beta))
        .collect();
    let delivery = a.delivery.as_str();
    w.message(
        a.agent,
        "attack",
        &ATTACK,
        t,
        &json!({"k": a.k, "t_s": t,
            "alpha_pos_rad": nums(a.alpha_position.as_slice()),
            "alpha_vel_rad_s": nums(a.alpha_velocity.as_slice()),
            "s_true_rad_s": s, "active": a.active, "delivery": delivery}),
    )?;
    w.message(
        a.agent,
        "measurement/tampered",
        &TAMPERED,
        t,
        &json!({"k": a.k, "t_s": t,
            "y_rad": nums(a.y.as_slice()), "y_dot_rad_s": nums(a.yd.as_slice()),
            "delivery": delivery}),
    )
}

/// The control center's estimate, sent torque and alarm.
fn center_messages(w: &mut impl Sink, info: &RunInfo, path: &Path, c: &CenterRecord) -> Result<()> {
    let t = info.t(c.k);
    info.agent(path, c.agent)?;
    w.message(
        c.agent,
        "estimate",
        &ESTIMATE,
        t,
        &json!({"k": c.k, "t_s": t,
            "s_hat_rad_s": nums(c.s_hat.as_slice()), "q_hat_rad": nums(c.q_hat.as_slice()),
            "q_dot_hat_rad_s": nums(c.qd_hat.as_slice()),
            "q_ddot_hat_rad_s2": nums(c.qdd_hat.as_slice())}),
    )?;
    w.message(
        c.agent,
        "torque/sent",
        &SENT,
        t,
        &json!({"k": c.k, "t_s": t,
            "u_nm": nums(c.u.as_slice())}),
    )?;
    w.message(
        c.agent,
        "alarm",
        &ALARM,
        t,
        &json!({"k": c.k, "t_s": t,
            "alarm": c.alarm, "rejected_input": c.rejected_input,
            "rejected_torque": c.rejected_torque, "state_reset": c.state_reset,
            "history_miss": c.history_miss, "missing_input": c.missing_input}),
    )
}
