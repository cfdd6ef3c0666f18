//! Reports, table outputs and the CSV export of run directories, through the real binary.
//! Every test has its own scratch folder and a watchdog; none asserts a wall time.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use fdi_common::records::Joints;
use fdi_common::trace::{TraceReader, TraceRecord};
use fdi_tests::{json, launch, launch_plain, run_dir_of, Scratch};

const WATCHDOG: Duration = Duration::from_secs(300);
const ROBOTS: [u32; 4] = [1, 2, 3, 4];
/// The paper's four figures (Figs. 3–6) and the two extra ones, per robot.
const FIGURES: [&str; 6] = [
    "position-error",
    "velocity-error",
    "attack-estimate",
    "acceleration-error",
    "torque",
    "delay-alarm",
];

fn stderr(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Every file the report promises, with the right signatures.
fn assert_report_complete(run_dir: &Path) {
    let report = run_dir.join("report");
    for id in ROBOTS {
        for f in FIGURES {
            let png = report.join(format!("robot{id}-{f}.png"));
            let bytes = std::fs::read(&png).unwrap_or_else(|e| panic!("{}: {e}", png.display()));
            assert!(
                bytes.starts_with(b"\x89PNG\r\n\x1a\n") && bytes.len() > 5_000,
                "{} is not a drawn PNG",
                png.display()
            );
            let svg = report.join(format!("robot{id}-{f}.svg"));
            let text =
                std::fs::read_to_string(&svg).unwrap_or_else(|e| panic!("{}: {e}", svg.display()));
            assert!(
                text.starts_with("<svg") && text.contains("<polyline") && text.contains("<text"),
                "{} is not a drawn SVG",
                svg.display()
            );
        }
    }
    let md = std::fs::read_to_string(report.join("report.md")).expect("report.md");
    for id in ROBOTS {
        assert!(
            md.contains(&format!("## Robot {id}")),
            "robot {id} in:\n{md}"
        );
        for f in FIGURES {
            assert!(
                md.contains(&format!("(robot{id}-{f}.png)")),
                "robot{id}-{f}.png linked in:\n{md}"
            );
        }
    }
    for section in ["## RMSE", "## Detection", "trace digest", "| seed |"] {
        assert!(md.contains(section), "{section} in:\n{md}");
    }
    for f in ["detection.csv", "segments.csv"] {
        assert!(report.join(f).is_file(), "missing report/{f}");
    }
}

#[test]
fn ipc_run_writes_every_report_file_and_report_remakes_them() {
    let dir = Scratch::new("report-ipc");
    let summary = json(&launch(
        &["run", "--duration-s", "2", "--json"],
        &dir.0,
        WATCHDOG,
    ));
    let run_dir = run_dir_of(&summary);
    assert_report_complete(&run_dir);
    let digest = summary["trace_digest"].as_str().expect("digest");
    let md = std::fs::read_to_string(run_dir.join("report/report.md")).expect("report.md");
    assert!(
        md.contains(digest) && md.contains("| engine | ipc |"),
        "{md}"
    );

    // The standalone command rebuilds the same report from the run directory alone.
    std::fs::remove_dir_all(run_dir.join("report")).expect("remove report");
    let out = launch_plain(&["report", run_dir.to_str().expect("utf-8 path")], WATCHDOG);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_report_complete(&run_dir);
    let again = std::fs::read_to_string(run_dir.join("report/report.md")).expect("report.md");
    assert!(again.contains(digest) && again.contains("| engine | ipc |"));
    assert!(!again.contains("## Warnings"), "{again}");
}

#[test]
fn inproc_run_writes_every_report_file() {
    let dir = Scratch::new("report-inproc");
    let summary = json(&launch(
        &["run", "--duration-s", "2", "--engine", "inproc", "--json"],
        &dir.0,
        WATCHDOG,
    ));
    let run_dir = run_dir_of(&summary);
    assert_report_complete(&run_dir);
    let md = std::fs::read_to_string(run_dir.join("report/report.md")).expect("report.md");
    assert!(md.contains("| engine | inproc |"), "{md}");
}

#[test]
fn tables_write_markdown_csv_json_and_a_bar_chart() {
    let dir = Scratch::new("tables");
    for table in ["table1", "table2"] {
        let out = launch(
            &[table, "--engine", "inproc", "--duration-s", "1"],
            &dir.0,
            WATCHDOG,
        );
        assert!(out.status.success(), "{table}: {}", stderr(&out));
        let folder = std::fs::read_dir(&dir.0)
            .expect("out folder")
            .flatten()
            .map(|e| e.path())
            .find(|p| p.to_string_lossy().ends_with(&format!("-{table}")))
            .unwrap_or_else(|| panic!("no {table} folder in {}", dir.0.display()));
        for ext in ["md", "csv", "json", "png", "svg"] {
            let f = folder.join(format!("{table}.{ext}"));
            assert!(
                std::fs::metadata(&f).is_ok_and(|m| m.len() > 0),
                "missing {}",
                f.display()
            );
        }
        let csv = std::fs::read_to_string(folder.join(format!("{table}.csv"))).expect("csv");
        assert_eq!(csv.lines().count(), 5, "header and four rows:\n{csv}");
        let v: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(folder.join(format!("{table}.json"))).expect("json"),
        )
        .expect("valid JSON");
        assert_eq!(v["rows"].as_array().map(Vec::len), Some(4));
    }
}

/// Rows of a numeric CSV file as (header, rows of fields).
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header = lines
        .next()
        .unwrap_or_else(|| panic!("{} is empty", path.display()))
        .split(',')
        .map(str::to_string)
        .collect::<Vec<_>>();
    let rows = lines
        .map(|l| l.split(',').map(str::to_string).collect::<Vec<_>>())
        .collect::<Vec<_>>();
    for r in &rows {
        assert_eq!(
            r.len(),
            header.len(),
            "{}: ragged row {r:?}",
            path.display()
        );
    }
    (header, rows)
}

/// One row as column name → text.
fn fields<'a>(header: &'a [String], row: &'a [String]) -> BTreeMap<&'a str, &'a str> {
    header
        .iter()
        .map(String::as_str)
        .zip(row.iter().map(String::as_str))
        .collect()
}

fn f64_bits(row: &BTreeMap<&str, &str>, col: &str) -> u64 {
    let s = row.get(col).unwrap_or_else(|| panic!("no column {col}"));
    s.parse::<f64>()
        .unwrap_or_else(|e| panic!("{col} = {s:?}: {e}"))
        .to_bits()
}

fn int(row: &BTreeMap<&str, &str>, col: &str) -> u64 {
    let s = row.get(col).unwrap_or_else(|| panic!("no column {col}"));
    s.parse::<u64>()
        .unwrap_or_else(|e| panic!("{col} = {s:?}: {e}"))
}

fn flag(row: &BTreeMap<&str, &str>, col: &str) -> bool {
    match row.get(col).copied() {
        Some("1") => true,
        Some("0") => false,
        other => panic!("{col} = {other:?}"),
    }
}

fn same_joints(row: &BTreeMap<&str, &str>, name: &str, j: &Joints) {
    for (i, x) in j.as_slice().iter().enumerate() {
        let col = format!("{name}{}", i + 1);
        assert_eq!(f64_bits(row, &col), x.to_bits(), "{col}");
    }
}

/// Compares one CSV row with the trace record it came from, bit for bit.
fn assert_row_is_record(row: &BTreeMap<&str, &str>, rec: &TraceRecord) {
    match rec {
        TraceRecord::Agent(a) => {
            assert_eq!(int(row, "k"), a.k);
            assert_eq!(int(row, "agent"), u64::from(a.agent));
            assert_eq!(f64_bits(row, "t"), a.t.to_bits());
            for (name, j) in [
                ("q", &a.q),
                ("qd", &a.qd),
                ("qdd", &a.qdd),
                ("y", &a.y),
                ("yd", &a.yd),
                ("u_applied", &a.u_applied),
            ] {
                same_joints(row, name, j);
            }
            assert_eq!(f64_bits(row, "tau"), a.tau.to_bits());
            assert_eq!(flag(row, "missed"), a.missed);
        }
        TraceRecord::Attack(a) => {
            assert_eq!(int(row, "k"), a.k);
            assert_eq!(int(row, "agent"), u64::from(a.agent));
            for (name, j) in [
                ("alpha_position", &a.alpha_position),
                ("alpha_velocity", &a.alpha_velocity),
                ("y", &a.y),
                ("yd", &a.yd),
            ] {
                same_joints(row, name, j);
            }
            assert_eq!(flag(row, "active"), a.active);
        }
        TraceRecord::Center(c) => {
            assert_eq!(int(row, "k"), c.k);
            assert_eq!(int(row, "agent"), u64::from(c.agent));
            for (name, j) in [
                ("s_hat", &c.s_hat),
                ("q_hat", &c.q_hat),
                ("qd_hat", &c.qd_hat),
                ("qdd_hat", &c.qdd_hat),
                ("u", &c.u),
            ] {
                same_joints(row, name, j);
            }
            assert_eq!(flag(row, "alarm"), c.alarm);
            assert_eq!(flag(row, "rejected_input"), c.rejected_input);
        }
        TraceRecord::Latency { k, agent, stamps } => {
            assert_eq!(int(row, "k"), *k);
            assert_eq!(int(row, "agent"), u64::from(*agent));
            assert_eq!(int(row, "agent_sent_ns"), stamps.agent_sent_ns);
            assert_eq!(
                int(row, "attacker_received_ns"),
                stamps.attacker_received_ns
            );
            assert_eq!(int(row, "attacker_sent_ns"), stamps.attacker_sent_ns);
            assert_eq!(int(row, "center_received_ns"), stamps.center_received_ns);
            assert_eq!(int(row, "center_sent_ns"), stamps.center_sent_ns);
            assert_eq!(int(row, "agent_received_ns"), stamps.agent_received_ns);
        }
        TraceRecord::Event { .. } => unreachable!("events are compared apart"),
    }
}

/// The readable records of a trace, and the error that ended it, if any.
fn read_trace(path: &Path) -> (Vec<TraceRecord>, Option<String>) {
    let reader = TraceReader::open(path).unwrap_or_else(|e| panic!("{e}"));
    let mut recs = Vec::new();
    for r in reader {
        match r {
            Ok(r) => recs.push(r),
            Err(e) => return (recs, Some(e.to_string())),
        }
    }
    (recs, None)
}

fn export_dir(run_dir: &Path) -> PathBuf {
    run_dir.join("export")
}

fn export(run_dir: &Path) -> std::process::Output {
    launch_plain(
        &[
            "trace",
            "export",
            run_dir.to_str().expect("utf-8 path"),
            "--format",
            "csv",
        ],
        WATCHDOG,
    )
}

/// Checks `<stem>.csv` (and `<stem>-latency.csv`) against the records of `trace`.
fn assert_csv_matches(run_dir: &Path, stem: &str, recs: &[TraceRecord]) {
    let main: Vec<&TraceRecord> = recs
        .iter()
        .filter(|r| {
            matches!(
                r,
                TraceRecord::Agent(_) | TraceRecord::Attack(_) | TraceRecord::Center(_)
            )
        })
        .collect();
    let (header, rows) = read_csv(&export_dir(run_dir).join(format!("{stem}.csv")));
    assert_eq!(rows.len(), main.len(), "{stem}.csv rows");
    for (row, rec) in rows.iter().zip(&main) {
        assert_row_is_record(&fields(&header, row), rec);
    }
    let latency: Vec<&TraceRecord> = recs
        .iter()
        .filter(|r| matches!(r, TraceRecord::Latency { .. }))
        .collect();
    let path = export_dir(run_dir).join(format!("{stem}-latency.csv"));
    if latency.is_empty() {
        assert!(!path.exists(), "{} without latency records", path.display());
    } else {
        let (header, rows) = read_csv(&path);
        assert_eq!(rows.len(), latency.len(), "{stem}-latency.csv rows");
        for (row, rec) in rows.iter().zip(&latency) {
            assert_row_is_record(&fields(&header, row), rec);
        }
    }
}

#[test]
fn csv_export_round_trips_every_trace_value_bit_for_bit() {
    let dir = Scratch::new("export");
    let run_dir = run_dir_of(&json(&launch(
        &["run", "--duration-s", "2", "--json"],
        &dir.0,
        WATCHDOG,
    )));
    let out = export(&run_dir);
    assert!(out.status.success(), "{}", stderr(&out));
    let mut events = 0;
    for stem in [
        "agent-1",
        "agent-2",
        "agent-3",
        "agent-4",
        "attacker",
        "control-center",
    ] {
        let (recs, err) = read_trace(&run_dir.join(format!("traces/{stem}.trace")));
        assert_eq!(err, None);
        assert!(recs.len() >= 2000, "{stem}: {} records", recs.len());
        assert_csv_matches(&run_dir, stem, &recs);
        events += recs
            .iter()
            .filter(|r| matches!(r, TraceRecord::Event { .. }))
            .count();
    }
    let text = std::fs::read_to_string(export_dir(&run_dir).join("events.csv")).expect("events");
    assert!(text.starts_with("process,t,message\n"), "{text}");
    // Messages may hold quoted commas but no newlines: one line per event.
    assert_eq!(text.lines().count() - 1, events, "{text}");
}

#[test]
fn truncated_trace_is_exported_up_to_the_damage_then_named_with_its_offset() {
    let dir = Scratch::new("export-cut");
    let run_dir = run_dir_of(&json(&launch(
        &["run", "--duration-s", "1", "--engine", "inproc", "--json"],
        &dir.0,
        WATCHDOG,
    )));
    let trace = run_dir.join("traces/attacker.trace");
    let bytes = std::fs::read(&trace).expect("trace");
    std::fs::write(&trace, &bytes[..bytes.len() - 7]).expect("cut");
    let (recs, err) = read_trace(&trace);
    assert!(err.is_some(), "the cut trace reads whole");
    assert_eq!(recs.len(), 4 * 1000 - 1, "all but the cut record");

    let out = export(&run_dir);
    assert!(!out.status.success(), "export of a cut trace succeeded");
    let msg = stderr(&out);
    assert!(
        msg.contains(&trace.display().to_string()) && msg.contains("byte offset"),
        "{msg}"
    );
    // The records before the damage are all there, and the other traces whole.
    assert_csv_matches(&run_dir, "attacker", &recs);
    let (recs, _) = read_trace(&run_dir.join("traces/control-center.trace"));
    assert_csv_matches(&run_dir, "control-center", &recs);
}

#[test]
fn trace_of_an_unknown_format_version_is_refused_naming_file_and_version() {
    let dir = Scratch::new("export-version");
    let run_dir = run_dir_of(&json(&launch(
        &["run", "--duration-s", "1", "--engine", "inproc", "--json"],
        &dir.0,
        WATCHDOG,
    )));
    let trace = run_dir.join("traces/control-center.trace");
    let mut bytes = std::fs::read(&trace).expect("trace");
    bytes[8..12].copy_from_slice(&99u32.to_le_bytes());
    std::fs::write(&trace, &bytes).expect("rewrite");

    let out = export(&run_dir);
    assert!(
        !out.status.success(),
        "export of a version-99 trace succeeded"
    );
    let msg = stderr(&out);
    assert!(
        msg.contains("version 99") && msg.contains(&trace.display().to_string()),
        "{msg}"
    );
    // The other traces are exported all the same.
    let (recs, _) = read_trace(&run_dir.join("traces/attacker.trace"));
    assert_csv_matches(&run_dir, "attacker", &recs);

    let out = launch_plain(&["report", run_dir.to_str().expect("utf-8 path")], WATCHDOG);
    assert!(
        !out.status.success(),
        "report of a version-99 trace succeeded"
    );
    let msg = stderr(&out);
    assert!(msg.contains("version 99"), "{msg}");
}
