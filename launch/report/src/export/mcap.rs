//! MCAP export: the whole run as `RUN_DIR/export/run.mcap`, for Foxglove and PlotJuggler.
//!
//! One topic per agent and stream (`/agent<id>/state`, `/agent<id>/attack`, …, listed in
//! [`topics`] and docs/traces.md), JSON messages (`json` encoding) with a `jsonschema` schema
//! record per message type, log time = publish time = the simulated time of the tick in ns
//! (from [`fdi_common::engine::tick_time`]). Each message also carries its tick `k` and `t_s`.
//! The records of each trace are written per kind in (tick, agent) order; a metadata record
//! `fdi-mas` holds the scenario, its agents and the planned ticks. JSON has no NaN or infinity:
//! a non-finite number (a corrupt attack, a diverged robot) is written as `null`.
//!
//! The detector statistics (`/agent<id>/detectors`) are those of `fdi-launch detect`, each
//! tick's written as it comes ([`detectors::each_tick`], as the CSV export's). The file is
//! written in chunks of [`CHUNK_SIZE`] (before compression), each compressed with zstd (the
//! compression Foxglove and the `mcap` CLI write; every MCAP reader takes it): memory does not
//! grow with the run but for one chunk index per chunk. A damaged trace is exported up to its last whole record, the file is closed whole,
//! then the export fails naming the file and the byte offset. A failed write abandons the
//! export and removes its temporary file ([`super`]).

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::sync::LazyLock;

use anyhow::{bail, Context, Result};
use fdi_common::detect;
use fdi_common::records::true_s;
use fdi_common::trace::{TraceReader, TraceRecord};
use serde_json::{json, Map, Value};

use super::detectors;
use super::sources::{
    abandoned, failed, read_sorted, stem, trace_files, write_failure, OutDir, RunInfo, WriteFailed,
};

/// The type of a message field, as its JSON schema says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Ty {
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
pub(crate) type Field = (&'static str, Ty, &'static str);

/// One message type: its schema name and fields (every field is always present).
#[derive(Debug)]
pub(crate) struct Schema {
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
        pub(crate) const $id: Schema = Schema { name: $name, description: $desc, fields: &[$($f),*] };
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
pub(crate) static DETECTORS: LazyLock<Schema> = LazyLock::new(|| {
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
        let [_, threshold, verdict, alarm] = detectors::fields_of(k.name);
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
#[cfg(test)]
pub(crate) fn topics() -> [(&'static str, &'static Schema); 15] {
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

/// The topic name of `name` for agent `agent`.
pub(crate) fn topic(agent: u32, name: &str) -> String {
    format!("/agent{agent}/{name}")
}

/// The JSON schema of a message type.
pub(crate) fn json_schema(s: &Schema) -> Value {
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

/// The chunk size of the MCAP file, bytes: messages are written to the file a chunk at a time
/// (the `mcap` crate writes a chunk straight to the file and keeps only the chunk's message
/// index, 16 bytes a message), and the summary keeps one chunk index per chunk: about 500
/// bytes a chunk, 1.5 MB for the 3 GB of a 300 s run of the paper's four robots.
pub(crate) const CHUNK_SIZE: u64 = 1 << 20;

/// The MCAP file being written: its channels made as their first message comes.
struct Mcap {
    /// The file it becomes (it is written under a temporary name beside it).
    path: PathBuf,
    w: mcap::Writer<BufWriter<Noted>>,
    /// The first error of the file beneath the writer.
    first: FirstError,
    channels: BTreeMap<(u32, &'static str), u16>,
    sequence: u32,
    buf: Vec<u8>,
}

/// Nanoseconds of a time in seconds; an error for a time no log time can hold.
fn ns(t: f64) -> Result<u64> {
    let x = (t * 1e9).round();
    if !(x.is_finite() && x >= 0.0 && x < u64::MAX as f64) {
        bail!("time {t} s is not a log time (finite, ≥ 0)");
    }
    Ok(x as u64)
}

/// How the chunks of the MCAP file are compressed: zstd at level 1. On the paper's 40 s run its
/// 397 MB of chunks became 81 MB, against 91 MB at zstd's default level 3 (and twice the
/// time), 84 MB at level 9 (ten times), and 149 MB with lz4 (docs/traces.md).
const COMPRESSION: (mcap::Compression, u32) = (mcap::Compression::Zstd, 1);

/// The options of the MCAP writer: chunks of [`CHUNK_SIZE`] (before compression), each
/// compressed with [`COMPRESSION`] on this thread.
fn options() -> mcap::WriteOptions {
    mcap::WriteOptions::new()
        .compression(Some(COMPRESSION.0))
        .compression_level(COMPRESSION.1)
        .compression_threads(0)
        .chunk_size(Some(CHUNK_SIZE))
        .profile("")
        .library(concat!("fdi-launch ", env!("CARGO_PKG_VERSION")))
}

/// The first error of the operating system that the file under the MCAP writer met.
type FirstError = Rc<RefCell<Option<io::Error>>>;

/// The file under the MCAP writer, keeping the first error the operating system gave: the
/// `mcap` crate hands some on inside errors of its own, where the error's number (ENOSPC) is
/// lost.
struct Noted {
    file: File,
    first: FirstError,
}

impl Noted {
    fn note<T>(&self, r: io::Result<T>) -> io::Result<T> {
        if let Err(e) = &r {
            let mut first = self.first.borrow_mut();
            if first.is_none() && e.kind() != io::ErrorKind::Interrupted {
                *first = Some(match e.raw_os_error() {
                    Some(code) => io::Error::from_raw_os_error(code),
                    None => io::Error::new(e.kind(), e.to_string()),
                });
            }
        }
        r
    }
}

impl Write for Noted {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let r = self.file.write(buf);
        self.note(r)
    }

    fn flush(&mut self) -> io::Result<()> {
        let r = self.file.flush();
        self.note(r)
    }
}

impl Seek for Noted {
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        let r = self.file.seek(pos);
        self.note(r)
    }
}

impl Mcap {
    /// Writes the MCAP file `path` into `file` (its temporary).
    fn create(path: &Path, file: File) -> Result<Self> {
        let first = FirstError::default();
        let noted = Noted {
            file,
            first: first.clone(),
        };
        let w = options()
            .create(BufWriter::with_capacity(1 << 16, noted))
            .map_err(|e| failure(path, &first, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            w,
            first,
            channels: BTreeMap::new(),
            sequence: 0,
            buf: Vec::with_capacity(1 << 10),
        })
    }

    /// Writes `msg` on topic `name` of `agent` (agent 0 with `name` a whole topic: `/events`).
    fn write(
        &mut self,
        agent: u32,
        name: &'static str,
        schema: &Schema,
        t: f64,
        msg: &Value,
    ) -> Result<()> {
        let (path, first) = (&self.path, &self.first);
        let channel = match self.channels.get(&(agent, name)) {
            Some(c) => *c,
            None => {
                let text = serde_json::to_vec(&json_schema(schema)).context("a schema")?;
                let s = self
                    .w
                    .add_schema(schema.name, "jsonschema", &text)
                    .map_err(|e| failure(path, first, e))?;
                let topic = if agent == 0 {
                    name.to_string()
                } else {
                    topic(agent, name)
                };
                let c = self
                    .w
                    .add_channel(s, &topic, "json", &BTreeMap::new())
                    .map_err(|e| failure(path, first, e))?;
                self.channels.insert((agent, name), c);
                c
            }
        };
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, msg).context("a message")?;
        let time = ns(t)?;
        self.sequence = self.sequence.wrapping_add(1);
        self.w
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: channel,
                    sequence: self.sequence,
                    log_time: time,
                    publish_time: time,
                },
                &self.buf,
            )
            .map_err(|e| failure(&self.path, &self.first, e))
    }

    fn metadata(&mut self, info: &RunInfo) -> Result<()> {
        let s = &info.resolved.scenario;
        let agents: Vec<String> = info.agents.keys().map(u32::to_string).collect();
        let mut m = BTreeMap::new();
        m.insert("scenario".to_string(), s.name.clone());
        m.insert("seed".to_string(), s.seed.to_string());
        m.insert("clock".to_string(), s.clock.as_str().to_string());
        m.insert("control_period_s".to_string(), info.dt.to_string());
        m.insert("beta".to_string(), info.beta.to_string());
        m.insert("agents".to_string(), agents.join(","));
        m.insert("ticks".to_string(), info.resolved.ticks().to_string());
        m.insert("scenario_toml".to_string(), info.resolved.to_toml());
        self.w
            .write_metadata(&mcap::records::Metadata {
                name: "fdi-mas".into(),
                metadata: m,
            })
            .map_err(|e| failure(&self.path, &self.first, e))
    }

    /// Closes the file whole (summary, footer) and waits until every byte is on disk.
    fn finish(mut self) -> Result<mcap::Summary> {
        let summary = self
            .w
            .finish()
            .map_err(|e| failure(&self.path, &self.first, e))?;
        let noted = self
            .w
            .into_inner()
            .into_inner()
            .map_err(|e| WriteFailed::io(&self.path, e.into_error()))?;
        noted
            .file
            .sync_all()
            .map_err(|e| WriteFailed::io(&self.path, e))?;
        Ok(summary)
    }
}

/// A failure of the MCAP writer: every one ends the file (the writer refuses any later write),
/// so every one abandons the export, named by its cause: the file's own first error when it
/// had one (the `mcap` crate may have wrapped it), else the writer's.
fn failure(path: &Path, first: &FirstError, e: mcap::McapError) -> anyhow::Error {
    if let Some(os) = first.borrow_mut().take() {
        return WriteFailed::io(path, os);
    }
    match e {
        mcap::McapError::Io(e) => WriteFailed::io(path, e),
        e => WriteFailed::other(path, e),
    }
}

pub(super) fn export(run_dir: &Path) -> Result<()> {
    let files = trace_files(run_dir)?;
    let dir = OutDir::open(run_dir)?;
    let out = dir.path.join("run.mcap");
    // The file is written under a temporary name beside `run.mcap` (removed when dropped) and
    // renamed once whole: a failed export leaves no partial file, and an earlier `run.mcap`
    // stays as it was until the new one replaces it.
    let written = tempfile::Builder::new()
        .prefix(".run.mcap.")
        // As `File::create` would make it (the umask applies), not only for its owner.
        .permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666))
        .tempfile_in(&dir.path)
        .map_err(|e| WriteFailed::io(&out, e))
        .and_then(|tmp| {
            let (file, tmp) = tmp.into_parts();
            let failures = write(run_dir, &files, &out, file)?;
            tmp.persist(&out)
                .map_err(|e| WriteFailed::io(&out, e.error))?;
            Ok(failures)
        });
    match written {
        Ok(failures) => failed(failures),
        Err(e) => {
            dir.discard();
            Err(abandoned(e, "MCAP"))
        }
    }
}

/// Writes the MCAP file `out` into `file`, its temporary. The failures of traces that could not
/// be exported whole (the file holds what was read before); an error ends the export.
fn write(run_dir: &Path, files: &[PathBuf], out: &Path, file: File) -> Result<Vec<String>> {
    let mut w = Mcap::create(out, file)?;
    let mut failures = Vec::new();
    let mut run: Option<RunInfo> = None;
    for f in files {
        let mut n = 0;
        match export_file(f, &mut w, &mut run, &mut n) {
            Ok(()) => println!("{} -> {}: {n} records", f.display(), out.display()),
            Err(e) if write_failure(&e).is_some() => return Err(e),
            Err(e) if n > 0 => failures.push(format!(
                "{e:#} (the {n} records before it are exported to {})",
                out.display()
            )),
            Err(e) => failures.push(format!("{e:#}")),
        }
    }
    if let Some(info) = &run {
        match detectors(run_dir, info, &mut w) {
            Ok(Ok(n)) => println!("detector statistics -> {}: {n} ticks", out.display()),
            Ok(Err(none)) => println!("{}: {none}", out.display()),
            Err(e) if write_failure(&e).is_some() => return Err(e),
            Err(e) => failures.push(format!("{e:#}")),
        }
        w.metadata(info)?;
    }
    let summary = w.finish()?;
    let messages = summary.stats.as_ref().map_or(0, |s| s.message_count);
    println!(
        "{}: {messages} messages on {} topics",
        out.display(),
        summary.channels.len()
    );
    Ok(failures)
}

fn nums(v: &[f64]) -> Value {
    Value::from(v)
}

/// Exports one trace into `w`, counting its records in `n`. `run`: the scenario of the first
/// trace; every later trace must hold the same.
fn export_file(path: &Path, w: &mut Mcap, run: &mut Option<RunInfo>, n: &mut u64) -> Result<()> {
    let mut reader = TraceReader::open(path)?;
    let info = RunInfo::from_header(path, reader.header())?;
    if let Some(first) = run.as_ref() {
        if first.resolved != info.resolved {
            bail!(
                "{}: the scenario in its header differs from that of the run's other traces",
                path.display()
            );
        }
    }
    let stem = stem(path);
    read_sorted(path, &mut reader, n, |rec, at| {
        record(w, &info, path, &stem, rec)
            .with_context(|| format!("{}: record at byte offset {at}", path.display()))
    })?;
    if run.is_none() {
        *run = Some(info);
    }
    Ok(())
}

/// The messages of one record.
fn record(w: &mut Mcap, info: &RunInfo, path: &Path, stem: &str, rec: &TraceRecord) -> Result<()> {
    match rec {
        TraceRecord::Agent(a) => {
            let t = info.t(a.k);
            let (q, qd, qdd, dof) = info.desired(path, a.agent, a.k)?;
            let (q, qd, qdd) = (&q[..dof], &qd[..dof], &qdd[..dof]);
            let diff = |d: &[f64], x: &[f64]| -> Vec<f64> {
                d.iter().zip(x).map(|(d, x)| d - x).collect()
            };
            let id = a.agent;
            w.write(
                id,
                "state",
                &STATE,
                t,
                &json!({"k": a.k, "t_s": t,
                "q_rad": nums(a.q.as_slice()), "q_dot_rad_s": nums(a.qd.as_slice()),
                "q_ddot_rad_s2": nums(a.qdd.as_slice())}),
            )?;
            w.write(
                id,
                "desired",
                &DESIRED,
                t,
                &json!({"k": a.k, "t_s": t,
                "q_des_rad": nums(q), "q_dot_des_rad_s": nums(qd), "q_ddot_des_rad_s2": nums(qdd)}),
            )?;
            w.write(
                id,
                "tracking_error",
                &TRACKING,
                t,
                &json!({"k": a.k, "t_s": t,
                "e_rad": diff(q, a.q.as_slice()), "e_dot_rad_s": diff(qd, a.qd.as_slice())}),
            )?;
            w.write(
                id,
                "measurement/clean",
                &CLEAN,
                t,
                &json!({"k": a.k, "t_s": t,
                "y_rad": nums(a.y.as_slice()), "y_dot_rad_s": nums(a.yd.as_slice())}),
            )?;
            w.write(
                id,
                "torque/applied",
                &APPLIED,
                t,
                &json!({"k": a.k, "t_s": t,
                "u_nm": nums(a.u_applied.as_slice()), "missed": a.missed}),
            )?;
            w.write(
                id,
                "delay",
                &DELAY,
                t,
                &json!({"k": a.k, "t_s": t, "tau_s": a.tau}),
            )
        }
        TraceRecord::Attack(a) => {
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
            w.write(
                a.agent,
                "attack",
                &ATTACK,
                t,
                &json!({"k": a.k, "t_s": t,
                "alpha_pos_rad": nums(a.alpha_position.as_slice()),
                "alpha_vel_rad_s": nums(a.alpha_velocity.as_slice()),
                "s_true_rad_s": s, "active": a.active, "delivery": delivery}),
            )?;
            w.write(
                a.agent,
                "measurement/tampered",
                &TAMPERED,
                t,
                &json!({"k": a.k, "t_s": t,
                "y_rad": nums(a.y.as_slice()), "y_dot_rad_s": nums(a.yd.as_slice()),
                "delivery": delivery}),
            )
        }
        TraceRecord::Center(c) => {
            let t = info.t(c.k);
            info.agent(path, c.agent)?;
            w.write(
                c.agent,
                "estimate",
                &ESTIMATE,
                t,
                &json!({"k": c.k, "t_s": t,
                "s_hat_rad_s": nums(c.s_hat.as_slice()), "q_hat_rad": nums(c.q_hat.as_slice()),
                "q_dot_hat_rad_s": nums(c.qd_hat.as_slice()),
                "q_ddot_hat_rad_s2": nums(c.qdd_hat.as_slice())}),
            )?;
            w.write(
                c.agent,
                "torque/sent",
                &SENT,
                t,
                &json!({"k": c.k, "t_s": t,
                "u_nm": nums(c.u.as_slice())}),
            )?;
            w.write(
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
        TraceRecord::Latency { k, agent, stamps } => {
            let t = info.t(*k);
            info.agent(path, *agent)?;
            w.write(
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
            w.write(
                a.agent,
                "actuation",
                &ACTUATION,
                t,
                &json!({"k": a.k, "t_s": t,
                "alpha_u_nm": nums(a.alpha_u.as_slice()), "u_nm": nums(a.u.as_slice()),
                "held_s": a.held_s, "active": a.active, "delivery": a.delivery.as_str()}),
            )
        }
        TraceRecord::Event { t, message } => w.write(
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
            w.write(
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

/// The `/agent<id>/detectors` topics: every joined tick's statistics ([`detectors::each_tick`])
/// written as they come. The number of joined ticks, or why there are none.
fn detectors(run_dir: &Path, info: &RunInfo, w: &mut Mcap) -> Result<Result<u64, String>> {
    detectors::each_tick(run_dir, info, |tick| {
        let mut msg = Map::new();
        msg.insert("k".into(), Value::from(tick.k));
        msg.insert("t_s".into(), Value::from(tick.t));
        msg.insert("in_force".into(), Value::from(tick.in_force));
        for s in tick.statistics {
            let [value, threshold, verdict, alarm] = detectors::fields_of(s.name);
            msg.insert(value, s.value.map_or(Value::Null, Value::from));
            msg.insert(threshold, s.threshold.map_or(Value::Null, Value::from));
            msg.insert(verdict, Value::from(s.verdict));
            msg.insert(alarm, Value::from(s.alarm));
        }
        w.write(
            tick.agent,
            "detectors",
            &DETECTORS,
            tick.t,
            &Value::Object(msg),
        )
    })
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use fdi_common::engine::tick_time;

    use super::*;

    use super::super::tests::fixture_copy;
    use crate::join;

    /// The messages each topic must have: counted from the traces themselves and their join.
    fn expected(dir: &Path) -> BTreeMap<String, u64> {
        let mut want: BTreeMap<String, u64> = BTreeMap::new();
        let mut add = |agent: u32, names: &[&str]| {
            for n in names {
                *want.entry(topic(agent, n)).or_default() += 1;
            }
        };
        let mut events = 0;
        let mut scenario = None;
        for f in trace_files(dir).expect("traces") {
            let reader = TraceReader::open(&f).expect("the fixture reads");
            scenario.get_or_insert_with(|| {
                RunInfo::from_header(&f, reader.header()).expect("its scenario")
            });
            for r in reader {
                match r.expect("the fixture reads whole") {
                    TraceRecord::Agent(a) => add(
                        a.agent,
                        &[
                            "state",
                            "desired",
                            "tracking_error",
                            "measurement/clean",
                            "torque/applied",
                            "delay",
                        ],
                    ),
                    TraceRecord::Attack(a) => add(a.agent, &["attack", "measurement/tampered"]),
                    TraceRecord::Center(c) => add(c.agent, &["estimate", "torque/sent", "alarm"]),
                    TraceRecord::Latency { agent, .. } => add(agent, &["latency"]),
                    TraceRecord::Actuation(a) => add(a.agent, &["actuation"]),
                    TraceRecord::Event { .. } => events += 1,
                    TraceRecord::Monitor(m) => add(m.agent, &["monitor"]),
                }
            }
        }
        let info = scenario.expect("a trace");
        join::join_run(&info.resolved, dir, 0.0, |r| {
            add(r.agent.agent, &["detectors"])
        })
        .expect("joined");
        if events > 0 {
            want.insert("/events".into(), events);
        }
        want
    }

    #[test]
    fn every_topic_reads_back_with_the_run_s_message_count_schema_fields_and_tick_times() {
        let dir = fixture_copy();
        export(dir.path()).expect("exported");
        let bytes = std::fs::read(dir.path().join("export/run.mcap")).expect("run.mcap");
        let want = expected(dir.path());
        let dt = fdi_common::scenario::load_file(
            &fdi_common::run_dir::RunDir::new(dir.path()).scenario(),
        )
        .expect("the fixture's scenario")
        .scenario
        .control_period_s;
        assert!(want.len() >= 4 * 12, "{want:?}");

        let schemas: BTreeMap<&str, &Schema> = topics().iter().map(|(n, s)| (*n, *s)).collect();
        let mut got: BTreeMap<String, u64> = BTreeMap::new();
        let mut last: BTreeMap<String, u64> = BTreeMap::new();
        for m in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
            let m = m.expect("a whole message");
            let topic = m.channel.topic.clone();
            let schema = m.channel.schema.as_ref().expect("a schema");
            assert_eq!(schema.encoding, "jsonschema");
            assert_eq!(m.channel.message_encoding, "json");
            let fields: BTreeSet<String> = serde_json::from_slice::<Value>(&schema.data)
                .expect("a JSON schema")["properties"]
                .as_object()
                .expect("properties")
                .keys()
                .cloned()
                .collect();
            let name = topic.splitn(3, '/').nth(2).unwrap_or(&topic);
            let declared = if topic == "/events" {
                &EVENT
            } else {
                schemas
                    .get(name)
                    .unwrap_or_else(|| panic!("{topic}: not a listed topic"))
            };
            assert_eq!(schema.name, declared.name, "{topic}");
            let body: Value = serde_json::from_slice(&m.data).expect("a JSON message");
            let keys: BTreeSet<String> = body
                .as_object()
                .expect("an object")
                .keys()
                .cloned()
                .collect();
            assert_eq!(keys, fields, "{topic}");
            assert_eq!(m.log_time, m.publish_time, "{topic}");
            if let Some(k) = body.get("k").and_then(Value::as_u64) {
                let t = tick_time(k, dt);
                // Read from the text (serde_json's own parsing may miss the last bit).
                let text = std::str::from_utf8(&m.data).expect("utf-8");
                let at = text.find("\"t_s\":").expect("t_s") + 6;
                let end = text[at..].find([',', '}']).expect("its end") + at;
                let t_s: f64 = text[at..end].parse().expect("a number");
                assert_eq!(t_s.to_bits(), t.to_bits(), "{topic}");
                assert_eq!(m.log_time, ns(t).expect("a time"), "{topic}");
            }
            let before = last.insert(topic.clone(), m.log_time).unwrap_or(0);
            assert!(before <= m.log_time, "{topic}: log times out of order");
            *got.entry(topic).or_default() += 1;
        }
        assert_eq!(got, want);
        let summary = mcap::Summary::read(&bytes)
            .expect("a summary")
            .expect("a summary");
        assert_eq!(summary.channels.len(), want.len());
        assert_eq!(summary.metadata_indexes.len(), 1, "the fdi-mas metadata");
        // What was read above came out of compressed chunks.
        assert!(!summary.chunk_indexes.is_empty());
        for c in &summary.chunk_indexes {
            assert_eq!(c.compression, "zstd");
            assert!(c.compressed_size < c.uncompressed_size, "{c:?}");
        }
    }

    /// The file is written a bounded chunk at a time: every chunk holds at most
    /// [`CHUNK_SIZE`] bytes of messages (and the one message that crossed the line).
    #[test]
    fn messages_are_written_in_chunks_of_at_most_chunk_size() {
        let dir = tempfile::tempdir().expect("scratch");
        let path = dir.path().join("run.mcap");
        let file = File::create(&path).expect("a file");
        let mut w = Mcap::create(&path, file).expect("a writer");
        let q: Vec<f64> = (0..6).map(|i| f64::from(i) * 0.1).collect();
        let mut largest = 0;
        for k in 0..40_000u64 {
            let t = tick_time(k, 1e-3);
            let msg = json!({"k": k, "t_s": t, "q_rad": q, "q_dot_rad_s": q, "q_ddot_rad_s2": q});
            largest = largest.max(serde_json::to_vec(&msg).expect("JSON").len() as u64);
            w.write(1 + (k % 4) as u32, "state", &STATE, t, &msg)
                .expect("written");
        }
        w.finish().expect("closed");
        let bytes = std::fs::read(&path).expect("run.mcap");
        let summary = mcap::Summary::read(&bytes)
            .expect("a summary")
            .expect("a summary");
        // A message record: opcode, length, header (22 bytes), data.
        let record = 9 + 22 + largest;
        assert!(
            summary.chunk_indexes.len() >= 4,
            "{} chunks",
            summary.chunk_indexes.len()
        );
        for c in &summary.chunk_indexes {
            assert!(
                c.uncompressed_size <= CHUNK_SIZE + record,
                "a chunk of {} bytes",
                c.uncompressed_size
            );
        }
    }

    #[test]
    fn every_schema_lists_each_field_once_and_requires_it() {
        for (name, s) in topics().iter().chain([&("events", &EVENT)]) {
            let v = json_schema(s);
            let props = v["properties"].as_object().expect("properties");
            assert_eq!(props.len(), s.fields.len(), "{name}: a field named twice");
            assert_eq!(
                v["required"].as_array().map(Vec::len),
                Some(s.fields.len()),
                "{name}"
            );
            assert!(
                props.values().all(|p| p["description"].is_string()),
                "{name}"
            );
        }
    }
}
