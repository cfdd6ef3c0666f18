//! A child's standard error, relayed to the launcher's line by line, keeping the last line: the
//! cause a process gives when it fails (`fdi-control-center: writing …: No space left on
//! device`), so that the launcher's headline can name it instead of a bare exit status.

use std::io::{BufRead, BufReader, Read, Write};
use std::thread::JoinHandle;

/// Longest line kept as a cause, bytes (the relay passes longer lines on whole).
const MAX_CAUSE: usize = 2000;

/// The relay of one child's stderr.
#[derive(Debug)]
pub struct StderrRelay {
    thread: Option<JoinHandle<Option<String>>>,
    last: Option<String>,
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
        let thread = std::thread::Builder::new()
            .name(format!("stderr of {label}"))
            .spawn(move || relay(stderr, prefix.as_deref(), tee.as_ref()))
            .ok();
        Self { thread, last: None }
    }

    /// The child's last non-empty line, once its stderr is closed. Call it only after the child
    /// has exited (it waits for the end of the stream).
    pub fn last_line(&mut self) -> Option<&str> {
        if let Some(t) = self.thread.take() {
            self.last = t.join().ok().flatten();
        }
        self.last.as_deref()
    }

    /// The cause a failed process gave: its last line without the `fdi-<role>: ` (or
    /// `fdi-agent <id>: `) it starts with.
    pub fn cause(&mut self) -> Option<String> {
        let line = self.last_line()?.trim();
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

fn relay(stderr: impl Read, prefix: Option<&str>, tee: Option<&Tee>) -> Option<String> {
    let mut input = BufReader::new(stderr);
    let mut line = Vec::new();
    let mut last = None;
    loop {
        line.clear();
        match input.read_until(b'\n', &mut line) {
            Ok(0) | Err(_) => return last,
            Ok(_) => {
                // Ours may be closed or full: a lost line must not stop the child.
                let mut err = std::io::stderr().lock();
                if let Some(p) = prefix {
                    let _ = write!(err, "{p}: ");
                }
                let _ = err.write_all(&line);
                if !line.ends_with(b"\n") {
                    let _ = err.write_all(b"\n");
                }
                drop(err);
                let text = String::from_utf8_lossy(&line);
                let text = text.trim_end();
                if let Some(tee) = tee {
                    match prefix {
                        Some(p) => tee(&format!("{p}: {text}")),
                        None => tee(text),
                    }
                }
                if !text.trim().is_empty() {
                    let mut end = text.len().min(MAX_CAUSE);
                    while !text.is_char_boundary(end) {
                        end -= 1;
                    }
                    last = Some(text[..end].to_string());
                }
            }
        }
    }
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
        let mut relay = StderrRelay::start(child.stderr.take().expect("pipe"), "sh");
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
}
