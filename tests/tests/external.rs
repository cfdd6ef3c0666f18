//! Roles taken by programs outside the project (`[roles]`, docs/protocol.md), through the real
//! `fdi-launch` and the Python examples of `examples/python/` on the pinned iceoryx2 binding:
//!
//! * the Python attacker's bias and replay give the very run the Rust attacker gives under the
//!   equivalent profile (`examples/python/bias-replay.toml`): same digest, same RMSEs;
//! * a Python monitor's verdicts reach the report beside the built-in detectors, and a monitor
//!   changes nothing of the run (same digest as without it);
//! * the Python controller (the traditional law written again) gives the built-in traditional
//!   controller's digest in lockstep; its bad answers hold the last good torque, counted;
//! * a program that never says ready, dies, answers out of order, sends malformed messages, or
//!   is too slow stops the run (or, in realtime, is counted) with a message naming it, and
//!   leaves nothing behind.
//!
//! Python comes from `FDI_PYTHON` (`cargo test-all` sets up `target/py-venv` with
//! `examples/python/requirements.txt`). Without it the tests say they are skipped, unless
//! `FDI_REQUIRE_PYTHON` is set (CI), where they fail.

use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::Duration;

use fdi_common::engine::tick_time;
use fdi_common::records::Delivery;
use fdi_common::scenario::MAX_DOF;
use fdi_common::trace::TraceRecord;
use fdi_runtime::ipc::MeasurementMsg;
use fdi_tests::{json, launch, python, repo_path, run_dir_of, trace_records, Scratch};

const WATCHDOG: Duration = Duration::from_secs(300);

/// `scenario` (a repo file) with `[roles.<role>] command` run by `python` (paths made
/// absolute), the other changes of `edit` applied, written into `dir`.
fn with_python(
    scenario: &str,
    python: &Path,
    dir: &Path,
    edit: impl FnOnce(&mut toml::Table),
) -> PathBuf {
    let text = std::fs::read_to_string(repo_path(scenario)).expect("the scenario");
    let mut doc: toml::Table = toml::from_str(&text).expect("TOML");
    if let Some(roles) = doc.get_mut("roles").and_then(|r| r.as_table_mut()) {
        for (_, role) in roles.iter_mut() {
            let Some(cmd) = role.get_mut("command").and_then(|c| c.as_array_mut()) else {
                continue;
            };
            // `python3 examples/python/x.py ARGS…`: the venv's interpreter, the script by its
            // absolute path (the tests do not run in the repo root).
            cmd[0] = toml::Value::String(python.display().to_string());
            if let Some(script) = cmd.get_mut(1) {
                let rel = script.as_str().unwrap_or_default().to_string();
                *script = toml::Value::String(repo_path(&rel).display().to_string());
            }
        }
    }
    edit(&mut doc);
    let path = fdi_common::run_dir::RunDir::new(dir).scenario();
    std::fs::write(&path, toml::to_string(&doc).expect("TOML out")).expect("writing");
    path
}

/// A role table running `script` (written into `dir`, next to nothing: it imports the
/// examples' `fdi_protocol` by path) under `python`.
fn script_role(python: &Path, dir: &Path, name: &str, script: &str) -> toml::Value {
    let path = dir.join(format!("{name}.py"));
    let head = format!(
        "import sys\nsys.path.insert(0, {:?})\nimport fdi_protocol as fdi\n",
        repo_path("examples/python").display().to_string()
    );
    std::fs::write(&path, head + script).expect("writing the script");
    let mut role = toml::Table::new();
    role.insert(
        "command".into(),
        toml::Value::Array(vec![
            python.display().to_string().into(),
            path.display().to_string().into(),
        ]),
    );
    role.insert("name".into(), name.into());
    role.insert("timeout_s".into(), 2.0.into());
    toml::Value::Table(role)
}

/// Sets `[roles.<role>]`, and the run's `duration_s`.
fn set_role(doc: &mut toml::Table, role: &str, value: toml::Value, duration_s: f64) {
    doc.insert("duration_s".into(), duration_s.into());
    let roles = doc
        .entry("roles")
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    if let Some(t) = roles.as_table_mut() {
        t.insert(role.into(), value);
    }
}

/// The part of a closing note (an event of `recs`) that starts with `about`, e.g.
/// ``monitor `kinematic` ``.
fn closing_note(recs: &[TraceRecord], about: &str) -> Option<String> {
    recs.iter().find_map(|r| match r {
        TraceRecord::Event { message, .. } => message
            .split("; ")
            .find(|part| part.starts_with(about))
            .map(str::to_string),
        _ => None,
    })
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The run's trace digest (never null: a missing one fails the test).
fn digest(summary: &serde_json::Value) -> String {
    summary["trace_digest"]
        .as_str()
        .unwrap_or_else(|| panic!("no trace_digest in {summary}"))
        .to_string()
}

fn rmse(summary: &serde_json::Value) -> Vec<f64> {
    (1..=4)
        .map(|id| {
            summary["metrics"][id.to_string()]["rmse_rad"]
                .as_f64()
                .expect("an RMSE per robot")
        })
        .collect()
}

#[test]
fn the_python_attacker_gives_the_run_the_rust_attacker_gives() {
    let Some(python) = python() else { return };
    let s = Scratch::new("ext-attacker");
    let scenario = with_python(
        "examples/python/paper-python-attacker.toml",
        &python,
        &s.0,
        |_| {},
    );
    let scenario = scenario.display().to_string();
    let py = json(&launch(
        &["run", &scenario, "--engine", "ipc", "--json"],
        &s.0.join("py"),
        WATCHDOG,
    ));
    let profile = repo_path("examples/python/bias-replay.toml")
        .display()
        .to_string();
    let rust = json(&launch(
        &["run", "--engine", "ipc", "--attack", &profile, "--json"],
        &s.0.join("rust"),
        WATCHDOG,
    ));
    assert_eq!(
        digest(&py),
        digest(&rust),
        "the Python attacker's run differs from the Rust attacker's"
    );
    // Its attack is the program's, not its attack profile's (`none`): the summary and the
    // headers name the program (issue 33).
    let attack = py["attack"].as_str().unwrap_or_default();
    assert!(
        attack.starts_with("external program ") && attack.ends_with(" attacker.py"),
        "{py}"
    );
    let rmse_md = std::fs::read_to_string(run_dir_of(&py).join("rmse.md")).expect("rmse.md");
    assert!(rmse_md.contains(&format!("attack `{attack}`")), "{rmse_md}");
    assert_eq!(rmse(&py), rmse(&rust));
    // The attack did something, and the attacker's records say what: biased ticks delivered
    // with the injection, and no message went missing.
    let none = json(&launch(
        &["run", "--engine", "inproc", "--attack", "none", "--json"],
        &s.0.join("none"),
        WATCHDOG,
    ));
    assert_ne!(digest(&py), digest(&none));
    let recs = trace_records(&run_dir_of(&py).join("traces/attacker.trace"));
    let attacked = recs
        .iter()
        .filter(|r| matches!(r, TraceRecord::Attack(a) if a.active))
        .count();
    assert!(attacked > 10_000, "only {attacked} attacked ticks recorded");
    assert!(recs.iter().all(|r| match r {
        TraceRecord::Attack(a) => a.delivery == Delivery::Delivered,
        _ => true,
    }));
    let note = closing_note(&recs, "external attacker `");
    assert!(
        note.as_deref()
            .is_some_and(|n| n.contains("160000 answers")),
        "the attacker's closing note: {note:?}"
    );
}

#[test]
fn a_python_monitor_is_reported_beside_the_detectors_and_changes_nothing() {
    let Some(python) = python() else { return };
    let s = Scratch::new("ext-monitor");
    let scenario = with_python(
        "examples/python/paper-python-monitor.toml",
        &python,
        &s.0,
        |doc| {
            doc.insert("duration_s".into(), 10.0.into());
        },
    );
    let scenario = scenario.display().to_string();
    let with_out = launch(&["run", &scenario, "--json"], &s.0.join("with"), WATCHDOG);
    // iceoryx2's warning about its config file is not relayed as the monitor's line (the
    // examples' protocol module sets its log level as the run's processes do; issue 33).
    assert!(
        !stderr(&with_out).contains("No config file"),
        "{}",
        stderr(&with_out)
    );
    let with = json(&with_out);
    let without = json(&launch(
        &["run", "--duration-s", "10", "--json"],
        &s.0.join("without"),
        WATCHDOG,
    ));
    assert_eq!(digest(&with), digest(&without));
    for id in 1..=4 {
        let d = &with["metrics"][id.to_string()]["detectors"];
        for name in fdi_common::detect::names().into_iter().chain(["kinematic"]) {
            assert!(d[name].is_object(), "robot {id} lacks detector {name}: {d}");
        }
        assert_eq!(
            d["kinematic"]["missing"], 0,
            "robot {id}: {}",
            d["kinematic"]
        );
    }
    // The paper attack on robot 4 is detected by the monitor too.
    let onsets = with["metrics"]["4"]["detectors"]["kinematic"]["onsets"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    assert!(
        onsets.iter().any(|o| o["time_to_detect_s"].is_f64()),
        "the monitor detected nothing on robot 4: {onsets:?}"
    );
    let report =
        std::fs::read_to_string(run_dir_of(&with).join("report/report.md")).expect("report.md");
    assert!(
        report.contains(&format!(
            "| {} | kinematic |",
            fdi_common::detect::names().join(" | ")
        )),
        "report.md has no monitor column"
    );
    // The control center's account of the monitor, in the report: every verdict came.
    assert!(
        report.contains("* monitor `kinematic`: 40000 of 40000 verdicts"),
        "report.md lacks the monitor's account"
    );
}

/// Runs the paper scenario for `duration_s` with `[roles.<role>]` running `script`; returns
/// its output, once it checked that the run left no shared-memory file behind.
fn run_with_script(role: &str, name: &str, script: &str, duration_s: f64, clock: &str) -> Output {
    run_with_script_on("ipc", role, (name, script), duration_s, clock)
}

/// [`run_with_script`] on the engine `engine`.
fn run_with_script_on(
    engine: &str,
    role: &str,
    (name, script): (&str, &str),
    duration_s: f64,
    clock: &str,
) -> Output {
    let python = python().expect("checked by the caller");
    let s = Scratch::new(&format!("ext-{name}"));
    let value = script_role(&python, &s.0, name, script);
    let scenario = with_python("scenarios/paper.toml", &python, &s.0, |doc| {
        set_role(doc, role, value, duration_s);
        doc.insert("clock".into(), clock.into());
        if role == "attacker" {
            let mut attack = toml::Table::new();
            attack.insert("preset".into(), "none".into());
            doc.insert("attack".into(), toml::Value::Table(attack));
        }
        if role == "controller" {
            if let Some(c) = doc.get_mut("controller").and_then(|c| c.as_table_mut()) {
                c.insert("mode".into(), "external".into());
            }
        }
    });
    let scenario = scenario.display().to_string();
    let child = fdi_tests::spawn(
        &["run", &scenario, "--engine", engine, "--json"],
        &s.0.join("runs"),
    );
    let pid = child.id();
    let out = fdi_tests::wait_with_watchdog(child, WATCHDOG);
    // However the program misbehaved, the run leaves nothing behind.
    fdi_tests::assert_no_leftovers(pid);
    out
}

/// The run failed (exit 1), naming `name` and saying `what`.
fn assert_failed_naming(out: &Output, name: &str, what: &str) {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains(&format!("`{name}`")), "not named: {err}");
    assert!(err.contains(what), "no `{what}` in: {err}");
    eprintln!("{err}");
}

#[test]
fn an_external_role_that_never_says_ready_is_named() {
    if python().is_none() {
        return;
    }
    let out = run_with_script(
        "attacker",
        "never-ready",
        "import time\ntime.sleep(60)\n",
        1.0,
        "lockstep",
    );
    assert_failed_naming(&out, "never-ready", "not ready after");
    assert!(stderr(&out).contains("docs/protocol.md"));
}

#[test]
fn an_external_role_that_dies_is_named_with_what_it_printed() {
    if python().is_none() {
        return;
    }
    let script = "with fdi.Run('monitor') as run:\n    run.ready_and_wait_for_start()\n    \
                  raise SystemExit('the model file is missing')\n";
    let out = run_with_script("monitor", "dies", script, 2.0, "lockstep");
    assert_failed_naming(&out, "dies", "the model file is missing");
}

/// An attacker program answering each message with `answer` (Python: a function of the
/// message returning the list of messages to send), done after the last tick of every agent.
fn attacker_script(answer: &str) -> String {
    format!(
        "{answer}\nwith fdi.Run('attacker') as run:\n    \
         inbox = run.subscriber('fdi/external/attacker/in', fdi.MeasurementMsg)\n    \
         outbox = run.publisher('fdi/external/attacker/out', fdi.MeasurementMsg)\n    \
         relay = run.notifier('fdi/wake/attacker')\n    \
         run.ready_and_wait_for_start()\n    \
         left = set(run.env.agents)\n    \
         while left:\n        \
         batch = run.drain(inbox)\n        \
         if not batch:\n            run.wait()\n            continue\n        \
         for m in batch:\n            \
         last = m.seq == run.env.ticks - 1\n            \
         for a in answer(m):\n                outbox.send_copy(a)\n            \
         if last:\n                left.discard(m.agent)\n        \
         relay.notify()\n    \
         run.done_and_wait_for_stop()\n"
    )
}

#[test]
fn an_attacker_that_answers_out_of_order_is_named() {
    if python().is_none() {
        return;
    }
    // Tick 100 of agent 2 is answered as tick 101.
    let answer = "def answer(m):\n    if m.agent == 2 and m.seq == 100:\n        m.seq = 101\n    \
                  return [m]\n";
    let out = run_with_script(
        "attacker",
        "skips",
        &attacker_script(answer),
        1.0,
        "lockstep",
    );
    assert_failed_naming(&out, "skips", "agent 2: answered tick 101");
}

#[test]
fn an_attacker_that_sends_malformed_messages_is_named() {
    if python().is_none() {
        return;
    }
    let answer = "def answer(m):\n    if m.seq == 7:\n        m.dof = 3\n    return [m]\n";
    let out = run_with_script(
        "attacker",
        "malformed",
        &attacker_script(answer),
        1.0,
        "lockstep",
    );
    assert_failed_naming(&out, "malformed", "dof 3 where the run's agents have 2");
}

#[test]
fn an_attacker_that_stops_answering_is_named_after_its_timeout() {
    if python().is_none() {
        return;
    }
    let answer = "import time\ndef answer(m):\n    if m.seq >= 300:\n        time.sleep(30)\n    \
                  return [m]\n";
    let out = run_with_script(
        "attacker",
        "hangs",
        &attacker_script(answer),
        1.0,
        "lockstep",
    );
    // Which tick it owes first depends on how the agents batched: the message names one.
    assert_failed_naming(&out, "hangs", "no answer to tick ");
    assert!(stderr(&out).contains("within 2s"), "{}", stderr(&out));
}

#[test]
fn a_monitor_that_judges_out_of_order_is_named() {
    if python().is_none() {
        return;
    }
    let script = "with fdi.Run('monitor') as run:\n    \
                  alarms = run.publisher('fdi/alarm', fdi.AlarmMsg)\n    \
                  center = run.notifier('fdi/wake/center')\n    \
                  run.ready_and_wait_for_start()\n    \
                  a = fdi.AlarmMsg(seq=5, agent=run.env.agents[0], alarm=0, statistic=0.0)\n    \
                  alarms.send_copy(a)\n    center.notify()\n    run.wait(5.0)\n";
    let out = run_with_script("monitor", "early", script, 1.0, "lockstep");
    assert_failed_naming(&out, "early", "verdict on tick 5 where tick 0 was due");
}

#[test]
fn realtime_an_attacker_too_slow_for_its_deadline_is_counted_and_the_run_goes_on() {
    if python().is_none() {
        return;
    }
    // Every 100th tick of agent 1 is answered 20 ms late (the deadline is 5 ms).
    let answer =
        "import time\ndef answer(m):\n    if m.agent == 1 and m.seq % 100 == 50:\n        \
                  time.sleep(0.02)\n    return [m]\n";
    let python = python().expect("checked");
    let s = Scratch::new("ext-slow");
    let value = script_role(&python, &s.0, "slow", &attacker_script(answer));
    let scenario = with_python("scenarios/paper.toml", &python, &s.0, |doc| {
        set_role(doc, "attacker", value, 2.0);
        doc.insert("clock".into(), "realtime".into());
        let mut attack = toml::Table::new();
        attack.insert("preset".into(), "none".into());
        doc.insert("attack".into(), toml::Value::Table(attack));
    });
    let scenario = scenario.display().to_string();
    let out = launch(&["run", &scenario, "--json"], &s.0.join("runs"), WATCHDOG);
    let summary = fdi_tests::json_realtime(&out);
    let recs = trace_records(&run_dir_of(&summary).join("traces/attacker.trace"));
    let note =
        closing_note(&recs, "external attacker `slow`").expect("the attacker's closing note");
    eprintln!("{note}");
    let late: u64 = note
        .split(", ")
        .find(|p| p.contains("ticks past the"))
        .and_then(|p| p.split(' ').next())
        .and_then(|n| n.parse().ok())
        .expect("a count of late ticks in the note");
    assert!(late >= 1, "{note}");
    // Each late tick went to the control center as a gap marker: recorded missing.
    let missing = recs
        .iter()
        .filter(|r| matches!(r, TraceRecord::Attack(a) if a.delivery == Delivery::Missing))
        .count() as u64;
    assert_eq!(missing, late, "{note}");
}

#[test]
fn the_in_process_engine_refuses_external_roles() {
    let s = Scratch::new("ext-inproc");
    let scenario = repo_path("examples/python/paper-python-monitor.toml")
        .display()
        .to_string();
    let out = launch(&["run", &scenario, "--engine", "inproc"], &s.0, WATCHDOG);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("--engine ipc"), "{}", stderr(&out));
}

#[test]
fn realtime_the_monitors_verdicts_are_counted_received_late_and_missing() {
    let Some(python) = python() else { return };
    let s = Scratch::new("ext-monitor-rt");
    let scenario = with_python(
        "examples/python/paper-python-monitor.toml",
        &python,
        &s.0,
        |doc| {
            doc.insert("duration_s".into(), 3.0.into());
            doc.insert("clock".into(), "realtime".into());
        },
    );
    let scenario = scenario.display().to_string();
    let summary = fdi_tests::json_realtime(&launch(
        &["run", &scenario, "--json"],
        &s.0.join("runs"),
        WATCHDOG,
    ));
    let recs = trace_records(&run_dir_of(&summary).join("traces/control-center.trace"));
    let verdicts = recs
        .iter()
        .filter(|r| matches!(r, TraceRecord::Monitor(_)))
        .count() as u64;
    let late = recs
        .iter()
        .filter(|r| matches!(r, TraceRecord::Monitor(m) if m.late))
        .count() as u64;
    let note = closing_note(&recs, "monitor `kinematic`")
        .expect("the control center's note on the monitor");
    eprintln!("{note}");
    assert!(
        note.contains(&format!("{verdicts} of 12000 verdicts, {late} later than")),
        "{note}"
    );
    assert!(verdicts > 0);
    // What did not come is missing in the metrics, robot by robot.
    let missing: u64 = (1..=4)
        .map(|id| {
            summary["metrics"][id.to_string()]["detectors"]["kinematic"]["missing"]
                .as_u64()
                .expect("the monitor's metrics")
        })
        .sum();
    let controlled: u64 = (1..=4)
        .map(|id| {
            summary["metrics"][id.to_string()]["ticks"]
                .as_u64()
                .unwrap_or(0)
        })
        .sum();
    let lost = summary["lost_agents"].as_array().map_or(0, Vec::len);
    if lost == 0 {
        assert_eq!(missing, controlled - verdicts.min(controlled), "{note}");
    } else {
        eprintln!("{lost} agents were lost for a while: the missing count is not compared");
    }
}

/// The paper scenario, lockstep, with `[roles.attacker]` running `sh -c script` (a program that
/// does not speak the protocol: it never says ready, and the run stops after its 1 s timeout),
/// written into `dir`.
fn sh_attacker(dir: &Path, name: &str, script: &str) -> String {
    sh_role(dir, "attacker", name, script)
}

/// [`sh_attacker`] for `role` (`attacker` or `monitor`).
fn sh_role(dir: &Path, role_name: &str, name: &str, script: &str) -> String {
    let text = std::fs::read_to_string(repo_path("scenarios/paper.toml")).expect("the scenario");
    let mut doc: toml::Table = toml::from_str(&text).expect("TOML");
    let mut role = toml::Table::new();
    role.insert(
        "command".into(),
        toml::Value::Array(vec!["sh".into(), "-c".into(), script.into()]),
    );
    role.insert("name".into(), name.into());
    role.insert("timeout_s".into(), 1.0.into());
    set_role(&mut doc, role_name, toml::Value::Table(role), 1.0);
    let mut attack = toml::Table::new();
    attack.insert("preset".into(), "none".into());
    doc.insert("attack".into(), toml::Value::Table(attack));
    let path = fdi_common::run_dir::RunDir::new(dir).scenario();
    std::fs::write(&path, toml::to_string(&doc).expect("TOML out")).expect("writing");
    path.display().to_string()
}

/// The pid a script wrote into `file`, once it did.
fn pid_written(file: &Path) -> u32 {
    let mut pid = None;
    fdi_tests::wait_until(Duration::from_secs(30), || {
        pid = std::fs::read_to_string(file)
            .ok()
            .and_then(|s| s.trim().parse().ok());
        pid.is_some()
    });
    pid.unwrap_or_else(|| panic!("{} never held a pid", file.display()))
}

/// Runs `scenario` through `fdi-launch` with the watchdog (a hang fails the test), and checks
/// it stopped naming the program `name` and left no shared-memory file.
fn run_sh_attacker(scenario: &str, out_dir: &Path, name: &str, what: &str) -> Output {
    let child = fdi_tests::spawn(&["run", scenario, "--json"], out_dir);
    let pid = child.id();
    let out = fdi_tests::wait_with_watchdog(child, WATCHDOG);
    fdi_tests::assert_no_leftovers(pid);
    assert_failed_naming(&out, name, what);
    out
}

/// Regression (issue 29): a child that kept the program's stdout and stderr made the launcher
/// wait, silent, until it exited (a 2 s run took 20.6 s with a 20 s child). The children run
/// for an hour here: the watchdog catches a launcher that waits for them; once the launcher is
/// back, they are gone. Both a program that is still running at the end and one that exited
/// first, leaving its child, are checked.
#[test]
fn an_external_programs_lingering_child_does_not_delay_the_run() {
    for (name, end, what) in [
        ("lingering", "exec sleep 3600", "not ready after"),
        ("gone-first", "exit 0", "exited before it was ready"),
    ] {
        let s = Scratch::new(&format!("ext-{name}"));
        let pid_file = s.0.join("child.pid");
        let script = format!(
            "sleep 3600 & echo $! > {}; echo waiting; {end}",
            pid_file.display()
        );
        let scenario = sh_attacker(&s.0, name, &script);
        let out = run_sh_attacker(&scenario, &s.0.join("runs"), name, what);
        let child = pid_written(&pid_file);
        assert!(
            !fdi_tests::alive(child),
            "{name}: the program's child (pid {child}) outlived the run"
        );
        let err = stderr(&out);
        assert!(
            err.contains(&format!("external attacker `{name}`: waiting")),
            "{name}: the program's output is relayed: {err}"
        );
        if end == "exit 0" {
            assert!(
                err.contains(&format!("external attacker `{name}`"))
                    && err.contains(&format!(
                        "left 1 process running, ended: pid {child} (sleep)"
                    )),
                "{name}: the launcher names the program and what it ended: {err}"
            );
        }
    }
}

/// Regression (issue 29): a child that detached (its own session, its output closed) was
/// still running after the run ended. One that left the program's process group and was
/// orphaned (a double fork: init is its parent) is found by the run's variables in its
/// environment; one that left the group while the program lives, as a descendant.
#[test]
fn an_external_programs_detached_child_is_gone_when_the_run_ends() {
    let s = Scratch::new("ext-detached");
    let (orphan, descendant) = (s.0.join("orphan.pid"), s.0.join("descendant.pid"));
    let script = format!(
        "(setsid sleep 3600 < /dev/null > /dev/null 2>&1 & echo $! > {orphan}); \
         setsid sleep 3601 < /dev/null > /dev/null 2>&1 & echo $! > {descendant}; \
         exec sleep 3600",
        orphan = orphan.display(),
        descendant = descendant.display()
    );
    let scenario = sh_attacker(&s.0, "detached", &script);
    let out = run_sh_attacker(&scenario, &s.0.join("runs"), "detached", "not ready after");
    for file in [&orphan, &descendant] {
        let pid = pid_written(file);
        assert!(
            !fdi_tests::alive(pid),
            "the detached child (pid {pid}, {}) outlived the run",
            file.display()
        );
    }
    let err = stderr(&out);
    assert!(
        err.contains("external attacker `detached`") && err.contains("outside its group"),
        "the launcher names the program and what it ended: {err}"
    );
}

/// Regression (issue 51): a grandchild that calls `setsid` and runs with an empty environment
/// (nothing of the run's left to find it by) outlived the run, below the attacker's program and
/// the monitor's. The launcher is the subreaper of whatever its runs start: once its parent is
/// gone, the grandchild is the launcher's child, and it is ended with the run.
#[test]
fn a_grandchild_that_calls_setsid_with_an_empty_environment_is_ended_with_the_run() {
    for role in ["attacker", "monitor"] {
        let s = Scratch::new(&format!("ext-cleared-{role}"));
        let orphan = s.0.join("orphan.pid");
        let script = format!(
            "(env -i setsid sleep 3600 < /dev/null > /dev/null 2>&1 & echo $! > {}); \
             exec sleep 3600",
            orphan.display()
        );
        let scenario = sh_role(&s.0, role, "cleared", &script);
        run_sh_attacker(&scenario, &s.0.join("runs"), "cleared", "not ready after");
        let pid = pid_written(&orphan);
        assert!(
            !fdi_tests::alive(pid),
            "{role}: the grandchild (pid {pid}) outlived the run"
        );
    }
}

/// A measurement of agent 2 at tick `seq` (2 links, 1 ms ticks).
fn clean(seq: u64) -> MeasurementMsg {
    let mut y = [0.0; MAX_DOF];
    y[0] = 0.5;
    y[1] = -0.25;
    MeasurementMsg {
        y,
        flags: 0,
        ..MeasurementMsg::gap(seq, 2, 2, tick_time(seq, 1e-3))
    }
}

/// The attacker's record of a tick answered by an external program: the same message is
/// delivered and not active, a changed one is an injection, a gap marker is missing (replayed
/// when older messages came before it), a stamp that is not the tick's time is forged.
#[test]
fn the_attackers_record_of_an_external_answer_classifies_what_was_sent() {
    let c = clean(7);
    let same = fdi_attacker::external::record(&c, &c, false, 1e-3, 2);
    assert_eq!((same.delivery, same.active), (Delivery::Delivered, false));
    assert_eq!(same.y.as_slice(), &[0.5, -0.25]);
    let mut biased = c;
    biased.y[1] += 0.125;
    let r = fdi_attacker::external::record(&c, &biased, false, 1e-3, 2);
    assert_eq!((r.delivery, r.active), (Delivery::Delivered, true));
    assert_eq!(r.alpha_position.as_slice(), &[0.0, 0.125]);
    let gap = MeasurementMsg::gap(7, 2, 2, c.t);
    assert_eq!(
        fdi_attacker::external::record(&c, &gap, false, 1e-3, 2).delivery,
        Delivery::Missing
    );
    let replay = fdi_attacker::external::record(&c, &gap, true, 1e-3, 2);
    assert_eq!((replay.delivery, replay.active), (Delivery::Replayed, true));
    assert!(replay.y.as_slice().is_empty());
    let mut forged = c;
    forged.t += 1e-3;
    let f = fdi_attacker::external::record(&c, &forged, false, 1e-3, 2);
    assert_eq!((f.delivery, f.active), (Delivery::Forged, true));
}

// ---------------------------------------------------------------------------------------------
// The controller program (`[roles.controller]`, docs/protocol.md, "The controller program")

/// `examples/python/paper-python-controller.toml` for `duration_s` under `python`, with
/// `args` added to the controller's command and `edit` applied; written into `dir`.
fn python_controller(
    python: &Path,
    dir: &Path,
    duration_s: f64,
    args: &[&str],
    edit: impl FnOnce(&mut toml::Table),
) -> String {
    let path = with_python(
        "examples/python/paper-python-controller.toml",
        python,
        dir,
        |doc| {
            doc.insert("duration_s".into(), duration_s.into());
            let role = doc
                .get_mut("roles")
                .and_then(|r| r.get_mut("controller"))
                .and_then(|c| c.as_table_mut())
                .expect("[roles.controller]");
            if let Some(cmd) = role.get_mut("command").and_then(|c| c.as_array_mut()) {
                cmd.extend(args.iter().map(|a| toml::Value::String(a.to_string())));
            }
            edit(doc);
        },
    );
    path.display().to_string()
}

/// The closing note of the controller program named `name` in the control center's trace of
/// the run of `summary`.
fn controller_note(summary: &serde_json::Value, name: &str) -> String {
    let run = fdi_common::run_dir::RunDir::new(run_dir_of(summary));
    let recs = trace_records(&run.trace(fdi_common::run_dir::Process::Center));
    closing_note(&recs, &format!("controller `{name}`")).expect("the controller's closing note")
}

/// The first number after `", "` in the part of `note` that contains `what`.
fn count_in(note: &str, what: &str) -> u64 {
    note.split(", ")
        .find(|p| p.contains(what))
        .and_then(|p| p.split(' ').find_map(|w| w.parse().ok()))
        .unwrap_or_else(|| panic!("no count of `{what}` in {note}"))
}

/// Each robot's `rejected_torques` in `summary`, robots 1 to 4.
fn rejected_torques(summary: &serde_json::Value) -> Vec<u64> {
    (1..=4)
        .map(|r| summary["metrics"][r.to_string()]["rejected_torques"].as_u64())
        .collect::<Option<_>>()
        .expect("rejected_torques per robot")
}

/// The Python re-implementation of the traditional law (`examples/python/controller.py`) gives
/// the built-in traditional controller's run in lockstep, bit for bit, under the paper's
/// attack: the same trace digest.
#[test]
fn the_python_controller_gives_the_digest_of_the_built_in_traditional_law() {
    let Some(python) = python() else { return };
    let s = Scratch::new("ext-controller");
    let scenario = python_controller(&python, &s.0, 3.0, &[], |_| {});
    let py = json(&launch(
        &["run", &scenario, "--json"],
        &s.0.join("py"),
        WATCHDOG,
    ));
    assert_eq!(py["controller"], "external", "{py}");
    let dir = s.0.join("builtin");
    std::fs::create_dir_all(&dir).expect("a folder");
    let builtin = python_controller(&python, &dir, 3.0, &[], |doc| {
        doc.remove("roles");
        if let Some(c) = doc.get_mut("controller").and_then(|c| c.as_table_mut()) {
            c.insert("mode".into(), "traditional".into());
        }
    });
    let rust = json(&launch(
        &["run", &builtin, "--json"],
        &s.0.join("rust"),
        WATCHDOG,
    ));
    assert_eq!(rust["controller"], "traditional");
    // The in-process engine asks the program itself, as the control center does.
    let inproc = json(&launch(
        &["run", &scenario, "--engine", "inproc", "--json"],
        &s.0.join("py-inproc"),
        WATCHDOG,
    ));
    assert_eq!(inproc["engine"], "inproc", "{inproc}");
    for run in [&py, &inproc] {
        assert_eq!(digest(run), digest(&rust));
        assert_eq!(rejected_torques(run), [0; 4]);
        let note = controller_note(run, "python-traditional");
        assert!(
            note.contains(": 12000 answers, 0 with a non-finite"),
            "{note}"
        );
    }
}

/// An answer with non-finite torques, or of another number of joints than its robot's, sends
/// the last good torque again: counted as a rejected torque, the first named on stderr, all
/// counted in the closing note. The run goes on.
#[test]
fn a_controller_that_answers_non_finite_torques_or_the_wrong_joints_is_named_and_held() {
    let Some(python) = python() else { return };
    for (bad, what, said) in [
        (
            "non-finite",
            "with a non-finite",
            "a non-finite torque or Ŝ",
        ),
        (
            "dof",
            "with another number",
            "an answer of 3 joints for a robot of 2",
        ),
    ] {
        let s = Scratch::new(&format!("ext-controller-{bad}"));
        let args = ["--bad", bad, "--bad-from", "600"];
        let scenario = python_controller(&python, &s.0, 1.0, &args, |_| {});
        // The same on either engine: the in-process one asks the program as the control
        // center does.
        let mut digests = Vec::new();
        for engine in ["ipc", "inproc"] {
            let out = launch(
                &["run", &scenario, "--engine", engine, "--json"],
                &s.0.join(engine),
                WATCHDOG,
            );
            let summary = json(&out);
            assert_eq!(rejected_torques(&summary), [400; 4], "{bad} {engine}");
            let err = stderr(&out);
            assert!(err.contains("controller `python-traditional`"), "{err}");
            assert!(err.contains(said), "{bad} {engine}: {err}");
            let note = controller_note(&summary, "python-traditional");
            assert_eq!(count_in(&note, what), 1600, "{engine}: {note}");
            // The robots stayed under control on the held torques.
            for r in 1..=4 {
                let e = summary["metrics"][r.to_string()]["max_abs_error_rad"].as_f64();
                assert!(e.is_some_and(|e| e < 0.5), "{engine}: robot {r}: {e:?}");
            }
            digests.push(digest(&summary));
        }
        assert_eq!(digests[0], digests[1], "{bad}");
    }
}

/// Lockstep waits for every answer: a controller that stops answering stops the run after its
/// timeout, naming it and the tick; one that never says ready is named too.
#[test]
fn a_controller_that_stops_answering_or_never_says_ready_is_named() {
    let Some(python) = python() else { return };
    let s = Scratch::new("ext-controller-silent");
    let args = ["--bad", "silent", "--bad-from", "300"];
    let scenario = python_controller(&python, &s.0, 1.0, &args, |doc| {
        if let Some(c) = doc
            .get_mut("roles")
            .and_then(|r| r.get_mut("controller"))
            .and_then(|c| c.as_table_mut())
        {
            c.insert("timeout_s".into(), 2.0.into());
        }
    });
    for engine in ["ipc", "inproc"] {
        let child = fdi_tests::spawn(
            &["run", &scenario, "--engine", engine, "--json"],
            &s.0.join(engine),
        );
        let pid = child.id();
        let out = fdi_tests::wait_with_watchdog(child, WATCHDOG);
        fdi_tests::assert_no_leftovers(pid);
        assert_failed_naming(&out, "python-traditional", "no answer to tick 300 of agent");
    }
    for engine in ["ipc", "inproc"] {
        let out = run_with_script_on(
            engine,
            "controller",
            ("never-ready", "import time\ntime.sleep(60)\n"),
            1.0,
            "lockstep",
        );
        assert_failed_naming(&out, "never-ready", "not ready after");
    }
}

/// A controller program answering each question `q` with `ControllerOutMsg(seq=q.seq + shift,
/// agent=q.agent + other)`.
fn misanswering_controller(shift: u64, other: u32) -> String {
    format!(
        "with fdi.Run('controller') as run:\n    \
         questions = run.subscriber('fdi/external/controller/in', fdi.ControllerInMsg)\n    \
         answers = run.publisher('fdi/external/controller/out', fdi.ControllerOutMsg)\n    \
         center = run.notifier('fdi/wake/center')\n    \
         run.ready_and_wait_for_start()\n    \
         while True:\n        \
         batch = run.drain(questions, fdi.ControllerInMsg)\n        \
         if not batch:\n            run.wait()\n            continue\n        \
         for q in batch:\n            \
         answers.send_copy(fdi.ControllerOutMsg(seq=q.seq + {shift}, agent=q.agent + {other}, \
         dof=q.dof))\n        \
         center.notify()\n"
    )
}

/// An answer for another tick than the one asked, or for an agent the run does not have, stops
/// the run naming the program, on either engine (the in-process one asks the program as the
/// control center does), and leaves nothing behind.
#[test]
fn a_controller_that_answers_another_tick_or_agent_is_named() {
    if python().is_none() {
        return;
    }
    for engine in ["ipc", "inproc"] {
        for (name, script, what) in [
            (
                "ahead",
                misanswering_controller(1, 0),
                // (Whichever agent's answer the control center reads first.)
                ": answered tick 1 where tick 0 was asked",
            ),
            (
                "elsewhere",
                misanswering_controller(0, 100),
                ", which the run does not have (tick 0)",
            ),
        ] {
            let out = run_with_script_on(engine, "controller", (name, &script), 1.0, "lockstep");
            assert_failed_naming(&out, name, what);
        }
    }
}

/// Realtime: a question unanswered at its deadline holds the last good torque (a rejected
/// torque), counted late in the closing note; the run goes on to its end.
#[test]
fn realtime_a_silent_controller_holds_the_last_torque_past_each_deadline() {
    let Some(python) = python() else { return };
    let s = Scratch::new("ext-controller-realtime");
    let args = ["--bad", "silent", "--bad-from", "1000"];
    let scenario = python_controller(&python, &s.0, 2.0, &args, |doc| {
        doc.insert("clock".into(), "realtime".into());
    });
    let out = launch(&["run", &scenario, "--json"], &s.0.join("runs"), WATCHDOG);
    let summary = fdi_tests::json_realtime(&out);
    let rejected = rejected_torques(&summary);
    for (robot, r) in (1..=4).zip(&rejected) {
        // Every tick from 1000 on held its torque, unless its measurement never came (a robot
        // a loaded machine made silent for a while: uncontrolled); a loaded machine may make
        // earlier answers late too.
        let uncontrolled = summary["metrics"][robot.to_string()]["uncontrolled_ticks"]
            .as_u64()
            .expect("uncontrolled_ticks");
        assert!(
            *r <= 2000 && r + uncontrolled >= 1000,
            "robot {robot}: {r} held, {uncontrolled} uncontrolled"
        );
    }
    let note = controller_note(&summary, "python-traditional");
    eprintln!("{note}");
    assert_eq!(
        count_in(&note, "ticks past the"),
        rejected.iter().sum::<u64>(),
        "every rejected torque is a tick past its deadline: {note}"
    );
}

/// `scenario` (a repo file whose `[defaults]` model is the Panda's URDF) for `duration_s`, its
/// torques decided by `examples/python/controller.py` (`python-traditional`) under `python`;
/// written into `dir`.
fn python_controller_on(scenario: &str, python: &Path, dir: &Path, duration_s: f64) -> PathBuf {
    with_python(scenario, python, dir, |doc| {
        let urdf = repo_path("scenarios/robots/panda.urdf")
            .display()
            .to_string();
        let model = doc
            .get_mut("defaults")
            .and_then(|d| d.get_mut("model"))
            .and_then(|m| m.as_table_mut())
            .expect("[defaults] model");
        model.insert("path".into(), urdf.into());
        if let Some(c) = doc.get_mut("controller").and_then(|c| c.as_table_mut()) {
            c.insert("mode".into(), "external".into());
        }
        let mut role = toml::Table::new();
        let program = repo_path("examples/python/controller.py");
        role.insert(
            "command".into(),
            toml::Value::Array(vec![
                python.display().to_string().into(),
                program.display().to_string().into(),
            ]),
        );
        role.insert("name".into(), "python-traditional".into());
        set_role(doc, "controller", toml::Value::Table(role), duration_s);
    })
}

/// `examples/python/controller.py` deciding the torques of `scenario` (a repo file whose
/// `[defaults]` model is the Panda's URDF) for `duration_s` gives the built-in traditional
/// law's run, on both engines: its digest, no torque held.
fn the_python_controller_gives_the_built_in_digest_on(scenario: &str, duration_s: f64) {
    let Some(python) = python() else { return };
    let s = Scratch::new("ext-controller-team");
    let program = python_controller_on(scenario, &python, &s.0, duration_s);
    let builtin = repo_path(scenario).display().to_string();
    let duration = duration_s.to_string();
    let run = |file: &str, engine: &str, out: &str| {
        let args = [
            "run",
            file,
            "--duration-s",
            &duration,
            "--engine",
            engine,
            "--json",
        ];
        json(&launch(&args, &s.0.join(out), WATCHDOG))
    };
    let rust = run(&builtin, "inproc", "rust");
    assert_eq!(rust["controller"], "traditional");
    for engine in ["ipc", "inproc"] {
        let py = run(&program.display().to_string(), engine, engine);
        assert_eq!(py["controller"], "external", "{engine}");
        assert_eq!(digest(&py), digest(&rust), "{scenario} {engine}");
        assert_eq!(rejected_torques(&py), [0; 4], "{scenario} {engine}");
    }
}

/// The same program on the Panda team (7 joints, gains scaled by each arm's inertia, which the
/// program reads off the first question's `M(q_d)`): the built-in traditional law's digest too.
#[test]
fn the_python_controller_gives_the_built_in_digest_on_the_panda_team_too() {
    the_python_controller_gives_the_built_in_digest_on("scenarios/panda-team.toml", 2.0);
}

/// The same program takes a team of different robots (`scenarios/mixed-team.toml`: two
/// Pandas, two paper arms, each with its own gains; `FDI_DOF` is `mixed`, `FDI_JOINTS` each
/// robot's count).
#[test]
fn the_python_controller_gives_the_built_in_digest_on_a_mixed_team() {
    the_python_controller_gives_the_built_in_digest_on("scenarios/mixed-team.toml", 1.0);
}

/// A SIGKILLed launcher cannot end the programs it started, and a program need not watch its
/// parent: the kernel sends it SIGTERM when the launcher dies (here a shell that never says
/// ready, waited for by the launcher until it is killed).
#[test]
fn a_program_in_a_role_ends_when_its_launcher_is_sigkilled() {
    let s = Scratch::new("ext-orphan");
    let pid_file = s.0.join("program.pid");
    let text = std::fs::read_to_string(repo_path("scenarios/paper.toml")).expect("the scenario");
    let mut doc: toml::Table = toml::from_str(&text).expect("TOML");
    let mut role = toml::Table::new();
    let script = format!(
        "echo $$ > {:?}; exec sleep 300",
        pid_file.display().to_string()
    );
    role.insert(
        "command".into(),
        toml::Value::Array(vec!["sh".into(), "-c".into(), script.into()]),
    );
    role.insert("name".into(), "sleeper".into());
    role.insert("timeout_s".into(), 120.0.into());
    let attack: toml::Table = toml::from_str("preset = \"none\"").expect("TOML");
    doc.insert("attack".into(), toml::Value::Table(attack));
    set_role(&mut doc, "attacker", toml::Value::Table(role), 1.0);
    let scenario = s.0.join("scenario.toml");
    std::fs::write(&scenario, toml::to_string(&doc).expect("TOML out")).expect("writing");
    let mut child = fdi_tests::spawn(&["run", &scenario.to_string_lossy()], &s.0.join("runs"));
    let read_pid = || {
        let text = std::fs::read_to_string(&pid_file).ok()?;
        text.trim().parse::<u32>().ok()
    };
    let started = fdi_tests::wait_until(Duration::from_secs(60), || read_pid().is_some());
    let launcher = child.id();
    let others: Vec<u32> = (fdi_tests::children_of(launcher).into_iter())
        .map(|c| c.0)
        .collect();
    fdi_tests::signal(launcher, "-KILL");
    let _ = child.wait();
    assert!(started, "the program never started");
    let program = read_pid().expect("its pid");
    assert!(
        fdi_tests::wait_until(Duration::from_secs(30), || !fdi_tests::alive(program)),
        "the program {program} outlived its SIGKILLed launcher {launcher}"
    );
    // The run's own processes end too (they watch their parent); what they leave is reaped
    // by the next command once they are gone.
    assert!(
        fdi_tests::wait_until(Duration::from_secs(30), || others
            .iter()
            .all(|p| !fdi_tests::alive(*p))),
        "orphans: {others:?}"
    );
    // The next command reaps what the killed launcher left of its run.
    let v = fdi_tests::launch_plain(&["validate", &scenario.to_string_lossy()], WATCHDOG);
    assert!(v.status.success(), "{}", String::from_utf8_lossy(&v.stderr));
    fdi_tests::assert_no_leftovers(launcher);
}
