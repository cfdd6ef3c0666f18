//! A run that diverges still gets its report, in bounded time: the figures of values like
//! 1e300 or non-finite ones used to make the axis ticks loop for ever, and the report ignored
//! SIGINT meanwhile. Its `summary.json` holds non-finite numbers as words and `report` reads
//! them back (issue 51: it wrote `null`, which `report` could not read).

use std::time::Duration;

use fdi_tests::{launch, launch_plain, run_dir_of, Scratch};

/// A watchdog against a hang, not a speed check.
const WATCHDOG: Duration = Duration::from_secs(300);

#[test]
fn a_diverging_scenarios_report_finishes_and_can_be_made_again() {
    let s = Scratch::new("diverged-report");
    let paper = include_str!("../../scenarios/paper.toml");
    assert!(paper.contains("gain_k = 21.0"));
    let file = s.0.join("k21000.toml");
    std::fs::write(&file, paper.replace("gain_k = 21.0", "gain_k = 21000.0")).expect("write");
    let out = s.0.join("runs");
    for engine in ["inproc", "ipc"] {
        let o = launch(
            &[
                "run",
                &file.to_string_lossy(),
                "--engine",
                engine,
                "--duration-s",
                "2",
                "--json",
            ],
            &out,
            WATCHDOG,
        );
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(4), "{engine}: {stderr}");
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("run --json");
        assert!(
            v["metrics"]["1"]["diverged_at_s"].as_f64().is_some(),
            "{engine}: {v}"
        );
        let dir = run_dir_of(&v);
        let report = dir.join("report/report.md");
        assert!(report.is_file(), "{engine}: no report: {stderr}");
        let md = std::fs::read_to_string(&report).expect("report.md");
        assert!(md.contains("diverged at t ="), "{engine}: {md}");
        let written = std::fs::read_to_string(dir.join("summary.json")).expect("summary.json");
        let rmse = &serde_json::from_str::<serde_json::Value>(&written).expect("JSON")["metrics"]
            ["1"]["rmse_rad"];
        assert!(
            matches!(rmse.as_str(), Some("NaN" | "inf")),
            "{engine}: robot 1's RMSE is not finite, written as a word: {rmse}"
        );
        let again = launch_plain(&["report", &dir.to_string_lossy()], WATCHDOG);
        let said = String::from_utf8_lossy(&again.stderr);
        assert!(again.status.success(), "{engine}: {said}");
        assert!(!said.contains("cannot be read"), "{engine}: {said}");
    }
}
