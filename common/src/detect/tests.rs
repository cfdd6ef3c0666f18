//! Properties of the χ² and CUSUM detectors on synthetic residuals: records whose observer
//! state is zero, so that the innovation residual is the measurement itself.

use nalgebra::{DVector, Matrix4, Vector4};
use rand::SeedableRng;
use rand_chacha::ChaCha12Rng;
use rand_distr::{Distribution, StandardNormal};

use super::*;
use crate::records::{AgentRecord, AttackRecord, CenterRecord, Joints};

const DT: f64 = 1e-3;
/// Calibration window of the tests: 20 s, 20 000 ticks.
const CAL_S: f64 = 20.0;
const CAL_TICKS: u64 = 20_000;

/// The residual's true covariance `A Aᵀ`: position entries ~1e-4 rad, velocity entries
/// ~1e-3 rad/s, correlated.
fn a() -> Matrix4<f64> {
    Matrix4::new(
        1e-4, 0.0, 0.0, 0.0, //
        0.5e-4, 2e-4, 0.0, 0.0, //
        1e-3, -0.5e-3, 3e-3, 0.0, //
        0.0, 0.3e-3, 0.2e-3, 1e-3,
    )
}

/// Tick `k` of agent 1 whose innovation residual is `r` (y₁, y₂, ẏ₁, ẏ₂).
fn record(k: u64, r: Vector4<f64>) -> TickRecord {
    let j = Joints::from_slice;
    let zero = j(&[0.0, 0.0]);
    TickRecord {
        agent: AgentRecord {
            k,
            agent: 1,
            t: k as f64 * DT,
            q: zero,
            qd: zero,
            qdd: zero,
            y: zero,
            yd: zero,
            u_applied: zero,
            tau: 0.003,
            missed: false,
        },
        attack: AttackRecord {
            k,
            agent: 1,
            alpha_position: zero,
            alpha_velocity: zero,
            y: j(&[r[0], r[1]]),
            yd: j(&[r[2], r[3]]),
            active: false,
            delivery: Default::default(),
        },
        center: CenterRecord {
            k,
            agent: 1,
            s_hat: zero,
            q_hat: zero,
            qd_hat: zero,
            qdd_hat: zero,
            u: zero,
            alarm: false,
            rejected_input: false,
            rejected_torque: false,
            state_reset: false,
            history_miss: false,
            missing_input: false,
        },
        actuation: None,
        monitor: None,
    }
}

fn config(window_ticks: usize, p: f64) -> DetectorsConfig {
    DetectorsConfig {
        calibration_s: Some(CAL_S),
        chi2: Chi2Config {
            window_ticks,
            false_alarm_probability: p,
            threshold: None,
        },
        // These tests feed 4-entry residuals: the innovation of a two-link robot.
        residual: ResidualKind::Innovation,
        ..DetectorsConfig::defaults()
    }
}

/// Residuals `A n + bias(k)`, n standard normal from `seed`.
fn residuals(
    seed: u64,
    ticks: u64,
    bias: impl Fn(u64) -> Vector4<f64>,
) -> impl Iterator<Item = (u64, Vector4<f64>)> {
    let mut rng = ChaCha12Rng::seed_from_u64(seed);
    let a = a();
    (0..ticks).map(move |k| {
        let n = Vector4::from_fn(|_, _| StandardNormal.sample(&mut rng));
        (k, a * n + bias(k))
    })
}

/// The verdicts of the χ² and CUSUM detectors on one tick (the first two of [`RESIDUAL`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Verdicts {
    chi2: Verdict,
    cusum: Verdict,
}

impl Verdicts {
    fn of(v: &[Verdict]) -> Self {
        assert_eq!(RESIDUAL[0].name, CHI2);
        assert_eq!(RESIDUAL[1].name, CUSUM);
        Self {
            chi2: v[0],
            cusum: v[1],
        }
    }

    fn both(v: Verdict) -> Self {
        Self { chi2: v, cusum: v }
    }
}

/// Runs the detectors; returns the verdicts of the ticks after the calibration window.
fn run(c: &DetectorsConfig, stream: impl Iterator<Item = (u64, Vector4<f64>)>) -> Vec<Verdicts> {
    let mut d = RobotDetectors::new(c, DT, 30.0, 2);
    let mut out = Vec::new();
    for (k, r) in stream {
        let v = Verdicts::of(d.push(&record(k, r)));
        if k >= CAL_TICKS {
            out.push(v);
        }
    }
    out
}

fn alarm_share(v: &[Verdict]) -> f64 {
    v.iter().filter(|v| v.alarm(false)).count() as f64 / v.len() as f64
}

fn first_alarm(v: &[Verdict]) -> Option<usize> {
    v.iter().position(|v| v.alarm(false))
}

#[test]
fn a_residual_from_the_calibration_distribution_alarms_at_the_chosen_rate() {
    // Per tick: the share of alarmed ticks estimates p (binomial: 2000 ± 45 of 200 000). A
    // wrong covariance (Σ for Σ⁻¹, a missing ridge scale), or a quantile of the wrong degrees of
    // freedom, misses by far more than the tolerance; so would a window that is not summed.
    for (w, p, tolerance) in [(1, 0.01, 0.15), (10, 0.01, 0.25), (1, 0.05, 0.1)] {
        let verdicts = run(
            &config(w, p),
            residuals(7, CAL_TICKS + 200_000, |_| Vector4::zeros()),
        );
        let chi2: Vec<Verdict> = verdicts.iter().map(|v| v.chi2).collect();
        assert!(
            chi2[w - 1..]
                .iter()
                .all(|v| matches!(v, Verdict::Watched { .. })),
            "w = {w}: every tick after the window fills is judged"
        );
        let share = alarm_share(&chi2[w - 1..]);
        assert!(
            (share / p - 1.0).abs() < tolerance,
            "w = {w}, p = {p}: alarm share {share}"
        );
    }
}

#[test]
fn a_step_bias_of_six_standard_deviations_is_detected_by_both_within_a_few_ticks() {
    let sigma0 = a()[(0, 0)];
    let onset = CAL_TICKS + 5000;
    for seed in 1..=5 {
        let verdicts = run(
            &DetectorsConfig {
                calibration_s: Some(CAL_S),
                residual: ResidualKind::Innovation,
                ..DetectorsConfig::defaults()
            },
            residuals(seed, onset + 1000, |k| {
                Vector4::new(if k >= onset { 6.0 * sigma0 } else { 0.0 }, 0.0, 0.0, 0.0)
            }),
        );
        let before = (onset - CAL_TICKS) as usize;
        let chi2: Vec<Verdict> = verdicts.iter().map(|v| v.chi2).collect();
        let cusum: Vec<Verdict> = verdicts.iter().map(|v| v.cusum).collect();
        for (name, v) in [("chi2", &chi2), ("cusum", &cusum)] {
            assert_eq!(
                first_alarm(&v[..before]),
                None,
                "seed {seed}: {name} alarmed before the bias (defaults: p = 1e-6, h = 15)"
            );
            let delay = first_alarm(&v[before..]).expect("detected");
            assert!(delay < 25, "seed {seed}: {name} took {delay} ticks");
        }
    }
}

#[test]
fn cusum_detects_a_small_persistent_bias_that_the_per_tick_chi2_misses() {
    // One standard deviation along the first whitened axis: `A e₁`, so `z₁` shifts by 1.
    let shift = a().column(0).into_owned();
    let onset = CAL_TICKS + 2000;
    for seed in 11..=15 {
        let verdicts = run(
            &DetectorsConfig {
                calibration_s: Some(CAL_S),
                residual: ResidualKind::Innovation,
                ..DetectorsConfig::defaults()
            },
            residuals(seed, onset + 3000, |k| {
                if k >= onset {
                    shift
                } else {
                    Vector4::zeros()
                }
            }),
        );
        let after = &verdicts[(onset - CAL_TICKS) as usize..];
        let chi2: Vec<Verdict> = after.iter().map(|v| v.chi2).collect();
        let cusum: Vec<Verdict> = after.iter().map(|v| v.cusum).collect();
        assert!(
            alarm_share(&chi2) < 0.01,
            "seed {seed}: χ² alarmed on {} of the biased ticks",
            alarm_share(&chi2)
        );
        let delay = first_alarm(&cusum).expect("CUSUM detects the bias");
        // h / (δ − ν) = 15 / 0.5 = 30 ticks on average.
        assert!(delay < 150, "seed {seed}: CUSUM took {delay} ticks");
        assert!(
            alarm_share(&cusum[delay..]) > 0.9,
            "seed {seed}: the CUSUM alarm stays on while the bias lasts"
        );
    }
}

#[test]
fn the_same_input_gives_the_same_bits() {
    let bits = |v: &[Verdicts]| -> Vec<(u64, u64)> {
        let one = |v: Verdict| match v {
            Verdict::Watched { statistic, .. } => statistic.to_bits(),
            other => panic!("{other:?}"),
        };
        v.iter().map(|v| (one(v.chi2), one(v.cusum))).collect()
    };
    let c = config(5, 1e-3);
    let once = run(&c, residuals(3, CAL_TICKS + 3000, |_| Vector4::zeros()));
    let again = run(&c, residuals(3, CAL_TICKS + 3000, |_| Vector4::zeros()));
    assert_eq!(bits(&once[4..]), bits(&again[4..]));
}

#[test]
fn a_non_finite_or_absurd_measurement_is_counted_raises_the_alarm_and_leaves_the_state() {
    let c = config(1, 1e-6);
    let clean: Vec<(u64, Vector4<f64>)> =
        residuals(5, CAL_TICKS + 100, |_| Vector4::zeros()).collect();
    for bad in [f64::NAN, f64::INFINITY, 1e300] {
        let hit = CAL_TICKS + 50;
        let tampered = clean.iter().map(|&(k, r)| {
            (
                k,
                if k == hit {
                    Vector4::new(bad, 0.0, 0.0, 0.0)
                } else {
                    r
                },
            )
        });
        let got = run(&c, tampered);
        let want = run(&c, clean.iter().copied());
        let at = (hit - CAL_TICKS) as usize;
        assert_eq!(got[at], Verdicts::both(Verdict::NonFinite), "{bad}");
        assert!(got[at].chi2.alarm(false), "{bad}: the alarm is on");
        // The per-tick χ² of every other tick is untouched; the CUSUM before the hit too.
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            if i != at {
                assert_eq!(g.chi2, w.chi2, "{bad}, tick {i}");
            }
            if i < at {
                assert_eq!(g.cusum, w.cusum, "{bad}, tick {i}");
            }
        }
    }
    // Inside the calibration window, a non-finite residual is left out of the covariance and
    // counted.
    let mut d = RobotDetectors::new(&c, DT, 30.0, 2);
    for (k, r) in residuals(5, CAL_TICKS + 1, |_| Vector4::zeros()) {
        let r = if k == 10 {
            Vector4::new(f64::NAN, 0.0, 0.0, 0.0)
        } else {
            r
        };
        d.push(&record(k, r));
    }
    let cal = d.calibration();
    assert_eq!(
        (cal.samples, cal.non_finite, cal.missing),
        (CAL_TICKS - 2, 1, 1),
        "tick 0 has no previous record, tick 10 is NaN"
    );
    assert!(cal.failed.is_none() && cal.rms.iter().all(|x| x.is_finite()));
}

#[test]
fn a_singular_covariance_is_regularised_or_fails_the_calibration_when_told_not_to() {
    // Link 2 never moves and has no noise: its position residual is exactly zero.
    let stream = || {
        residuals(9, CAL_TICKS + 10, |_| Vector4::zeros())
            .map(|(k, r)| (k, Vector4::new(r[0], 0.0, r[2], r[3])))
    };
    let verdicts = run(&config(1, 1e-6), stream());
    assert!(verdicts.iter().all(|v| matches!(
        v.chi2,
        Verdict::Watched { statistic, .. } if statistic.is_finite()
    )));
    let off = DetectorsConfig {
        regularization: 0.0,
        ..config(1, 1e-6)
    };
    let mut d = RobotDetectors::new(&off, DT, 30.0, 2);
    let mut last = None;
    for (k, r) in stream() {
        last = Some(Verdicts::of(d.push(&record(k, r))));
    }
    assert_eq!(last, Some(Verdicts::both(Verdict::Uncalibrated)));
    let failed = d.calibration().failed.expect("failed");
    assert!(failed.contains("not positive definite"), "{failed}");
}

#[test]
fn a_gap_in_the_records_is_a_counted_miss_and_a_short_record_says_it_never_calibrated() {
    let gap = CAL_TICKS + 30;
    let verdicts = run(
        &config(1, 1e-6),
        residuals(4, CAL_TICKS + 60, |_| Vector4::zeros()).filter(|&(k, _)| k != gap),
    );
    let at = (gap - CAL_TICKS) as usize;
    assert_eq!(verdicts[at], Verdicts::both(Verdict::Missing));
    assert!(!verdicts[at].chi2.alarm(false) && verdicts[at].chi2.alarm(true));
    assert!(matches!(verdicts[at + 1].chi2, Verdict::Watched { .. }));

    let mut d = RobotDetectors::new(&config(1, 1e-6), DT, 30.0, 2);
    for (k, r) in residuals(4, 500, |_| Vector4::zeros()) {
        assert_eq!(
            Verdicts::of(d.push(&record(k, r))),
            Verdicts::both(Verdict::Calibrating)
        );
    }
    let failed = d.calibration().failed.expect("not calibrated");
    assert!(
        failed.contains("ended before the detectors could watch (500 ticks recorded, the calibration window is 20000)"),
        "{failed}"
    );
}

#[test]
fn the_residuals_are_the_measurement_minus_the_previous_observer_state() {
    let mut prev = record(6, Vector4::zeros()).center;
    prev.q_hat = Joints::from_slice(&[0.1, 0.2]);
    prev.qd_hat = Joints::from_slice(&[1.0, 2.0]);
    prev.qdd_hat = Joints::from_slice(&[50.0, 60.0]);
    let mut cur = record(7, Vector4::new(0.15, 0.1, 1.5, 3.0));
    cur.center.s_hat = Joints::from_slice(&[0.25, -0.5]);
    let innovation = residual::residual(ResidualKind::Innovation, 2, 30.0, Some(&prev), &cur)
        .expect("a residual");
    let want = DVector::from_vec(vec![0.15 - 0.1, 0.1 - 0.2, 1.5 - 1.0, 3.0 - 2.0]);
    assert!((innovation - want).norm() < 1e-15);
    let psi2 =
        residual::residual(ResidualKind::Psi2, 2, 30.0, Some(&prev), &cur).expect("a residual");
    let want = DVector::from_vec(vec![
        1.5 + 30.0 * 0.15 - 1.0 - 30.0 * 0.1 - 0.25,
        3.0 + 30.0 * 0.1 - 2.0 - 30.0 * 0.2 + 0.5,
    ]);
    assert!((psi2 - want).norm() < 1e-12);
    // Not the record of the tick before: no residual.
    let mut late = cur;
    late.center.k = 8;
    assert_eq!(
        residual::residual(ResidualKind::Innovation, 2, 30.0, Some(&prev), &late),
        Err(residual::Missing::NoPrevious)
    );
    assert_eq!(
        residual::residual(ResidualKind::Innovation, 3, 30.0, Some(&prev), &cur),
        Err(residual::Missing::Length)
    );
}
