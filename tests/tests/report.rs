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
        assert!(csv.starts_with("# made with scenario: "), "{csv}");
        assert_eq!(
            csv.lines().filter(|l| !l.starts_with('#')).count(),
            5,
            "header and four rows:\n{csv}"
        );
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

/// The columns `<stem><link><suffix>` of a vector (links from 1): `("q", "_dot_rad_s")`.
fn same_joints(row: &BTreeMap<&str, &str>, (stem, suffix): (&str, &str), j: &Joints) {
    for (i, x) in j.as_slice().iter().enumerate() {
        let col = format!("{stem}{}{suffix}", i + 1);
        assert_eq!(f64_bits(row, &col), x.to_bits(), "{col}");
    }
}

/// Compares one CSV row with the trace record it came from, bit for bit.
fn assert_row_is_record(row: &BTreeMap<&str, &str>, rec: &TraceRecord) {
    match rec {
        TraceRecord::Agent(a) => {
            assert_eq!(int(row, "k"), a.k);
            assert_eq!(int(row, "agent"), u64::from(a.agent));
            assert_eq!(f64_bits(row, "t_s"), a.t.to_bits());
            for (name, j) in [
                (("q", "_rad"), &a.q),
                (("q", "_dot_rad_s"), &a.qd),
                (("q", "_ddot_rad_s2"), &a.qdd),
                (("y", "_clean_rad"), &a.y),
                (("y", "_dot_clean_rad_s"), &a.yd),
                (("u", "_applied_nm"), &a.u_applied),
            ] {
                same_joints(row, name, j);
            }
            assert_eq!(f64_bits(row, "tau_s"), a.tau.to_bits());
            assert_eq!(flag(row, "missed"), a.missed);
        }
        TraceRecord::Attack(a) => {
            assert_eq!(int(row, "k"), a.k);
            assert_eq!(int(row, "agent"), u64::from(a.agent));
            for (name, j) in [
                (("alpha", "_pos_rad"), &a.alpha_position),
                (("alpha", "_vel_rad_s"), &a.alpha_velocity),
                (("y", "_tampered_rad"), &a.y),
                (("y", "_dot_tampered_rad_s"), &a.yd),
            ] {
                same_joints(row, name, j);
            }
            assert_eq!(flag(row, "active"), a.active);
            assert_eq!(row.get("delivery").copied(), Some(a.delivery.as_str()));
        }
        TraceRecord::Actuation(a) => {
            assert_eq!(int(row, "k"), a.k);
            assert_eq!(int(row, "agent"), u64::from(a.agent));
            same_joints(row, ("alpha", "_u_nm"), &a.alpha_u);
            same_joints(row, ("u", "_tampered_nm"), &a.u);
            assert_eq!(f64_bits(row, "held_s"), a.held_s.to_bits());
            assert_eq!(flag(row, "active"), a.active);
            assert_eq!(row.get("delivery").copied(), Some(a.delivery.as_str()));
        }
        TraceRecord::Center(c) => {
            assert_eq!(int(row, "k"), c.k);
            assert_eq!(int(row, "agent"), u64::from(c.agent));
            for (name, j) in [
                (("s", "_hat_rad_s"), &c.s_hat),
                (("q", "_hat_rad"), &c.q_hat),
                (("q", "_dot_hat_rad_s"), &c.qd_hat),
                (("q", "_ddot_hat_rad_s2"), &c.qdd_hat),
                (("u", "_sent_nm"), &c.u),
            ] {
                same_joints(row, name, j);
            }
            assert_eq!(flag(row, "alarm"), c.alarm);
            assert_eq!(flag(row, "rejected_input"), c.rejected_input);
            assert_eq!(flag(row, "missing_input"), c.missing_input);
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
        TraceRecord::Monitor(_) => unreachable!("no monitor in these runs"),
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

/// The (tick, agent) of a per-tick record: the order of the CSV rows.
fn tick_agent(r: &TraceRecord) -> (u64, u32) {
    match r {
        TraceRecord::Agent(a) => (a.k, a.agent),
        TraceRecord::Attack(a) => (a.k, a.agent),
        TraceRecord::Center(c) => (c.k, c.agent),
        TraceRecord::Actuation(a) => (a.k, a.agent),
        TraceRecord::Monitor(m) => (m.k, m.agent),
        TraceRecord::Latency { k, agent, .. } => (*k, *agent),
        TraceRecord::Event { .. } => (u64::MAX, u32::MAX),
    }
}

/// Checks `<stem>.csv` (and `<stem>-latency.csv`) against the records of `trace`, in (tick,
/// agent) order.
fn assert_csv_matches(run_dir: &Path, stem: &str, recs: &[TraceRecord]) {
    let mut main: Vec<&TraceRecord> = recs
        .iter()
        .filter(|r| {
            matches!(
                r,
                TraceRecord::Agent(_) | TraceRecord::Attack(_) | TraceRecord::Center(_)
            )
        })
        .collect();
    main.sort_by_key(|r| tick_agent(r));
    let (header, rows) = read_csv(&export_dir(run_dir).join(format!("{stem}.csv")));
    assert_eq!(rows.len(), main.len(), "{stem}.csv rows");
    for (row, rec) in rows.iter().zip(&main) {
        assert_row_is_record(&fields(&header, row), rec);
    }
    let mut latency: Vec<&TraceRecord> = recs
        .iter()
        .filter(|r| matches!(r, TraceRecord::Latency { .. }))
        .collect();
    latency.sort_by_key(|r| tick_agent(r));
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
        fdi_common::run_dir::Process::CENTER,
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
    assert!(text.starts_with("process,t_s,message\n"), "{text}");
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
    assert_csv_matches(&run_dir, fdi_common::run_dir::Process::CENTER, &recs);
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

/// The text elements of an SVG figure: (x, y, text).
fn svg_texts(svg: &str) -> Vec<(String, String, String)> {
    let mut out = Vec::new();
    let mut rest = svg;
    while let Some(start) = rest.find("<text") {
        rest = &rest[start..];
        let Some(open_end) = rest.find('>') else {
            break;
        };
        let Some(close) = rest.find("</text>") else {
            break;
        };
        let attrs = &rest[..open_end];
        let attr = |name: &str| {
            let key = format!(" {name}=\"");
            attrs
                .find(&key)
                .and_then(|i| attrs[i + key.len()..].split('"').next())
                .unwrap_or_default()
                .to_string()
        };
        out.push((
            attr("x"),
            attr("y"),
            rest[open_end + 1..close].trim().to_string(),
        ));
        rest = &rest[close..];
    }
    out
}

/// The numeric tick labels of a figure's first panel axes: (time axis, value axis). The time
/// axis labels share a `y` attribute, the value axis labels an `x` attribute; each axis is the
/// largest such group.
fn axis_ticks(svg: &str) -> (Vec<f64>, Vec<f64>) {
    let numeric: Vec<(String, String, f64)> = svg_texts(svg)
        .into_iter()
        .filter_map(|(x, y, t)| {
            t.replace('\u{2212}', "-")
                .parse::<f64>()
                .ok()
                .map(|v| (x, y, v))
        })
        .collect();
    let largest_group = |key: fn(&(String, String, f64)) -> &String| {
        let mut groups: BTreeMap<&String, Vec<f64>> = BTreeMap::new();
        for n in &numeric {
            groups.entry(key(n)).or_default().push(n.2);
        }
        groups
            .into_values()
            .max_by_key(Vec::len)
            .unwrap_or_default()
    };
    (largest_group(|n| &n.1), largest_group(|n| &n.0))
}

fn max_of(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::NEG_INFINITY, f64::max)
}

fn min_of(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::INFINITY, f64::min)
}

fn figure_svg(run_dir: &Path, stem: &str) -> String {
    let p = run_dir.join(format!("report/{stem}.svg"));
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

#[test]
fn paper_figures_show_the_papers_bounds_and_clip_the_switch_spikes() {
    let dir = Scratch::new("report-paper-figures");
    let run_dir = run_dir_of(&json(&launch(
        &["run", "--engine", "inproc", "--json"],
        &dir.0,
        WATCHDOG,
    )));
    let pos = figure_svg(&run_dir, "robot1-position-error");
    assert!(pos.contains("paper, Fig. 3(a): ±0.02 rad"), "no band label");
    let (t, y) = axis_ticks(&pos);
    assert_eq!(max_of(&t), 40.0, "time axis {t:?}");
    assert!(
        min_of(&y) <= -0.02 && max_of(&y) >= 0.02,
        "band off the axis {y:?}"
    );
    let vel = figure_svg(&run_dir, "robot1-velocity-error");
    assert!(
        vel.contains("paper, Fig. 3(b): ±0.01 rad/s"),
        "no band label"
    );
    assert!(figure_svg(&run_dir, "robot4-position-error").contains("paper, Fig. 6(a)"));

    // Robot 2's velocity error spikes to about 0.43 rad/s at the 5 s switch; its steady state
    // is near ±0.01 rad/s. The axis follows the steady state, the spikes are clipped and their
    // values written beside their markers.
    let vel2 = figure_svg(&run_dir, "robot2-velocity-error");
    let (_, y) = axis_ticks(&vel2);
    assert!(
        max_of(&y) < 0.1 && min_of(&y) > -0.1,
        "axis set by the spikes: {y:?}"
    );
    assert!(vel2.contains("clipped: "), "no clip note");
    assert!(
        vel2.contains("attack switches: 5, 20 s"),
        "switches not in the legend"
    );
    let peaks: Vec<f64> = svg_texts(&vel2)
        .into_iter()
        .filter_map(|(_, _, t)| t.replace('\u{2212}', "-").parse::<f64>().ok())
        .filter(|v| v.abs() > 0.2)
        .collect();
    assert!(!peaks.is_empty(), "no spike value written");
    let md = std::fs::read_to_string(run_dir.join("report/report.md")).expect("report.md");
    assert!(
        md.contains("## Reading the figures") && md.contains("Green band"),
        "{md}"
    );
}

#[test]
fn other_scenarios_get_no_paper_band() {
    let dir = Scratch::new("report-no-band");
    let scenario = fdi_tests::repo_path("scenarios/no-attack.toml");
    let run_dir = run_dir_of(&json(&launch(
        &[
            "run",
            scenario.to_str().expect("utf-8 path"),
            "--engine",
            "inproc",
            "--duration-s",
            "2",
            "--json",
        ],
        &dir.0,
        WATCHDOG,
    )));
    for f in ["robot1-position-error", "robot1-velocity-error"] {
        let svg = figure_svg(&run_dir, f);
        assert!(svg.contains("<polyline"), "{f} not drawn");
        assert!(!svg.contains("paper"), "{f} has a paper band");
    }
    let md = std::fs::read_to_string(run_dir.join("report/report.md")).expect("report.md");
    assert!(!md.contains("Green band"), "{md}");
}

#[test]
fn partial_run_figures_span_only_the_recorded_time() {
    let dir = Scratch::new("report-partial");
    let run_dir = run_dir_of(&json(&launch(
        &["run", "--engine", "inproc", "--duration-s", "2", "--json"],
        &dir.0,
        WATCHDOG,
    )));
    // The traces hold 2 s; the scenario now says 6 s: a run stopped a third of the way.
    let path = fdi_common::run_dir::RunDir::new(&run_dir).scenario();
    let text = std::fs::read_to_string(&path).expect("the scenario file");
    let cut: String = text
        .lines()
        .map(|l| {
            if l.starts_with("duration_s") {
                "duration_s = 6.0".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    assert_ne!(cut, text, "no duration_s line in {}", path.display());
    std::fs::write(&path, cut).expect("rewrite scenario.toml");
    let out = launch_plain(&["report", run_dir.to_str().expect("utf-8 path")], WATCHDOG);
    assert!(out.status.success(), "{}", stderr(&out));
    for id in ROBOTS {
        for f in FIGURES {
            let svg = figure_svg(&run_dir, &format!("robot{id}-{f}"));
            assert!(
                svg.contains("partial run: 2 s of 6 s recorded"),
                "robot{id}-{f}: no partial-run title"
            );
            let (t, _) = axis_ticks(&svg);
            let end = max_of(&t);
            assert!((1.5..=2.0).contains(&end), "robot{id}-{f}: time axis {t:?}");
        }
    }
    // Robot 1 is attacked from t = 0: in force over all of the recorded time.
    let timeline = figure_svg(&run_dir, "robot1-delay-alarm");
    assert!(
        timeline.contains("1 interval, 100.0 % of the time"),
        "robot 1's attack interval is not the recorded time"
    );
    let md = std::fs::read_to_string(run_dir.join("report/report.md")).expect("report.md");
    assert!(md.contains("This run is partial"), "{md}");
}

#[test]
fn timeline_draws_every_interval_of_the_per_tick_attack_flag() {
    let dir = Scratch::new("report-intervals");
    // 24 attacks of 40 ms on robot 1, one every 80 ms: separate intervals of the
    // per-tick flag, whatever its reading of the schedule (the value is non-zero in each).
    let mut segments = String::new();
    for k in 0..24 {
        let on = 50 + 80 * k;
        let _ = std::fmt::Write::write_fmt(
            &mut segments,
            format_args!(
                "  {{ from_s = {}, waveform = {{ kind = \"constant\", value = 5.0 }} }},\n  \
                 {{ from_s = {}, waveform = {{ kind = \"none\" }} }},\n",
                f64::from(on) / 1000.0,
                f64::from(on + 40) / 1000.0
            ),
        );
    }
    let profile = format!(
        "name = \"pulses\"\n[[channels]]\nagent = 1\nsignal = \"velocity\"\nlinks = [1, 2]\n\
         units = \"deg\"\nsegments = [\n  {{ from_s = 0.0, waveform = {{ kind = \"none\" }} }},\n\
         {segments}]\n"
    );
    let file = dir.0.join("pulses.toml");
    std::fs::write(&file, profile).expect("attack file");
    let run_dir = run_dir_of(&json(&launch(
        &[
            "run",
            "--engine",
            "inproc",
            "--duration-s",
            "2",
            "--attack",
            file.to_str().expect("utf-8 path"),
            "--json",
        ],
        &dir.0,
        WATCHDOG,
    )));
    let svg = figure_svg(&run_dir, "robot1-delay-alarm");
    assert!(
        svg.contains("24 intervals, 48.0 % of the time"),
        "{:?}",
        svg_texts(&svg)
            .into_iter()
            .map(|t| t.2)
            .filter(|t| t.contains("interval"))
            .collect::<Vec<_>>()
    );
    // One bar per interval in the attack colour, and the legend swatch.
    let bars = svg.matches("fill=\"#D55E00\"").count();
    assert_eq!(bars, 24 + 1, "attack bars in robot1-delay-alarm.svg");
    // The robots without an attack.
    assert!(figure_svg(&run_dir, "robot2-delay-alarm").contains("never"));
}

/// Regression (issue 55): a 64-robot run drew 7 figures per robot, PNG and SVG, one after the
/// other: 30 s of report for 0.55 s of simulation. A team of more than 8 robots leads with the
/// team figure (every robot's error on one plot) and the RMSE table; `report --robots` draws
/// the figures of the robots named, and refuses an id that is not the run's.
#[test]
fn a_large_team_leads_with_the_team_figure_and_draws_robots_on_demand() {
    let dir = Scratch::new("report-team");
    let file = dir.0.join("team12.toml");
    std::fs::write(&file, fdi_tests::paper_team(12)).expect("scenario");
    let path = file.to_string_lossy().into_owned();
    let run = [
        "run",
        &path,
        "--engine",
        "inproc",
        "--duration-s",
        "0.5",
        "--json",
    ];
    let run_dir = run_dir_of(&json(&launch(&run, &dir.0, WATCHDOG)));
    let report = run_dir.join("report");
    let files = |report: &Path| -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(report)
            .expect("the report folder")
            .filter_map(Result::ok)
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    };
    assert_eq!(
        files(&report),
        [
            "detection.csv",
            "report.md",
            "segments.csv",
            "team-position-error.png",
            "team-position-error.svg"
        ]
    );
    let svg = figure_svg(&run_dir, "team-position-error");
    assert!(
        svg.contains("each of the 12 robots") && svg.contains("largest RMSE"),
        "the team figure's legend"
    );
    // One curve per robot (the legend's sample lines are paths, not polylines).
    assert!(svg.matches("<polyline").count() >= 12, "a curve per robot");
    let md = std::fs::read_to_string(report.join("report.md")).expect("report.md");
    assert!(
        md.contains("## Team")
            && md.contains("(team-position-error.png)")
            && md.contains("Per-robot figures are drawn for 0 of the 12 robots")
            && md.contains("--robots 3,7")
            && !md.contains("## Robot 1\n"),
        "{md}"
    );
    assert!(
        md.contains("| 12 |"),
        "the RMSE table has every robot:\n{md}"
    );

    let rd = run_dir.to_string_lossy().into_owned();
    let out = launch_plain(&["report", &rd, "--robots", "3,11"], WATCHDOG);
    assert!(out.status.success(), "{}", stderr(&out));
    let names = files(&report);
    for id in [3, 11] {
        for f in FIGURES {
            for ext in ["png", "svg"] {
                let name = format!("robot{id}-{f}.{ext}");
                assert!(names.contains(&name), "{name} in {names:?}");
            }
        }
    }
    assert_eq!(names.len(), 5 + 2 * FIGURES.len() * 2, "{names:?}");
    let md = std::fs::read_to_string(report.join("report.md")).expect("report.md");
    assert!(
        md.contains("## Robot 3\n") && md.contains("## Robot 11\n") && !md.contains("## Robot 4\n"),
        "{md}"
    );

    let out = launch_plain(&["report", &rd, "--robots", "3,13"], WATCHDOG);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("--robots: 13 is not a robot of the run (its robots: 1–12)"),
        "{}",
        stderr(&out)
    );
}
