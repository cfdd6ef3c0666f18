//! Trace volume, through the real binary: `run --traces full|decimate=K|none` on both engines
//! (same digest and metrics as `full`, the kept ticks exactly), the size estimate refused
//! before a run directory exists, `runs prune`, and the consumers that need every tick.

use std::collections::BTreeSet;
use std::path::Path;
use std::time::Duration;

use fdi_common::trace::{Kept, TraceReader, TraceRecord};
use fdi_tests::{json, json_realtime, launch, run_dir_of, Scratch};

const WATCHDOG: Duration = Duration::from_secs(300);

/// `run --json` of the paper scenario for `duration` s with `extra` flags.
fn run(out: &Path, duration: &str, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["run", "--duration-s", duration, "--json"];
    args.extend(extra);
    json(&launch(&args, out, WATCHDOG))
}

/// The ticks of every record (events left out) of a trace, and its header's `kept`.
fn ticks_of(path: &Path) -> (Kept, BTreeSet<u64>, usize) {
    let r = TraceReader::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let kept = r.header().kept;
    let mut ticks = BTreeSet::new();
    let mut n = 0;
    for rec in r {
        let rec = rec.unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        if let Some(k) = rec.tick() {
            ticks.insert(k);
        }
        if !matches!(rec, TraceRecord::Event { .. }) {
            n += 1;
        }
    }
    (kept, ticks, n)
}

fn trace_files(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir.join("traces"))
        .map(|d| {
            d.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

fn summary_file(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).expect("summary"))
        .expect("json")
}

#[test]
fn every_traces_value_on_both_engines_gives_the_digest_and_metrics_of_full() {
    let out = Scratch::new("traces-values");
    let full = run(&out.0, "1", &["--engine", "inproc"]);
    let digest = full["trace_digest"].clone();
    assert_eq!(full["ticks"], 1000);
    for engine in ["inproc", "ipc"] {
        for traces in ["full", "decimate=7", "none"] {
            let s = run(&out.0, "1", &["--engine", engine, "--traces", traces]);
            let tag = format!("{engine} {traces}");
            assert_eq!(s["trace_digest"], digest, "{tag}");
            assert_eq!(s["metrics"], full["metrics"], "{tag}");
            assert_eq!(s["rmse_rad"], full["rmse_rad"], "{tag}");
            assert_eq!(s["ticks"], full["ticks"], "{tag}");
            let dir = run_dir_of(&s);
            assert_eq!(summary_file(&dir)["traces"], traces, "{tag}");
            let files = trace_files(&dir);
            match traces {
                "none" => assert!(files.is_empty(), "{tag}: {files:?}"),
                _ => {
                    assert_eq!(
                        files,
                        vec![
                            "agent-1.trace",
                            "agent-2.trace",
                            "agent-3.trace",
                            "agent-4.trace",
                            "attacker.trace",
                            "control-center.trace"
                        ],
                        "{tag}: no pipe is left behind"
                    );
                }
            }
            if traces == "decimate=7" {
                let want: BTreeSet<u64> = (0..1000).step_by(7).collect();
                for f in &files {
                    let (kept, ticks, n) = ticks_of(&dir.join("traces").join(f));
                    assert_eq!(kept, Kept::Decimate { every: 7 }, "{tag} {f}");
                    assert_eq!(ticks, want, "{tag} {f}: exactly the ticks 0, 7, 14, …");
                    let per_tick = if f.starts_with("agent") { 1 } else { 4 };
                    assert_eq!(
                        n,
                        want.len() * per_tick,
                        "{tag} {f}: every record of those ticks"
                    );
                }
                // The report draws its figures from them, and says so.
                let md = std::fs::read_to_string(dir.join("report/report.md")).expect("report");
                assert!(md.contains("decimated traces"), "{md}");
                assert!(std::fs::read_dir(dir.join("report"))
                    .expect("report dir")
                    .flatten()
                    .any(|e| e.file_name().to_string_lossy().ends_with(".png")));
            }
            if traces == "none" {
                let md = std::fs::read_to_string(dir.join("report/report.md")).expect("report");
                assert!(md.contains("No figures: the run kept no traces"), "{md}");
                assert!(!std::fs::read_dir(dir.join("report"))
                    .expect("report dir")
                    .flatten()
                    .any(|e| e.file_name().to_string_lossy().ends_with(".png")));
            }
        }
    }
}

#[test]
fn detect_and_replay_refuse_decimated_or_missing_traces_and_export_exports_what_is_there() {
    let out = Scratch::new("traces-refusals");
    for traces in ["decimate=10", "none"] {
        let s = run(&out.0, "0.5", &["--traces", traces]);
        let dir = run_dir_of(&s);
        let d = dir.to_string_lossy().into_owned();
        let o = launch(&["detect", &d], &out.0, WATCHDOG);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{traces}: detect must refuse");
        assert!(
            err.contains("needs every tick") && err.contains("--traces full"),
            "{traces}: {err}"
        );
        let o = launch(&["run", "--replay", &d], &out.0, WATCHDOG);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{traces}: replay must refuse");
        assert!(err.contains("needs every tick"), "{traces}: {err}");
        // The report of the run directory is made again from what is there.
        let o = fdi_tests::launch_plain(&["report", &d], WATCHDOG);
        assert!(
            o.status.success(),
            "{traces}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        if traces == "decimate=10" {
            let o = fdi_tests::launch_plain(&["trace", "export", &d], WATCHDOG);
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        }
    }
}

#[test]
fn an_oversized_run_is_refused_before_its_run_directory_exists_and_the_limit_can_be_lifted() {
    let out = Scratch::new("traces-estimate");
    let runs = out.0.join("runs");
    let o = launch(&["run", "--duration-s", "1e6"], &runs, WATCHDOG);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("refused before the start") && err.contains("--traces none"),
        "{err}"
    );
    assert!(!runs.exists(), "no run directory, not even its folder");
    // A 2 s run (~2.5 MB of traces) is over a 1 MB limit, and within a 100MB one.
    let o = launch(
        &["run", "--duration-s", "2", "--max-trace-size", "1MB"],
        &runs,
        WATCHDOG,
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("--max-trace-size"), "{err}");
    assert!(!runs.exists());
    let s = run(
        &runs,
        "2",
        &["--engine", "inproc", "--max-trace-size", "100MB"],
    );
    assert_eq!(s["ticks"], 2000);
    let o = launch(&["run", "--max-trace-size", "lots"], &runs, WATCHDOG);
    assert!(!o.status.success(), "a size that is not one is refused");
}

#[test]
fn runs_prune_keeps_the_newest_and_never_touches_a_folder_that_is_not_a_run() {
    let out = Scratch::new("traces-prune");
    let mut dirs = Vec::new();
    for _ in 0..3 {
        let s = run(&out.0, "0.05", &["--engine", "inproc"]);
        dirs.push(run_dir_of(&s));
        std::thread::sleep(Duration::from_millis(30));
    }
    let other = out.0.join("my-notes");
    std::fs::create_dir_all(other.join("traces")).expect("mkdir");
    std::fs::write(other.join("notes.txt"), "mine").expect("write");
    let root = out.0.to_string_lossy().into_owned();
    let o = fdi_tests::launch_plain(
        &["runs", "prune", "--keep", "1", "--out", &root, "--dry-run"],
        WATCHDOG,
    );
    assert!(o.status.success());
    assert!(dirs.iter().all(|d| d.is_dir()), "a dry run removes nothing");
    let o = fdi_tests::launch_plain(&["runs", "prune", "--keep", "1", "--out", &root], WATCHDOG);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(text.contains("removed 2 run directories"), "{text}");
    assert!(dirs[2].is_dir() && !dirs[1].exists() && !dirs[0].exists());
    assert!(other.join("notes.txt").is_file());
    let o = fdi_tests::launch_plain(&["runs", "list", "--out", &root], WATCHDOG);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("1 run directories"), "{text}");
}

#[test]
fn realtime_run_with_traces_none_over_ipc_completes_with_its_metrics() {
    let out = Scratch::new("traces-realtime");
    let o = launch(
        &[
            "run",
            "--clock",
            "realtime",
            "--duration-s",
            "2",
            "--traces",
            "none",
            "--json",
        ],
        &out.0,
        WATCHDOG,
    );
    let s = json_realtime(&o);
    assert_eq!(s["clock"], "realtime");
    assert_eq!(s["metrics"].as_object().map(|m| m.len()), Some(4));
    assert!(s["ticks"].as_u64().is_some_and(|t| t > 0));
    let dir = run_dir_of(&s);
    assert!(trace_files(&dir).is_empty());
}
