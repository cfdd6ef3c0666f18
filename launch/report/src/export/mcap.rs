//! MCAP export: the whole run as `RUN_DIR/export/run.mcap`, for Foxglove and PlotJuggler.
//!
//! The topics, encodings and schemas are [`crate::topics`]'s (the live view's too); log time =
//! publish time = the simulated time of the tick in ns (from [`fdi_common::engine::tick_time`]).
//! The records of each trace are written per kind in (tick, agent) order; a metadata record
//! `fdi-mas` holds the scenario, its agents and the planned ticks.
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

use anyhow::{bail, Context, Result};
use fdi_common::trace::TraceReader;
use serde_json::Value;

use super::detectors;
use super::sources::{failed, read_sorted, stem, trace_files, OutDir, Writes};
use crate::topics::{self, json_schema, log_time_ns, record, topic_name, RunInfo, Schema, Sink};

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
    /// The export's writes.
    writes: Writes,
    channels: BTreeMap<(u32, &'static str), u16>,
    sequence: u32,
    buf: Vec<u8>,
}

/// How the chunks of the MCAP file are compressed: zstd at level 1. On the paper's 40 s run its
/// 397 MB of chunks became 81 MB, against 91 MB at zstd's default level 3 (and twice the
/// time), 84 MB at level 9 (ten times), and 149 MB with lz4 (docs/traces.md).
const COMPRESSION: (mcap::Compression, u32) = (mcap::Compression::Zstd, 1);

/// The profile in the MCAP header: fdi-mas's own (JSON messages with JSON schemas, the
/// `fdi-mas` metadata record; docs/traces.md, "MCAP").
pub const PROFILE: &str = "fdi-mas";

/// The options of the MCAP writer: chunks of [`CHUNK_SIZE`] (before compression), each
/// compressed with [`COMPRESSION`] on this thread.
fn options() -> mcap::WriteOptions {
    mcap::WriteOptions::new()
        .compression(Some(COMPRESSION.0))
        .compression_level(COMPRESSION.1)
        .compression_threads(0)
        .chunk_size(Some(CHUNK_SIZE))
        .profile(PROFILE)
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
    fn create(path: &Path, file: File, writes: &Writes) -> Result<Self> {
        let first = FirstError::default();
        let noted = Noted {
            file,
            first: first.clone(),
        };
        let w = options()
            .create(BufWriter::with_capacity(1 << 16, noted))
            .map_err(|e| failure(writes, path, &first, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            w,
            first,
            writes: writes.clone(),
            channels: BTreeMap::new(),
            sequence: 0,
            buf: Vec::with_capacity(1 << 10),
        })
    }

    /// The channel of `name` of `agent`, made (with its schema) the first time it is asked for.
    fn channel(&mut self, agent: u32, name: &'static str, schema: &Schema) -> Result<u16> {
        if let Some(c) = self.channels.get(&(agent, name)) {
            return Ok(*c);
        }
        let (path, first, writes) = (&self.path, &self.first, &self.writes);
        let text = serde_json::to_vec(&json_schema(schema)).context("a schema")?;
        let s = self
            .w
            .add_schema(schema.name, "jsonschema", &text)
            .map_err(|e| failure(writes, path, first, e))?;
        let topic = topic_name(agent, name);
        let c = self
            .w
            .add_channel(s, &topic, "json", &BTreeMap::new())
            .map_err(|e| failure(writes, path, first, e))?;
        self.channels.insert((agent, name), c);
        Ok(c)
    }

    /// Makes the channel of every topic the run has ([`topics::run_topics`], the list the live
    /// view advertises) that no message reached: the file lists the same topics as the live
    /// view of the run. Returns those topics. A run stamped its hops when it has latency
    /// records (realtime runs of the ipc engine write one per tick).
    fn every_topic_of(&mut self, info: &RunInfo) -> Result<Vec<String>> {
        let stamped = self.channels.keys().any(|(_, n)| *n == "latency");
        let mut empty = Vec::new();
        for (agent, name, schema) in crate::topics::run_topics(&info.resolved, stamped) {
            if !self.channels.contains_key(&(agent, name)) {
                self.channel(agent, name, schema)?;
                empty.push(topic_name(agent, name));
            }
        }
        Ok(empty)
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
            .map_err(|e| failure(&self.writes, &self.path, &self.first, e))
    }

    /// Closes the file whole (summary, footer) and waits until every byte is on disk.
    fn finish(mut self) -> Result<mcap::Summary> {
        let summary = self
            .w
            .finish()
            .map_err(|e| failure(&self.writes, &self.path, &self.first, e))?;
        let noted = self
            .w
            .into_inner()
            .into_inner()
            .map_err(|e| self.writes.io(&self.path, e.into_error()))?;
        noted
            .file
            .sync_all()
            .map_err(|e| self.writes.io(&self.path, e))?;
        Ok(summary)
    }
}

impl Sink for Mcap {
    fn message(
        &mut self,
        agent: u32,
        name: &'static str,
        schema: &Schema,
        t: f64,
        msg: &Value,
    ) -> Result<()> {
        let channel = self.channel(agent, name, schema)?;
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, msg).context("a message")?;
        let time = log_time_ns(t)?;
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
            .map_err(|e| failure(&self.writes, &self.path, &self.first, e))
    }
}

/// A failure of the MCAP writer: every one ends the file (the writer refuses any later write),
/// so every one abandons the export, named by its cause: the file's own first error when it
/// had one (the `mcap` crate may have wrapped it), else the writer's.
fn failure(writes: &Writes, path: &Path, first: &FirstError, e: mcap::McapError) -> anyhow::Error {
    if let Some(os) = first.borrow_mut().take() {
        return writes.io(path, os);
    }
    match e {
        mcap::McapError::Io(e) => writes.io(path, e),
        e => writes.other(path, e),
    }
}

pub(super) fn export(run_dir: &Path, said: &mut dyn FnMut(&str)) -> Result<()> {
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
        .map_err(|e| dir.writes.io(&out, e))
        .and_then(|tmp| {
            let (file, tmp) = tmp.into_parts();
            let failures = write(run_dir, &files, (&out, file, &dir.writes), said)?;
            tmp.persist(&out)
                .map_err(|e| dir.writes.io(&out, e.error))?;
            Ok(failures)
        });
    match written {
        Ok(failures) => failed(failures),
        Err(e) => {
            dir.discard();
            Err(dir.writes.abandoned(e, "MCAP"))
        }
    }
}

/// Writes the MCAP file `out` into `file`, its temporary. The failures of traces that could not
/// be exported whole (the file holds what was read before); an error ends the export.
fn write(
    run_dir: &Path,
    files: &[PathBuf],
    (out, file, writes): (&Path, File, &Writes),
    said: &mut dyn FnMut(&str),
) -> Result<Vec<String>> {
    let mut w = Mcap::create(out, file, writes)?;
    let mut failures = Vec::new();
    let mut run: Option<RunInfo> = None;
    let mut empty = Vec::new();
    for f in files {
        let mut n = 0;
        match export_file(f, &mut w, &mut run, &mut n) {
            Ok(()) => said(&format!(
                "{} -> {}: {n} records",
                f.display(),
                out.display()
            )),
            Err(e) if writes.failed() => return Err(e),
            Err(e) if n > 0 => failures.push(format!(
                "{e:#} (the {n} records before it are exported to {})",
                out.display()
            )),
            Err(e) => failures.push(format!("{e:#}")),
        }
    }
    if let Some(info) = &run {
        match detectors(run_dir, info, &mut w) {
            Ok(Ok(n)) => said(&format!(
                "detector statistics -> {}: {n} ticks",
                out.display()
            )),
            Ok(Err(none)) => said(&format!("{}: {none}", out.display())),
            Err(e) if writes.failed() => return Err(e),
            Err(e) => failures.push(format!("{e:#}")),
        }
        w.metadata(info)?;
        empty = w.every_topic_of(info)?;
    }
    let summary = w.finish()?;
    let messages = summary.stats.as_ref().map_or(0, |s| s.message_count);
    let without = if empty.is_empty() {
        String::new()
    } else {
        format!(" ({} without messages: {})", empty.len(), empty.join(", "))
    };
    said(&format!(
        "{}: {messages} messages on {} topics{without}",
        out.display(),
        summary.channels.len()
    ));
    Ok(failures)
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

/// The `/agent<id>/detectors` topics: every joined tick's statistics ([`detectors::each_tick`])
/// written as they come. The number of joined ticks, or why there are none.
fn detectors(run_dir: &Path, info: &RunInfo, w: &mut Mcap) -> Result<Result<u64, String>> {
    detectors::each_tick(run_dir, info, |tick| topics::detectors::message(w, tick))
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use fdi_common::engine::tick_time;
    use fdi_common::trace::TraceRecord;
    use serde_json::json;

    use super::*;
    use crate::topics::{topic, topics, EVENT, STATE};

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
        join::join_run(
            &info.resolved,
            &fdi_common::run_dir::RunDir::new(dir),
            0.0,
            |r| add(r.agent.agent, &["detectors"]),
        )
        .expect("joined");
        if events > 0 {
            want.insert("/events".into(), events);
        }
        want
    }

    #[test]
    fn every_topic_reads_back_with_the_run_s_message_count_schema_fields_and_tick_times() {
        let dir = fixture_copy();
        export(dir.path(), &mut |_| {}).expect("exported");
        let bytes = std::fs::read(dir.path().join("export/run.mcap")).expect("run.mcap");
        let want = expected(dir.path());
        let dt = fdi_common::scenario::load_written(
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
                assert_eq!(m.log_time, log_time_ns(t).expect("a time"), "{topic}");
            }
            let before = last.insert(topic.clone(), m.log_time).unwrap_or(0);
            assert!(before <= m.log_time, "{topic}: log times out of order");
            *got.entry(topic).or_default() += 1;
        }
        assert_eq!(got, want);
        let summary = mcap::Summary::read(&bytes)
            .expect("a summary")
            .expect("a summary");
        assert_eq!(summary.channels.len(), want.len() + 1, "and /events, empty");
        assert_eq!(summary.metadata_indexes.len(), 1, "the fdi-mas metadata");
        // What was read above came out of compressed chunks.
        assert!(!summary.chunk_indexes.is_empty());
        for c in &summary.chunk_indexes {
            assert_eq!(c.compression, "zstd");
            assert!(c.compressed_size < c.uncompressed_size, "{c:?}");
        }
    }

    /// The header names fdi-mas's profile; the channels are the run's topics, the list the live
    /// view advertises: those with messages and those without (this fixture has no events).
    #[test]
    fn the_header_names_the_profile_and_the_channels_are_the_live_view_s_topics() {
        let dir = fixture_copy();
        export(dir.path(), &mut |_| {}).expect("exported");
        let bytes = std::fs::read(dir.path().join("export/run.mcap")).expect("run.mcap");
        let want = expected(dir.path());
        let header = mcap::read::LinearReader::new(&bytes)
            .expect("an MCAP file")
            .find_map(|r| match r.expect("a whole record") {
                mcap::records::Record::Header(h) => Some(h),
                _ => None,
            })
            .expect("a header record");
        assert_eq!(header.profile, PROFILE);
        let summary = mcap::Summary::read(&bytes)
            .expect("a summary")
            .expect("a summary");
        let info = RunInfo::from_header(
            &trace_files(dir.path()).expect("traces")[0],
            TraceReader::open(&trace_files(dir.path()).expect("traces")[0])
                .expect("a trace")
                .header(),
        )
        .expect("its scenario");
        let run: BTreeSet<String> = crate::topics::run_topics(&info.resolved, false)
            .into_iter()
            .map(|(agent, name, _)| topic_name(agent, name))
            .collect();
        let channels: BTreeSet<String> =
            summary.channels.values().map(|c| c.topic.clone()).collect();
        assert_eq!(channels, run);
        assert!(run.len() > want.len() && !want.contains_key("/events"));
    }

    /// The file is written a bounded chunk at a time: every chunk holds at most
    /// [`CHUNK_SIZE`] bytes of messages (and the one message that crossed the line).
    #[test]
    fn messages_are_written_in_chunks_of_at_most_chunk_size() {
        let dir = tempfile::tempdir().expect("scratch");
        let path = dir.path().join("run.mcap");
        let file = File::create(&path).expect("a file");
        let mut w = Mcap::create(&path, file, &Writes::default()).expect("a writer");
        let q: Vec<f64> = (0..6).map(|i| f64::from(i) * 0.1).collect();
        let mut largest = 0;
        for k in 0..40_000u64 {
            let t = tick_time(k, 1e-3);
            let msg = json!({"k": k, "t_s": t, "q_rad": q, "q_dot_rad_s": q, "q_ddot_rad_s2": q});
            largest = largest.max(serde_json::to_vec(&msg).expect("JSON").len() as u64);
            w.message(1 + (k % 4) as u32, "state", &STATE, t, &msg)
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
