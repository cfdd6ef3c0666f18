//! A child's standard error, relayed to the launcher's line by line, keeping the last line: the
//! cause a process gives when it fails (`fdi-control-center: writing …: No space left on
//! device`), so that the launcher's headline can name it instead of a bare exit status.
//!
//! A relayed line is at most [`MAX_LINE`] bytes (the rest of a longer one is read and dropped,
//! and the line says it was cut), so that what a child prints never grows the launcher's
//! memory. The end of the stream is awaited for a bounded time only: a process that left the
//! child's process group may keep it open for as long as it lives.

use std::io::{BufRead, BufReader, Read, Write};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// Longest line kept as a cause, bytes (the relay passes longer lines on, up to [`MAX_LINE`]).
const MAX_CAUSE: usize = 2000;

/// Longest line relayed, bytes: the rest of a longer line is dropped and the line ends with
/// `… (line cut at 65536 bytes)`. docs/protocol.md states it.
pub const MAX_LINE: usize = 64 * 1024;

/// How long the cause of a failed child waits for the end of its stream (its last line may be
/// on its way) before it is taken from what was relayed so far.
const CAUSE_WAIT: Duration = Duration::from_secs(1);

/// What the relay thread shares with its owner.
#[derive(Debug, Default)]
struct Progress {
    /// The last non-empty line so far, at most [`MAX_CAUSE`] bytes.
    last: Option<String>,
    /// The stream ended (or could not be read at all).
    ended: bool,
}

/// The relay of one child's stderr.
#[derive(Debug)]
pub struct StderrRelay {
    state: Arc<(Mutex<Progress>, Condvar)>,
}

impl StderrRelay {
    /// Starts relaying `stderr` (the read end of a child's stderr pipe) to this process's.
    #[cfg(test)]
    pub fn start(stderr: impl Read + Send + 'static, label: &str) -> Self {
        Self::start_prefixed(stderr, label, None)
    }

    /// [`Self::start`] for a program outside the project (`[roles]`): each line it prints is
    /// relayed after `prefix: ` (its own lines do not say who printed them).
    pub fn start_prefixed(
        stderr: impl Read + Send + 'static,
        label: &str,
        prefix: Option<String>,
    ) -> Self {
        Self::start_teed(stderr, label, prefix, None)
    }

    /// [`Self::start_prefixed`], each line also handed to `tee` (`fdi-launch serve` sends
    /// them to the coordinating host).
    pub fn start_teed(
        stderr: impl Read + Send + 'static,
        label: &str,
        prefix: Option<String>,
        tee: Option<Tee>,
    ) -> Self {
        let state = Arc::new((Mutex::new(Progress::default()), Condvar::new()));
        let shared = Arc::clone(&state);
        let spawned = std::thread::Builder::new()
            .name(format!("stderr of {label}"))
            .spawn(move || {
                let mut out = std::io::stderr();
                relay(
                    BufReader::new(stderr),
                    &mut out,
                    prefix.as_deref(),
                    tee.as_ref(),
                    &shared.0,
                );
                lock(&shared.0).ended = true;
                shared.1.notify_all();
            });
        if spawned.is_err() {
            // Nothing will be relayed: nothing to wait for.
            lock(&state.0).ended = true;
        }
        Self { state }
    }

    /// Waits at most `limit` for the end of the stream; returns whether it ended.
    pub fn wait_end(&self, limit: Duration) -> bool {
        let (progress, ended) = &*self.state;
        let deadline = Instant::now() + limit;
        let mut p = lock(progress);
        while !p.ended {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            p = ended
                .wait_timeout(p, left)
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
        true
    }

    /// The child's last non-empty line. Call it only after the child has exited: it waits for
    /// the end of the stream, at most [`CAUSE_WAIT`] (a process the child left behind may hold
    /// the stream open), then takes the last line relayed so far.
    pub fn last_line(&self) -> Option<String> {
        self.wait_end(CAUSE_WAIT);
        lock(&self.state.0).last.clone()
    }

    /// The cause a failed process gave: its last line without the `fdi-<role>: ` (or
    /// `fdi-agent <id>: `) it starts with.
    pub fn cause(&self) -> Option<String> {
        let line = self.last_line()?;
        let line = line.trim();
        let named = |program: &str| {
            let mut words = program.split(' ');
            words.next().is_some_and(|w| w.starts_with("fdi-"))
                && words.all(|w| !w.is_empty() && w.bytes().all(|b| b.is_ascii_digit()))
        };
        let cause = match line.split_once(": ") {
            Some((program, rest)) if named(program) => rest,
            _ => line,
        };
        (!cause.is_empty()).then(|| cause.to_string())
    }
}

/// Where a relay also hands each line it relays.
pub type Tee = std::sync::Arc<dyn Fn(&str) + Send + Sync>;

/// Reads one line of `input` without its newline into `line`, keeping at most `cap` bytes of
/// it and reading past the rest. Returns the bytes the line had in all, its newline left out,
/// or `None` at the end of the stream; more than `line.len()` when it was cut.
fn read_line_capped(
    input: &mut impl BufRead,
    line: &mut Vec<u8>,
    cap: usize,
) -> std::io::Result<Option<usize>> {
    line.clear();
    let mut total = 0;
    let mut any = false;
    loop {
        let buf = match input.fill_buf() {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if buf.is_empty() {
            return Ok(any.then_some(total));
        }
        any = true;
        let newline = buf.iter().position(|&b| b == b'\n');
        let content = &buf[..newline.unwrap_or(buf.len())];
        let room = cap.saturating_sub(line.len());
        line.extend_from_slice(&content[..content.len().min(room)]);
        total += content.len();
        let used = content.len() + usize::from(newline.is_some());
        input.consume(used);
        if newline.is_some() {
            return Ok(Some(total));
        }
    }
}

/// Where to cut `line` to keep at most `cap` bytes: `cap`, moved back to the start of a UTF-8
/// sequence when it falls inside one (a cut line stays valid UTF-8 when it was).
fn cut_point(line: &[u8], cap: usize) -> usize {
    let mut end = cap.min(line.len());
    let back = end.saturating_sub(3);
    while end > back && line.get(end).is_some_and(|b| b & 0xC0 == 0x80) {
        end -= 1;
    }
    end
}

/// Relays `input` line by line to `out` (each line after `prefix: `, at most [`MAX_LINE`]
/// bytes), hands each to `tee`, and keeps the last non-empty one in `progress`.
fn relay(
    mut input: impl BufRead,
    out: &mut impl Write,
    prefix: Option<&str>,
    tee: Option<&Tee>,
    progress: &Mutex<Progress>,
) {
    let mut line = Vec::new();
    let mut whole = Vec::new();
    // One byte more than the cap is kept: it tells whether the cap cuts a UTF-8 sequence.
    while let Ok(Some(total)) = read_line_capped(&mut input, &mut line, MAX_LINE + 1) {
        let note = if total > MAX_LINE {
            line.truncate(cut_point(&line, MAX_LINE));
            format!(" … (line cut at {MAX_LINE} bytes)")
        } else {
            String::new()
        };
        // One write: the lines of several children do not interleave. Ours may be closed or
        // full: a lost line must not stop the child.
        whole.clear();
        if let Some(p) = prefix {
            whole.extend_from_slice(p.as_bytes());
            whole.extend_from_slice(b": ");
        }
        whole.extend_from_slice(&line);
        whole.extend_from_slice(note.as_bytes());
        whole.push(b'\n');
        let _ = out.write_all(&whole);
        let text = String::from_utf8_lossy(&line);
        let text = text.trim_end();
        if let Some(tee) = tee {
            match prefix {
                Some(p) => tee(&format!("{p}: {text}{note}")),
                None => tee(&format!("{text}{note}")),
            }
        }
        if !text.trim().is_empty() {
            let mut end = text.len().min(MAX_CAUSE);
            while !text.is_char_boundary(end) {
                end -= 1;
            }
            lock(progress).last = Some(text[..end].to_string());
        }
    }
}

/// The state behind a lock, even if a thread panicked while holding it (the state is plain
/// data, consistent at every step).
pub fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::process::{Command, Stdio};

    /// The cause a relay reports for a child running `script` under `sh`, which fails.
    fn cause_of(script: &str) -> Option<String> {
        let mut child = Command::new("sh")
            .args(["-c", script])
            .stderr(Stdio::piped())
            .spawn()
            .expect("sh");
        let relay = StderrRelay::start(child.stderr.take().expect("pipe"), "sh");
        assert!(!child.wait().expect("wait").success());
        relay.cause()
    }

    #[test]
    fn a_failed_child_is_named_with_the_cause_it_printed_last() {
        assert_eq!(
            cause_of(
                "echo 'fdi-control-center: a warning first' >&2; \
                 echo 'fdi-control-center: writing runs/x/traces/control-center.trace: No space left on device (os error 28)' >&2; \
                 exit 1"
            )
            .as_deref(),
            Some(
                "writing runs/x/traces/control-center.trace: No space left on device (os error 28)"
            )
        );
    }

    #[test]
    fn an_agent_is_named_with_the_cause_without_its_program_name_and_id() {
        assert_eq!(
            cause_of(
                "echo 'fdi-agent 3: writing a.trace: No space left on device (os error 28)' >&2; exit 1"
            )
            .as_deref(),
            Some("writing a.trace: No space left on device (os error 28)")
        );
    }

    #[test]
    fn a_child_that_printed_nothing_gives_no_cause() {
        assert_eq!(cause_of("exit 1"), None);
    }

    /// What [`relay`] writes for `input` after `p: `, and the last line it kept.
    fn relayed(input: impl Read) -> (Vec<u8>, Option<String>) {
        let mut out = Vec::new();
        let progress = Mutex::new(Progress::default());
        relay(
            BufReader::with_capacity(MAX_LINE, input),
            &mut out,
            Some("p"),
            None,
            &progress,
        );
        let last = progress
            .into_inner()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .last;
        (out, last)
    }

    /// Regression (issue 29): one 200 MB line without a newline on an external program's
    /// stdout was held whole (the launcher's RSS rose to 218 MB). It is relayed cut at the cap,
    /// saying so, and what follows it is relayed as before.
    #[test]
    fn a_200_mb_line_is_cut_at_the_cap() {
        let huge = std::io::repeat(b'x').take(200 << 20);
        let (out, last) = relayed(huge.chain(&b"\nthe next line\n"[..]));
        let note = format!(" … (line cut at {MAX_LINE} bytes)\n");
        let first = format!("p: {}{note}", "x".repeat(MAX_LINE));
        assert_eq!(out.len(), first.len() + "p: the next line\n".len());
        assert!(
            out.starts_with(first.as_bytes()),
            "the first line is cut and says so"
        );
        assert!(out.ends_with(b"p: the next line\n"));
        assert_eq!(last.as_deref(), Some("the next line"));

        // The same line at the end of the stream, without a newline: cut too.
        let (out, last) = relayed(std::io::repeat(b'y').take(200 << 20));
        assert_eq!(
            out.len(),
            format!("p: {}{note}", "y".repeat(MAX_LINE)).len()
        );
        assert!(out.ends_with(note.as_bytes()));
        let last = last.expect("a last line");
        assert!(last.len() <= MAX_CAUSE && last.bytes().all(|b| b == b'y'));
    }

    #[test]
    fn a_line_of_exactly_the_cap_is_whole_and_a_cut_keeps_utf8() {
        let line = "z".repeat(MAX_LINE) + "\n";
        let (out, _) = relayed(line.as_bytes());
        assert_eq!(out, format!("p: {line}").into_bytes());

        // 'é' is two bytes: the cap falls inside the last one, which is left out whole.
        let line = "a".repeat(MAX_LINE - 1) + "éé\n";
        let (out, _) = relayed(line.as_bytes());
        let text = String::from_utf8(out).expect("valid UTF-8");
        assert_eq!(
            text,
            format!(
                "p: {} … (line cut at {MAX_LINE} bytes)\n",
                "a".repeat(MAX_LINE - 1)
            )
        );
    }

    #[test]
    fn empty_lines_and_a_last_line_without_newline_are_relayed() {
        let (out, last) = relayed(&b"one\n\nlast"[..]);
        assert_eq!(out, b"p: one\np: \np: last\n");
        assert_eq!(last.as_deref(), Some("last"));
    }

    /// A process left holding the stream open does not hold the cause back: it is taken
    /// from what was relayed once the wait is over.
    #[test]
    fn the_end_of_a_stream_held_open_is_awaited_for_a_bounded_time() {
        let (reader, mut writer) = std::io::pipe().expect("pipe");
        let relay = StderrRelay::start(reader, "held");
        writer
            .write_all(b"fdi-agent 1: the cause\n")
            .expect("write");
        assert!(!relay.wait_end(Duration::from_millis(100)));
        assert_eq!(relay.cause().as_deref(), Some("the cause"));
        drop(writer);
        assert!(relay.wait_end(Duration::from_secs(30)));
    }
}
