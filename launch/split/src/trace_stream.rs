//! The traces of a split run's remote processes streamed to the coordinator as they grow, for
//! the live view (`run --hosts FILE --live`, docs/multi-host.md): each serve puts its
//! processes' trace bytes in chunks, each with its offset in the trace, on a key of its own
//! (`p/<host>/run/<prefix>/trace/<process>`), at Zenoh's lowest priority (after the run's
//! frames), once the coordinator subscribed to it (a viewer watches); nobody subscribed,
//! nothing is read or sent.
//!
//! Puts, not queries: a query's end is sent by Zenoh on its receiving thread, which with
//! [`fdi_net::ONE_RUNTIME_THREAD`] is also the thread that empties the session's
//! queue. Asked for trace pieces during a run, a serve whose queue the run's frames and the
//! piece filled waited on that thread for room only that thread could make: the session stopped
//! and both ends took the other for gone. A put is queued by the thread that puts.

use std::fs::File;
use std::io::Read;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use fdi_common::run_dir::Process;
use fdi_net::{keys, Net, NetOutbox};
pub use fdi_orchestrator::run::split::{Chunk, Received, Subscribed};

/// The most trace bytes in one chunk: well inside one of Zenoh's batches (64 KiB), so that a
/// chunk never holds the run's frames back for long.
pub const CHUNK: usize = 32 << 10;
/// How often a streamer looks for new bytes once it has sent all there were.
const POLL: Duration = Duration::from_millis(20);
/// How often a streamer asks whether the coordinator subscribed.
const MATCH_POLL: Duration = Duration::from_millis(100);

/// The key the trace of `process` is streamed on by `host` in the run `prefix`.
pub fn key(host: &str, prefix: &str, process: Process) -> String {
    keys::said(host, prefix, &format!("trace/{process}"))
}

/// A chunk as put: its offset (8 bytes, little endian), then its bytes.
fn encode((offset, bytes): (u64, &[u8])) -> Vec<u8> {
    let mut out = Vec::with_capacity(8 + bytes.len());
    out.extend_from_slice(&offset.to_le_bytes());
    out.extend_from_slice(bytes);
    out
}

/// A chunk as received; refused (described) if it is not one.
pub fn decode(payload: &[u8]) -> Result<Chunk, String> {
    let (head, bytes) = payload.split_first_chunk::<8>().ok_or_else(|| {
        format!(
            "a trace chunk of {} bytes, without its offset",
            payload.len()
        )
    })?;
    if bytes.len() > CHUNK {
        return Err(format!(
            "a trace chunk of {} bytes, over {CHUNK}",
            bytes.len()
        ));
    }
    Ok((u64::from_le_bytes(*head), bytes.to_vec()))
}

/// One trace a serve streams.
struct Stream {
    process: Process,
    path: PathBuf,
    outbox: NetOutbox,
    file: Option<File>,
    offset: u64,
    subscribed: bool,
}

impl Stream {
    /// Puts the next chunk, if the trace grew: whether it did.
    fn step(&mut self, buf: &mut [u8]) -> Result<bool> {
        if self.file.is_none() {
            // The process makes its trace once it started.
            self.file = File::open(&self.path).ok();
        }
        let Some(f) = &mut self.file else {
            return Ok(false);
        };
        let n = f
            .read(buf)
            .with_context(|| format!("reading {}", self.path.display()))?;
        if n == 0 {
            return Ok(false);
        }
        self.outbox
            .put(&encode((self.offset, &buf[..n])))
            .with_context(|| format!("sending the trace of {}", self.process))?;
        self.offset += n as u64;
        Ok(true)
    }
}

/// A serve's streams of its share of a run's traces (stopped when dropped).
pub struct Streamer {
    stop: Arc<AtomicBool>,
}

impl Streamer {
    /// Streams the traces `traces` (each process with its trace file) of host `here` in the
    /// run `prefix`, each once the coordinator subscribed to it, on a thread of its own.
    pub fn start(
        net: &Net,
        (here, prefix): (&str, &str),
        traces: &[(Process, PathBuf)],
    ) -> Result<Self> {
        let mut streams = Vec::new();
        for (process, path) in traces {
            streams.push(Stream {
                process: *process,
                path: path.clone(),
                // After the run's frames: a viewer's catch-up never holds them back.
                outbox: net.outbox_background(&key(here, prefix, *process))?,
                file: None,
                offset: 0,
                subscribed: false,
            });
        }
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = stop.clone();
        std::thread::Builder::new()
            .name("trace stream".into())
            .spawn(move || stream(streams, &stopped))
            .context("starting the thread that streams the traces")?;
        Ok(Self { stop })
    }
}

impl Drop for Streamer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
    }
}

/// Streams `streams` until `stop`: a trace's chunks once it has a subscriber, as far as written.
fn stream(mut streams: Vec<Stream>, stop: &AtomicBool) {
    let mut buf = vec![0u8; CHUNK];
    let mut asked = Instant::now() - MATCH_POLL;
    while !stop.load(Ordering::Acquire) {
        let ask = asked.elapsed() >= MATCH_POLL.saturating_sub(POLL);
        if ask {
            asked = Instant::now();
        }
        let mut grew = false;
        for s in &mut streams {
            if !s.subscribed {
                s.subscribed = ask && s.outbox.matched();
                continue;
            }
            match s.step(&mut buf) {
                Ok(g) => grew |= g,
                Err(e) => {
                    log::info!("the live view's stream stopped: {e:#}");
                    return;
                }
            }
        }
        if !grew {
            // Nobody subscribed: only the next question.
            let idle = streams.iter().all(|s| !s.subscribed);
            std::thread::sleep(if idle { MATCH_POLL } else { POLL });
        }
    }
}

/// Subscribes to the stream of the trace of `process` on host `host` in the run `prefix`, for
/// `readers` readers (one subscription: its host begins to stream once it sees one, so a
/// second, later, could miss the first chunks): the chunks in order to each reader; dropping
/// what it holds (the subscription) ends them.
pub fn subscribe(
    net: &Net,
    (host, prefix): (&str, &str),
    process: Process,
    readers: usize,
) -> Result<Subscribed> {
    let (to, readers): (Vec<_>, Vec<_>) = (0..readers).map(|_| mpsc::channel()).unzip();
    // (On Zenoh's thread: only decoded and handed over.)
    let subscription = net.subscribe(&key(host, prefix, process), move |_, payload| {
        let chunk = decode(&payload);
        for t in &to {
            let _ = t.send(chunk.clone());
        }
    })?;
    Ok(Subscribed {
        readers,
        held: Box::new(subscription),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_chunk_reads_back_and_what_is_not_one_is_refused() {
        let bytes = [1u8, 2, 3];
        assert_eq!(decode(&encode((7, &bytes))), Ok((7, bytes.to_vec())));
        assert_eq!(decode(&encode((0, &[]))), Ok((0, Vec::new())));
        let short = decode(&[1, 2, 3]).expect_err("3 bytes are no chunk");
        assert!(short.contains("without its offset"), "{short}");
        let big = vec![0u8; CHUNK + 1];
        let over = decode(&encode((0, &big))).expect_err("a chunk over the size");
        assert!(over.contains("over"), "{over}");
    }
}
