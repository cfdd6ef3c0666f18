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
    let mut v: Vec<String> = std::fs::read_dir(fdi_common::run_dir::RunDir::new(dir).traces())
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
    serde_json::from_str(
        &std::fs::read_to_string(fdi_common::run_dir::RunDir::new(dir).summary()).expect("summary"),
    )
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
                    let (kept, ticks, n) =
                        ticks_of(&fdi_common::run_dir::RunDir::new(&dir).traces().join(f));
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
    std::fs::create_dir_all(fdi_common::run_dir::RunDir::new(&other).traces()).expect("mkdir");
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
    assert!(
        text.contains("1 output folders in") && text.contains("(1 run)"),
        "{text}"
    );
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

/// The folder names in `dir` (hidden ones too), sorted; none when it does not exist.
fn names_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|d| {
            d.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// A copy of the run directory `run` (scenario, summary, traces) at `at/run` on a tmpfs with
/// about `room` bytes to spare: a disk that fills up as soon as an export writes more. `None`
/// (the test is skipped, saying why) where the test cannot mount.
fn on_a_small_disk(
    run: &Path,
    at: &Path,
    room: u64,
) -> Option<(fdi_tests::mounts::Mount, std::path::PathBuf)> {
    let page = |n: u64| n.div_ceil(4096) * 4096;
    let mut files = vec![
        fdi_common::run_dir::RunDir::new(run).scenario(),
        fdi_common::run_dir::RunDir::new(run).summary(),
    ];
    files.extend(
        trace_files(run)
            .iter()
            .map(|f| fdi_common::run_dir::RunDir::new(run).traces().join(f)),
    );
    let used: u64 = files
        .iter()
        .map(|f| page(std::fs::metadata(f).expect("a file of the run").len()))
        .sum();
    let mount = match fdi_tests::mounts::Mount::tmpfs(at, used + room) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("{}", fdi_tests::mounts::skip_reason(&e));
            return None;
        }
    };
    let copy = at.join("run");
    std::fs::create_dir_all(fdi_common::run_dir::RunDir::new(&copy).traces())
        .expect("the copy's folders");
    for f in &files {
        let rel = f.strip_prefix(run).expect("in the run");
        std::fs::copy(f, copy.join(rel)).expect("the run fits on the small disk");
    }
    Some((mount, copy))
}

/// What an earlier export left in `RUN_DIR/export`, which a failed export must not touch.
const EARLIER: [(&str, &str); 2] = [
    ("run.mcap", "an earlier MCAP export\n"),
    ("agent-1.csv", "an earlier CSV export\n"),
];

fn earlier_export(run: &Path) {
    std::fs::create_dir_all(run.join("export")).expect("export/");
    for (name, text) in EARLIER {
        std::fs::write(run.join("export").join(name), text).expect("an earlier export");
    }
}

fn assert_only_the_earlier_export(run: &Path, what: &str) {
    let names: Vec<&str> = EARLIER.iter().map(|(n, _)| *n).collect();
    let mut want = names.clone();
    want.sort_unstable();
    assert_eq!(names_in(&run.join("export")), want, "{what}");
    for (name, text) in EARLIER {
        let got = std::fs::read_to_string(run.join("export").join(name)).expect("still there");
        assert_eq!(got, text, "{what}: {name} was changed");
    }
}

/// Regression (issue 29): an MCAP export into a full disk said "attempted another write after a
/// write method failed" without naming ENOSPC and left a partial `run.mcap`. It names the file
/// and the cause, and leaves nothing: no `export/` it made, an earlier `run.mcap` untouched.
#[test]
fn mcap_export_into_a_full_disk_leaves_no_partial_file_and_names_enospc() {
    let out = Scratch::new("export-full-mcap");
    let s = run(&out.0, "1", &["--engine", "inproc"]);
    // ~2.5 MB of traces, ~10 MB of MCAP: 256 KiB to spare is full long before the end.
    let Some((_disk, run_dir)) = on_a_small_disk(&run_dir_of(&s), &out.0.join("disk"), 256 << 10)
    else {
        return;
    };
    let d = run_dir.to_string_lossy().into_owned();
    for earlier in [false, true] {
        if earlier {
            earlier_export(&run_dir);
        }
        let o = fdi_tests::launch_plain(&["trace", "export", &d, "--format", "mcap"], WATCHDOG);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "the export into a full disk succeeded");
        let file = run_dir.join("export/run.mcap");
        assert!(
            err.contains(&format!(
                "writing {}: no space left on device (ENOSPC)",
                file.display()
            )) && err.contains("abandoned"),
            "{err}"
        );
        assert!(!err.contains("attempted another write"), "{err}");
        if earlier {
            assert_only_the_earlier_export(&run_dir, "MCAP");
        } else {
            assert!(
                !run_dir.join("export").exists(),
                "{:?}",
                names_in(&run_dir.join("export"))
            );
        }
    }
}

/// Regression (issue 29): a CSV export into a full disk left a half-written `export/`. It names
/// the file and the cause, and leaves nothing: no `export/` it made, earlier files untouched.
#[test]
fn csv_export_into_a_full_disk_leaves_no_partial_export() {
    let out = Scratch::new("export-full-csv");
    let s = run(&out.0, "1", &["--engine", "inproc"]);
    let Some((_disk, run_dir)) = on_a_small_disk(&run_dir_of(&s), &out.0.join("disk"), 256 << 10)
    else {
        return;
    };
    let d = run_dir.to_string_lossy().into_owned();
    for earlier in [false, true] {
        if earlier {
            earlier_export(&run_dir);
        }
        let o = fdi_tests::launch_plain(&["trace", "export", &d, "--format", "csv"], WATCHDOG);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "the export into a full disk succeeded");
        let export = run_dir.join("export").display().to_string();
        assert!(
            err.contains(&format!("writing {export}/"))
                && err.contains(".csv: no space left on device (ENOSPC)")
                && err.contains("abandoned"),
            "{err}"
        );
        if earlier {
            assert_only_the_earlier_export(&run_dir, "CSV");
        } else {
            assert!(
                !run_dir.join("export").exists(),
                "{:?}",
                names_in(&run_dir.join("export"))
            );
        }
    }
}

/// What keeps a folder's files from being removed, undone on drop: a read-only mount as root
/// (root may delete anything else), a folder without write permission otherwise.
enum Stubborn {
    Mounted {
        _undone_on_drop: fdi_tests::mounts::Mount,
    },
    ReadOnly(Vec<std::path::PathBuf>),
}

impl Stubborn {
    /// `dir`'s files cannot be removed; `moved`: where `dir` may be by the time this is
    /// undone. `None` (the test is skipped, saying why) where that cannot be made.
    fn make(dir: &Path, moved: std::path::PathBuf) -> Option<Self> {
        use std::os::unix::fs::{MetadataExt, PermissionsExt};
        let root = std::fs::metadata("/proc/self").is_ok_and(|m| m.uid() == 0);
        if !root {
            let ro = std::fs::Permissions::from_mode(0o555);
            std::fs::set_permissions(dir, ro).expect("chmod");
            return Some(Self::ReadOnly(vec![dir.to_path_buf(), moved]));
        }
        match fdi_tests::mounts::Mount::read_only(dir) {
            Ok(mut m) => {
                m.also_at(moved);
                Some(Self::Mounted { _undone_on_drop: m })
            }
            Err(e) => {
                eprintln!("{}", fdi_tests::mounts::skip_reason(&e));
                None
            }
        }
    }
}

impl Drop for Stubborn {
    fn drop(&mut self) {
        use std::os::unix::fs::PermissionsExt;
        if let Self::ReadOnly(dirs) = self {
            for d in dirs.iter() {
                let _ = std::fs::set_permissions(d, std::fs::Permissions::from_mode(0o755));
            }
        }
    }
}

/// Regression (issue 29): `runs prune` that met a file it could not delete stopped, left that
/// run directory half-removed and no longer listed, and skipped the older ones. It names the
/// path and the cause, removes the older ones all the same, leaves a tombstone that `runs list`
/// shows, and the next prune removes it.
#[test]
fn prune_continues_past_a_file_it_cannot_remove() {
    let out = Scratch::new("prune-stubborn");
    let mut dirs = Vec::new();
    for _ in 0..3 {
        let s = run(&out.0, "0.05", &["--engine", "inproc"]);
        dirs.push(run_dir_of(&s));
        std::thread::sleep(Duration::from_millis(30));
    }
    let name = dirs[1]
        .file_name()
        .expect("a name")
        .to_string_lossy()
        .into_owned();
    let tomb = out.0.join(format!("{name}.pruning"));
    let Some(stubborn) = Stubborn::make(
        &fdi_common::run_dir::RunDir::new(&dirs[1]).traces(),
        fdi_common::run_dir::RunDir::new(&tomb).traces(),
    ) else {
        return;
    };
    let root = out.0.to_string_lossy().into_owned();
    let o = fdi_tests::launch_plain(&["runs", "prune", "--keep", "1", "--out", &root], WATCHDOG);
    let (text, err) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(
        !o.status.success(),
        "a prune that left a run succeeded: {text}"
    );
    let cause = match &stubborn {
        Stubborn::Mounted { .. } => "read-only file system (EROFS)",
        Stubborn::ReadOnly(_) => "permission denied (EACCES)",
    };
    // Each trace file is named (in the order the folder lists them) with the cause.
    let traces = format!(
        "could not remove {}/",
        fdi_common::run_dir::RunDir::new(&tomb).traces().display()
    );
    assert!(
        err.lines()
            .any(|l| l.contains(&traces) && l.ends_with(&format!(".trace: {cause}"))),
        "{err}"
    );
    assert!(
        err.contains(&format!("stays as {}", tomb.display())),
        "{err}"
    );
    assert!(text.contains("removed 1 run directories"), "{text}");
    assert!(!dirs[0].exists(), "the older run was skipped");
    assert!(dirs[2].is_dir(), "the newest run was removed");
    assert!(!dirs[1].exists() && tomb.is_dir());
    let o = fdi_tests::launch_plain(&["runs", "list", "--out", &root], WATCHDOG);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        text.contains(&format!("{name}.pruning")) && text.contains("half-removed"),
        "{text}"
    );
    assert!(text.contains("(1 run, 1 half-removed)"), "{text}");
    drop(stubborn);
    let o = fdi_tests::launch_plain(&["runs", "prune", "--keep", "1", "--out", &root], WATCHDOG);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        text.contains(&format!("removed {}", tomb.display())),
        "{text}"
    );
    assert!(!tomb.exists() && dirs[2].is_dir());
}

/// The Actuation records of the attacker's trace of the run `summary`, in the trace's order.
fn actuations(summary: &serde_json::Value) -> Vec<fdi_common::records::ActuationRecord> {
    let dir = run_dir_of(summary);
    let path = fdi_common::run_dir::RunDir::new(&dir).trace(fdi_common::run_dir::Process::Attacker);
    TraceReader::open(&path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .filter_map(|r| match r {
            Ok(TraceRecord::Actuation(a)) => Some(a),
            Ok(_) => None,
            Err(e) => panic!("{}: {e}", path.display()),
        })
        .collect()
}

#[test]
fn both_engines_record_the_torque_path_of_an_attacked_robot_alike() {
    let out = Scratch::new("traces-actuation");
    let args = ["--attack", "actuator-bias"];
    let inproc = run(&out.0, "1", &[&["--engine", "inproc"][..], &args].concat());
    let ipc = run(&out.0, "1", &[&["--engine", "ipc"][..], &args].concat());
    assert_eq!(inproc["trace_digest"], ipc["trace_digest"]);
    let (a, b) = (actuations(&inproc), actuations(&ipc));
    // Robot 1's torque path, every tick of the second.
    assert_eq!(a.len(), 1000, "in-process: {} records", a.len());
    assert!(a.iter().all(|r| r.agent == 1));
    assert_eq!(
        a, b,
        "the in-process engine's torque-path records are the processes'"
    );
}
