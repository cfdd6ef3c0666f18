//! `fdi-launch attacks`: the attack-class table of docs/attacks.md, on short runs. One row per
//! class and reported robot in both `attacks.csv` and `attacks.md`, finite RMSEs (or a
//! divergence said), and values that do not exist (no onset, nothing detected) marked as such,
//! never written as 0.

use std::time::Duration;

use fdi_tests::{launch, Scratch};

const WATCHDOG: Duration = Duration::from_secs(600);

/// The shipped classes and the robots the table reports for each.
const SHIPPED: [(&str, &[&str]); 15] = [
    ("none", &["1"]),
    ("paper", &["1", "2", "3", "4"]),
    ("scale", &["1"]),
    ("sign-flip", &["1"]),
    ("freeze", &["1"]),
    ("replay-example", &["1"]),
    ("actuator-bias", &["1"]),
    ("torque-delay", &["1"]),
    ("dos-drop", &["1"]),
    ("dos-burst", &["1"]),
    ("dos-window", &["1"]),
    ("measurement-delay", &["1"]),
    ("forge-stamp", &["1"]),
    ("replay-original", &["1"]),
    ("stealthy-bias", &["1"]),
];

/// The markdown cells of a time to detect that has no value.
const NO_VALUE: [&str; 3] = ["missed", "no onset", "—"];

#[test]
fn attacks_table_has_a_row_per_class_and_marks_what_is_undefined() {
    let dir = Scratch::new("attacks-table");
    // 11 s: the classes that start at 10 s have their onset, the runs stay short.
    let out = launch(&["attacks", "--duration-s", "11"], &dir.0, WATCHDOG);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stdout.contains(&format!("table written to {}", dir.0.display())),
        "{stdout}"
    );
    for ext in ["md", "csv", "json", "png", "svg"] {
        let f = dir.0.join(format!("attacks.{ext}"));
        assert!(
            std::fs::metadata(&f).is_ok_and(|m| m.len() > 0),
            "missing {}",
            f.display()
        );
    }

    let csv_text = std::fs::read_to_string(dir.0.join("attacks.csv")).expect("attacks.csv");
    // The first line says how the table was made (a `#` comment), then the CSV proper.
    let (made, csv_text) = csv_text.split_once('\n').expect("a comment line");
    assert_eq!(
        made,
        "# made with scenario: the embedded paper scenario; numerics: the paper's calibration (docs/model.md, \"Gains\")"
    );
    // No field of this table needs CSV quoting (names, numbers, empty fields).
    assert!(!csv_text.contains('"'), "{csv_text}");
    let mut lines = csv_text.lines();
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
    };
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    for r in &rows {
        assert_eq!(r.len(), header.len(), "{r:?}");
    }

    // One row per shipped class and reported robot, in the table's order for each class.
    for (class, robots) in SHIPPED {
        let got: Vec<&str> = rows
            .iter()
            .filter(|r| r[0] == class)
            .map(|r| r[1])
            .collect();
        assert_eq!(got, robots, "rows of class {class}:\n{csv_text}");
    }
    let mut keys: Vec<(&str, &str)> = rows.iter().map(|r| (r[0], r[1])).collect();
    let n = keys.len();
    keys.sort_unstable();
    keys.dedup();
    assert_eq!(keys.len(), n, "a class and robot appear once:\n{csv_text}");

    // RMSEs: finite, or empty with the time the robot diverged.
    for r in &rows {
        for mode in ["traditional", "proposed"] {
            let rmse = r[col(&format!("{mode}_rmse_rad"))];
            let diverged = r[col(&format!("{mode}_diverged_at_s"))];
            if diverged.is_empty() {
                let x: f64 = rmse
                    .parse()
                    .unwrap_or_else(|_| panic!("{} {mode}: RMSE `{rmse}`", r[0]));
                assert!(x.is_finite() && x > 0.0, "{} {mode}: RMSE {x}", r[0]);
            } else {
                assert!(rmse.is_empty(), "{} {mode}: diverged, RMSE `{rmse}`", r[0]);
                let t: f64 = diverged.parse().expect("a divergence time");
                assert!(t > 0.0 && t <= 11.0, "{} {mode}: diverged at {t}", r[0]);
            }
        }
    }

    // Without an attack there is no onset: nothing detected, no time to detect (not 0).
    let none = rows.iter().find(|r| r[0] == "none").expect("the none row");
    for d in fdi_common::detect::names() {
        assert_eq!(none[col(&format!("{d}_onsets"))], "0", "{d}");
        assert_eq!(none[col(&format!("{d}_detected"))], "0", "{d}");
        assert_eq!(none[col(&format!("{d}_mean_time_to_detect_s"))], "", "{d}");
    }
    // The stealthy bias hides from χ² on Ψ2: an onset, not detected, no time to detect.
    let stealthy = rows
        .iter()
        .find(|r| r[0] == "stealthy-bias")
        .expect("the stealthy-bias row");
    assert_eq!(stealthy[col("chi2_onsets")], "1");
    assert_eq!(stealthy[col("chi2_detected")], "0");
    assert_eq!(stealthy[col("chi2_mean_time_to_detect_s")], "");

    // The markdown: the same rows in the same order, and the same values.
    let md = std::fs::read_to_string(dir.0.join("attacks.md")).expect("attacks.md");
    let table: Vec<Vec<&str>> = md
        .lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| class |"))
        .map(|l| {
            l.trim_start_matches("| ")
                .trim_end_matches(" |")
                .split(" | ")
                .collect()
        })
        .collect();
    assert_eq!(table.len(), rows.len(), "{md}");
    for (cells, r) in table.iter().zip(&rows) {
        assert_eq!((cells[0], cells[1]), (r[0], r[1]), "{md}");
        for (i, mode) in ["traditional", "proposed"].iter().enumerate() {
            let rmse = r[col(&format!("{mode}_rmse_rad"))];
            let cell = cells[2 + i];
            if rmse.is_empty() {
                assert!(cell.starts_with("diverged at t = "), "{}: {cell}", r[0]);
            } else {
                let x: f64 = rmse.parse().expect("an RMSE");
                assert_eq!(cell, format!("{x:.4}"), "{} {mode}", r[0]);
            }
        }
        for (j, d) in fdi_common::detect::names().iter().enumerate() {
            let (detected, time) = (cells[4 + 3 * j], cells[5 + 3 * j]);
            let onsets = r[col(&format!("{d}_onsets"))];
            if onsets == "0" {
                assert_eq!((detected, time), ("no onset", "no onset"), "{} {d}", r[0]);
            }
            match r[col(&format!("{d}_mean_time_to_detect_s"))] {
                "" => assert!(NO_VALUE.contains(&time), "{} {d}: `{time}`", r[0]),
                t => {
                    let x: f64 = t.parse().expect("a time to detect");
                    assert_eq!(time, format!("{x:.3}"), "{} {d}", r[0]);
                }
            }
        }
    }
    assert!(table.iter().any(|c| c[0] == "none" && c[4] == "no onset"));
    assert!(table
        .iter()
        .any(|c| c[0] == "stealthy-bias" && c[8] == "missed"));
}

/// The table pasted into docs/attacks.md is what `fdi-launch attacks` makes now: a change of the
/// model, an attack or a detector that moves a number fails here until the table is made again
/// (docs/attacks.md, "The table") and its reading below it checked.
#[test]
fn the_documented_table_is_the_one_the_command_makes() {
    let dir = Scratch::new("attacks-doc");
    let out = launch(&["attacks"], &dir.0, WATCHDOG);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let made = std::fs::read_to_string(dir.0.join("attacks.md")).expect("attacks.md");
    let doc =
        std::fs::read_to_string(fdi_tests::repo_path("docs/attacks.md")).expect("docs/attacks.md");
    let begin = "<!-- generated by `fdi-launch attacks`: begin -->\n";
    let end = "<!-- generated by `fdi-launch attacks`: end -->";
    let from = doc.find(begin).expect("the table's begin marker") + begin.len();
    let to = doc.find(end).expect("the table's end marker");
    let pasted = &doc[from..to];
    let first_difference = pasted
        .lines()
        .zip(made.lines())
        .find(|(p, m)| p != m)
        .map(|(p, m)| format!("pasted: {p}\nmade:   {m}"))
        .unwrap_or_else(|| "a line more or less".into());
    assert!(
        pasted == made,
        "docs/attacks.md's table is not the one `fdi-launch attacks` makes now: run it, paste \
         its attacks.md between the markers, and check the text that reads the table. First \
         difference:\n{first_difference}"
    );
}

/// A class that cannot run as short as `--duration-s` (the stealthy bias's detectors calibrate
/// over 2 s) stops the table before any run, naming the class and the field.
#[test]
fn a_duration_too_short_for_a_class_is_refused_before_anything_runs() {
    let dir = Scratch::new("attacks-short");
    let out = launch(&["attacks", "--duration-s", "1"], &dir.0, WATCHDOG);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{said}");
    assert!(
        said.contains("attack class `stealthy-bias`")
            && said.contains("detectors.calibration_s")
            && said.contains("duration_s = 1 s"),
        "{said}"
    );
    assert!(!dir.0.join("attacks.csv").exists(), "a table was written");
}
