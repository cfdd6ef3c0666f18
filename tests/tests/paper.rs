//! The paper's experiment by default (issue: the first command reproduces the paper): the
//! embedded scenario reproduces Table I under the default numerics, and every table says under
//! which numerics it was made.

use std::time::Duration;

use fdi_common::control::ObserverInput;
use fdi_common::engine::{run_inproc_any, RunSummary};
use fdi_common::scenario::{self, ControllerMode};
use fdi_tests::{launch, repo_path, Scratch};
use serde_json::Value;

const WATCHDOG: Duration = Duration::from_secs(300);

/// Table I of the paper: (robot, traditional, proposed) RMSE in rad.
const PAPER_TABLE1: [(u32, f64, f64); 4] = [
    (1, 0.028, 0.008),
    (2, 0.041, 0.013),
    (3, 0.026, 0.009),
    (4, 0.015, 0.010),
];

fn run(mode: ControllerMode) -> RunSummary {
    let mut r = scenario::paper().expect("the embedded scenario");
    r.scenario.controller.mode = mode;
    run_inproc_any(&r, |_| {}).expect("the engine runs")
}

#[test]
fn the_paper_scenario_reproduces_table_i_under_the_default_numerics() {
    let paper = scenario::paper().expect("the embedded scenario");
    assert_eq!(
        paper.scenario.controller.observer_input,
        ObserverInput::Sample,
        "the default observer input is the sample"
    );
    assert!(paper.scenario.controller.update_law.is_paper());
    // Measured: proposed 0.0086 / 0.0107 / 0.0086 / 0.0087, traditional 0.0187 / 0.0494 /
    // 0.0204 / 0.0092 rad (docs/model.md, "Reproduction").
    let traditional = run(ControllerMode::Traditional);
    let proposed = run(ControllerMode::Proposed);
    for (id, _, paper_proposed) in PAPER_TABLE1 {
        let t = traditional.metrics[&id.to_string()].rmse_rad;
        let p = proposed.metrics[&id.to_string()].rmse_rad;
        assert!(
            (p / paper_proposed - 1.0).abs() <= 0.25,
            "robot {id}: proposed {p}, paper {paper_proposed}: outside ±25 %"
        );
        assert!(p < t, "robot {id}: proposed {p} not below traditional {t}");
        if id <= 3 {
            assert!(t / p >= 2.0, "robot {id}: ratio {} below 2", t / p);
        }
    }
    assert!(proposed.numerics.is_empty(), "{:?}", proposed.numerics);
}

#[test]
fn a_table_of_another_scenario_names_its_numerics_and_what_it_replaced() {
    let s = Scratch::new("table1-long-horizon");
    let file = repo_path("scenarios/paper-long-horizon.toml");
    let o = launch(
        &[
            "table1",
            "--engine",
            "inproc",
            "--scenario",
            &file.to_string_lossy(),
            "--duration-s",
            "0.3",
            "--json",
        ],
        &s.0,
        WATCHDOG,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let t: Value = serde_json::from_slice(&o.stdout).expect("table1 --json");
    let made = &t["made_with"];
    let fields: Vec<&str> = made["numerics"]
        .as_array()
        .expect("numerics")
        .iter()
        .filter_map(|d| d["field"].as_str())
        .collect();
    assert_eq!(
        fields,
        [
            "controller.update_law.dead_zone_rad_s",
            "controller.update_law.leakage_w_per_s"
        ],
        "{made}"
    );
    let replaced = made["replaced"].to_string();
    assert!(
        replaced.contains("attack `none` → `paper`") && replaced.contains("duration 300 s"),
        "{replaced}"
    );
    // The markdown header says the same, and that the paper's values are for comparison only.
    let dir = std::fs::read_dir(&s.0)
        .expect("the table's folder")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.to_string_lossy().ends_with("-table1"))
        .expect("a table1 folder");
    let md = std::fs::read_to_string(dir.join("table1.md")).expect("table1.md");
    assert!(
        md.contains("controller.update_law.leakage_w_per_s = 10.0 (paper: 0.0)")
            && md.contains("differ from the paper's calibration"),
        "{md}"
    );
    let csv = std::fs::read_to_string(dir.join("table1.csv")).expect("table1.csv");
    assert!(
        csv.starts_with("# made with scenario: ") && csv.contains("dead_zone_rad_s = 0.17"),
        "{csv}"
    );
}

#[test]
fn a_numerics_flag_is_named_in_the_table_and_the_run_summary() {
    let s = Scratch::new("numerics-flags");
    let o = launch(
        &[
            "table2",
            "--engine",
            "inproc",
            "--observer-input",
            "step-mean",
            "--duration-s",
            "0.2",
            "--json",
        ],
        &s.0,
        WATCHDOG,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let t: Value = serde_json::from_slice(&o.stdout).expect("table2 --json");
    assert_eq!(
        t["made_with"]["numerics"],
        serde_json::json!([{ "field": "controller.observer_input", "value": "\"step-mean\"", "paper": "\"sample\"" }])
    );
    // Robot 1 is the paper's: its paper values stay beside the run's, and the verdict judges
    // each of them on this run's value over the paper's.
    let rows = t["rows"].as_array().expect("rows");
    let cells = t["verdict"]["cells"].as_array().expect("verdict cells");
    assert_eq!(cells.len(), rows.len(), "{}", t["verdict"]);
    for (r, c) in rows.iter().zip(cells) {
        let (this, paper) = (r["rmse_rad"].as_f64(), r["paper_rmse_rad"].as_f64());
        let (Some(this), Some(paper)) = (this, paper) else {
            panic!("a row without its values: {r}");
        };
        assert_eq!(c["row"], r["case"], "{c}");
        assert_eq!(c["ratio"].as_f64(), Some(this / paper), "{c}");
        assert_eq!(c["within"], (this / paper - 1.0).abs() <= 0.25, "{c}");
    }

    let o = launch(
        &[
            "run",
            "--engine",
            "inproc",
            "--leakage-w-per-s",
            "5",
            "--duration-s",
            "0.2",
            "--json",
        ],
        &s.0,
        WATCHDOG,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: Value = serde_json::from_slice(&o.stdout).expect("run --json");
    assert_eq!(
        v["numerics"],
        serde_json::json!([{ "field": "controller.update_law.leakage_w_per_s", "value": "5.0", "paper": "0.0" }])
    );
    let run_dir = fdi_tests::run_dir_of(&v);
    let report = std::fs::read_to_string(run_dir.join("report/report.md")).expect("report.md");
    assert!(
        report.contains("| numerics | controller.update_law.leakage_w_per_s = 5.0 (paper: 0.0) |"),
        "{report}"
    );
}

#[test]
fn a_bad_numerics_flag_names_the_flag_and_the_choices() {
    let s = Scratch::new("numerics-bad");
    let o = launch(
        &[
            "table1",
            "--engine",
            "inproc",
            "--observer-input",
            "midpoint",
        ],
        &s.0,
        WATCHDOG,
    );
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("--observer-input") && stderr.contains("sample or step-mean"),
        "{stderr}"
    );
    let o = launch(
        &["run", "--engine", "inproc", "--dead-zone-rad-s", "-1"],
        &s.0,
        WATCHDOG,
    );
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && stderr.contains("controller.update_law.dead_zone_rad_s"),
        "{stderr}"
    );
}
