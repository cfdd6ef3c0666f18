//! The scored benchmark (`fdi-launch score`, docs/score.md): a controller's row is the same
//! from two runs of the suite (what two labs with the same code get), whether run whole or in
//! shards and aggregated, two rows print side by side, and a wrong detector, team or row file
//! is named before anything runs. The suite's team of the paper only: the Panda teams' runs
//! take a minute a controller (the suite's plan of every team is a unit test of
//! `fdi_campaign::score`).

use std::time::Duration;

use fdi_tests::{json, launch, launch_plain, Scratch};

const WATCHDOG: Duration = Duration::from_secs(600);

#[test]
fn a_controller_s_row_is_the_same_from_two_runs_and_two_rows_compare() {
    let dir = Scratch::new("score");
    let out = |name: &str| dir.0.join(name);
    let suite = ["--controller", "traditional", "--teams", "paper"];
    let row = |name: &str, more: &[&str]| {
        let args = [&["score"][..], &suite[..], more].concat();
        launch(&args, &out(name), WATCHDOG)
    };
    let a = json(&row("a", &["--json"]));
    // The same suite in two shards, then aggregated: each shard runs its part only.
    for k in ["1/2", "2/2"] {
        let shard = row("b", &["--shard", k]);
        let said = String::from_utf8_lossy(&shard.stderr);
        assert!(shard.status.success() && shard.stdout.is_empty(), "{said}");
        assert!(
            said.contains(&format!("shard {k}: 24 of the campaign's 48 runs")),
            "{said}"
        );
    }
    let b = json(&row("b", &["--aggregate", "--json"]));
    assert_eq!(a, b, "the same row from a run whole and from two shards");
    assert_eq!(a["suite"], "fdi-mas-score-2");
    assert_eq!(a["teams"], serde_json::json!(["paper"]));
    assert_eq!(a["controller"], "traditional");
    let cells = a["cells"].as_array().expect("cells");
    // Every class of the attack table but the attack-free reference, at each of three seeds.
    assert_eq!(cells.len() % 3, 0);
    assert!(cells.len() >= 3 * 15, "{}", cells.len());
    let overall = a["score"]["overall"].as_f64().expect("a score");
    assert!(overall > 0.0 && overall < 100.0, "{overall}");
    // The traditional law has no estimate: its alarm on ‖Ŝ‖ never detects an onset.
    assert_eq!(a["score"]["detected_share"].as_f64(), Some(0.0));

    let stored = out("a").join("score.json");
    let compared = launch_plain(
        &[
            "score",
            "--controller",
            "gated",
            "--teams",
            "paper",
            "--compare",
            &stored.to_string_lossy(),
            "--out",
            &out("c").to_string_lossy(),
        ],
        WATCHDOG,
    );
    let text = String::from_utf8_lossy(&compared.stdout);
    assert!(compared.status.success(), "{text}");
    assert!(
        text.contains("| | gated / s_hat_norm | traditional / s_hat_norm |")
            && text.contains("| overall |"),
        "{text}"
    );
}

#[test]
fn an_unknown_detector_or_a_file_that_is_no_row_is_named_before_anything_runs() {
    let dir = Scratch::new("score-bad");
    let folder = dir.0.join("nothing");
    let bad = launch(&["score", "--detector", "psychic"], &folder, WATCHDOG);
    let said = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success());
    assert!(
        said.contains("suite.detector: unknown detector `psychic`") && said.contains("chi2"),
        "{said}"
    );
    let bad = launch(&["score", "--teams", "paper,ur5"], &folder, WATCHDOG);
    let said = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && said.contains("suite.teams[1]") && said.contains("panda"),
        "{said}"
    );
    assert!(!folder.exists(), "nothing is written for a suite refused");
    // `--status` and `--aggregate` run nothing: a folder without the suite is named, not made.
    for what in ["--status", "--aggregate"] {
        let bad = launch(&["score", what], &folder, WATCHDOG);
        let said = String::from_utf8_lossy(&bad.stderr);
        assert!(
            !bad.status.success() && said.contains("holds no suite"),
            "{said}"
        );
        assert!(!folder.exists(), "{what} made the folder");
    }
    let not_a_row = dir.0.join("not-a-row.json");
    std::fs::write(&not_a_row, "{\"suite\": 1}").expect("write");
    let bad = launch(
        &["score", "--compare", &not_a_row.to_string_lossy()],
        dir.0.as_path(),
        WATCHDOG,
    );
    let said = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success());
    assert!(said.contains("not-a-row.json: not a score row"), "{said}");
}
