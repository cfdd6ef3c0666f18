//! Supervision at the edges of a run (docs/faults.md, "Edges of a run"), through the real
//! binaries: a process that dies or stops before the start, an interrupt before the start and
//! while the report is written (both clocks), a control center that lost every robot, a report
//! that fails, a `summary.json` that cannot be read. None asserts a wall time; signals are sent
//! on an observed state, never after a fixed sleep.

use std::fs;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

use fdi_tests::{
    alive, assert_no_leftovers, children_of, launcher, signal, wait_until, wait_with_watchdog,
    Scratch, Tmpfs,
};

const WATCHDOG: Duration = Duration::from_secs(300);

fn stderr_of(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Files directly in `dir` (none when it does not exist).
fn entries(dir: &Path) -> Vec<PathBuf> {
    fs::read_dir(dir)
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default()
}

/// A copy of `fdi-launch` in `dir` with a fake `fdi-agent` beside it (newer, so the launcher
/// starts it for every agent): agent 2 runs `agent2` (shell), every other agent is the real one
/// (the copy's multi-call mode).
fn launcher_with_agent_2(dir: &Path, agent2: &str) -> PathBuf {
    let me = dir.join("fdi-launch");
    fs::copy(launcher(), &me).expect("copy fdi-launch");
    let agent = dir.join("fdi-agent");
    let script = format!(
        "#!/bin/sh\ncase \" $* \" in\n  *\" --agent 2 \"*) {agent2} ;;\nesac\nexec \"$(dirname \"$0\")/fdi-launch\" process agent \"$@\"\n"
    );
    fs::write(&agent, script).expect("script");
    let mut perm = fs::metadata(&agent).expect("meta").permissions();
    std::os::unix::fs::PermissionsExt::set_mode(&mut perm, 0o755);
    fs::set_permissions(&agent, perm).expect("chmod");
    me
}

/// `program run ARGS --out OUT` leading a process group of its own, as a shell starts a
/// foreground job (so that a signal to the group is what a terminal's Ctrl-C sends).
fn job(program: &Path, args: &[&str], out: &Path) -> Command {
    let mut c = Command::new(program);
    c.arg("run")
        .args(args)
        .arg("--out")
        .arg(out)
        .process_group(0)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    c
}

/// Starts [`job`].
fn spawn_as_job(program: &Path, args: &[&str], out: &Path) -> Child {
    job(program, args, out)
        .spawn()
        .expect("spawning fdi-launch")
}

/// Starts [`job`] held at the hold point `point` (docs/faults.md, "Hold points") until it is
/// signalled.
fn spawn_held_job(program: &Path, args: &[&str], out: &Path, point: &str) -> Child {
    job(program, args, out)
        .env(fdi_common::stop::HOLD_VAR, point)
        .spawn()
        .expect("spawning fdi-launch")
}

/// `kill -SIG -- -PGID`: the whole process group led by `leader`.
fn signal_group(leader: u32, sig: &str) {
    let st = Command::new("kill")
        .args([sig, "--", &format!("-{leader}")])
        .status()
        .expect("kill(1)");
    assert!(st.success(), "kill {sig} -{leader}");
}

/// Regression (issue 18): a process killed or stopped before the start cost the 30 s of the
/// ready wait and was not named (`not ready after 30s: agent 2`); in realtime the launcher
/// took an agent's death before the start for a loss to be survived. The ready wait now watches
/// exits and stops as the run does: the process and its signal are named, on both clocks, and
/// nothing is left.
#[test]
fn a_process_killed_or_stopped_before_the_start_is_named_with_its_signal_on_both_clocks() {
    for clock in ["lockstep", "realtime"] {
        for (what, body, expected) in [
            (
                "killed",
                "kill -KILL $$",
                "was killed by signal 9 SIGKILL before the start",
            ),
            (
                "stopped",
                "kill -STOP $$",
                "has been stopped (SIGSTOP or a debugger)",
            ),
        ] {
            let dir = Scratch::new(&format!("early-{what}-{clock}"));
            let me = launcher_with_agent_2(&dir.0, body);
            let out = dir.0.join("out");
            let child = spawn_as_job(&me, &["--clock", clock, "--duration-s", "2"], &out);
            let launcher_pid = child.id();
            let r = wait_with_watchdog(child, WATCHDOG);
            let err = stderr_of(&r);
            assert_eq!(r.status.code(), Some(1), "{clock}, {what}: {err}");
            assert!(
                err.contains("the run did not start")
                    && err.contains("agent 2 (pid ")
                    && err.contains(expected)
                    && !err.contains("not ready after"),
                "{clock}, {what}: {err}"
            );
            assert!(entries(&out).is_empty(), "left: {:?}", entries(&out));
            assert_no_leftovers(launcher_pid);
        }
    }
}

/// Regression (issue 18): an interrupt in the first moments of a run was reported as a child
/// killed by SIGINT, or as an interrupt with exit status 1. Before the start (here agent 2 never
/// reports ready: it sleeps), SIGINT or SIGTERM to the process group stops every process and
/// exits 128 + signal with `interrupted by … before the start`, leaving nothing, on both clocks.
#[test]
fn an_interrupt_of_the_process_group_before_the_start_exits_128_plus_signal_on_both_clocks() {
    for clock in ["lockstep", "realtime"] {
        for (sig, name, code) in [("-INT", "SIGINT", 130), ("-TERM", "SIGTERM", 143)] {
            let dir = Scratch::new(&format!("early-interrupt-{clock}-{name}"));
            let me = launcher_with_agent_2(&dir.0, "exec sleep 120");
            let out = dir.0.join("out");
            let child = spawn_as_job(&me, &["--clock", clock, "--duration-s", "2"], &out);
            let leader = child.id();
            // Every process is up (agent 2 asleep, the others ready and waiting for the start).
            assert!(
                wait_until(Duration::from_secs(60), || children_of(leader).len() == 6),
                "the six processes never started"
            );
            let kids: Vec<u32> = children_of(leader).into_iter().map(|c| c.0).collect();
            signal_group(leader, sig);
            let r = wait_with_watchdog(child, WATCHDOG);
            let err = stderr_of(&r);
            assert_eq!(r.status.code(), Some(code), "{clock}, {name}: {err}");
            assert!(
                err.contains(&format!("interrupted by {name} before the start"))
                    && !err.contains("was killed by signal"),
                "{clock}, {name}: {err}"
            );
            assert!(entries(&out).is_empty(), "left: {:?}", entries(&out));
            assert!(
                wait_until(Duration::from_secs(10), || kids.iter().all(|p| !alive(*p))),
                "processes left: {kids:?}"
            );
            assert_no_leftovers(leader);
        }
    }
}

/// The report being written: its staging folder exists in the run directory.
fn reporting(out: &Path) -> bool {
    entries(out).iter().any(|run| {
        entries(run).iter().any(|e| {
            e.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with(".report-partial-"))
        })
    })
}

/// Regression (issue 18): Ctrl-C while the report was written was swallowed: the launcher
/// finished the report (up to ~30 s for a long run) and exited 0. It now stops at once, keeps
/// the summary, `rmse.md` and the traces, leaves no half-written report, says so and exits
/// 128 + signal; on both clocks, to the process group.
#[test]
fn an_interrupt_while_the_report_is_written_stops_it_keeps_the_run_and_exits_128_plus_signal() {
    for (clock, duration, sig, name, code) in [
        ("lockstep", "20", "-INT", "SIGINT", 130),
        ("realtime", "4", "-TERM", "SIGTERM", 143),
    ] {
        let dir = Scratch::new(&format!("report-interrupt-{clock}"));
        let out = dir.0.join("out");
        // Held once the report's folder is made (docs/faults.md, "Hold points"), whatever
        // the machine's speed: the signal comes while the report is written.
        let child = spawn_held_job(
            &launcher(),
            &["--clock", clock, "--duration-s", duration, "--json"],
            &out,
            "report",
        );
        let leader = child.id();
        let mut seen = false;
        assert!(
            wait_until(WATCHDOG, || {
                seen = reporting(&out);
                seen || !alive(leader)
            }),
            "neither the report nor the end"
        );
        assert!(
            seen,
            "{clock}: the run ended before its report was seen being written"
        );
        signal_group(leader, sig);
        let r = wait_with_watchdog(child, WATCHDOG);
        let err = stderr_of(&r);
        assert_eq!(r.status.code(), Some(code), "{clock}: {err}");
        assert!(
            err.contains(&format!(
                "interrupted by {name} while the report was written"
            )) && err.contains("keeps summary.json, rmse.md and the traces"),
            "{clock}: {err}"
        );
        let run = entries(&out).pop().expect("the run directory");
        assert!(
            fdi_common::run_dir::RunDir::new(&run).summary().is_file()
                && run.join("rmse.md").is_file()
        );
        let names: Vec<String> = entries(&run)
            .iter()
            .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .collect();
        assert!(
            !names
                .iter()
                .any(|n| n == "report" || n.starts_with(".report")),
            "{clock}: a half-written report was left: {names:?}"
        );
        assert!(!err.contains("[W]"), "iceoryx2's own logger printed: {err}");
        assert_no_leftovers(leader);
    }
}

/// Regression (issue 51): the in-process engine never looked at the stop: Ctrl-C during a
/// long `--engine inproc` run went unheard until the report. It now stops the engine before
/// its next tick, keeps what it ran (the traces, a summary saying it is partial) and exits 130.
#[test]
fn ctrl_c_stops_an_in_process_run_between_ticks_and_keeps_what_it_ran() {
    let dir = Scratch::new("inproc-interrupt");
    let out = dir.0.join("out");
    // 20 000 simulated seconds: minutes of the engine's time, unless it is stopped.
    let child = spawn_as_job(
        &launcher(),
        &[
            "--engine",
            "inproc",
            "--duration-s",
            "20000",
            "--traces",
            "decimate=1000",
            "--json",
        ],
        &out,
    );
    let leader = child.id();
    // Mid-run: agent 1's trace holds records beyond its header (written in 8 KiB blocks).
    let grown = || {
        entries(&out)
            .iter()
            .filter_map(|r| fs::metadata(r.join("traces/agent-1.trace")).ok())
            .any(|m| m.len() > 16 << 10)
    };
    assert!(
        wait_until(WATCHDOG, || grown() || !alive(leader)),
        "the run neither grew its trace nor ended"
    );
    signal_group(leader, "-INT");
    let r = wait_with_watchdog(child, WATCHDOG);
    let err = stderr_of(&r);
    assert_eq!(r.status.code(), Some(130), "{err}");
    assert!(
        err.contains("interrupted by SIGINT after")
            && err.contains("the in-process engine stopped"),
        "{err}"
    );
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).expect("run --json");
    assert_eq!(v["partial"]["signal"], 2, "{err}");
    let (ticks, planned) = (v["ticks"].as_u64(), v["planned_ticks"].as_u64());
    assert!(
        ticks.is_some_and(|t| t > 0) && ticks < planned && planned == Some(20_000_000),
        "{ticks:?} of {planned:?}"
    );
    let run = entries(&out).pop().expect("the run directory");
    assert!(fdi_common::run_dir::RunDir::new(&run).summary().is_file());
}

/// Regression (issue 18): a control center with no robot left reported done and the run was
/// taken as finished ("the others ran to the end", exit 3). Every robot lost for good (here
/// all four SIGKILLed mid-run) is a failed run: exit 5, said as such.
#[test]
fn realtime_every_robot_lost_for_good_is_a_failed_run_exit_5() {
    let dir = Scratch::new("rt-all-lost");
    let out = dir.0.join("out");
    let child = spawn_as_job(
        &launcher(),
        &["--clock", "realtime", "--duration-s", "3", "--json"],
        &out,
    );
    let leader = child.id();
    // Mid-run: every agent's trace holds records beyond its header.
    let trace_len = |id: u32| -> u64 {
        entries(&out)
            .iter()
            .filter_map(|r| fs::metadata(r.join(format!("traces/agent-{id}.trace"))).ok())
            .map(|m| m.len())
            .sum()
    };
    assert!(
        wait_until(Duration::from_secs(60), || {
            let first = trace_len(1);
            std::thread::sleep(Duration::from_millis(100));
            first > 0 && trace_len(1) > first
        }),
        "the run never recorded"
    );
    for (pid, _) in children_of(leader)
        .into_iter()
        .filter(|(_, c)| c.contains("--agent "))
    {
        signal(pid, "-KILL");
    }
    let r = wait_with_watchdog(child, WATCHDOG);
    let err = stderr_of(&r);
    assert_eq!(r.status.code(), Some(5), "{err}");
    assert!(
        err.contains("run failed (exit 5): the control center lost every robot for good"),
        "{err}"
    );
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).expect("summary JSON");
    assert_eq!(v["lost_agents"].as_array().map(Vec::len), Some(4), "{v}");
    assert_eq!(v["planned_ticks"], 3000);
    assert_no_leftovers(leader);
}

/// Regression (issue 18): a report that failed (disk full) left a partial `report/` and the run
/// exited 0, and the cause was printed twice (`No space left on device (os error 28): No space
/// left on device (os error 28)`). The report is written whole or not at all, the run exits 1
/// naming the cause once, and keeps its summary and traces.
#[test]
fn a_report_that_fails_leaves_no_partial_report_and_the_run_exits_1_naming_the_cause_once() {
    // The traces of this 2 s lockstep run take 2.5 MB, its report 2.6 MB more: in 3.2 MB the
    // run fits and its report does not. Needs root (a tmpfs); skipped with the reason otherwise.
    let fs_ = match Tmpfs::mount("report", "3200k") {
        Ok(t) => t,
        Err(why) => {
            eprintln!("skipped: cannot mount a tmpfs to fill up (needs root): {why}");
            return;
        }
    };
    let out = fs_.0 .0.join("runs");
    let child = spawn_as_job(&launcher(), &["--duration-s", "2"], &out);
    let r = wait_with_watchdog(child, WATCHDOG);
    let err = stderr_of(&r);
    assert_eq!(r.status.code(), Some(1), "{err}");
    let line = err
        .lines()
        .find(|l| l.contains("could not be made"))
        .unwrap_or_else(|| panic!("no report error:\n{err}"));
    assert!(
        line.starts_with("fdi-launch: error: the report of ")
            && line.matches("No space left on device").count() == 1
            && line.contains("summary.json, rmse.md and the traces are kept"),
        "{line}"
    );
    let run = entries(&out).pop().expect("the run directory");
    assert!(fdi_common::run_dir::RunDir::new(&run).summary().is_file());
    let names: Vec<String> = entries(&run)
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    assert!(
        !names
            .iter()
            .any(|n| n == "report" || n.starts_with(".report")),
        "a partial report was left: {names:?}"
    );
}

/// Regression (issue 18): a `summary.json` that is a directory or not UTF-8 was reported as
/// "missing". `report` says what it is.
#[test]
fn a_summary_that_cannot_be_read_is_said_as_it_is_not_missing() {
    let dir = Scratch::new("summary-unreadable");
    let out = dir.0.join("out");
    let r = wait_with_watchdog(
        spawn_as_job(&launcher(), &["--duration-s", "0.2", "--json"], &out),
        WATCHDOG,
    );
    assert_eq!(r.status.code(), Some(0), "{}", stderr_of(&r));
    let run = entries(&out).pop().expect("the run directory");
    let summary = fdi_common::run_dir::RunDir::new(&run).summary();
    for (case, make, expected) in [
        (
            "not UTF-8",
            (|p: &Path| fs::write(p, b"{\"scenario\": \"\xff\xfe\"}").expect("write")) as fn(&Path),
            "cannot be read (it is not UTF-8 text)",
        ),
        (
            "a directory",
            |p: &Path| {
                let _ = fs::remove_file(p);
                fs::create_dir(p).expect("mkdir");
            },
            "cannot be read (it is a directory)",
        ),
    ] {
        make(&summary);
        let r = Command::new(launcher())
            .arg("report")
            .arg(&run)
            .stdin(Stdio::null())
            .output()
            .expect("report");
        let err = stderr_of(&r);
        assert!(
            err.contains(expected) && !err.contains("is missing"),
            "{case}: {err}"
        );
        assert!(r.status.success(), "{case}: {err}");
    }
}
