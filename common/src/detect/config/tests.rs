use super::*;

fn paths(c: &DetectorsConfig, duration_s: f64) -> Vec<String> {
    c.problems("detectors", duration_s, 1e-3, Some(2))
        .into_iter()
        .map(|p| format!("{}: {}", p.path, p.message))
        .collect()
}

#[test]
fn the_defaults_are_valid_and_a_window_that_does_not_fit_is_refused_only_when_given() {
    assert!(paths(&DetectorsConfig::defaults(), 40.0).is_empty());
    // The innovation of a two-link robot: 4 entries.
    let d = DetectorsConfig {
        residual: ResidualKind::Innovation,
        ..DetectorsConfig::defaults()
    };
    assert!(paths(&d, 40.0).is_empty());
    // The default window does not refuse a run shorter than it: the run reports its
    // detectors as not calibrated.
    assert!(paths(&d, 1.0).is_empty());
    let given = DetectorsConfig {
        calibration_s: Some(2.0),
        ..d
    };
    let p = paths(&given, 1.0);
    assert_eq!(p.len(), 1, "{p:?}");
    assert!(
        p[0].starts_with(
            "detectors.calibration_s: the calibration window (2 s) must end before the run does"
        ),
        "{p:?}"
    );
    assert_eq!(paths(&given, 2.0).len(), 1, "a window as long as the run");
    assert!(paths(&given, 2.001).is_empty());
    // 4 residual entries need 41 ticks.
    let short = DetectorsConfig {
        calibration_s: Some(0.040),
        ..d
    };
    let p = paths(&short, 1.0);
    assert!(p[0].contains("fewer than 41 control periods"), "{p:?}");
}

/// `[detectors]` in a scenario file: parsed, validated with its field paths by the
/// scenario's own `validate`, written back out only when it is not the default.
#[test]
fn the_scenario_table_parses_validates_and_round_trips() {
    use crate::scenario::{load_str, paper, PAPER_SCENARIO};
    let r = paper().expect("valid");
    assert!(
        r.scenario.detectors.is_default(),
        "absent means the defaults"
    );
    assert!(!r.to_toml().contains("detectors"));
    let with = |table: &str| format!("{PAPER_SCENARIO}\n[detectors]\n{table}\n");
    let r = load_str(
        &with("calibration_s = 4.5\nresidual = \"psi2\"\nchi2 = { window_ticks = 20 }\ncusum = { drift = 1.0, threshold = 8.0 }"),
        "t",
        None,
    )
    .expect("valid");
    let d = r.scenario.detectors;
    assert_eq!(d.calibration_s, Some(4.5));
    assert_eq!(d.residual, ResidualKind::Psi2);
    assert_eq!(d.chi2.window_ticks, 20);
    assert_eq!(
        d.chi2.false_alarm_probability, 1e-6,
        "the rest keeps its default"
    );
    assert_eq!((d.cusum.drift, d.cusum.threshold), (1.0, 8.0));
    let again = load_str(&r.to_toml(), "again", None).expect("round trip");
    assert_eq!(again.scenario.detectors, d);
    for (table, want) in [
        (
            "calibration_s = 40.0",
            "detectors.calibration_s: the calibration window (40 s) must end before the run does",
        ),
        (
            "chi2 = { window_ticks = 0 }",
            "detectors.chi2.window_ticks: must be in 1..=1000",
        ),
        (
            "frobnicate = 1",
            "detectors.frobnicate: unknown field `frobnicate`",
        ),
        (
            "cusum = { h = 3.0 }",
            "detectors.cusum.h: unknown field `h`",
        ),
        (
            "residual = \"kalman\"",
            "detectors.residual: unknown variant `kalman`",
        ),
    ] {
        let err = load_str(&with(table), "t", None)
            .expect_err(table)
            .to_string();
        assert!(err.contains(want), "{table}: {err}");
    }
}

#[test]
fn every_bad_value_is_named_by_its_field() {
    let bad = DetectorsConfig {
        calibration_s: Some(f64::NAN),
        residual: ResidualKind::Innovation,
        regularization: -1.0,
        chi2: Chi2Config {
            window_ticks: 0,
            false_alarm_probability: 1.0,
            threshold: Some(0.0),
        },
        cusum: CusumConfig {
            drift: f64::INFINITY,
            threshold: -2.0,
        },
    };
    let p = paths(&bad, 40.0);
    for field in [
        "detectors.calibration_s: must be finite",
        "detectors.regularization: must be finite and in [0, 1]",
        "detectors.chi2.window_ticks: must be in 1..=1000",
        "detectors.chi2.false_alarm_probability: must be in (0, 1)",
        "detectors.chi2.threshold: must be finite and > 0",
        "detectors.cusum.drift: must be finite and ≥ 0",
        "detectors.cusum.threshold: must be finite and > 0",
    ] {
        assert!(p.iter().any(|l| l.starts_with(field)), "{field}: {p:?}");
    }
    assert_eq!(p.len(), 7, "{p:?}");
}
