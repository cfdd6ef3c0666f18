//! Hostile and damaged files through the real `fdi-launch` binary (docs/faults.md, "Hostile
//! and damaged files"): a corrupt length in a trace, devices given as scenario or attack files,
//! a scenario too large once its attack is inlined, a process failing at start, a full disk.
//! The property test over damaged traces is `launch/src/damage_tests.rs`.

use std::fs;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::Duration;

use fdi_tests::{
    json, launch, launch_plain, launch_watching_children, launcher, leftovers_of, run_dir_of,
    wait_with_watchdog, Scratch, Tmpfs,
};

const WATCHDOG: Duration = Duration::from_secs(300);

fn stderr_of(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Files directly in `dir` (none when it does not exist).
fn entries(dir: &Path) -> Vec<std::path::PathBuf> {
    fs::read_dir(dir)
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default()
}

/// Asserts an orderly refusal: exit status 1 (not a panic's 101 or an abort), no panic message,
/// and every fragment in stderr.
fn assert_refused(out: &Output, fragments: &[&str], what: &str) {
    let err = stderr_of(out);
    assert_eq!(out.status.code(), Some(1), "{what}: {}\n{err}", out.status);
    assert!(!err.contains("panicked"), "{what} panicked:\n{err}");
    for f in fragments {
        assert!(err.contains(f), "{what}: stderr lacks `{f}`:\n{err}");
    }
}

#[test]
fn a_corrupt_string_length_in_a_trace_header_is_an_error_naming_file_and_offset_not_a_crash() {
    let dir = Scratch::new("header-flip");
    let v = json(&launch(
        &["run", "--duration-s", "0.05", "--json"],
        &dir.0,
        WATCHDOG,
    ));
    let good = run_dir_of(&v);
    for (n, process) in ["agent-1", "attacker", fdi_common::run_dir::Process::CENTER]
        .iter()
        .enumerate()
    {
        let damaged = dir.0.join(format!("damaged-{n}"));
        fs::create_dir_all(fdi_common::run_dir::RunDir::new(&damaged).traces()).expect("traces/");
        for f in [
            fdi_common::run_dir::RunDir::SCENARIO,
            fdi_common::run_dir::RunDir::SUMMARY,
        ] {
            fs::copy(good.join(f), damaged.join(f)).expect("copy");
        }
        for t in entries(&fdi_common::run_dir::RunDir::new(&good).traces()) {
            fs::copy(
                &t,
                fdi_common::run_dir::RunDir::new(&damaged)
                    .traces()
                    .join(t.file_name().expect("name")),
            )
            .expect("copy");
        }
        // Byte 17 is the varint length of the header's process name: 0xfd says a u64 follows,
        // and the name's bytes make it about 8e18 (this used to panic with `capacity overflow`
        // or abort with `memory allocation of … bytes failed`).
        let trace = fdi_common::run_dir::RunDir::new(&damaged)
            .traces()
            .join(format!("{process}.trace"));
        let mut bytes = fs::read(&trace).expect("read");
        bytes[17] = 0xfd;
        fs::write(&trace, &bytes).expect("write");
        let named = trace.display().to_string();
        let d = damaged.to_string_lossy().into_owned();
        let fragments = [named.as_str(), "byte offset 12"];
        let report = launch_plain(&["report", &d], WATCHDOG);
        assert_refused(&report, &fragments, &format!("report, {process}"));
        let export = launch_plain(&["trace", "export", &d], WATCHDOG);
        assert_refused(&export, &fragments, &format!("trace export, {process}"));
        if *process != fdi_common::run_dir::Process::CENTER {
            // The replay reads the recorded attacker and agent traces (the center is re-run).
            let out = dir.0.join("replays").to_string_lossy().into_owned();
            let replay = launch_plain(&["run", "--replay", &d, "--out", &out], WATCHDOG);
            assert_refused(&replay, &fragments, &format!("run --replay, {process}"));
            assert!(
                entries(&dir.0.join("replays")).is_empty(),
                "a refused replay made a run directory"
            );
        }
    }
}

/// Runs `fdi-launch ARGS` with its address space capped at 4 GiB, so that a regression that
/// reads a device without bound fails here instead of exhausting the machine's memory.
fn launch_capped(args: &[&str]) -> Output {
    let child = Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 4194304 && exec \"$0\" \"$@\"")
        .arg(launcher())
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("sh");
    wait_with_watchdog(child, WATCHDOG)
}

#[test]
fn a_device_as_scenario_or_attack_file_is_refused_without_reading_it() {
    let dir = Scratch::new("device-input");
    let out = dir.0.join("out");
    let o = out.to_string_lossy().into_owned();
    for args in [
        vec!["run", "/dev/zero", "--out", &o],
        vec!["run", "--attack", "/dev/zero", "--out", &o],
        vec!["run", "/dev/stdin", "--out", &o],
    ] {
        let r = launch_capped(&args);
        assert_refused(
            &r,
            &["is not a regular file", "must be regular files of at most"],
            &args.join(" "),
        );
    }
    let v = launch_capped(&["validate", "/dev/zero"]);
    assert_eq!(v.status.code(), Some(2), "{}", stderr_of(&v));
    assert!(stderr_of(&v).contains("/dev/zero is not a regular file (a character device)"));
    assert!(entries(&out).is_empty(), "{:?}", entries(&out));
}

/// Regression (issue 51): a named pipe given as a scenario, attack, deployment or campaign file
/// blocked the launcher in its open (until a writer came) and it ignored SIGINT and SIGTERM
/// meanwhile. Nobody writes to this pipe: each command refuses it at once, naming it.
#[test]
fn a_named_pipe_given_as_a_file_is_refused_at_once_not_waited_on() {
    let dir = Scratch::new("fifo-input");
    let fifo = dir.0.join("scenario.toml");
    let made = Command::new("mkfifo").arg(&fifo).status().expect("mkfifo");
    assert!(made.success(), "mkfifo {}", fifo.display());
    let (f, out) = (
        fifo.to_string_lossy().into_owned(),
        dir.0.join("out").to_string_lossy().into_owned(),
    );
    for args in [
        vec!["run", &f, "--out", &out],
        vec!["run", "--attack", &f, "--out", &out],
        vec!["run", "--hosts", &f, "--out", &out],
        vec!["sweep", &f, "--out", &out],
    ] {
        let r = launch_capped(&args);
        assert_refused(
            &r,
            &[&format!("{f} is not a regular file (a named pipe)")],
            &args.join(" "),
        );
    }
    let v = launch_capped(&["validate", &f]);
    assert_eq!(v.status.code(), Some(2), "{}", stderr_of(&v));
    assert!(stderr_of(&v).contains("is not a regular file (a named pipe)"));
    assert!(entries(&dir.0.join("out")).is_empty());
}

#[test]
fn a_scenario_too_large_once_its_attack_is_inlined_is_refused_before_a_run_directory_exists() {
    // Under the size limit as a file (about 0.75 MB), about 2 MB once written out in full: the
    // processes could not read it back, and used to fail at start after the launcher had made
    // the run directory.
    let dir = Scratch::new("inlined-too-large");
    let mut text = String::from(
        "name = \"many-segments\"\n[[channels]]\nagent = 1\nsignal = \"position\"\nlinks = [1, 2]\nunits = \"rad\"\nsegments = [\n",
    );
    for i in 0..19_000 {
        text.push_str(&format!("{{from_s={i}.0,waveform={{kind=\"none\"}}}},\n"));
    }
    text.push_str("]\n");
    let attack = dir.0.join("many-segments.toml");
    fs::write(&attack, text).expect("write");
    let out = dir.0.join("out");
    let a = attack.to_string_lossy().into_owned();
    let o = out.to_string_lossy().into_owned();
    let w = launch_watching_children(
        &["run", "--attack", &a, "--duration-s", "0.1", "--out", &o],
        WATCHDOG,
    );
    assert_refused(
        &w.output,
        &[
            "the scenario as used (its attack inlined) is",
            "byte limit of scenario files",
        ],
        "inlined too large",
    );
    assert!(entries(&out).is_empty(), "{:?}", entries(&out));
    assert!(w.children.is_empty(), "processes started: {:?}", w.children);
}

/// A copy of `fdi-launch` in `dir` with a fake `fdi-agent` beside it (newer, so the launcher
/// starts it for every agent) that prints `message` to stderr and exits 1.
fn launcher_with_failing_agent(dir: &Path, message: &str) -> std::path::PathBuf {
    let me = dir.join("fdi-launch");
    fs::copy(launcher(), &me).expect("copy fdi-launch");
    let agent = dir.join("fdi-agent");
    fs::write(&agent, format!("#!/bin/sh\necho '{message}' >&2\nexit 1\n")).expect("script");
    let mut perm = fs::metadata(&agent).expect("meta").permissions();
    std::os::unix::fs::PermissionsExt::set_mode(&mut perm, 0o755);
    fs::set_permissions(&agent, perm).expect("chmod");
    me
}

#[test]
fn a_run_whose_process_fails_at_start_removes_its_run_directory_and_names_the_cause() {
    let dir = Scratch::new("fails-at-start");
    let me = launcher_with_failing_agent(&dir.0, "fdi-agent: cannot do what agents do");
    let out = dir.0.join("out");
    let child = Command::new(&me)
        .args(["run", "--duration-s", "0.1", "--out"])
        .arg(&out)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    let pid = child.id();
    let r = wait_with_watchdog(child, WATCHDOG);
    assert_refused(
        &r,
        &[
            "the run did not start",
            "failed: cannot do what agents do (exited with status 1) before the start",
        ],
        "failing agent",
    );
    // It used to leave `scenario.toml` and an empty `traces/` behind.
    assert!(entries(&out).is_empty(), "left behind: {:?}", entries(&out));
    let left = leftovers_of(pid);
    assert!(left.is_empty(), "iceoryx2 files: {left:?}");
}

#[test]
fn a_full_disk_is_the_headline_naming_the_trace_and_the_partial_traces_stay_readable() {
    // Needs a file system that fills up: a small tmpfs (root only). The mechanism is also
    // unit-tested without mounts (trace.rs: /dev/full; relay.rs: the headline).
    let fs_ = match Tmpfs::mount("disk", "400k") {
        Ok(t) => t,
        Err(why) => {
            eprintln!("skipped: cannot mount a tmpfs to fill up (needs root): {why}");
            return;
        }
    };
    let out = fs_.0 .0.join("runs");
    let o = out.to_string_lossy().into_owned();
    // The estimate refuses the run before its start, naming the free space ...
    let refused = launch_plain(&["run", "--duration-s", "2", "--out", &o], WATCHDOG);
    let err = stderr_of(&refused);
    assert_eq!(refused.status.code(), Some(1), "{err}");
    assert!(
        err.contains("refused before the start") && err.contains("free in"),
        "{err}"
    );
    assert!(entries(&out).is_empty(), "left behind: {:?}", entries(&out));
    // ... started anyway, the disk fills.
    let r = launch_plain(
        &["run", "--duration-s", "2", "--out", &o, "--no-space-check"],
        WATCHDOG,
    );
    let err = stderr_of(&r);
    assert_eq!(r.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    // The headline names the cause and the file, not just an exit status.
    let headline = err
        .lines()
        .find(|l| l.starts_with("fdi-launch: error:"))
        .unwrap_or_else(|| panic!("no error line:\n{err}"));
    assert!(
        headline.contains("failed: writing ")
            && headline.contains(".trace: No space left on device"),
        "{headline}"
    );
    let run_dir = entries(&out).pop().expect("the run directory");
    for t in entries(&fdi_common::run_dir::RunDir::new(&run_dir).traces()) {
        // Readable up to the last whole frame; a cut frame is named by its offset.
        let reader = fdi_common::trace::TraceReader::open(&t);
        if let Ok(reader) = reader {
            for rec in reader {
                if let Err(e) = rec {
                    assert!(e.to_string().contains("byte offset"), "{e}");
                }
            }
        }
    }
}

/// Bad command-line values are refused before anything is made, saying what is wrong: a
/// negative duration reaches the scenario's own check (not clap's `-- -5` tip), on `run` and on
/// `table1` (whose runs used to be refused only by their processes, after the run directories
/// were made), and an `--out` naming a file says it is not a folder.
#[test]
fn bad_command_line_values_are_refused_before_anything_is_made() {
    let dir = Scratch::new("cli-values");
    let out = dir.0.join("out");
    let out_s = out.to_string_lossy().into_owned();
    for args in [
        vec!["run", "--duration-s", "-5", "--out", &out_s],
        vec![
            "table1",
            "--engine",
            "inproc",
            "--duration-s",
            "-1",
            "--out",
            &out_s,
        ],
    ] {
        let o = launch_plain(&args, WATCHDOG);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?}");
        assert!(
            err.contains("command-line overrides")
                && err.contains("duration_s: must be finite and > 0, got -"),
            "{args:?}: {err}"
        );
        assert!(!err.contains("tip:"), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?}: nothing is made");
    }
    let file = dir.0.join("a-file");
    std::fs::write(&file, "not a folder").expect("file");
    let file_s = file.to_string_lossy().into_owned();
    let o = launch_plain(
        &[
            "run",
            "--engine",
            "inproc",
            "--duration-s",
            "0.1",
            "--out",
            &file_s,
        ],
        WATCHDOG,
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains(&format!("--out {file_s} is not a folder")),
        "{err}"
    );
}
