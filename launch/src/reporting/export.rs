//! Trace export: every `RUN_DIR/traces/<process>.trace` becomes `RUN_DIR/export/<process>.csv`,
//! a header row and one row per record. Latency records go to `<process>-latency.csv`, events of
//! every trace to `events.csv`; records of a kind the process does not usually write (say,
//! center records in an agent trace) to `<process>-<kind>.csv`.
//!
//! Floats are written with Rust's `{}` (shortest text that parses back to the same `f64`, bit for
//! bit), flags as `0`/`1`, vectors as one column per link (`q1`, `q2`, …; a record with fewer
//! links than the trace's scenario leaves the extra cells empty). A damaged trace is exported up
//! to its last whole record, then the export fails naming the file and the byte offset.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write};
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
    let mut events = Csv::create(&events_path, "process,t,message")?;
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

/// A CSV file being written.
struct Csv {
    path: PathBuf,
    out: BufWriter<File>,
    line: String,
}

impl Csv {
    fn create(path: &Path, header: &str) -> Result<Self> {
        let file = File::create(path).with_context(|| format!("creating {}", path.display()))?;
        let mut c = Self {
            path: path.to_path_buf(),
            out: BufWriter::with_capacity(1 << 16, file),
            line: String::with_capacity(512),
        };
        c.line.push_str(header);
        c.end()?;
        Ok(c)
    }

    /// Writes the line built so far.
    fn end(&mut self) -> Result<()> {
        self.line.push('\n');
        self.out
            .write_all(self.line.as_bytes())
            .with_context(|| format!("writing {}", self.path.display()))?;
        self.line.clear();
        Ok(())
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
}

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Self::Agent => "agent",
            Self::Attack => "attacker",
            Self::Center => "control-center",
            Self::Latency => "latency",
        }
    }

    fn header(self, dof: usize) -> String {
        let v = |name: &str| -> String {
            (1..=dof)
                .map(|i| format!("{name}{i}"))
                .collect::<Vec<_>>()
                .join(",")
        };
        match self {
            Self::Agent => format!(
                "k,agent,t,{},{},{},{},{},{},tau,missed",
                v("q"),
                v("qd"),
                v("qdd"),
                v("y"),
                v("yd"),
                v("u_applied")
            ),
            Self::Attack => format!(
                "k,agent,{},{},{},{},active",
                v("alpha_position"),
                v("alpha_velocity"),
                v("y"),
                v("yd")
            ),
            Self::Center => format!(
                "k,agent,{},{},{},{},{},alarm,rejected_input,rejected_torque,state_reset,history_miss",
                v("s_hat"),
                v("q_hat"),
                v("qd_hat"),
                v("qdd_hat"),
                v("u")
            ),
            Self::Latency => "k,agent,agent_sent_ns,attacker_received_ns,attacker_sent_ns,center_received_ns,center_sent_ns,agent_received_ns".into(),
        }
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
            TraceRecord::Event { t, message } => {
                let _ = write!(events.line, "{},{},{}", quote(&stem), t, quote(message));
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
        row(&mut csv.line, &rec, dof).with_context(|| {
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

/// Quotes a CSV field when it needs it.
fn quote(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn joints(line: &mut String, j: &Joints, dof: usize) -> Result<()> {
    let v = j.as_slice();
    if v.len() > dof {
        bail!("a vector of {} entries, {dof} columns", v.len());
    }
    for i in 0..dof {
        line.push(',');
        if let Some(x) = v.get(i) {
            let _ = write!(line, "{x}");
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

fn row(line: &mut String, rec: &TraceRecord, dof: usize) -> Result<()> {
    match rec {
        TraceRecord::Agent(a) => agent_row(line, a, dof),
        TraceRecord::Attack(a) => attack_row(line, a, dof),
        TraceRecord::Center(c) => center_row(line, c, dof),
        TraceRecord::Latency { k, agent, stamps } => {
            let _ = write!(
                line,
                "{k},{agent},{},{},{},{},{},{}",
                stamps.agent_sent_ns,
                stamps.attacker_received_ns,
                stamps.attacker_sent_ns,
                stamps.center_received_ns,
                stamps.center_sent_ns,
                stamps.agent_received_ns
            );
            Ok(())
        }
        TraceRecord::Event { .. } => Ok(()),
    }
}

fn agent_row(line: &mut String, a: &AgentRecord, dof: usize) -> Result<()> {
    let _ = write!(line, "{},{},{}", a.k, a.agent, a.t);
    for j in [&a.q, &a.qd, &a.qdd, &a.y, &a.yd, &a.u_applied] {
        joints(line, j, dof)?;
    }
    let _ = write!(line, ",{},{}", a.tau, flag(a.missed));
    Ok(())
}

fn attack_row(line: &mut String, a: &AttackRecord, dof: usize) -> Result<()> {
    let _ = write!(line, "{},{}", a.k, a.agent);
    for j in [&a.alpha_position, &a.alpha_velocity, &a.y, &a.yd] {
        joints(line, j, dof)?;
    }
    let _ = write!(line, ",{}", flag(a.active));
    Ok(())
}

fn center_row(line: &mut String, c: &CenterRecord, dof: usize) -> Result<()> {
    let _ = write!(line, "{},{}", c.k, c.agent);
    for j in [&c.s_hat, &c.q_hat, &c.qd_hat, &c.qdd_hat, &c.u] {
        joints(line, j, dof)?;
    }
    let _ = write!(
        line,
        ",{},{},{},{},{}",
        flag(c.alarm),
        flag(c.rejected_input),
        flag(c.rejected_torque),
        flag(c.state_reset),
        flag(c.history_miss)
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_have_one_column_per_field() {
        let h = Kind::Agent.header(2);
        assert_eq!(
            h,
            "k,agent,t,q1,q2,qd1,qd2,qdd1,qdd2,y1,y2,yd1,yd2,u_applied1,u_applied2,tau,missed"
        );
        let mut line = String::new();
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
        agent_row(&mut line, &a, 2).expect("fits");
        assert_eq!(line.split(',').count(), h.split(',').count());
        let fields: Vec<f64> = line
            .split(',')
            .map(|x| x.parse::<f64>().expect("number"))
            .collect();
        assert_eq!(fields[5].to_bits(), 1e-300_f64.to_bits());
        assert_eq!(fields[9].to_bits(), (1.0_f64 / 3.0).to_bits());
        assert_eq!(fields[12].to_bits(), (-0.0_f64).to_bits());
        assert_eq!(Kind::Attack.header(2).split(',').count(), 11);
        // k, agent, 5 joint pairs, alarm, rejected_input, rejected_torque, state_reset, history_miss
        assert_eq!(Kind::Center.header(2).split(',').count(), 17);
    }

    #[test]
    fn fields_with_commas_or_quotes_are_quoted() {
        assert_eq!(quote("plain"), "plain");
        assert_eq!(quote("a, b"), "\"a, b\"");
        assert_eq!(quote("say \"hi\""), "\"say \"\"hi\"\"\"");
    }
}
