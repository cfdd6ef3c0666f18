//! Binary traces: the one place bincode is used.
//!
//! File layout: the 8-byte magic `FDITRACE`, a little-endian `u32` format version, then frames.
//! Each frame is a little-endian `u32` length followed by that many bytes of bincode (2.x,
//! standard configuration, serde). The first frame is the [`TraceHeader`] (process, scenario
//! text, seed); every later frame is one [`TraceRecord`]. Writers flush on drop, so a process
//! that ends by a handled signal keeps every record it wrote; a file cut short by a crash reads
//! up to its last whole frame and names the byte offset of the damage.
//!
//! Reading never trusts a length from the file: a frame is at most [`MAX_HEADER_BYTES`] (the
//! header) or [`MAX_RECORD_BYTES`] (a record) long and never longer than what is left of the
//! file, checked before its buffer is sized; bincode decodes it under the same limit, so a
//! corrupt string or sequence length inside a frame is refused before anything is allocated for
//! it. Only regular files are read. Every damage is an error naming the file and the byte offset
//! of the frame, and the records before it stay readable. Writers refuse frames the reader
//! would refuse.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// What a file that is not a regular one is ([`crate::files`], where the input files' reader
/// takes it too).
pub use crate::files::file_kind;
use crate::limits::MAX_FILE_BYTES;
use crate::records::{ActuationRecord, AgentRecord, AttackRecord, CenterRecord, MonitorRecord};

/// First bytes of every trace file.
pub const MAGIC: &[u8; 8] = b"FDITRACE";
/// Format version written by this build; readers refuse any other. Version 4 added
/// [`TraceHeader::kept`].
pub const FORMAT_VERSION: u32 = 4;
/// Largest header frame written or read: the scenario as used (at most
/// [`MAX_FILE_BYTES`]) and a few names.
pub const MAX_HEADER_BYTES: u32 = (MAX_FILE_BYTES as u32) + (1 << 16);
/// Largest record frame written or read (the largest record, an event with its message, is a
/// few hundred bytes).
pub const MAX_RECORD_BYTES: u32 = 1 << 16;

/// First frame of a trace.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TraceHeader {
    pub format_version: u32,
    /// `agent-<id>`, `attacker`, `control-center` or `inproc`.
    pub process: String,
    /// The scenario as used, TOML with the attack inlined.
    pub scenario_toml: String,
    pub seed: u64,
    /// `lockstep` or `realtime`.
    pub clock: String,
    /// What of the process's records the file holds: every one, or those of every K-th tick.
    pub kept: Kept,
}

/// What a trace file keeps of its process's records (`fdi-launch run --traces`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Kept {
    /// Every record.
    #[default]
    Full,
    /// The records of ticks 0, `every`, 2 `every`, … and every event.
    Decimate { every: u32 },
}

impl Kept {
    /// True when a file that keeps `self` holds `record`.
    pub fn keeps(self, record: &TraceRecord) -> bool {
        match (self, record.tick()) {
            (Self::Full, _) | (_, None) => true,
            (Self::Decimate { every }, Some(k)) => k % u64::from(every.max(1)) == 0,
        }
    }
}

impl std::fmt::Display for Kept {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Full => f.write_str("full"),
            Self::Decimate { every } => write!(f, "decimate={every}"),
        }
    }
}

/// Per-hop monotonic-clock stamps of one message, ns (0 = not stamped).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct HopStamps {
    pub agent_sent_ns: u64,
    pub attacker_received_ns: u64,
    pub attacker_sent_ns: u64,
    pub center_received_ns: u64,
    pub center_sent_ns: u64,
    pub agent_received_ns: u64,
}

/// One frame after the header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum TraceRecord {
    Agent(AgentRecord),
    Attack(AttackRecord),
    Center(CenterRecord),
    /// Latency stamps of the torque that agent `agent` received for tick `k`.
    Latency {
        k: u64,
        agent: u32,
        stamps: HopStamps,
    },
    /// Something the process wants on record (lost peer, rejected message, shutdown reason).
    Event {
        t: f64,
        message: String,
    },
    /// The attacker's record of a torque it relayed (a run that attacks the torque path).
    Actuation(ActuationRecord),
    /// The control center's record of a monitor program's verdict (`[roles.monitor]`).
    Monitor(MonitorRecord),
}

impl TraceRecord {
    /// The tick the record belongs to; `None` for an event.
    pub fn tick(&self) -> Option<u64> {
        match self {
            Self::Agent(a) => Some(a.k),
            Self::Attack(a) => Some(a.k),
            Self::Center(c) => Some(c.k),
            Self::Latency { k, .. } => Some(*k),
            Self::Actuation(a) => Some(a.k),
            Self::Monitor(m) => Some(m.k),
            Self::Event { .. } => None,
        }
    }
}

/// Bytes a trace file spends on `record`: its frame length and its bincode encoding, as
/// [`TraceWriter::write`] writes it.
pub fn record_frame_bytes(record: &TraceRecord) -> Result<u64, bincode::error::EncodeError> {
    let body = bincode::serde::encode_to_vec(record, config())?;
    Ok(4 + body.len() as u64)
}

/// Bytes a trace file spends before its first record: magic, version and the header frame.
pub fn header_bytes(header: &TraceHeader) -> Result<u64, bincode::error::EncodeError> {
    let body = bincode::serde::encode_to_vec(header, config())?;
    Ok(12 + 4 + body.len() as u64)
}

/// What a trace was being used for when an I/O error happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TraceOp {
    Creating,
    Writing,
    Opening,
    Reading,
}

impl std::fmt::Display for TraceOp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Creating => "creating",
            Self::Writing => "writing",
            Self::Opening => "opening",
            Self::Reading => "reading",
        })
    }
}

/// How a trace file is damaged at some byte offset.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Damage {
    #[error("file ends inside the version")]
    EndsInVersion,
    #[error("no header frame")]
    NoHeader,
    #[error("file ends inside a frame length")]
    EndsInLength,
    #[error("frame length {len} exceeds the {limit} byte limit of a {what} frame")]
    TooLong {
        len: u32,
        limit: u32,
        what: &'static str,
    },
    #[error("frame length {len} exceeds the {left} bytes left in the file")]
    BeyondEnd { len: u32, left: u64 },
    #[error("file ends inside a frame ({got} of {len} bytes)")]
    EndsInFrame { got: usize, len: u32 },
    #[error("frame has {0} trailing bytes")]
    Trailing(usize),
    #[error("header says format version {found}, the file {file}")]
    HeaderVersion { found: u32, file: u32 },
}

/// Trace errors name the file and, for damage, the byte offset.
#[derive(Debug, thiserror::Error)]
pub enum TraceError {
    #[error("{op} {}: {cause}", path.display())]
    Io {
        op: TraceOp,
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("{}: not a regular file ({kind}); a trace must be a regular file", path.display())]
    NotAFile { path: PathBuf, kind: &'static str },
    #[error("{}: not an fdi-mas trace (no `FDITRACE` at byte offset 0)", path.display())]
    BadMagic { path: PathBuf },
    #[error("{}: trace format version {found} (byte offset 8) is not supported (this build reads version {FORMAT_VERSION})", path.display())]
    UnknownVersion { path: PathBuf, found: u32 },
    #[error("{}: damaged frame at byte offset {offset}: {damage}", path.display())]
    Damaged {
        path: PathBuf,
        offset: u64,
        damage: Damage,
    },
    #[error("{}: damaged frame at byte offset {offset}: cannot decode frame: {}", path.display(), describe_decode(cause))]
    Decode {
        path: PathBuf,
        offset: u64,
        cause: bincode::error::DecodeError,
    },
    #[error("{}: cannot encode record: {cause}", path.display())]
    Encode {
        path: PathBuf,
        cause: bincode::error::EncodeError,
    },
    #[error("{}: a {what} frame of {len} bytes is over the {limit} byte limit readers accept", path.display())]
    FrameTooLarge {
        path: PathBuf,
        what: &'static str,
        len: usize,
        limit: u32,
    },
}

impl TraceError {
    /// The byte offset of the damage, for a damaged file.
    pub fn offset(&self) -> Option<u64> {
        match self {
            Self::Damaged { offset, .. } | Self::Decode { offset, .. } => Some(*offset),
            Self::BadMagic { .. } => Some(0),
            Self::UnknownVersion { .. } => Some(8),
            _ => None,
        }
    }

    /// The file concerned.
    pub fn path(&self) -> &Path {
        match self {
            Self::Io { path, .. }
            | Self::NotAFile { path, .. }
            | Self::BadMagic { path }
            | Self::UnknownVersion { path, .. }
            | Self::Damaged { path, .. }
            | Self::Decode { path, .. }
            | Self::Encode { path, .. }
            | Self::FrameTooLarge { path, .. } => path,
        }
    }
}

/// Words for the decode errors a damaged frame gives.
fn describe_decode(e: &bincode::error::DecodeError) -> String {
    use bincode::error::DecodeError as D;
    match e {
        D::LimitExceeded => "a length inside it claims more than a frame may hold".into(),
        D::UnexpectedEnd { additional } => {
            format!("it ends {additional} bytes before its content does")
        }
        other => other.to_string(),
    }
}

/// Which frame is read or written: the header or a record, with its size limit.
#[derive(Debug, Clone, Copy)]
enum FrameKind {
    Header,
    Record,
}

impl FrameKind {
    fn limit(self) -> u32 {
        match self {
            Self::Header => MAX_HEADER_BYTES,
            Self::Record => MAX_RECORD_BYTES,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Self::Header => "header",
            Self::Record => "record",
        }
    }
}

fn config() -> bincode::config::Configuration {
    bincode::config::standard()
}

/// Decoding under a limit: a length inside a frame that claims more than the frame could hold
/// is refused before bincode allocates for it. bincode counts what it decodes by in-memory size
/// (a one-byte varint length counts 8 bytes, an `f64` 8), so an undamaged frame of `n` bytes
/// counts at most `8 n`; the limit is the smallest of a few sizes that is not below that, and
/// what a corrupt length can make bincode allocate stays within 16 times that bound (at most
/// 16 MiB, for the largest header).
fn decode<T: serde::de::DeserializeOwned>(
    bytes: &[u8],
) -> Result<(T, usize), bincode::error::DecodeError> {
    const SMALL: usize = 1 << 12;
    const MEDIUM: usize = 1 << 16;
    const LARGE: usize = 1 << 20;
    const HUGE: usize = 1 << 24;
    const _: () = assert!(8 * (MAX_HEADER_BYTES as usize) <= HUGE);
    let c = config();
    match bytes.len().saturating_mul(8) {
        n if n <= SMALL => bincode::serde::decode_from_slice(bytes, c.with_limit::<SMALL>()),
        n if n <= MEDIUM => bincode::serde::decode_from_slice(bytes, c.with_limit::<MEDIUM>()),
        n if n <= LARGE => bincode::serde::decode_from_slice(bytes, c.with_limit::<LARGE>()),
        _ => bincode::serde::decode_from_slice(bytes, c.with_limit::<HUGE>()),
    }
}

/// Longest time a written record may sit in the writer's buffer: a process killed outright
/// (SIGKILL, no chance to flush) loses at most this much of its trace.
pub const FLUSH_INTERVAL: std::time::Duration = std::time::Duration::from_millis(100);

/// Appends frames to a trace file.
#[derive(Debug)]
pub struct TraceWriter {
    path: PathBuf,
    /// `None`: a writer that keeps nothing ([`TraceWriter::discarding`]).
    out: Option<BufWriter<File>>,
    buf: Vec<u8>,
    last_flush: std::time::Instant,
}

impl TraceWriter {
    /// Creates (truncates) `path` and writes the magic, version and header.
    pub fn create(path: &Path, header: &TraceHeader) -> Result<Self, TraceError> {
        let file = File::create(path).map_err(|cause| TraceError::Io {
            op: TraceOp::Creating,
            path: path.to_path_buf(),
            cause,
        })?;
        let mut w = Self {
            path: path.to_path_buf(),
            out: Some(BufWriter::with_capacity(1 << 16, file)),
            buf: Vec::with_capacity(512),
            last_flush: std::time::Instant::now(),
        };
        let mut start = MAGIC.to_vec();
        start.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        w.write_out(&start)?;
        w.frame(header, FrameKind::Header)?;
        Ok(w)
    }

    /// A writer that encodes and checks its records as any other but keeps none: for a process
    /// that writes no trace (the replayer, whose `--trace` is the recording it reads).
    pub fn discarding() -> Self {
        Self {
            path: PathBuf::new(),
            out: None,
            buf: Vec::new(),
            last_flush: std::time::Instant::now(),
        }
    }

    fn write_out(&mut self, bytes: &[u8]) -> Result<(), TraceError> {
        match self.out.as_mut().map(|out| out.write_all(bytes)) {
            Some(Err(e)) => Err(self.io(e)),
            Some(Ok(())) | None => Ok(()),
        }
    }

    fn io(&self, cause: std::io::Error) -> TraceError {
        TraceError::Io {
            op: TraceOp::Writing,
            path: self.path.clone(),
            cause,
        }
    }

    fn frame<T: Serialize>(&mut self, value: &T, kind: FrameKind) -> Result<(), TraceError> {
        self.buf.clear();
        bincode::serde::encode_into_std_write(value, &mut self.buf, config()).map_err(|cause| {
            TraceError::Encode {
                path: self.path.clone(),
                cause,
            }
        })?;
        let len = match u32::try_from(self.buf.len()) {
            Ok(len) if len <= kind.limit() => len,
            _ => {
                return Err(TraceError::FrameTooLarge {
                    path: self.path.clone(),
                    what: kind.name(),
                    len: self.buf.len(),
                    limit: kind.limit(),
                })
            }
        };
        self.write_out(&len.to_le_bytes())?;
        let buf = std::mem::take(&mut self.buf);
        let written = self.write_out(&buf);
        self.buf = buf;
        written
    }

    /// Appends a record; flushes when [`FLUSH_INTERVAL`] has passed since the last flush.
    pub fn write(&mut self, record: &TraceRecord) -> Result<(), TraceError> {
        self.frame(record, FrameKind::Record)?;
        if self.last_flush.elapsed() >= FLUSH_INTERVAL {
            self.flush()?;
        }
        Ok(())
    }

    pub fn flush(&mut self) -> Result<(), TraceError> {
        self.last_flush = std::time::Instant::now();
        match self.out.as_mut().map(std::io::Write::flush) {
            Some(Err(e)) => Err(self.io(e)),
            Some(Ok(())) | None => Ok(()),
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for TraceWriter {
    fn drop(&mut self) {
        // Best effort: an explicit `flush` reports errors; a drop on the way out cannot.
        if let Some(out) = self.out.as_mut() {
            let _ = out.flush();
        }
    }
}

/// What a [`TraceReader`] reads from: a file, a pipe, or a file followed as it grows.
struct Input(Box<dyn Read + Send>);

impl Read for Input {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        self.0.read(buf)
    }
}

impl std::fmt::Debug for Input {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Input")
    }
}

/// Reads a trace frame by frame.
#[derive(Debug)]
pub struct TraceReader {
    path: PathBuf,
    input: BufReader<Input>,
    offset: u64,
    /// Byte offset of the frame read last.
    last: u64,
    /// The file's length when it was opened: no frame may reach beyond it.
    file_len: u64,
    header: TraceHeader,
    buf: Vec<u8>,
    done: bool,
}

impl TraceReader {
    /// Opens a trace and reads its header. Refuses anything but a regular file.
    pub fn open(path: &Path) -> Result<Self, TraceError> {
        let io = |op, cause| TraceError::Io {
            op,
            path: path.to_path_buf(),
            cause,
        };
        let file = crate::files::open_to_read(path).map_err(|e| io(TraceOp::Opening, e))?;
        let meta = file.metadata().map_err(|e| io(TraceOp::Opening, e))?;
        if !meta.is_file() {
            return Err(TraceError::NotAFile {
                path: path.to_path_buf(),
                kind: file_kind(meta.file_type()),
            });
        }
        Self::start(Box::new(file), path, meta.len())
    }

    /// Reads a trace as it is written, from the read end of a pipe (`file`) that `path` names:
    /// every read blocks until its writer wrote the frame or closed the pipe (the end of the
    /// trace). Frame lengths are still bounded by the limits of a frame; the file's length is
    /// unknown.
    pub fn from_pipe(file: File, path: &Path) -> Result<Self, TraceError> {
        Self::start(Box::new(file), path, u64::MAX)
    }

    /// Reads the trace `path` names from `input`, a reader that blocks until the next bytes are
    /// written or the trace ended (a file followed as its process writes it), as a pipe is.
    pub fn follow(input: impl Read + Send + 'static, path: &Path) -> Result<Self, TraceError> {
        Self::start(Box::new(input), path, u64::MAX)
    }

    fn start(file: Box<dyn Read + Send>, path: &Path, file_len: u64) -> Result<Self, TraceError> {
        let io = |op, cause| TraceError::Io {
            op,
            path: path.to_path_buf(),
            cause,
        };
        let mut input = BufReader::with_capacity(1 << 16, Input(file));
        let mut magic = [0u8; 8];
        if read_full(&mut input, &mut magic).map_err(|e| io(TraceOp::Reading, e))? < 8
            || &magic != MAGIC
        {
            return Err(TraceError::BadMagic {
                path: path.to_path_buf(),
            });
        }
        let mut v = [0u8; 4];
        if read_full(&mut input, &mut v).map_err(|e| io(TraceOp::Reading, e))? < 4 {
            return Err(TraceError::Damaged {
                path: path.to_path_buf(),
                offset: 8,
                damage: Damage::EndsInVersion,
            });
        }
        let found = u32::from_le_bytes(v);
        if found != FORMAT_VERSION {
            return Err(TraceError::UnknownVersion {
                path: path.to_path_buf(),
                found,
            });
        }
        let mut r = Self {
            path: path.to_path_buf(),
            input,
            offset: 12,
            last: 12,
            file_len,
            header: TraceHeader {
                format_version: found,
                process: String::new(),
                scenario_toml: String::new(),
                seed: 0,
                clock: String::new(),
                kept: Kept::Full,
            },
            buf: Vec::new(),
            done: false,
        };
        let header = match r.next_frame::<TraceHeader>(FrameKind::Header)? {
            Some(h) => h,
            None => return Err(r.damaged(12, Damage::NoHeader)),
        };
        if header.format_version != found {
            return Err(r.damaged(
                12,
                Damage::HeaderVersion {
                    found: header.format_version,
                    file: found,
                },
            ));
        }
        r.header = header;
        Ok(r)
    }

    pub fn header(&self) -> &TraceHeader {
        &self.header
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Byte offset of the record returned last (of the header before the first), so that a
    /// record found wrong can be named by where it is.
    pub fn last_offset(&self) -> u64 {
        self.last
    }

    fn damaged(&mut self, offset: u64, damage: Damage) -> TraceError {
        self.done = true;
        TraceError::Damaged {
            path: self.path.clone(),
            offset,
            damage,
        }
    }

    fn next_frame<T: serde::de::DeserializeOwned>(
        &mut self,
        kind: FrameKind,
    ) -> Result<Option<T>, TraceError> {
        let start = self.offset;
        let io = |s: &mut Self, cause| {
            s.done = true;
            TraceError::Io {
                op: TraceOp::Reading,
                path: s.path.clone(),
                cause,
            }
        };
        let mut len = [0u8; 4];
        match read_full(&mut self.input, &mut len) {
            Ok(0) => return Ok(None),
            Ok(4) => {}
            Ok(_) => return Err(self.damaged(start, Damage::EndsInLength)),
            Err(e) => return Err(io(self, e)),
        }
        let len = u32::from_le_bytes(len);
        // Both bounds are checked before the buffer is sized for the frame.
        if len > kind.limit() {
            return Err(self.damaged(
                start,
                Damage::TooLong {
                    len,
                    limit: kind.limit(),
                    what: kind.name(),
                },
            ));
        }
        let left = self.file_len.saturating_sub(start + 4);
        if u64::from(len) > left {
            return Err(self.damaged(start, Damage::BeyondEnd { len, left }));
        }
        self.buf.clear();
        self.buf.resize(len as usize, 0);
        match read_full(&mut self.input, &mut self.buf) {
            Ok(n) if n == len as usize => {}
            // The file shrank since it was opened.
            Ok(got) => return Err(self.damaged(start, Damage::EndsInFrame { got, len })),
            Err(e) => return Err(io(self, e)),
        }
        match decode::<T>(&self.buf) {
            Ok((v, used)) if used == self.buf.len() => {
                self.last = start;
                self.offset = start + 4 + u64::from(len);
                Ok(Some(v))
            }
            Ok((_, used)) => {
                let trailing = self.buf.len() - used;
                Err(self.damaged(start, Damage::Trailing(trailing)))
            }
            Err(cause) => {
                self.done = true;
                Err(TraceError::Decode {
                    path: self.path.clone(),
                    offset: start,
                    cause,
                })
            }
        }
    }
}

fn read_full(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

impl Iterator for TraceReader {
    type Item = Result<TraceRecord, TraceError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match self.next_frame::<TraceRecord>(FrameKind::Record) {
            Ok(Some(r)) => Some(Ok(r)),
            Ok(None) => {
                self.done = true;
                None
            }
            Err(e) => Some(Err(e)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::records::Joints;

    fn tmp(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("fdi-trace-test-{}-{name}", std::process::id()))
    }

    fn header() -> TraceHeader {
        TraceHeader {
            format_version: FORMAT_VERSION,
            process: "attacker".into(),
            scenario_toml: "name = \"x\"".into(),
            seed: 9,
            clock: "lockstep".into(),
            kept: Kept::Decimate { every: 7 },
        }
    }

    fn record(k: u64) -> TraceRecord {
        TraceRecord::Attack(AttackRecord {
            k,
            agent: 1,
            alpha_position: Joints::from_slice(&[0.1, k as f64]),
            alpha_velocity: Joints::from_slice(&[0.0, -1.0]),
            y: Joints::from_slice(&[1.0, 2.0]),
            yd: Joints::from_slice(&[3.0, f64::MIN_POSITIVE]),
            active: k.is_multiple_of(2),
            delivery: Default::default(),
        })
    }

    #[test]
    fn records_round_trip_bit_exactly() {
        let p = tmp("roundtrip");
        {
            let mut w = TraceWriter::create(&p, &header()).expect("create");
            for k in 0..100 {
                w.write(&record(k)).expect("write");
            }
        }
        let r = TraceReader::open(&p).expect("open");
        assert_eq!(r.header(), &header());
        let got: Vec<TraceRecord> = r.map(|x| x.expect("record")).collect();
        assert_eq!(got, (0..100).map(record).collect::<Vec<_>>());
        let _ = std::fs::remove_file(&p);
    }

    #[test]
    fn decimation_keeps_the_records_of_every_kth_tick_and_every_event() {
        let every = Kept::Decimate { every: 5 };
        let kept: Vec<u64> = (0..23).filter(|k| every.keeps(&record(*k))).collect();
        assert_eq!(kept, vec![0, 5, 10, 15, 20]);
        let event = TraceRecord::Event {
            t: 0.3,
            message: "x".into(),
        };
        assert!(every.keeps(&event));
        assert!((0..23).all(|k| Kept::Full.keeps(&record(k))));
        assert_eq!(every.to_string(), "decimate=5");
    }

    #[test]
    fn a_trace_reads_from_a_pipe_as_it_is_written_and_ends_when_the_writer_closes() {
        let (rx, tx) = std::io::pipe().expect("pipe");
        let p = tmp("pipe");
        let writer = std::thread::spawn(move || {
            // A writer of a regular file, its bytes copied into the pipe: the same frames.
            let mut w = TraceWriter::create(&p, &header()).expect("create");
            for k in 0..50 {
                w.write(&record(k)).expect("write");
            }
            w.flush().expect("flush");
            let bytes = std::fs::read(&p).expect("read");
            let _ = std::fs::remove_file(&p);
            let mut tx = tx;
            tx.write_all(&bytes).expect("pipe write");
            // Dropping `tx` closes the pipe: the end of the trace.
        });
        let file = File::from(std::os::fd::OwnedFd::from(rx));
        let r = TraceReader::from_pipe(file, Path::new("agent-1.pipe")).expect("header");
        assert_eq!(r.header(), &header());
        let got: Vec<TraceRecord> = r.map(|x| x.expect("record")).collect();
        assert_eq!(got, (0..50).map(record).collect::<Vec<_>>());
        writer.join().expect("writer");
    }

    #[test]
    fn frame_sizes_are_those_the_writer_writes() {
        let p = tmp("sizes-estimate");
        {
            let mut w = TraceWriter::create(&p, &header()).expect("create");
            for k in 0..10 {
                w.write(&record(k)).expect("write");
            }
        }
        let want = header_bytes(&header()).expect("header")
            + (0..10)
                .map(|k| record_frame_bytes(&record(k)).expect("record"))
                .sum::<u64>();
        assert_eq!(std::fs::metadata(&p).expect("meta").len(), want);
        let _ = std::fs::remove_file(&p);
    }

    #[test]
    fn truncated_file_reads_up_to_the_damage_and_names_the_offset() {
        let p = tmp("truncated");
        {
            let mut w = TraceWriter::create(&p, &header()).expect("create");
            for k in 0..10 {
                w.write(&record(k)).expect("write");
            }
        }
        let full = std::fs::read(&p).expect("read");
        std::fs::write(&p, &full[..full.len() - 3]).expect("truncate");
        let mut ok = 0;
        let mut err = None;
        for r in TraceReader::open(&p).expect("open") {
            match r {
                Ok(_) => ok += 1,
                Err(e) => err = Some(e.to_string()),
            }
        }
        assert_eq!(ok, 9);
        let err = err.expect("an error for the cut frame");
        assert!(
            err.contains("byte offset") && err.contains(&p.display().to_string()),
            "{err}"
        );
        let _ = std::fs::remove_file(&p);
    }

    #[test]
    fn unknown_version_and_bad_magic_are_refused() {
        let p = tmp("version");
        drop(TraceWriter::create(&p, &header()).expect("create"));
        let mut bytes = std::fs::read(&p).expect("read");
        bytes[8..12].copy_from_slice(&99u32.to_le_bytes());
        std::fs::write(&p, &bytes).expect("write");
        let e = TraceReader::open(&p).expect_err("version 99");
        assert!(e.to_string().contains("version 99"), "{e}");
        std::fs::write(&p, b"not a trace at all").expect("write");
        assert!(matches!(
            TraceReader::open(&p),
            Err(TraceError::BadMagic { .. })
        ));
        let _ = std::fs::remove_file(&p);
    }

    /// Every record of `p` that reads, and the error that ends the reading (if any).
    fn read_all(p: &Path) -> (usize, Option<TraceError>) {
        let mut ok = 0;
        let r = match TraceReader::open(p) {
            Ok(r) => r,
            Err(e) => return (0, Some(e)),
        };
        for rec in r {
            match rec {
                Ok(_) => ok += 1,
                Err(e) => return (ok, Some(e)),
            }
        }
        (ok, None)
    }

    #[test]
    fn a_corrupt_string_length_in_the_header_is_an_error_naming_the_offset_not_an_allocation() {
        let p = tmp("header-len");
        {
            let mut w = TraceWriter::create(&p, &header()).expect("create");
            w.write(&record(0)).expect("write");
        }
        let good = std::fs::read(&p).expect("read");
        // Offset 17: the varint length of `process`. 0xfd says "a u64 follows": the next eight
        // bytes (the name itself) become a length of about 8e18 bytes; 0xfc a u32 length.
        for marker in [0xfd_u8, 0xfc, 0xfb] {
            let mut bytes = good.clone();
            bytes[17] = marker;
            std::fs::write(&p, &bytes).expect("write");
            let e = TraceReader::open(&p).expect_err("damaged header");
            assert_eq!(e.offset(), Some(12), "{e}");
            assert!(e.to_string().contains(&p.display().to_string()), "{e}");
        }
        let _ = std::fs::remove_file(&p);
    }

    #[test]
    fn a_corrupt_frame_length_is_refused_before_its_buffer_is_sized_and_earlier_records_read() {
        let p = tmp("frame-len");
        let mut ends = Vec::new();
        {
            let mut w = TraceWriter::create(&p, &header()).expect("create");
            for k in 0..5 {
                w.flush().expect("flush");
                ends.push(std::fs::metadata(&p).expect("meta").len());
                w.write(&record(k)).expect("write");
            }
        }
        let good = std::fs::read(&p).expect("read");
        // The length of record 3, within the per-frame limit but beyond the end of the file,
        // then over the limit.
        let at = ends[3] as usize;
        for len in [40_000_u32, u32::MAX] {
            let mut bytes = good.clone();
            bytes[at..at + 4].copy_from_slice(&len.to_le_bytes());
            std::fs::write(&p, &bytes).expect("write");
            let (ok, e) = read_all(&p);
            let e = e.expect("an error");
            assert_eq!(ok, 3, "{e}");
            assert_eq!(e.offset(), Some(ends[3]), "{e}");
            assert!(
                matches!(
                    e,
                    TraceError::Damaged {
                        damage: Damage::BeyondEnd { .. } | Damage::TooLong { .. },
                        ..
                    }
                ),
                "{e}"
            );
        }
        let _ = std::fs::remove_file(&p);
    }

    #[test]
    fn special_files_are_refused_as_traces_without_reading_them() {
        let e = TraceReader::open(Path::new("/dev/zero")).expect_err("a device");
        assert!(
            matches!(e, TraceError::NotAFile { .. }) && e.to_string().contains("/dev/zero"),
            "{e}"
        );
        let e = TraceReader::open(&std::env::temp_dir()).expect_err("a directory");
        assert!(matches!(e, TraceError::NotAFile { .. }), "{e}");
    }

    #[test]
    fn a_full_disk_is_reported_as_no_space_writing_the_trace() {
        // /dev/full fails every write with ENOSPC, like a full file system.
        let p = Path::new("/dev/full");
        if !p.exists() {
            eprintln!("skipped: no /dev/full on this system");
            return;
        }
        let mut w = TraceWriter::create(p, &header()).expect("opening /dev/full succeeds");
        let e = w.flush().expect_err("ENOSPC");
        match &e {
            TraceError::Io {
                op: TraceOp::Writing,
                cause,
                ..
            } => assert_eq!(cause.kind(), std::io::ErrorKind::StorageFull, "{e}"),
            other => panic!("not a write error: {other}"),
        }
        let text = e.to_string();
        assert!(
            text.starts_with("writing /dev/full: ") && text.contains("No space left on device"),
            "{text}"
        );
    }

    #[test]
    fn frames_over_the_readers_limit_are_refused_by_the_writer() {
        let p = tmp("too-large");
        let mut w = TraceWriter::create(&p, &header()).expect("create");
        let e = w
            .write(&TraceRecord::Event {
                t: 0.0,
                message: "x".repeat(MAX_RECORD_BYTES as usize),
            })
            .expect_err("over the limit");
        assert!(matches!(e, TraceError::FrameTooLarge { .. }), "{e}");
        let mut big = header();
        big.scenario_toml = "#".repeat(MAX_HEADER_BYTES as usize);
        assert!(matches!(
            TraceWriter::create(&p, &big),
            Err(TraceError::FrameTooLarge { .. })
        ));
        let _ = std::fs::remove_file(&p);
    }

    #[test]
    fn headers_and_records_of_every_size_round_trip_under_the_decode_limit() {
        // A 4095-byte header (the corrupt-values scenario's) used to be refused: bincode counts
        // a varint length as 8 bytes against the limit, so a frame needs more than its length.
        let p = tmp("sizes");
        let mut sizes: Vec<usize> = vec![0, 1, 100, 4000, 4095, 4096, 8192, 65_536, 131_072];
        sizes.push(MAX_FILE_BYTES as usize);
        for n in sizes {
            let mut h = header();
            h.scenario_toml = "x".repeat(n);
            let message = "m".repeat(n.min(MAX_RECORD_BYTES as usize - 64));
            {
                let mut w = TraceWriter::create(&p, &h).expect("create");
                w.write(&TraceRecord::Event {
                    t: 1.0,
                    message: message.clone(),
                })
                .expect("write");
                w.write(&record(3)).expect("write");
            }
            let r = TraceReader::open(&p).unwrap_or_else(|e| panic!("{n}: {e}"));
            assert_eq!(r.header(), &h);
            let got: Vec<TraceRecord> = r.map(|x| x.expect("record")).collect();
            assert_eq!(
                got,
                vec![TraceRecord::Event { t: 1.0, message }, record(3)],
                "{n}"
            );
        }
        let _ = std::fs::remove_file(&p);
    }
}
