//! The scored benchmark (`fdi-launch score`, docs/score.md): a controller's row is the same
//! from two runs of the suite (what two labs with the same code get), two rows print side by
//! side, and a wrong detector or row file is named before anything runs.

use std::time::Duration;

use fdi_tests::{json, launch, launch_plain, Scratch};

const WATCHDOG: Duration = Duration::from_secs(600);

#[test]
fn a_controller_s_row_is_the_same_from_two_runs_and_two_rows_compare() {
    let dir = Scratch::new("score");
    let out = |name: &str| dir.0.join(name);
    let row = |controller: &str, name: &str| {
        let folder = out(name);
        let args = ["score", "--controller", controller, "--json"];
        json(&launch(&args, &folder, WATCHDOG))
    };
    let (a, b) = (row("traditional", "a"), row("traditional", "b"));
    assert_eq!(a, b, "the same row from two runs");
    assert_eq!(a["suite"], "fdi-mas-score-1");
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
    let bad = launch(
        &["score", "--detector", "psychic"],
        dir.0.as_path(),
        WATCHDOG,
    );
    let said = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success());
    assert!(
        said.contains("unknown detector `psychic`") && said.contains("chi2"),
        "{said}"
    );
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
