//! `fdi-launch sweep`: a small campaign (2 points × 2 seeds, in-process, short runs) gives one
//! row per run whose metrics are those of `fdi-launch run --engine inproc` of the same resolved
//! scenario; a rerun skips what is stored and runs only what is missing; an edited campaign
//! reuses only the runs whose resolved scenario did not change; a bad axis path is refused
//! naming it. And `table1 --seeds 2`.

use std::path::Path;
use std::time::Duration;

use fdi_tests::{launch, Scratch};
use serde_json::Value;

const WATCHDOG: Duration = Duration::from_secs(600);
const PAPER: &str = include_str!("../../scenarios/paper.toml");
const DURATION: &str = "0.4";

fn campaign(dir: &Path, betas: &str) -> std::path::PathBuf {
    let p = dir.join("small.toml");
    std::fs::write(
        &p,
        format!(
            "name = \"small\"\nmode = \"product\"\n[set]\nduration_s = {DURATION}\n\
             [[axes]]\npath = \"controller.beta\"\nvalues = [{betas}]\n\
             [[axes]]\npath = \"seed\"\nrange = {{ start = 1, stop = 2, step = 1 }}\n"
        ),
    )
    .expect("campaign file");
    p
}

fn sweep(campaign: &Path, out: &Path) -> (String, String) {
    let o = launch(
        &[
            "sweep",
            &campaign.to_string_lossy(),
            "--jobs",
            "2",
            "--engine",
            "inproc",
        ],
        out,
        WATCHDOG,
    );
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "sweep failed: {stdout}\n{stderr}");
    (stdout, stderr)
}

/// The rows of `results.json`, without the wall-clock time (a run done again takes another).
fn results(out: &Path) -> Vec<Value> {
    let text = std::fs::read_to_string(out.join("results.json")).expect("results.json");
    match serde_json::from_str(&text).expect("results.json is JSON") {
        Value::Array(mut rows) => {
            for r in &mut rows {
                r.as_object_mut()
                    .expect("a row is an object")
                    .remove("wall_s");
            }
            rows
        }
        other => panic!("results.json is not a list: {other}"),
    }
}

#[test]
fn a_small_campaign_matches_single_runs_and_resumes() {
    let s = Scratch::new("sweep");
    let out = s.0.join("campaign");
    let c = campaign(&s.0, "20.0, 30.0");
    let (stdout, _) = sweep(&c, &out);
    assert!(
        stdout.contains("4 runs (2 points × 2 seeds)") && stdout.contains("skipped 0, ran 4"),
        "{stdout}"
    );
    let rows = results(&out);
    assert_eq!(rows.len(), 4, "{rows:?}");
    let seen: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| {
            (
                r["controller.beta"].as_f64().expect("beta column"),
                r["seed"].as_f64().expect("seed column"),
            )
        })
        .collect();
    assert_eq!(
        seen,
        vec![(20.0, 1.0), (20.0, 2.0), (30.0, 1.0), (30.0, 2.0)]
    );
    for r in &rows {
        for robot in 1..=4 {
            for col in ["rmse_rad", "max_abs_error_rad", "deadline_misses"] {
                let key = format!("robot{robot}.{col}");
                assert!(r[&key].as_f64().is_some(), "no {key} in {r}");
            }
            let key = format!("robot{robot}.detectors.chi2.onsets.n");
            assert!(r[&key].as_f64().is_some(), "no {key} in {r}");
        }
    }
    let aggregate = std::fs::read_to_string(out.join("aggregate.csv")).expect("aggregate.csv");
    assert!(
        aggregate.starts_with("controller.beta,metric,runs,n,mean,sd,ci_low,ci_high\n"),
        "{aggregate}"
    );
    assert!(
        aggregate.contains("\n20.0,robot1.rmse_rad,2,2,"),
        "{aggregate}"
    );
    assert!(out
        .join("figures/rmse_rad-vs-controller_beta.png")
        .is_file());
    assert!(out
        .join("figures/rmse_rad-vs-controller_beta.svg")
        .is_file());

    // The point beta = 20, seed 2 as a plain run of the same scenario.
    let scenario = s.0.join("beta20.toml");
    assert!(PAPER.contains("beta = 30.0\n"));
    std::fs::write(&scenario, PAPER.replace("beta = 30.0\n", "beta = 20.0\n")).expect("scenario");
    let o = launch(
        &[
            "run",
            &scenario.to_string_lossy(),
            "--engine",
            "inproc",
            "--seed",
            "2",
            "--duration-s",
            DURATION,
            "--json",
        ],
        &s.0.join("runs"),
        WATCHDOG,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let single: Value = serde_json::from_slice(&o.stdout).expect("run --json");
    let row = &rows[1];
    assert_eq!(row["trace_digest"], single["trace_digest"]);
    for robot in ["1", "2", "3", "4"] {
        let m = &single["metrics"][robot];
        for col in [
            "rmse_rad",
            "max_abs_error_rad",
            "alarm_coverage",
            "false_alarms",
        ] {
            let got = row[format!("robot{robot}.{col}")]
                .as_f64()
                .expect("sweep value");
            let want = m[col].as_f64().expect("run value");
            assert_eq!(got.to_bits(), want.to_bits(), "robot {robot} {col}");
        }
        // A value the run leaves null (nothing to measure in so short a run) is an empty cell.
        for det in fdi_common::detect::names() {
            let want = &m["detectors"][det]["coverage"];
            let got = &row[format!("robot{robot}.detectors.{det}.coverage")];
            match want.as_f64() {
                Some(w) => assert_eq!(got.as_f64().map(f64::to_bits), Some(w.to_bits())),
                None => assert!(got.is_null(), "robot {robot} {det}: {got} for null"),
            }
        }
    }

    // A lost result: only that run again.
    let points: Vec<_> = std::fs::read_dir(out.join("points"))
        .expect("points folder")
        .map(|e| e.expect("entry").path())
        .collect();
    assert_eq!(points.len(), 4, "{points:?}");
    std::fs::remove_file(&points[0]).expect("removing a stored result");
    let (stdout, _) = sweep(&c, &out);
    assert!(
        stdout.contains("3 already done (skipped), 1 to run")
            && stdout.contains("skipped 3, ran 1"),
        "{stdout}"
    );
    assert_eq!(results(&out), rows, "the rerun changed the results");
    let (stdout, _) = sweep(&c, &out);
    assert!(stdout.contains("skipped 4, ran 0"), "{stdout}");

    // An edited campaign: beta = 30 is now 40; only beta = 20 is reused.
    let c = campaign(&s.0, "20.0, 40.0");
    let (stdout, _) = sweep(&c, &out);
    assert!(stdout.contains("skipped 2, ran 2"), "{stdout}");
    let edited = results(&out);
    assert_eq!(edited.len(), 4);
    assert_eq!(edited[..2], rows[..2]);
    assert_eq!(edited[2]["controller.beta"].as_f64(), Some(40.0));
    assert_ne!(edited[2]["trace_digest"], rows[2]["trace_digest"]);
}

#[test]
fn a_bad_axis_path_is_refused_by_name() {
    let s = Scratch::new("sweep-bad");
    let c = s.0.join("bad.toml");
    std::fs::write(
        &c,
        "name = \"bad\"\n[[axes]]\npath = \"controller.betta\"\nvalues = [1.0]\n",
    )
    .expect("campaign file");
    let out = s.0.join("out");
    let o = launch(&["sweep", &c.to_string_lossy()], &out, WATCHDOG);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("controller.betta") && stderr.contains("beta, detection"),
        "{stderr}"
    );
    assert!(
        !out.join("points").exists(),
        "a refused campaign created its folder"
    );

    std::fs::write(
        &c,
        "name = \"bad\"\n[[axes]]\npath = \"agents[9].delay.offset_s\"\nvalues = [0.01]\n",
    )
    .expect("campaign file");
    let o = launch(&["sweep", &c.to_string_lossy()], &out, WATCHDOG);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("agents[9].delay.offset_s") && stderr.contains("4 elements"),
        "{stderr}"
    );
}

/// A seed range near 2⁶³ was computed in floats: its eight seeds were one, the campaign ran
/// once and showed the seed as 9223372036854776000.
#[test]
fn a_seed_range_near_2_to_the_63_runs_every_seed_exactly() {
    let s = Scratch::new("sweep-seeds");
    let c = s.0.join("seeds.toml");
    std::fs::write(
        &c,
        "name = \"seeds\"\n[set]\nduration_s = 0.1\n[[axes]]\npath = \"seed\"\n\
         range = { start = 9223372036854775800, stop = 9223372036854775807, step = 1 }\n",
    )
    .expect("campaign file");
    let out = s.0.join("out");
    let (stdout, _) = sweep(&c, &out);
    assert!(
        stdout.contains("8 runs (1 points × 8 seeds)") && stdout.contains("ran 8, failed 0"),
        "{stdout}"
    );
    let seeds: Vec<Option<u64>> = results(&out).iter().map(|r| r["seed"].as_u64()).collect();
    let want: Vec<u64> = (i64::MAX as u64 - 7..=i64::MAX as u64).collect();
    assert_eq!(seeds, want.iter().copied().map(Some).collect::<Vec<_>>());
    // results.csv: the header names `seed` once; every seed is written to its last digit.
    let csv = std::fs::read_to_string(out.join("results.csv")).expect("results.csv");
    let header: Vec<&str> = csv.lines().next().expect("a header").split(',').collect();
    let column = header
        .iter()
        .position(|h| *h == "seed")
        .expect("a seed column");
    let shown: Vec<&str> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(column).expect("a seed cell"))
        .collect();
    let want_text: Vec<String> = want.iter().map(u64::to_string).collect();
    assert_eq!(shown, want_text);
}

/// Two axes on one path ran the later axis's value under the earlier one's column.
#[test]
fn two_axes_on_one_path_are_refused_before_anything_runs() {
    let s = Scratch::new("sweep-two-axes");
    let c = s.0.join("two.toml");
    std::fs::write(
        &c,
        "name = \"two\"\n[[axes]]\nlabel = \"a\"\npath = \"controller.beta\"\nvalues = [10.0, 20.0]\n\
         [[axes]]\nlabel = \"b\"\npath = \"controller.beta\"\nvalues = [30.0]\n",
    )
    .expect("campaign file");
    let out = s.0.join("out");
    let o = launch(&["sweep", &c.to_string_lossy()], &out, WATCHDOG);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("axes `a` (axes[0].path (line 4, column 1)) and `b` (axes[1].path (line 8, column 1)) both set `controller.beta`"),
        "{stderr}"
    );
    assert!(!out.exists(), "a refused campaign created its folder");
}

#[test]
fn table1_over_two_seeds_gives_a_mean_and_an_interval_per_cell() {
    let s = Scratch::new("table1-seeds");
    let o = launch(
        &[
            "table1",
            "--seeds",
            "2",
            "--jobs",
            "2",
            "--engine",
            "inproc",
            "--duration-s",
            "0.3",
            "--json",
        ],
        &s.0,
        WATCHDOG,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let t: Value = serde_json::from_slice(&o.stdout).expect("table1 --json");
    assert_eq!(t["seeds"], serde_json::json!([1, 2]));
    let rows = t["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 4);
    for r in rows {
        for cell in ["traditional_rmse_rad", "proposed_rmse_rad"] {
            let c = &r[cell];
            assert_eq!(c["n"], 2, "{r}");
            let (lo, mean, hi) = (
                c["ci_low"].as_f64().expect("ci_low"),
                c["mean"].as_f64().expect("mean"),
                c["ci_high"].as_f64().expect("ci_high"),
            );
            assert!(
                lo <= mean && mean <= hi && c["sd"].as_f64().is_some(),
                "{r}"
            );
        }
        assert!(r["paper_proposed"].as_f64().is_some(), "{r}");
    }
}
