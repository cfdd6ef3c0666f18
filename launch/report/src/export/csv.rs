//! CSV export: every `RUN_DIR/traces/<process>.trace` becomes `RUN_DIR/export/<process>.csv`, a
//! header row and one row per record, in (tick, agent) order. Latency records go to
//! `<process>-latency.csv`, the attacker's torque records to `attacker-actuation.csv`, a monitor
//! program's verdicts to `control-center-monitor.csv`, events of
//! every trace to `events.csv`; records of a kind the process does not usually write (say,
//! center records in an agent trace) to `<process>-<kind>.csv`. The detectors' statistics of
//! every joined tick go to `detectors.csv` (the MCAP export's `/agent<id>/detectors`). Every
//! column is listed in docs/traces.md.
//!
//! Every column name carries its unit (`q1_rad`, `q1_dot_rad_s`, `u1_applied_nm`, `t_s`); `t_s`
//! is [`fdi_common::engine::tick_time`] of the tick `k`. The control center's file also holds
//! the desired trajectory of the scenario in its header and the true attack term
//! `S = S₂ + β S₁` ([`true_s`]) from the attacker's record of the same tick.
//!
//! Floats are written with Rust's `{}` (shortest text that parses back to the same `f64`, bit for
//! bit), flags as `0`/`1`, vectors as one column per link (a record with fewer links than the
//! trace's scenario leaves the extra cells empty). Fields are quoted where CSV needs it (a comma,
//! a quote or a line break in an event message). A damaged trace is exported up to its last
//! whole record, then the export fails naming the file and the byte offset.

use std::collections::BTreeMap;
use std::fmt::{Display, Write as _};
use std::fs::File;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use fdi_common::records::{
    true_s, ActuationRecord, AgentRecord, AttackRecord, CenterRecord, Joints,
};
#[cfg(test)]
use fdi_common::scenario::MAX_DOF;
use fdi_common::trace::{HopStamps, TraceReader, TraceRecord};

use super::detectors;
use super::sources::{
    failed, read_sorted, scan, stem, trace_files, Kind, OutDir, RunInfo, Sorted, Writes,
};
use crate::columns;

pub(super) fn export(run_dir: &Path, said: &mut dyn FnMut(&str)) -> Result<()> {
    let files = trace_files(run_dir)?;
    let dir = OutDir::open(run_dir)?;
    // Every CSV is written into a temporary folder in `RUN_DIR/export` (removed when dropped),
    // then moved into place once all are whole: a failed export leaves no partial file, and
    // the files of an earlier export stay as they were.
    let written = tempfile::Builder::new()
        .prefix(".csv.")
        .tempdir_in(&dir.path)
        .map_err(|e| dir.writes.io(&dir.path, e))
        .and_then(|tmp| {
            let out = Out {
                tmp: tmp.path().to_path_buf(),
                dir: dir.path.clone(),
                writes: dir.writes.clone(),
            };
            let failures = write(run_dir, &files, &out, said)?;
            out.commit()?;
            Ok(failures)
        });
    match written {
        Ok(failures) => failed(failures),
        Err(e) => {
            dir.discard();
            Err(dir.writes.abandoned(e, "CSV"))
        }
    }
}

/// Where the CSV files go: written in `tmp`, moved into `dir` (`RUN_DIR/export`) when whole.
struct Out {
    tmp: PathBuf,
    dir: PathBuf,
    writes: Writes,
}

impl Out {
    /// Moves every file written into place. A rename within one folder of one file system
    /// needs no space; one that fails anyway is named.
    fn commit(&self) -> Result<()> {
        let failed = |path: &Path, e| self.writes.io(path, e);
        let entries = std::fs::read_dir(&self.tmp).map_err(|e| failed(&self.dir, e))?;
        for e in entries {
            let name = e.map_err(|e| failed(&self.dir, e))?.file_name();
            let to = self.dir.join(&name);
            std::fs::rename(self.tmp.join(&name), &to).map_err(|e| failed(&to, e))?;
        }
        Ok(())
    }
}

/// Writes every CSV of `files` (the traces of `run_dir`) into `out.tmp`, then the detectors'
/// statistics. The failures of traces that could not be exported whole (their files hold what
/// was read before); an error ends the export.
fn write(
    run_dir: &Path,
    files: &[PathBuf],
    out: &Out,
    said: &mut dyn FnMut(&str),
) -> Result<Vec<String>> {
    let mut events = Csv::create(out, "events.csv", &["process", "t_s", "message"])?;
    let mut failures = Vec::new();
    let mut run: Option<RunInfo> = None;
    for f in files {
        let mut n = 0;
        match export_file(f, out, &mut events, &mut run, &mut n) {
            Ok(()) => said(&format!(
                "{} -> {}: {n} records",
                f.display(),
                out.dir.display()
            )),
            Err(e) if out.writes.failed() => return Err(e),
            Err(e) if n > 0 => failures.push(format!(
                "{e:#} (the {n} records before it are exported to {})",
                out.dir.display()
            )),
            Err(e) => failures.push(format!("{e:#}")),
        }
    }
    events.finish()?;
    if let Some(info) = &run {
        let path = out.dir.join(DETECTORS_CSV);
        match detectors_csv(run_dir, info, out) {
            Ok(Ok(n)) => said(&format!(
                "detector statistics -> {}: {n} ticks",
                path.display()
            )),
            Ok(Err(none)) => said(&format!("{}: {none}", out.dir.display())),
            Err(e) if out.writes.failed() => return Err(e),
            Err(e) => failures.push(format!("{e:#}")),
        }
    }
    Ok(failures)
}

/// The file of the detectors' statistics.
const DETECTORS_CSV: &str = "detectors.csv";

/// The columns of `detectors.csv` for the detectors `names`: the tick, then each detector's
/// fields ([`detectors::fields_of`]).
fn detectors_header(names: &[&str]) -> Vec<String> {
    ["k", "agent", "t_s", "in_force"]
        .into_iter()
        .map(String::from)
        .chain(names.iter().flat_map(|n| detectors::fields_of(n)))
        .collect()
}

/// `detectors.csv`: a row per joined tick and robot, in (tick, agent) order, with every
/// detector's statistic (empty without a verdict), configured threshold (empty before it is
/// calibrated), verdict and alarm ([`detectors::each_tick`], what the MCAP export writes). The
/// rows before a failure of the join are kept.
fn detectors_csv(run_dir: &Path, info: &RunInfo, out: &Out) -> Result<Result<u64, String>> {
    let mut csv = Csv::create(
        out,
        DETECTORS_CSV,
        &detectors_header(&detectors::names(info)),
    )?;
    let written = detectors::each_tick(run_dir, info, |tick| {
        let row = &mut csv.row;
        head(row, tick.k, tick.agent, info);
        row.push(flag(tick.in_force));
        for s in tick.statistics {
            for x in [s.value, s.threshold] {
                match x {
                    Some(x) => row.push(x),
                    None => row.push_empty(),
                }
            }
            row.push(s.verdict);
            row.push(flag(s.alarm));
        }
        csv.end()
    });
    let finished = csv.finish();
    let written = written?;
    finished?;
    Ok(written)
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

/// A CSV file being written (under the export's temporary folder). A row reaches the file
/// whole or not at all.
struct Csv {
    /// The file it becomes, for the messages.
    path: PathBuf,
    writes: Writes,
    out: csv::Writer<File>,
    row: Row,
}

impl Csv {
    /// The file `name` of the export `out`, with its header row.
    fn create<H: AsRef<[u8]>>(out: &Out, name: &str, header: &[H]) -> Result<Self> {
        let path = out.dir.join(name);
        let file = File::create(out.tmp.join(name)).map_err(|e| out.writes.io(&path, e))?;
        let mut c = Self {
            path,
            writes: out.writes.clone(),
            out: csv::WriterBuilder::new()
                .buffer_capacity(1 << 16)
                .from_writer(file),
            row: Row::default(),
        };
        let written = c.out.write_record(header);
        written.map_err(|e| c.failure(e))?;
        Ok(c)
    }

    /// Writes the row built so far and starts the next.
    fn end(&mut self) -> Result<()> {
        let written = self.out.write_byte_record(&self.row.record);
        self.row.record.clear();
        written.map_err(|e| self.failure(e))
    }

    /// A failure to write the file: every one abandons the export (a row of the wrong length
    /// is a fault of this program, not of the trace).
    fn failure(&self, e: csv::Error) -> anyhow::Error {
        match e.into_kind() {
            csv::ErrorKind::Io(e) => self.writes.io(&self.path, e),
            other => self.writes.other(&self.path, format!("{other:?}")),
        }
    }

    /// Writes what is buffered and waits until every byte is on disk.
    fn finish(self) -> Result<()> {
        let file = self
            .out
            .into_inner()
            .map_err(|e| self.writes.io(&self.path, e.into_error()))?;
        file.sync_all().map_err(|e| self.writes.io(&self.path, e))
    }
}

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Self::Agent => "agent",
            Self::Attack => "attacker",
            Self::Center => fdi_common::run_dir::Process::CENTER,
            Self::Latency => "latency",
            Self::Actuation => "actuation",
            Self::Monitor => "monitor",
        }
    }

    /// The groups of its columns (`fdi_report::columns`, the list the tick table of the
    /// Python package shares).
    fn columns(self) -> &'static [&'static [columns::Col]] {
        match self {
            Self::Agent => &[columns::KEY, columns::AGENT],
            Self::Attack => &[columns::KEY, columns::ATTACK],
            Self::Center => &[
                columns::KEY,
                columns::DESIRED,
                columns::S_TRUE,
                columns::CENTER,
            ],
            Self::Latency => &[columns::KEY, columns::LATENCY],
            Self::Actuation => &[columns::KEY, columns::ACTUATION],
            Self::Monitor => &[columns::KEY, columns::MONITOR],
        }
    }

    /// The column names for vectors of `dof` links.
    fn header(self, dof: usize) -> Vec<String> {
        columns::named(self.columns(), dof)
            .into_iter()
            .map(|(name, _)| name)
            .collect()
    }
}

/// The row kind a process writes as its main CSV.
fn main_kind(process: &str) -> Option<Kind> {
    if process.starts_with("agent") {
        Some(Kind::Agent)
    } else if process == "attacker" {
        Some(Kind::Attack)
    } else if process == fdi_common::run_dir::Process::CENTER {
        Some(Kind::Center)
    } else {
        None
    }
}

/// The attacker's records of a run, looked up in (tick, agent) order: the injected values of
/// the ticks the control center's rows need for `S`.
struct AttackLookup {
    sorted: Sorted,
    /// Why the attacker trace ended early (a damage), if it did.
    problem: Option<String>,
}

impl AttackLookup {
    fn open(path: &Path) -> Result<Self> {
        let mut reader = TraceReader::open(path)?;
        let mut n = 0;
        let (keys, damage) = scan(path, &mut reader, &mut n, |_, _| Ok(()))?;
        let keys = keys
            .into_iter()
            .filter(|(kind, _)| *kind == Kind::Attack)
            .collect();
        Ok(Self {
            sorted: Sorted::open(path, &keys)?,
            problem: damage.map(|e| format!("{e:#}")),
        })
    }

    /// The attacker's record of tick `k` of `agent`; calls come in (tick, agent) order.
    fn get(&mut self, k: u64, agent: u32) -> Option<AttackRecord> {
        while self
            .sorted
            .peek()
            .is_some_and(|(hk, ha, _)| (hk, ha) < (k, agent))
        {
            self.sorted.pop();
        }
        match self.sorted.peek() {
            Some((hk, ha, _)) if (hk, ha) == (k, agent) => match self.sorted.pop() {
                Some((TraceRecord::Attack(a), _)) => Some(a),
                _ => None,
            },
            _ => None,
        }
    }
}

/// Exports one trace, counting its records in `n`. Records before a damage are written.
/// `run`: the scenario of the first trace (the detectors' statistics are computed from it).
fn export_file(
    path: &Path,
    out: &Out,
    events: &mut Csv,
    run: &mut Option<RunInfo>,
    n: &mut u64,
) -> Result<()> {
    let mut reader = TraceReader::open(path)?;
    let stem = stem(path);
    let header = reader.header().clone();
    let info = RunInfo::from_header(path, &header)?;
    if run.is_none() {
        *run = Some(info.clone());
    }
    let dof = info.dof;
    let main = main_kind(&header.process).or_else(|| main_kind(&stem));
    let mut files: BTreeMap<Kind, Csv> = BTreeMap::new();
    let file_for = |kind: Kind| -> String {
        if Some(kind) == main {
            format!("{stem}.csv")
        } else {
            format!("{stem}-{}.csv", kind.name())
        }
    };
    if let Some(k) = main {
        files.insert(k, Csv::create(out, &file_for(k), &k.header(dof))?);
    }
    // The attacker trace beside this one, for S in the control center's rows.
    let attacker = path.with_file_name("attacker.trace");
    let mut lookup: Option<Result<AttackLookup, String>> = None;
    let read = read_sorted(path, &mut reader, n, |rec, at| {
        let Some((kind, _, _)) = Kind::of(rec) else {
            if let TraceRecord::Event { t, message } = rec {
                events.row.push(&stem);
                events.row.push(t);
                events.row.push(message);
                events.end()?;
            }
            return Ok(());
        };
        let csv = match files.entry(kind) {
            std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::btree_map::Entry::Vacant(e) => {
                e.insert(Csv::create(out, &file_for(kind), &kind.header(dof))?)
            }
        };
        let attack = match rec {
            TraceRecord::Center(c) => lookup
                .get_or_insert_with(|| AttackLookup::open(&attacker).map_err(|e| format!("{e:#}")))
                .as_mut()
                .ok()
                .and_then(|l| l.get(c.k, c.agent)),
            _ => None,
        };
        csv.row.record.clear();
        row(&mut csv.row, rec, &info, path, attack.as_ref())
            .with_context(|| format!("{}: record at byte offset {at}", path.display()))?;
        csv.end()
    });
    for (_, c) in files {
        c.finish()?;
    }
    read?;
    match lookup {
        Some(Err(e)) => bail!(
            "{}: the s_true columns of its CSV are empty: the attacker trace could not be read: {e}",
            path.display()
        ),
        Some(Ok(AttackLookup {
            problem: Some(p), ..
        })) => bail!(
            "{}: the s_true columns of its CSV are empty from where the attacker trace could no longer be read: {p}",
            path.display()
        ),
        _ => Ok(()),
    }
}

/// `dof` cells of a vector; an error when it has more entries.
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

/// `dof` cells, the first `n` of `v`.
fn first_of(row: &mut Row, v: &[f64], n: usize, dof: usize) {
    for i in 0..dof {
        match v.get(i).filter(|_| i < n) {
            Some(x) => row.push(x),
            None => row.push_empty(),
        }
    }
}

fn flag(b: bool) -> &'static str {
    if b {
        "1"
    } else {
        "0"
    }
}

/// Builds the row of `rec` in `row` (emptied by the caller). `attack`: the attacker's record
/// of the same tick and agent, for a center record.
fn row(
    row: &mut Row,
    rec: &TraceRecord,
    info: &RunInfo,
    path: &Path,
    attack: Option<&AttackRecord>,
) -> Result<()> {
    let dof = info.dof;
    match rec {
        TraceRecord::Agent(a) => agent_row(row, a, info),
        TraceRecord::Attack(a) => attack_row(row, a, info),
        TraceRecord::Center(c) => center_row(row, c, info, path, attack),
        TraceRecord::Latency { k, agent, stamps } => {
            latency_row(row, *k, *agent, stamps, info);
            Ok(())
        }
        TraceRecord::Event { .. } => Ok(()),
        TraceRecord::Monitor(m) => {
            head(row, m.k, m.agent, info);
            row.push(flag(m.alarm));
            row.push(m.statistic);
            row.push(flag(m.late));
            Ok(())
        }
        TraceRecord::Actuation(a) => actuation_row(row, a, info, dof),
    }
}

fn head(row: &mut Row, k: u64, agent: u32, info: &RunInfo) {
    row.push(k);
    row.push(agent);
    row.push(info.t(k));
}

fn latency_row(row: &mut Row, k: u64, agent: u32, stamps: &HopStamps, info: &RunInfo) {
    head(row, k, agent, info);
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
}

fn actuation_row(row: &mut Row, a: &ActuationRecord, info: &RunInfo, dof: usize) -> Result<()> {
    head(row, a.k, a.agent, info);
    joints(row, &a.alpha_u, dof)?;
    joints(row, &a.u, dof)?;
    row.push(a.held_s);
    row.push(flag(a.active));
    row.push(a.delivery.as_str());
    Ok(())
}

fn agent_row(row: &mut Row, a: &AgentRecord, info: &RunInfo) -> Result<()> {
    let dof = info.dof;
    head(row, a.k, a.agent, info);
    for j in [&a.q, &a.qd, &a.qdd, &a.y, &a.yd, &a.u_applied] {
        joints(row, j, dof)?;
    }
    row.push(a.tau);
    row.push(flag(a.missed));
    Ok(())
}

fn attack_row(row: &mut Row, a: &AttackRecord, info: &RunInfo) -> Result<()> {
    let dof = info.dof;
    head(row, a.k, a.agent, info);
    for j in [&a.alpha_position, &a.alpha_velocity, &a.y, &a.yd] {
        joints(row, j, dof)?;
    }
    row.push(flag(a.active));
    row.push(a.delivery.as_str());
    Ok(())
}

fn center_row(
    row: &mut Row,
    c: &CenterRecord,
    info: &RunInfo,
    path: &Path,
    attack: Option<&AttackRecord>,
) -> Result<()> {
    let dof = info.dof;
    head(row, c.k, c.agent, info);
    let (q, qd, qdd, n) = info.desired(path, c.agent, c.k)?;
    for v in [&q, &qd, &qdd] {
        first_of(row, v, n, dof);
    }
    // S of the links both injected vectors have; empty without the attacker's record.
    let s: Vec<f64> = attack.map_or_else(Vec::new, |a| {
        a.alpha_position
            .as_slice()
            .iter()
            .zip(a.alpha_velocity.as_slice())
            .map(|(p, v)| true_s(*p, *v, info.beta))
            .collect()
    });
    first_of(row, &s, n, dof);
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
    use fdi_common::engine::tick_time;

    use super::*;

    use super::super::tests::fixture_copy;

    fn read(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
        let mut r = csv::Reader::from_path(path).expect("a CSV");
        let header = r
            .headers()
            .expect("a header")
            .iter()
            .map(String::from)
            .collect();
        let rows = r
            .records()
            .map(|x| x.expect("a row").iter().map(String::from).collect())
            .collect();
        (header, rows)
    }

    #[test]
    fn column_names_carry_their_units() {
        assert_eq!(
            Kind::Agent.header(2).join(","),
            "k,agent,t_s,q1_rad,q2_rad,q1_dot_rad_s,q2_dot_rad_s,q1_ddot_rad_s2,q2_ddot_rad_s2,\
             y1_clean_rad,y2_clean_rad,y1_dot_clean_rad_s,y2_dot_clean_rad_s,\
             u1_applied_nm,u2_applied_nm,tau_s,missed"
        );
        assert_eq!(
            Kind::Attack.header(1).join(","),
            "k,agent,t_s,alpha1_pos_rad,alpha1_vel_rad_s,y1_tampered_rad,y1_dot_tampered_rad_s,active,delivery"
        );
        assert_eq!(
            Kind::Actuation.header(1).join(","),
            "k,agent,t_s,alpha1_u_nm,u1_tampered_nm,held_s,active,delivery"
        );
        assert_eq!(
            Kind::Center.header(1).join(","),
            "k,agent,t_s,q1_des_rad,q1_dot_des_rad_s,q1_ddot_des_rad_s2,s1_true_rad_s,s1_hat_rad_s,\
             q1_hat_rad,q1_dot_hat_rad_s,q1_ddot_hat_rad_s2,u1_sent_nm,alarm,rejected_input,\
             rejected_torque,state_reset,history_miss,missing_input"
        );
    }

    /// Regression (issue 33): the detectors' statistics were in the MCAP export only.
    /// `detectors.csv` has every detector's columns, a row per joined tick and robot, and the
    /// values the MCAP export has, bit for bit.
    #[test]
    fn detectors_csv_holds_every_detectors_statistic_as_the_mcap_export_does() {
        let dir = fixture_copy();
        export(dir.path(), &mut |_| {}).expect("CSV exported");
        super::super::mcap::export(dir.path(), &mut |_| {}).expect("MCAP exported");
        let (header, rows) = read(&dir.path().join("export/detectors.csv"));
        let names = fdi_common::detect::names();
        assert!(
            names.contains(&"chi2") && names.contains(&"cusum"),
            "{names:?}"
        );
        for column in ["k", "agent", "t_s", "in_force"]
            .into_iter()
            .map(String::from)
            .chain(names.iter().flat_map(|n| {
                [
                    n.to_string(),
                    format!("{n}_threshold"),
                    format!("{n}_verdict"),
                    format!("{n}_alarm"),
                ]
            }))
        {
            assert_eq!(
                header.iter().filter(|h| **h == column).count(),
                1,
                "{column} in {header:?}"
            );
        }
        assert_eq!(header.len(), 4 + 4 * names.len(), "{header:?}");
        let col = |name: &str| header.iter().position(|h| h == name).expect(name);
        // The MCAP export's messages of each robot, in tick order.
        let bytes = std::fs::read(dir.path().join("export/run.mcap")).expect("run.mcap");
        let mut messages: BTreeMap<u32, Vec<serde_json::Value>> = BTreeMap::new();
        for m in ::mcap::MessageStream::new(&bytes).expect("an MCAP file") {
            let m = m.expect("a message");
            let topic = &m.channel.topic;
            if let Some(id) = topic
                .strip_suffix("/detectors")
                .and_then(|t| t.strip_prefix("/agent"))
            {
                let id: u32 = id.parse().expect("an agent id");
                messages
                    .entry(id)
                    .or_default()
                    .push(serde_json::from_slice(&m.data).expect("JSON"));
            }
        }
        assert_eq!(rows.len(), messages.values().map(Vec::len).sum::<usize>());
        let mut next: BTreeMap<u32, usize> = BTreeMap::new();
        let mut watched = 0;
        for row in &rows {
            let agent: u32 = row[col("agent")].parse().expect("agent");
            let i = next.entry(agent).or_default();
            let m = &messages[&agent][*i];
            *i += 1;
            assert_eq!(row[col("k")], m["k"].to_string());
            for name in &names {
                let [value, threshold, verdict, alarm] = super::super::detectors::fields_of(name);
                for field in [&value, &threshold] {
                    let cell = &row[col(field)];
                    match m[field.as_str()].as_f64() {
                        Some(x) => assert_eq!(
                            cell.parse::<f64>().map(f64::to_bits),
                            Ok(x.to_bits()),
                            "{field}"
                        ),
                        // JSON has no NaN or infinity: the CSV's cell is empty or one.
                        None => assert!(
                            cell.is_empty() || cell.parse::<f64>().is_ok_and(|x| !x.is_finite()),
                            "{field}: {cell}"
                        ),
                    }
                }
                assert_eq!(
                    Some(row[col(&verdict)].as_str()),
                    m[verdict.as_str()].as_str()
                );
                assert_eq!(row[col(&alarm)], flag(m[alarm.as_str()] == true));
                watched += usize::from(row[col(&verdict)] == "watched");
            }
        }
        assert!(watched > 0, "no detector watched a tick of the fixture");
    }

    #[test]
    fn short_vectors_leave_empty_cells_and_long_ones_are_refused() {
        let mut r = Row::default();
        joints(&mut r, &Joints::from_slice(&[0.5]), 2).expect("fits");
        assert_eq!(r.record.iter().collect::<Vec<_>>(), [&b"0.5"[..], b""]);
        assert!(joints(&mut r, &Joints::from_slice(&[1.0, 2.0]), 1).is_err());
    }

    /// The fixture's center rows: sorted, timed by `tick_time`, with the scenario's desired
    /// trajectory and the attacker's `S` of the same tick, bit for bit.
    #[test]
    fn the_center_file_holds_time_desired_trajectory_and_true_s_in_tick_agent_order() {
        let dir = fixture_copy();
        export(dir.path(), &mut |_| {}).expect("exported");
        let trace = dir.path().join("traces/control-center.trace");
        let reader = TraceReader::open(&trace).expect("opens");
        let info = RunInfo::from_header(&trace, reader.header()).expect("its scenario");
        let attacks: BTreeMap<(u64, u32), AttackRecord> =
            TraceReader::open(&dir.path().join("traces/attacker.trace"))
                .expect("opens")
                .filter_map(|r| match r.expect("whole") {
                    TraceRecord::Attack(a) => Some(((a.k, a.agent), a)),
                    _ => None,
                })
                .collect();
        let (header, rows) = read(&dir.path().join("export/control-center.csv"));
        assert_eq!(rows.len(), attacks.len(), "one row per center record");
        let col = |name: &str| header.iter().position(|h| h == name).expect(name);
        let bits = |row: &[String], name: &str| -> u64 {
            row[col(name)].parse::<f64>().expect(name).to_bits()
        };
        let mut before = None;
        for row in &rows {
            let k: u64 = row[col("k")].parse().expect("k");
            let agent: u32 = row[col("agent")].parse().expect("agent");
            assert!(before < Some((k, agent)), "rows out of (tick, agent) order");
            before = Some((k, agent));
            assert_eq!(bits(row, "t_s"), tick_time(k, info.dt).to_bits());
            let a = info.agents.get(&agent).expect("a scenario agent");
            let r = a.trajectory.reference::<MAX_DOF>(tick_time(k, info.dt));
            let x = &attacks[&(k, agent)];
            for i in 0..a.dof {
                let l = i + 1;
                assert_eq!(bits(row, &format!("q{l}_des_rad")), r.q[i].to_bits());
                assert_eq!(bits(row, &format!("q{l}_dot_des_rad_s")), r.qd[i].to_bits());
                let s = true_s(
                    x.alpha_position.as_slice()[i],
                    x.alpha_velocity.as_slice()[i],
                    info.beta,
                );
                assert_eq!(bits(row, &format!("s{l}_true_rad_s")), s.to_bits());
            }
        }
        // Some tick of the fixture has a non-zero desired angle and attack term.
        assert!(rows.iter().any(|r| r[col("q1_des_rad")] != "0"));
        assert!(rows.iter().any(|r| r[col("s1_true_rad_s")] != "0"));
    }
}
