//! Trace export: every `RUN_DIR/traces/<process>.trace` becomes `RUN_DIR/export/<process>.csv`,
//! a header row and one row per record. Latency records go to `<process>-latency.csv`, events of
//! every trace to `events.csv`; records of a kind the process does not usually write (say,
//! center records in an agent trace) to `<process>-<kind>.csv`.
//!
//! Floats are written with Rust's `{}` (shortest text that parses back to the same `f64`, bit for
//! bit), flags as `0`/`1`, vectors as one column per link (`q1`, `q2`, …; a record with fewer
//! links than the trace's scenario leaves the extra cells empty). Fields are quoted where CSV
//! needs it (a comma, a quote or a line break in an event message). A damaged trace is exported
//! up to its last whole record, then the export fails naming the file and the byte offset.

use std::collections::BTreeMap;
use std::fmt::{Display, Write as _};
use std::fs::File;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use fdi_common::records::{AgentRecord, AttackRecord, CenterRecord, Joints};
use fdi_common::scenario::{self, MAX_DOF};
use fdi_common::trace::{TraceReader, TraceRecord};

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    Csv,
}

/// `fdi-launch trace export RUN_DIR`.
pub fn export(run_dir: &Path, format: Format) -> Result<()> {
    match format {
        Format::Csv => export_csv(run_dir),
    }
}

fn export_csv(run_dir: &Path) -> Result<()> {
    let traces = run_dir.join("traces");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&traces)
        .with_context(|| format!("reading {}", traces.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "trace"))
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("{}: no trace files", traces.display());
    }
    let out = run_dir.join("export");
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let events_path = out.join("events.csv");
    let mut events = Csv::create(&events_path, &["process", "t", "message"])?;
    let mut failures = Vec::new();
    for f in &files {
        let mut n = 0;
        match export_file(f, &out, &mut events, &mut n) {
            Ok(()) => println!("{} -> {}: {n} records", f.display(), out.display()),
            Err(e) if n > 0 => failures.push(format!(
                "{e:#} (the {n} records before it are exported to {})",
                out.display()
            )),
            Err(e) => failures.push(format!("{e:#}")),
        }
    }
    events.finish()?;
    match failures.len() {
        0 => Ok(()),
        1 => bail!("{}", failures[0]),
        n => bail!(
            "{n} traces could not be exported whole:\n{}",
            failures.join("\n")
        ),
    }
}

/// One row being built: its fields, each formatted with `{}`.
#[derive(Default)]
struct Row {
    record: csv::ByteRecord,
    field: String,
}

impl Row {
    fn push(&mut self, value: impl Display) {
        self.field.clear();
        let _ = write!(self.field, "{value}");
        self.record.push_field(self.field.as_bytes());
    }

    fn push_empty(&mut self) {
        self.record.push_field(b"");
    }
}

/// A CSV file being written. A row reaches the file whole or not at all.
struct Csv {
    path: PathBuf,
    out: csv::Writer<File>,
    row: Row,
}

impl Csv {
    fn create<H: AsRef<[u8]>>(path: &Path, header: &[H]) -> Result<Self> {
        let file = File::create(path).with_context(|| format!("creating {}", path.display()))?;
        let mut c = Self {
            path: path.to_path_buf(),
            out: csv::WriterBuilder::new()
                .buffer_capacity(1 << 16)
                .from_writer(file),
            row: Row::default(),
        };
        c.out
            .write_record(header)
            .with_context(|| format!("writing {}", c.path.display()))?;
        Ok(c)
    }

    /// Writes the row built so far and starts the next.
    fn end(&mut self) -> Result<()> {
        let written = self.out.write_byte_record(&self.row.record);
        self.row.record.clear();
        written.with_context(|| format!("writing {}", self.path.display()))
    }

    fn finish(mut self) -> Result<()> {
        self.out
            .flush()
            .with_context(|| format!("writing {}", self.path.display()))
    }
}

/// The kinds of rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    Agent,
    Attack,
    Center,
    Latency,
    Actuation,
}

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Self::Agent => "agent",
            Self::Attack => "attacker",
            Self::Center => "control-center",
            Self::Latency => "latency",
            Self::Actuation => "actuation",
        }
    }

    /// The column names: one per field, vectors as `<name>1` … `<name><dof>`.
    fn header(self, dof: usize) -> Vec<String> {
        let (head, vectors, tail): (&[&str], &[&str], &[&str]) = match self {
            Self::Agent => (
                &["k", "agent", "t"],
                &["q", "qd", "qdd", "y", "yd", "u_applied"],
                &["tau", "missed"],
            ),
            Self::Attack => (
                &["k", "agent"],
                &["alpha_position", "alpha_velocity", "y", "yd"],
                &["active", "delivery"],
            ),
            Self::Actuation => (
                &["k", "agent"],
                &["alpha_u", "u"],
                &["held_s", "active", "delivery"],
            ),
            Self::Center => (
                &["k", "agent"],
                &["s_hat", "q_hat", "qd_hat", "qdd_hat", "u"],
                &[
                    "alarm",
                    "rejected_input",
                    "rejected_torque",
                    "state_reset",
                    "history_miss",
                    "missing_input",
                ],
            ),
            Self::Latency => (
                &[
                    "k",
                    "agent",
                    "agent_sent_ns",
                    "attacker_received_ns",
                    "attacker_sent_ns",
                    "center_received_ns",
                    "center_sent_ns",
                    "agent_received_ns",
                ],
                &[],
                &[],
            ),
        };
        let vectors = vectors
            .iter()
            .flat_map(|name| (1..=dof).map(move |i| format!("{name}{i}")));
        head.iter()
            .map(|h| h.to_string())
            .chain(vectors)
            .chain(tail.iter().map(|t| t.to_string()))
            .collect()
    }
}

/// The row kind a process writes as its main CSV.
fn main_kind(process: &str) -> Option<Kind> {
    if process.starts_with("agent") {
        Some(Kind::Agent)
    } else if process == "attacker" {
        Some(Kind::Attack)
    } else if process == "control-center" {
        Some(Kind::Center)
    } else {
        None
    }
}

/// Exports one trace, counting its records in `n`. Records before a damage are written.
fn export_file(path: &Path, out: &Path, events: &mut Csv, n: &mut u64) -> Result<()> {
    let mut reader = TraceReader::open(path)?;
    let stem = path
        .file_stem()
        .map_or_else(|| "trace".into(), |s| s.to_string_lossy().into_owned());
    let header = reader.header().clone();
    // Columns per vector: the largest model of the trace's scenario (the records carry their
    // own lengths; a scenario that does not parse falls back to the largest record allowed).
    let dof = scenario::load_str(&header.scenario_toml, &stem, None)
        .ok()
        .and_then(|r| r.scenario.agent_dofs().into_values().max())
        .unwrap_or(MAX_DOF);
    let main = main_kind(&header.process).or_else(|| main_kind(&stem));
    let mut files: BTreeMap<Kind, Csv> = BTreeMap::new();
    let file_for = |kind: Kind| -> PathBuf {
        if Some(kind) == main {
            out.join(format!("{stem}.csv"))
        } else {
            out.join(format!("{stem}-{}.csv", kind.name()))
        }
    };
    if let Some(k) = main {
        files.insert(k, Csv::create(&file_for(k), &k.header(dof))?);
    }
    let mut failure = None;
    while let Some(rec) = reader.next() {
        let rec = match rec {
            Ok(r) => r,
            Err(e) => {
                failure = Some(e);
                break;
            }
        };
        *n += 1;
        let kind = match &rec {
            TraceRecord::Agent(_) => Kind::Agent,
            TraceRecord::Attack(_) => Kind::Attack,
            TraceRecord::Center(_) => Kind::Center,
            TraceRecord::Latency { .. } => Kind::Latency,
            TraceRecord::Actuation(_) => Kind::Actuation,
            TraceRecord::Event { t, message } => {
                events.row.push(&stem);
                events.row.push(t);
                events.row.push(message);
                events.end()?;
                continue;
            }
        };
        let csv = match files.entry(kind) {
            std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::btree_map::Entry::Vacant(e) => {
                e.insert(Csv::create(&file_for(kind), &kind.header(dof))?)
            }
        };
        let at = reader.last_offset();
        row(&mut csv.row, &rec, dof).with_context(|| {
            format!(
                "{}: record {n} (byte offset {at}) does not fit the columns",
                path.display()
            )
        })?;
        csv.end()?;
    }
    for (_, c) in files {
        c.finish()?;
    }
    match failure {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}

fn joints(row: &mut Row, j: &Joints, dof: usize) -> Result<()> {
    let v = j.as_slice();
    if v.len() > dof {
        bail!("a vector of {} entries, {dof} columns", v.len());
    }
    for i in 0..dof {
        match v.get(i) {
            Some(x) => row.push(x),
            None => row.push_empty(),
        }
    }
    Ok(())
}

fn flag(b: bool) -> &'static str {
    if b {
        "1"
    } else {
        "0"
    }
}

/// Builds the row of `rec` in `row` (emptied first).
fn row(row: &mut Row, rec: &TraceRecord, dof: usize) -> Result<()> {
    row.record.clear();
    match rec {
        TraceRecord::Agent(a) => agent_row(row, a, dof),
        TraceRecord::Attack(a) => attack_row(row, a, dof),
        TraceRecord::Center(c) => center_row(row, c, dof),
        TraceRecord::Latency { k, agent, stamps } => {
            row.push(k);
            row.push(agent);
            for ns in [
                stamps.agent_sent_ns,
                stamps.attacker_received_ns,
                stamps.attacker_sent_ns,
                stamps.center_received_ns,
                stamps.center_sent_ns,
                stamps.agent_received_ns,
            ] {
                row.push(ns);
            }
            Ok(())
        }
        TraceRecord::Event { .. } => Ok(()),
        TraceRecord::Actuation(a) => {
            row.push(a.k);
            row.push(a.agent);
            joints(row, &a.alpha_u, dof)?;
            joints(row, &a.u, dof)?;
            row.push(a.held_s);
            row.push(flag(a.active));
            row.push(a.delivery.as_str());
            Ok(())
        }
    }
}

fn agent_row(row: &mut Row, a: &AgentRecord, dof: usize) -> Result<()> {
    row.push(a.k);
    row.push(a.agent);
    row.push(a.t);
    for j in [&a.q, &a.qd, &a.qdd, &a.y, &a.yd, &a.u_applied] {
        joints(row, j, dof)?;
    }
    row.push(a.tau);
    row.push(flag(a.missed));
    Ok(())
}

fn attack_row(row: &mut Row, a: &AttackRecord, dof: usize) -> Result<()> {
    row.push(a.k);
    row.push(a.agent);
    for j in [&a.alpha_position, &a.alpha_velocity, &a.y, &a.yd] {
        joints(row, j, dof)?;
    }
    row.push(flag(a.active));
    row.push(a.delivery.as_str());
    Ok(())
}

fn center_row(row: &mut Row, c: &CenterRecord, dof: usize) -> Result<()> {
    row.push(c.k);
    row.push(c.agent);
    for j in [&c.s_hat, &c.q_hat, &c.qd_hat, &c.qdd_hat, &c.u] {
        joints(row, j, dof)?;
    }
    for b in [
        c.alarm,
        c.rejected_input,
        c.rejected_torque,
        c.state_reset,
        c.history_miss,
        c.missing_input,
    ] {
        row.push(flag(b));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The CSV text of `header` and `rows`, as the export writes it.
    fn csv_text(header: &[String], rows: &[&Row]) -> String {
        let mut w = csv::Writer::from_writer(Vec::new());
        w.write_record(header).expect("header");
        for r in rows {
            w.write_byte_record(&r.record).expect("row");
        }
        String::from_utf8(w.into_inner().expect("flushed")).expect("utf-8")
    }

    #[test]
    fn headers_have_one_column_per_field() {
        let h = Kind::Agent.header(2);
        assert_eq!(
            h.join(","),
            "k,agent,t,q1,q2,qd1,qd2,qdd1,qdd2,y1,y2,yd1,yd2,u_applied1,u_applied2,tau,missed"
        );
        let mut row = Row::default();
        let a = AgentRecord {
            k: 3,
            agent: 1,
            t: 0.003,
            q: Joints::from_slice(&[0.1, -0.2]),
            qd: Joints::from_slice(&[1e-300, 2.0]),
            qdd: Joints::from_slice(&[f64::MIN_POSITIVE, 0.0]),
            y: Joints::from_slice(&[1.0 / 3.0, 0.0]),
            yd: Joints::from_slice(&[0.0, -0.0]),
            u_applied: Joints::from_slice(&[5.0, 6.0]),
            tau: 0.003,
            missed: true,
        };
        agent_row(&mut row, &a, 2).expect("fits");
        // Through a CSV reader: the header and the row come back, every float bit for bit.
        let text = csv_text(&h, &[&row]);
        let mut reader = csv::Reader::from_reader(text.as_bytes());
        assert_eq!(reader.headers().expect("header"), h.as_slice());
        let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.expect("row")).collect();
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0].len(), h.len());
        let fields: Vec<f64> = rows[0]
            .iter()
            .map(|x| x.parse::<f64>().expect("number"))
            .collect();
        assert_eq!(fields[5].to_bits(), 1e-300_f64.to_bits());
        assert_eq!(fields[9].to_bits(), (1.0_f64 / 3.0).to_bits());
        assert_eq!(fields[12].to_bits(), (-0.0_f64).to_bits());
        // k, agent, 4 joint pairs, active, delivery
        assert_eq!(Kind::Attack.header(2).len(), 12);
        // k, agent, 5 joint pairs, alarm, rejected_input, rejected_torque, state_reset,
        // history_miss, missing_input
        assert_eq!(Kind::Center.header(2).len(), 18);
        // k, agent, alpha_u and u pairs, held_s, active, delivery
        assert_eq!(
            Kind::Actuation.header(2).join(","),
            "k,agent,alpha_u1,alpha_u2,u1,u2,held_s,active,delivery"
        );
    }

    #[test]
    fn short_vectors_leave_empty_cells_and_long_ones_are_refused() {
        let a = AttackRecord {
            k: 7,
            agent: 2,
            alpha_position: Joints::from_slice(&[0.5]),
            alpha_velocity: Joints::from_slice(&[1.0, 2.0]),
            y: Joints::from_slice(&[3.0, 4.0]),
            yd: Joints::from_slice(&[5.0, 6.0]),
            active: true,
            delivery: Default::default(),
        };
        let mut r = Row::default();
        row(&mut r, &TraceRecord::Attack(a), 2).expect("fits");
        assert_eq!(
            csv_text(&Kind::Attack.header(2), &[&r]),
            "k,agent,alpha_position1,alpha_position2,alpha_velocity1,alpha_velocity2,y1,y2,yd1,yd2,active,delivery\n\
             7,2,0.5,,1,2,3,4,5,6,1,delivered\n"
        );
        assert!(row(&mut r, &TraceRecord::Attack(a), 1).is_err());
    }

    #[test]
    fn fields_with_commas_quotes_or_line_breaks_are_quoted() {
        let mut rows = Vec::new();
        for message in ["plain", "a, b", "say \"hi\"", "two\nlines"] {
            let mut r = Row::default();
            r.push("agent-1");
            r.push(0.5);
            r.push(message);
            rows.push(r);
        }
        let header = ["process", "t", "message"].map(String::from);
        let text = csv_text(&header, &rows.iter().collect::<Vec<_>>());
        assert_eq!(
            text,
            "process,t,message\nagent-1,0.5,plain\nagent-1,0.5,\"a, b\"\n\
             agent-1,0.5,\"say \"\"hi\"\"\"\nagent-1,0.5,\"two\nlines\"\n"
        );
        let mut reader = csv::Reader::from_reader(text.as_bytes());
        let messages: Vec<String> = reader
            .records()
            .map(|r| r.expect("row")[2].to_string())
            .collect();
        assert_eq!(messages, ["plain", "a, b", "say \"hi\"", "two\nlines"]);
    }
}
