//! The multi-process runtime, through the real binaries: each test has its own run prefix
//! (the launcher's pid) and output folder, and a watchdog; none asserts a wall time.

use std::time::Duration;

use fdi_tests::{
    alive, children_of, json, launch, leftovers_of, signal, spawn, wait_until, wait_with_watchdog,
    Scratch,
};

const WATCHDOG: Duration = Duration::from_secs(300);

#[test]
fn lockstep_ipc_digest_equals_the_in_process_digest() {
    let dir = Scratch::new("digest");
    let out = dir.0.to_string_lossy().into_owned();
    let ipc = json(&launch(
        &["run", "--duration-s", "3", "--json"],
        dir.0.as_path(),
        WATCHDOG,
    ));
    let inproc = json(&launch(
        &["run", "--duration-s", "3", "--engine", "inproc", "--json"],
        dir.0.as_path(),
        WATCHDOG,
    ));
    assert_eq!(ipc["engine"], "ipc");
    assert_eq!(ipc["trace_digest"], inproc["trace_digest"], "under {out}");
    assert_eq!(ipc["rmse_rad"], inproc["rmse_rad"]);
    assert_eq!(ipc["ticks"], 3000);
    // The run directory holds what SPEC §7 lists.
    let run_dir = std::path::PathBuf::from(ipc["run_dir"].as_str().expect("run_dir"));
    for f in [
        "scenario.toml",
        "summary.json",
        "rmse.md",
        "rmse.csv",
        "traces/attacker.trace",
        "traces/control-center.trace",
        "traces/agent-4.trace",
    ] {
        assert!(
            run_dir.join(f).is_file(),
            "missing {f} in {}",
            run_dir.display()
        );
    }
}

#[test]
fn two_runs_at_once_do_not_interfere() {
    let dir = Scratch::new("concurrent");
    let args = ["run", "--duration-s", "2", "--json"];
    let a = spawn(&args, &dir.0);
    let b = spawn(
        &["run", "--duration-s", "2", "--json", "--attack", "none"],
        &dir.0,
    );
    let (a, b) = (
        json(&wait_with_watchdog(a, WATCHDOG)),
        json(&wait_with_watchdog(b, WATCHDOG)),
    );
    let solo_a = json(&launch(
        &["run", "--duration-s", "2", "--json", "--engine", "inproc"],
        &dir.0,
        WATCHDOG,
    ));
    let solo_b = json(&launch(
        &[
            "run",
            "--duration-s",
            "2",
            "--json",
            "--engine",
            "inproc",
            "--attack",
            "none",
        ],
        &dir.0,
        WATCHDOG,
    ));
    assert_eq!(a["trace_digest"], solo_a["trace_digest"]);
    assert_eq!(b["trace_digest"], solo_b["trace_digest"]);
    assert_ne!(
        a["trace_digest"], b["trace_digest"],
        "the two runs differ in their attack"
    );
}

#[test]
fn realtime_smoke_run_completes_and_reports_deadline_misses() {
    let dir = Scratch::new("realtime");
    let out = launch(
        &["run", "--clock", "realtime", "--duration-s", "1", "--json"],
        &dir.0,
        WATCHDOG,
    );
    let v = json(&out);
    assert_eq!(v["clock"], "realtime");
    assert_eq!(v["ticks"], 1000);
    for id in ["1", "2", "3", "4"] {
        assert!(
            v["metrics"][id]["deadline_misses"].is_u64(),
            "deadline misses of agent {id}: {}",
            v["metrics"][id]
        );
        assert!(v["rmse_rad"][id].as_f64().is_some_and(f64::is_finite));
    }
}

#[test]
fn killing_an_agent_stops_the_run_naming_it_and_leaves_nothing_behind() {
    let dir = Scratch::new("kill-agent");
    let mut child = spawn(&["run", "--duration-s", "600"], &dir.0);
    let launcher = child.id();
    let mut victim = None;
    assert!(
        wait_until(Duration::from_secs(60), || {
            victim = children_of(launcher)
                .into_iter()
                .find(|(_, cmd)| cmd.contains("--agent 2"));
            victim.is_some()
        }),
        "agent 2 never started"
    );
    let (pid, _) = victim.expect("agent 2");
    // Let the run get going, then kill the agent the hard way.
    std::thread::sleep(Duration::from_millis(300));
    let others: Vec<u32> = children_of(launcher)
        .into_iter()
        .map(|c| c.0)
        .filter(|p| *p != pid)
        .collect();
    signal(pid, "-KILL");
    let status = loop {
        if let Some(st) = child.try_wait().expect("poll") {
            break st;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut stderr = String::new();
    if let Some(mut e) = child.stderr.take() {
        use std::io::Read;
        let _ = e.read_to_string(&mut stderr);
    }
    assert!(!status.success(), "the launcher must fail the run");
    assert!(
        stderr.contains("agent 2") && stderr.contains("SIGKILL"),
        "stderr: {stderr}"
    );
    assert!(
        wait_until(Duration::from_secs(5), || others.iter().all(|p| !alive(*p))),
        "processes left: {:?}",
        others.iter().filter(|p| alive(**p)).collect::<Vec<_>>()
    );
    assert!(
        leftovers_of(launcher).is_empty(),
        "{:?}",
        leftovers_of(launcher)
    );
}

#[test]
fn ctrl_c_stops_every_process_and_removes_the_shared_memory() {
    let dir = Scratch::new("ctrl-c");
    let child = spawn(&["run", "--duration-s", "600"], &dir.0);
    let launcher = child.id();
    assert!(
        wait_until(Duration::from_secs(60), || children_of(launcher).len() == 6),
        "the six processes never started"
    );
    std::thread::sleep(Duration::from_millis(300));
    let procs: Vec<u32> = children_of(launcher).into_iter().map(|c| c.0).collect();
    signal(launcher, "-INT");
    let out = wait_with_watchdog(child, WATCHDOG);
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("interrupted"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        procs.iter().all(|p| !alive(*p)),
        "processes left: {procs:?}"
    );
    assert!(
        leftovers_of(launcher).is_empty(),
        "{:?}",
        leftovers_of(launcher)
    );
}
