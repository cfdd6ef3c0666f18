//! Replay, through the real binary: `run --replay RUN_DIR` (the recorded control center's golden
//! regression) and the `replay` attack waveform on both engines.

use std::time::Duration;

use fdi_tests::{json, launch, repo_path, run_dir_of, Scratch};

const WATCHDOG: Duration = Duration::from_secs(300);

#[test]
fn replaying_a_recorded_run_reproduces_its_trace_digest() {
    let dir = Scratch::new("replay-run");
    let recorded = json(&launch(
        &["run", "--duration-s", "2", "--json"],
        &dir.0,
        WATCHDOG,
    ));
    let rec_dir = run_dir_of(&recorded);
    let rec_arg = rec_dir.to_string_lossy().into_owned();
    let replayed = json(&launch(
        &["run", "--replay", &rec_arg, "--json"],
        &dir.0,
        WATCHDOG,
    ));
    assert_eq!(replayed["trace_digest"], recorded["trace_digest"]);
    assert_eq!(replayed["recorded_trace_digest"], recorded["trace_digest"]);
    assert_eq!(replayed["digests_match"], true);
    assert_eq!(replayed["engine"], "replay");
    assert_eq!(replayed["ticks"], 2000);
    let new_dir = run_dir_of(&replayed);
    assert_ne!(new_dir, rec_dir);
    for f in [
        "summary.json",
        "traces/attacker.trace",
        "traces/control-center.trace",
        "traces/agent-1.trace",
        "traces/agent-4.trace",
    ] {
        assert!(new_dir.join(f).is_file(), "missing {f}");
    }

    // A recording whose digest does not match what its center produces: non-zero exit.
    let summary = fdi_common::run_dir::RunDir::new(&rec_dir).summary();
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).expect("summary")).expect("json");
    v["trace_digest"] = serde_json::Value::String("0".repeat(64));
    std::fs::write(&summary, v.to_string()).expect("rewriting summary");
    let out = launch(&["run", "--replay", &rec_arg, "--json"], &dir.0, WATCHDOG);
    assert!(!out.status.success(), "a differing digest must fail");
    assert!(String::from_utf8_lossy(&out.stderr).contains("differs"));

    // A damaged attacker trace is refused, naming the file.
    let attacker = rec_dir.join("traces/attacker.trace");
    let bytes = std::fs::read(&attacker).expect("attacker trace");
    std::fs::write(&attacker, &bytes[..bytes.len() / 2]).expect("truncating");
    let out = launch(&["run", "--replay", &rec_arg], &dir.0, WATCHDOG);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("attacker.trace"), "{err}");

    // A missing agent trace too.
    std::fs::write(&attacker, &bytes).expect("restoring");
    std::fs::remove_file(rec_dir.join("traces/agent-3.trace")).expect("removing");
    let out = launch(&["run", "--replay", &rec_arg], &dir.0, WATCHDOG);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("agent-3.trace"), "{err}");
}

#[test]
fn replay_waveform_runs_alike_on_both_engines_and_replays() {
    let dir = Scratch::new("replay-waveform");
    let profile = repo_path("scenarios/attacks/replay-example.toml");
    let profile = profile.to_string_lossy().into_owned();
    let run = |engine: &str| {
        json(&launch(
            &[
                "run",
                "--engine",
                engine,
                "--attack",
                &profile,
                "--duration-s",
                "8",
                "--json",
            ],
            &dir.0,
            WATCHDOG,
        ))
    };
    let ipc = run("ipc");
    let inproc = run("inproc");
    assert_eq!(ipc["attack"], "replay-example");
    assert_eq!(ipc["ticks"], 8000);
    assert_eq!(ipc["trace_digest"], inproc["trace_digest"]);
    assert_eq!(ipc["rmse_rad"], inproc["rmse_rad"]);
    // The replay starts at 6 s: robot 1 is attacked once, there.
    assert_eq!(ipc["metrics"]["1"]["onsets"][0]["t_s"], 6.0);

    // The recorded run replays to the same digest.
    let rec = run_dir_of(&ipc).to_string_lossy().into_owned();
    let replayed = json(&launch(
        &["run", "--replay", &rec, "--json"],
        &dir.0,
        WATCHDOG,
    ));
    assert_eq!(replayed["trace_digest"], ipc["trace_digest"]);
}
