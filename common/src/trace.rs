//! Binary traces: the one place bincode is used.
//!
//! File layout: the 8-byte magic `FDITRACE`, a little-endian `u32` format version, then frames.
//! Each frame is a little-endian `u32` length followed by that many bytes of bincode (2.x,
//! standard configuration, serde). The first frame is the [`TraceHeader`] (process, scenario
//! text, seed); every later frame is one [`TraceRecord`]. Writers flush on drop, so a process
//! that ends by a handled signal keeps every record it wrote; a file cut short by a crash reads
//! up to its last whole frame and names the byte offset of the damage.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::records::{AgentRecord, AttackRecord, CenterRecord};

/// First bytes of every trace file.
pub const MAGIC: &[u8; 8] = b"FDITRACE";
/// Format version written by this build; readers refuse any other.
pub const FORMAT_VERSION: u32 = 2;
/// Largest frame accepted when reading (guards against a corrupt length).
pub const MAX_FRAME_BYTES: u32 = 1 << 26;

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
}

/// Trace errors name the file and, for damage, the byte offset.
#[derive(Debug, thiserror::Error)]
pub enum TraceError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: not an fdi-mas trace (bad magic)")]
    BadMagic { path: PathBuf },
    #[error("{path}: trace format version {found} is not supported (this build reads version {FORMAT_VERSION})")]
    UnknownVersion { path: PathBuf, found: u32 },
    #[error("{path}: damaged frame at byte offset {offset}: {reason}")]
    Damaged {
        path: PathBuf,
        offset: u64,
        reason: String,
    },
    #[error("{path}: cannot encode record: {reason}")]
    Encode { path: PathBuf, reason: String },
}

fn config() -> bincode::config::Configuration {
    bincode::config::standard()
}

/// Longest time a written record may sit in the writer's buffer: a process killed outright
/// (SIGKILL, no chance to flush) loses at most this much of its trace.
pub const FLUSH_INTERVAL: std::time::Duration = std::time::Duration::from_millis(100);

/// Appends frames to a trace file.
#[derive(Debug)]
pub struct TraceWriter {
    path: PathBuf,
    out: BufWriter<File>,
    buf: Vec<u8>,
    last_flush: std::time::Instant,
}

impl TraceWriter {
    /// Creates (truncates) `path` and writes the magic, version and header.
    pub fn create(path: &Path, header: &TraceHeader) -> Result<Self, TraceError> {
        let io = |source| TraceError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = File::create(path).map_err(io)?;
        let mut w = Self {
            path: path.to_path_buf(),
            out: BufWriter::with_capacity(1 << 16, file),
            buf: Vec::with_capacity(512),
            last_flush: std::time::Instant::now(),
        };
        w.out.write_all(MAGIC).map_err(io)?;
        w.out.write_all(&FORMAT_VERSION.to_le_bytes()).map_err(io)?;
        w.frame(header)?;
        Ok(w)
    }

    fn frame<T: Serialize>(&mut self, value: &T) -> Result<(), TraceError> {
        self.buf.clear();
        bincode::serde::encode_into_std_write(value, &mut self.buf, config()).map_err(|e| {
            TraceError::Encode {
                path: self.path.clone(),
                reason: e.to_string(),
            }
        })?;
        let len = u32::try_from(self.buf.len()).map_err(|_| TraceError::Encode {
            path: self.path.clone(),
            reason: "frame over 4 GiB".into(),
        })?;
        let io = |source| TraceError::Io {
            path: self.path.clone(),
            source,
        };
        self.out.write_all(&len.to_le_bytes()).map_err(io)?;
        self.out
            .write_all(&self.buf)
            .map_err(|source| TraceError::Io {
                path: self.path.clone(),
                source,
            })
    }

    /// Appends a record; flushes when [`FLUSH_INTERVAL`] has passed since the last flush.
    pub fn write(&mut self, record: &TraceRecord) -> Result<(), TraceError> {
        self.frame(record)?;
        if self.last_flush.elapsed() >= FLUSH_INTERVAL {
            self.flush()?;
        }
        Ok(())
    }

    pub fn flush(&mut self) -> Result<(), TraceError> {
        self.last_flush = std::time::Instant::now();
        self.out.flush().map_err(|source| TraceError::Io {
            path: self.path.clone(),
            source,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for TraceWriter {
    fn drop(&mut self) {
        // Best effort: an explicit `flush` reports errors; a drop on the way out cannot.
        let _ = self.out.flush();
    }
}

/// Reads a trace frame by frame.
#[derive(Debug)]
pub struct TraceReader {
    path: PathBuf,
    input: BufReader<File>,
    offset: u64,
    header: TraceHeader,
    buf: Vec<u8>,
    done: bool,
}

impl TraceReader {
    pub fn open(path: &Path) -> Result<Self, TraceError> {
        let io = |source| TraceError::Io {
            path: path.to_path_buf(),
            source,
        };
        let mut input = BufReader::with_capacity(1 << 16, File::open(path).map_err(io)?);
        let mut magic = [0u8; 8];
        if input.read_exact(&mut magic).is_err() || &magic != MAGIC {
            return Err(TraceError::BadMagic {
                path: path.to_path_buf(),
            });
        }
        let mut v = [0u8; 4];
        input.read_exact(&mut v).map_err(|_| TraceError::Damaged {
            path: path.to_path_buf(),
            offset: 8,
            reason: "file ends inside the version".into(),
        })?;
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
            header: TraceHeader {
                format_version: found,
                process: String::new(),
                scenario_toml: String::new(),
                seed: 0,
                clock: String::new(),
            },
            buf: Vec::new(),
            done: false,
        };
        r.header = match r.next_frame::<TraceHeader>()? {
            Some(h) => h,
            None => {
                return Err(TraceError::Damaged {
                    path: path.to_path_buf(),
                    offset: 12,
                    reason: "no header frame".into(),
                })
            }
        };
        Ok(r)
    }

    pub fn header(&self) -> &TraceHeader {
        &self.header
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    fn damaged(&mut self, offset: u64, reason: impl Into<String>) -> TraceError {
        self.done = true;
        TraceError::Damaged {
            path: self.path.clone(),
            offset,
            reason: reason.into(),
        }
    }

    fn next_frame<T: serde::de::DeserializeOwned>(&mut self) -> Result<Option<T>, TraceError> {
        let start = self.offset;
        let mut len = [0u8; 4];
        match read_full(&mut self.input, &mut len) {
            Ok(0) => return Ok(None),
            Ok(4) => {}
            Ok(_) => return Err(self.damaged(start, "file ends inside a frame length")),
            Err(e) => {
                return Err(TraceError::Io {
                    path: self.path.clone(),
                    source: e,
                })
            }
        }
        let len = u32::from_le_bytes(len);
        if len > MAX_FRAME_BYTES {
            return Err(self.damaged(
                start,
                format!("frame length {len} exceeds the {MAX_FRAME_BYTES} byte limit"),
            ));
        }
        self.buf.resize(len as usize, 0);
        match read_full(&mut self.input, &mut self.buf) {
            Ok(n) if n == len as usize => {}
            Ok(n) => {
                return Err(self.damaged(
                    start,
                    format!("file ends inside a frame ({n} of {len} bytes)"),
                ))
            }
            Err(e) => {
                return Err(TraceError::Io {
                    path: self.path.clone(),
                    source: e,
                })
            }
        }
        let decoded = bincode::serde::decode_from_slice::<T, _>(&self.buf, config());
        match decoded {
            Ok((v, used)) if used == self.buf.len() => {
                self.offset = start + 4 + u64::from(len);
                Ok(Some(v))
            }
            Ok((_, used)) => Err(self.damaged(
                start,
                format!("frame has {} trailing bytes", self.buf.len() - used),
            )),
            Err(e) => Err(self.damaged(start, format!("cannot decode frame: {e}"))),
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
        match self.next_frame::<TraceRecord>() {
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
}
