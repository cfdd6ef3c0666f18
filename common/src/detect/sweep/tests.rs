use super::*;
use crate::detect::names;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const DT: f64 = 0.01;

fn watched(statistic: f64) -> Verdict {
    Verdict::Watched {
        statistic,
        threshold: f64::NAN,
    }
}

/// 100 ticks of 10 ms: no verdict in the first 10; the attack in force at 30..50 and 70..80; the
/// statistic 1 at rest, 5 from tick 33 to 51 (3 ticks late, 2 ticks past the end), a spike of 3
/// at tick 60, 8 at 75..80.
fn synthetic() -> Vec<Sample> {
    (0..100u32)
        .map(|k| {
            let statistic = match k {
                33..=51 => 5.0,
                60 => 3.0,
                75..=79 => 8.0,
                _ => 1.0,
            };
            Sample {
                t: f64::from(k) * DT,
                in_force: (30..50).contains(&k) || (70..80).contains(&k),
                verdict: if k < 10 {
                    Verdict::Calibrating
                } else {
                    watched(statistic)
                },
            }
        })
        .collect()
}

fn close(a: Option<f64>, b: f64) -> bool {
    a.is_some_and(|a| (a - b).abs() < 1e-12)
}

#[test]
fn a_synthetic_series_gives_its_known_rates_and_delays() {
    let s = synthetic();
    // Threshold 2: in force 33..50 and 75..80 alarmed (17 + 5 of 30); attack-free 50, 51 (the
    // alarm outlasting the attack, no new rising edge) and the spike at 60 (one false alarm).
    let t = tally(&s, 2.0);
    assert_eq!(t.no_verdict_ticks, 10);
    assert_eq!((t.in_force_ticks, t.in_force_alarms), (30, 22));
    assert_eq!((t.free_ticks, t.free_alarms), (60, 3));
    assert_eq!(t.false_alarms, 1);
    assert_eq!((t.onsets, t.detected, t.alarm_on_at_onset), (2, 2, 0));
    assert!(close(t.tpr(), 22.0 / 30.0), "{t:?}");
    assert!(close(t.fpr(), 3.0 / 60.0), "{t:?}");
    assert!(close(t.mean_delay_s(), (0.03 + 0.05) / 2.0), "{t:?}");
    // One false alarm in 60 watched attack-free ticks of 10 ms: 100 per minute.
    assert!(close(t.false_alarms_per_min(DT), 100.0), "{t:?}");

    // Threshold 4: the spike is gone.
    let t = tally(&s, 4.0);
    assert_eq!(
        (t.in_force_alarms, t.free_alarms, t.false_alarms),
        (22, 2, 0)
    );
    assert!(close(t.false_alarms_per_min(DT), 0.0));

    // Threshold 6: only the second attack, detected 5 ticks in; the first is undetected and
    // is not averaged in.
    let t = tally(&s, 6.0);
    assert_eq!((t.in_force_alarms, t.free_alarms), (5, 0));
    assert_eq!((t.onsets, t.detected), (2, 1));
    assert!(close(t.mean_delay_s(), 0.05), "{t:?}");

    // Above everything: nothing detected, the delay is undefined rather than a number.
    let t = tally(&s, 10.0);
    assert_eq!((t.in_force_alarms, t.free_alarms, t.detected), (0, 0, 0));
    assert_eq!(t.tpr(), Some(0.0));
    assert_eq!(t.mean_delay_s(), None);
}

#[test]
fn an_alarm_already_on_at_an_onset_detects_it_at_once_and_is_counted_so() {
    // The alarm is on from tick 5 (attack-free), the attack starts at tick 10.
    let s: Vec<Sample> = (0..20u32)
        .map(|k| Sample {
            t: f64::from(k) * DT,
            in_force: k >= 10,
            verdict: watched(if k >= 5 { 9.0 } else { 0.0 }),
        })
        .collect();
    let t = tally(&s, 1.0);
    assert_eq!((t.onsets, t.detected, t.alarm_on_at_onset), (1, 1, 1));
    assert_eq!(t.mean_delay_s(), Some(0.0));
    assert_eq!(t.false_alarms, 1);
}

#[test]
fn non_finite_ticks_alarm_and_missing_ones_keep_the_alarm_at_every_threshold() {
    let v = [
        watched(5.0),
        Verdict::Missing,
        Verdict::NonFinite,
        watched(0.0),
        Verdict::Missing,
        Verdict::Uncalibrated,
    ];
    let s: Vec<Sample> = v
        .iter()
        .enumerate()
        .map(|(k, &verdict)| Sample {
            t: k as f64 * DT,
            in_force: false,
            verdict,
        })
        .collect();
    // Threshold 1: on, kept, on, off, kept off, no verdict.
    let t = tally(&s, 1.0);
    assert_eq!((t.free_ticks, t.free_alarms, t.no_verdict_ticks), (5, 3, 1));
    assert_eq!(t.false_alarms, 1);
    // Threshold 10: only the non-finite tick.
    let t = tally(&s, 10.0);
    assert_eq!((t.free_alarms, t.false_alarms), (1, 1));
}

#[test]
fn without_an_onset_the_true_positive_rate_and_the_delay_are_undefined() {
    let s: Vec<Sample> = (0..50u32)
        .map(|k| Sample {
            t: f64::from(k) * DT,
            in_force: false,
            verdict: watched(f64::from(k)),
        })
        .collect();
    let t = tally(&s, 10.0);
    assert_eq!((t.onsets, t.in_force_ticks), (0, 0));
    assert_eq!((t.tpr(), t.mean_delay_s()), (None, None));
    assert!(close(t.fpr(), 39.0 / 50.0));
}

#[test]
fn the_thresholds_are_zero_a_log_grid_over_the_positive_statistics_and_the_configured_one() {
    let s = synthetic();
    let grid = thresholds(&s, 5, Some(2.5));
    assert_eq!(grid.len(), 7, "{grid:?}");
    assert_eq!((grid[0], grid[1], grid[6]), (0.0, 1.0, 8.0));
    assert!(grid.contains(&2.5));
    let logs: Vec<f64> = grid
        .iter()
        .filter(|x| **x > 0.0 && **x != 2.5)
        .map(|x| x.ln())
        .collect();
    for w in logs.windows(2) {
        assert!((w[1] - w[0] - 8f64.ln() / 4.0).abs() < 1e-12, "{grid:?}");
    }
    // A configured value on the grid appears once; no statistic: 0 and the configured value.
    assert_eq!(thresholds(&s, 2, Some(8.0)), [0.0, 1.0, 8.0]);
    let none = [Sample {
        t: 0.0,
        in_force: false,
        verdict: Verdict::Uncalibrated,
    }];
    assert_eq!(thresholds(&none, 10, Some(3.0)), [0.0, 3.0]);
}

#[test]
fn rates_and_detections_never_rise_with_the_threshold() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut in_force = false;
    let s: Vec<Sample> = (0..5000u32)
        .map(|k| {
            if rng.random_bool(0.01) {
                in_force = !in_force;
            }
            let base = if in_force { 3.0 } else { 1.0 };
            let verdict = match rng.random_range(0..100) {
                0 => Verdict::Missing,
                1 => Verdict::NonFinite,
                2 => Verdict::Calibrating,
                _ => watched(base * rng.random_range(0.0..2.0f64)),
            };
            Sample {
                t: f64::from(k) * DT,
                in_force,
                verdict,
            }
        })
        .collect();
    let grid = thresholds(&s, 40, None);
    let tallies: Vec<Tally> = grid.iter().map(|&x| tally(&s, x)).collect();
    assert!(tallies[0].onsets > 10);
    for w in tallies.windows(2) {
        assert!(w[1].in_force_alarms <= w[0].in_force_alarms);
        assert!(w[1].free_alarms <= w[0].free_alarms);
        assert!(w[1].detected <= w[0].detected);
        assert_eq!(w[1].onsets, w[0].onsets);
    }
    let (lo, hi) = (&tallies[0], &tallies[tallies.len() - 1]);
    assert!(lo.tpr().is_some_and(|x| x > 0.9) && hi.tpr().is_some_and(|x| x < 0.05));
}

/// At the configured thresholds the sweep is the metrics: on the paper's scenario (6 s), every
/// robot's false alarms, onsets, detections, coverage, alarmed share of attack-free time and
/// delays match what `metrics` computed, for all three detectors, and `s_hat_norm` replayed from
/// `Ŝ` is the center's recorded alarm at every tick.
#[test]
fn the_configured_thresholds_reproduce_the_metrics_and_the_centers_alarm() {
    let mut r = crate::scenario::paper().expect("paper");
    r.scenario.duration_s = 6.0;
    let mut rec = Recorder::for_scenario(&r);
    let mut center_alarms = 0u64;
    let summary = crate::engine::run_inproc_any(&r, |t| {
        center_alarms += u64::from(t.center.alarm);
        rec.push(t);
    })
    .expect("run");
    assert!(center_alarms > 100, "{center_alarms} alarm ticks");
    let recorded = rec.finish();
    assert_eq!(recorded.s_hat_mismatches.len(), 4);
    assert!(
        recorded.s_hat_mismatches.values().all(|n| *n == 0),
        "{:?}",
        recorded.s_hat_mismatches
    );
    let mut compared = 0;
    for name in names() {
        let d = recorded.detector(name).expect("detector");
        let configured = d.configured.expect("a configured threshold");
        let points = sweep(d, 8);
        let at = points
            .iter()
            .find(|p| p.configured)
            .expect("the configured threshold is on the grid");
        assert_eq!(at.threshold, configured);
        for (id, t) in &at.robots {
            let m = &summary.metrics[&id.to_string()];
            let dm = &m.detectors[name];
            let what = format!("{name}, robot {id}: {t:?}\n{dm:?}");
            assert_eq!(t.false_alarms, dm.false_alarms, "{what}");
            assert_eq!(t.onsets, dm.onsets.len() as u64, "{what}");
            let delays: Vec<f64> = dm
                .onsets
                .iter()
                .filter_map(|o| o.time_to_detect_s)
                .collect();
            assert_eq!(t.detected, delays.len() as u64, "{what}");
            let on = dm.alarm_on_at_onset.iter().filter(|x| **x).count() as u64;
            assert_eq!(t.alarm_on_at_onset, on, "{what}");
            assert_eq!(
                dm.coverage,
                (m.attacked_ticks > 0).then(|| t.in_force_alarms as f64 / m.attacked_ticks as f64),
                "{what}"
            );
            assert_eq!(dm.false_alarm_share, t.fpr(), "{what}");
            match t.mean_delay_s() {
                Some(mean) => {
                    let want = delays.iter().sum::<f64>() / delays.len() as f64;
                    assert!((mean - want).abs() < 1e-12, "{what}");
                }
                None => assert!(delays.is_empty(), "{what}"),
            }
            compared += 1;
        }
    }
    assert_eq!(compared, 4 * names().len());
}

/// The MCAP export writes each tick's statistics as they come: `observe` gives the very samples
/// `push` keeps, in the order of `names()`, and keeps none of them (memory does not grow with the
/// run), with the thresholds `finish` reports.
#[test]
fn observe_gives_the_samples_push_keeps_and_keeps_none() {
    let mut r = crate::scenario::paper().expect("paper");
    r.scenario.duration_s = 1.0;
    let (mut kept, mut streamed) = (Recorder::for_scenario(&r), Recorder::for_scenario(&r));
    let mut seen: BTreeMap<u32, Vec<Vec<Sample>>> = BTreeMap::new();
    crate::engine::run_inproc_any(&r, |t| {
        kept.push(t);
        let s = streamed.observe(t).expect("an agent of the scenario");
        seen.entry(t.agent.agent).or_default().push(s);
    })
    .expect("run");
    let configured = streamed.configured();
    let (kept, streamed) = (kept.finish(), streamed.finish());
    assert_eq!(seen.len(), 4);
    for (i, name) in names().iter().enumerate() {
        let d = kept.detector(name).expect("detector");
        assert_eq!(configured[i], (*name, d.configured));
        for (id, series) in &d.robots {
            let got: Vec<Sample> = seen[id].iter().map(|s| s[i]).collect();
            // Compared as text: a NaN threshold is equal to itself there.
            assert_eq!(
                format!("{got:?}"),
                format!("{series:?}"),
                "{name}, robot {id}"
            );
        }
        let none = streamed.detector(name).expect("detector");
        assert!(none.robots.values().all(Vec::is_empty), "{name}");
    }
}
