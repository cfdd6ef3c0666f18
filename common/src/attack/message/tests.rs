use super::*;
use crate::rng::{stream, Purpose};
use proptest::prelude::*;
use rand::Rng;

const DT: f64 = 1e-3;

/// `t_k = k·Δ`, as the engines compute it.
fn t(k: u64) -> f64 {
    k as f64 * DT
}

fn attack(path: Path, segments: &[(f64, Effect)]) -> MessageAttack {
    MessageAttack {
        agent: 1,
        path,
        segments: segments
            .iter()
            .map(|&(from_s, effect)| MessageSegment { from_s, effect })
            .collect(),
    }
}

fn rng(seed: u64, path: Path) -> ChaCha12Rng {
    stream(
        seed,
        1,
        Purpose::AttackMessages {
            torque: path == Path::Torque,
        },
    )
}

/// A compiled line whose payload is the tick number, so what arrives tells which tick sent it.
fn line(path: Path, segments: &[(f64, Effect)], seed: u64) -> MessageLine<u64> {
    MessageLine::compile(&attack(path, segments), rng(seed, path))
}

/// What the line makes of ticks `0..n`.
fn run(line: &mut MessageLine<u64>, n: u64) -> Vec<Sent<u64>> {
    (0..n).map(|k| line.send(k, t(k), k)).collect()
}

fn live(k: u64) -> Sent<u64> {
    Sent::Delivered {
        payload: k,
        held_s: 0.0,
    }
}

/// Which ticks were dropped; every other one must be delivered untouched.
fn dropped(sent: &[Sent<u64>]) -> Vec<bool> {
    sent.iter()
        .enumerate()
        .map(|(k, s)| match *s {
            Sent::Missing => true,
            s => {
                assert_eq!(s, live(k as u64), "tick {k}");
                false
            }
        })
        .collect()
}

fn drop_all_the_time(probability: f64) -> [(f64, Effect); 1] {
    [(0.0, Effect::Drop { probability })]
}

#[test]
fn drop_drops_a_share_within_a_few_standard_errors_of_its_probability() {
    let n = 100_000u64;
    for path in [Path::Measurement, Path::Torque] {
        for p in [0.05, 0.3, 0.5, 0.9] {
            for seed in [1, 7] {
                let mut l = line(path, &drop_all_the_time(p), seed);
                let drops = dropped(&run(&mut l, n)).iter().filter(|d| **d).count();
                let share = drops as f64 / n as f64;
                let se = (p * (1.0 - p) / n as f64).sqrt();
                assert!(
                    (share - p).abs() < 4.0 * se,
                    "{path:?}, p = {p}, seed {seed}: share {share}, {} standard errors off",
                    (share - p) / se
                );
            }
        }
    }
}

#[test]
fn drop_with_probability_zero_drops_nothing_and_one_everything() {
    for path in [Path::Measurement, Path::Torque] {
        let mut none = line(path, &drop_all_the_time(0.0), 3);
        assert!(dropped(&run(&mut none, 20_000)).iter().all(|d| !d));
        let mut all = line(path, &drop_all_the_time(1.0), 3);
        assert!(dropped(&run(&mut all, 20_000)).iter().all(|d| *d));
    }
}

#[test]
fn drop_is_deterministic_for_a_seed_and_differs_for_another() {
    let verdicts = |seed| {
        dropped(&run(
            &mut line(Path::Measurement, &drop_all_the_time(0.5), seed),
            2000,
        ))
    };
    assert_eq!(verdicts(11), verdicts(11));
    assert_ne!(verdicts(11), verdicts(12));
    // The two paths of one agent draw from distinct streams.
    let torque = dropped(&run(
        &mut line(Path::Torque, &drop_all_the_time(0.5), 11),
        2000,
    ));
    assert_ne!(verdicts(11), torque);
}

proptest! {
    /// One draw per message, dropped or not: message `i` of the segment is dropped exactly
    /// when the `i`-th number of the stream is below `p`. So a prefix of ticks gets the same
    /// verdicts whatever comes later, and a higher probability drops a superset.
    #[test]
    fn drop_takes_one_draw_per_message(seed in any::<u64>(), p in 0.0f64..=1.0, q in 0.0f64..=1.0, n in 1u64..600, later in 0u64..3) {
        let schedule = [(0.0, Effect::Drop { probability: p })];
        let mut reference = rng(seed, Path::Measurement);
        let want: Vec<bool> = (0..n).map(|_| reference.random::<f64>() < p).collect();
        let mut l = line(Path::Measurement, &schedule, seed);
        let got = dropped(&run(&mut l, n));
        prop_assert_eq!(&got, &want);
        // The same stream continued with other ticks, or another schedule after the prefix.
        let tail = [
            (0.0, Effect::Drop { probability: p }),
            (t(n), [Effect::Pass, Effect::Drop { probability: q }, Effect::Drop { probability: 1.0 }][later as usize]),
        ];
        let mut longer = line(Path::Measurement, &tail, seed);
        let prefix = dropped(&run(&mut longer, n + 300));
        prop_assert_eq!(&prefix[..n as usize], &want[..]);
        // Coupling: under the larger probability every message dropped under the smaller is
        // dropped too.
        let (lo, hi) = (p.min(q), p.max(q));
        let under = |p| dropped(&run(&mut line(Path::Measurement, &[(0.0, Effect::Drop { probability: p })], seed), n));
        let (a, b) = (under(lo), under(hi));
        prop_assert!(a.iter().zip(&b).all(|(x, y)| !x || *y));
    }
}

/// `(mean run of drops, mean run of deliveries, number of runs of drops)`, in seconds, over
/// whole runs (the first and last run are left out: they are cut by the window).
fn runs(dropped: &[bool]) -> (f64, f64, usize) {
    let mut lengths: Vec<(bool, usize)> = Vec::new();
    for &d in dropped {
        match lengths.last_mut() {
            Some((state, len)) if *state == d => *len += 1,
            _ => lengths.push((d, 1)),
        }
    }
    let whole = &lengths[1..lengths.len() - 1];
    let mean = |state: bool| {
        let l: Vec<usize> = whole.iter().filter(|r| r.0 == state).map(|r| r.1).collect();
        (
            l.iter().sum::<usize>() as f64 * DT / l.len() as f64,
            l.len(),
        )
    };
    let ((bad, n), (good, _)) = (mean(true), mean(false));
    (bad, good, n)
}

#[test]
fn burst_drops_come_in_runs_with_the_configured_mean_length_and_gap() {
    // 200 s at 1 ms. The channel switches state at a message with probability
    // 1 − exp(−Δ / mean): a run lasts `mean` on average, plus half a tick of rounding.
    let n = 200_000;
    let (mean_gap_s, mean_length_s) = (0.5, 0.1);
    for seed in [1, 2] {
        let burst = Effect::Burst {
            mean_gap_s,
            mean_length_s,
        };
        let d = dropped(&run(&mut line(Path::Measurement, &[(0.0, burst)], seed), n));
        let (bad, good, bursts) = runs(&d);
        // About 200 s / 0.6 s ≈ 330 bursts; a mean of that many exponential lengths has a
        // relative standard error of about 5.5 %.
        assert!(bursts > 250, "seed {seed}: {bursts} bursts");
        assert!(
            (bad / mean_length_s - 1.0).abs() < 0.2,
            "seed {seed}: mean burst {bad} s, want {mean_length_s} s"
        );
        assert!(
            (good / mean_gap_s - 1.0).abs() < 0.2,
            "seed {seed}: mean gap {good} s, want {mean_gap_s} s"
        );
        // Runs, not scattered drops: independent drops with the same share would make runs
        // of about one tick.
        assert!(bad / DT > 50.0);
    }
}

#[test]
fn burst_starts_its_segment_in_the_good_state() {
    // The first message of a segment that begins with the first tick: no time has passed,
    // so the channel cannot have left its good state.
    for seed in 0..50 {
        let fast = Effect::Burst {
            mean_gap_s: 1e-6,
            mean_length_s: 1e-6,
        };
        let mut l = line(Path::Torque, &[(0.0, fast)], seed);
        assert_eq!(l.send(0, 0.0, 0), live(0), "seed {seed}");
    }
    // A channel that (almost surely) never leaves the state it is in: the segment, started
    // in the good state, delivers everything.
    let sticky = Effect::Burst {
        mean_gap_s: 1e12,
        mean_length_s: 1e12,
    };
    let d = dropped(&run(
        &mut line(Path::Measurement, &[(0.5, sticky)], 4),
        2000,
    ));
    assert!(d.iter().all(|d| !d));
}

#[test]
fn a_second_burst_segment_starts_in_the_good_state_too() {
    // The first segment goes bad at once and stays bad; the second never switches: it
    // must deliver everything, whatever state the first one ended in.
    let stuck_bad = Effect::Burst {
        mean_gap_s: 1e-9,
        mean_length_s: 1e12,
    };
    let sticky = Effect::Burst {
        mean_gap_s: 1e12,
        mean_length_s: 1e12,
    };
    for second in [
        vec![(t(1000), sticky)],
        vec![(t(1000), Effect::Pass), (t(1500), sticky)],
    ] {
        let mut schedule = vec![(0.0, stuck_bad)];
        schedule.extend(second.iter().copied());
        let d = dropped(&run(&mut line(Path::Measurement, &schedule, 5), 2000));
        assert!(d[1..1000].iter().all(|d| *d), "the first segment is bad");
        assert!(
            d[1000..].iter().all(|d| !d),
            "{second:?}: {} drops after the first segment",
            d[1000..].iter().filter(|d| **d).count()
        );
    }
}

fn delay(by_s: f64, amplitude_s: f64, rate_rad_s: f64) -> Effect {
    Effect::Delay {
        by_s,
        amplitude_s,
        rate_rad_s,
    }
}

#[test]
fn delay_on_the_torque_path_holds_each_command_back_by_d_of_its_time() {
    for (by_s, amplitude_s, rate_rad_s) in [(0.01, 0.0, 0.0), (0.004, 0.003, 7.0)] {
        let mut l = line(
            Path::Torque,
            &[
                (t(500), delay(by_s, amplitude_s, rate_rad_s)),
                (t(1500), Effect::Pass),
            ],
            1,
        );
        for k in 0..2000 {
            let d = by_s + amplitude_s * (rate_rad_s * t(k)).sin();
            let want = if (500..1500).contains(&k) {
                Sent::Delivered {
                    payload: k,
                    held_s: d,
                }
            } else {
                live(k)
            };
            assert_eq!(l.send(k, t(k), k), want, "tick {k}");
        }
    }
    // The sine part is really there.
    let mut l = line(Path::Torque, &[(0.0, delay(0.004, 0.003, 7.0))], 1);
    let held: Vec<f64> = (0..1000)
        .map(|k| l.send(k, t(k), k).usable().expect("delivered").1)
        .collect();
    let (lo, hi) = held
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), h| {
            (a.min(*h), b.max(*h))
        });
    assert!(
        lo < 0.0015 && hi > 0.0065 && lo >= 0.001 - 1e-15,
        "{lo} .. {hi}"
    );
}

#[test]
fn delay_on_the_measurement_path_gets_the_newest_arrival_by_exact_tick_arithmetic() {
    // d = 3.5 Δ from the first tick to 1 s, then pass: the message of tick j arrives at
    // t_j + d, so at tick k the newest arrival is j = k − 4; nothing has arrived before
    // tick 4.
    let d = 0.0035;
    let mut l = line(
        Path::Measurement,
        &[(0.0, delay(d, 0.0, 0.0)), (t(1000), Effect::Pass)],
        1,
    );
    for k in 0..1500u64 {
        let got = l.send(k, t(k), k);
        let want = match k {
            0..4 => Sent::Missing,
            4..1000 => {
                let j = k - 4;
                assert!(t(j) + d <= t(k) && t(k) < t(j + 1) + d);
                live(j)
            }
            _ => live(k),
        };
        assert_eq!(got, want, "tick {k}");
    }
}

/// The newest message (by tick) that has arrived by tick `k` under `schedule` on the
/// measurement path, every tick being sent: arrival `t_j + d(t_j)` under a delay, `t_j`
/// otherwise.
fn newest_arrival(schedule: &[(f64, Effect)], k: u64) -> Option<u64> {
    (0..=k).rev().find(|&j| {
        let held = schedule
            .iter()
            .rev()
            .find(|s| s.0 <= t(j))
            .and_then(|s| s.1.delay(t(j)))
            .unwrap_or(0.0);
        t(j) + held <= t(k)
    })
}

proptest! {
    /// Under any delay (a sine part fast enough to reorder arrivals included) the center
    /// gets the newest message delivered by then, and the live one again after the delay.
    #[test]
    fn delay_on_the_measurement_path_matches_a_brute_force_arrival_schedule(
        start in 0u64..50, len in 1u64..400,
        by in 0.0f64..0.05, amp_share in -1.0f64..=1.0, rate in 0.0f64..400.0,
    ) {
        let schedule = [
            (t(start), delay(by, amp_share * by, rate)),
            (t(start + len), Effect::Pass),
        ];
        let mut l = line(Path::Measurement, &schedule, 1);
        for k in 0..start + len + 100 {
            let want = newest_arrival(&schedule, k).map_or(Sent::Missing, live);
            prop_assert_eq!(l.send(k, t(k), k), want, "tick {}", k);
        }
    }
}

#[test]
fn forge_stamp_forges_every_message_of_its_segment_on_both_paths() {
    for path in [Path::Measurement, Path::Torque] {
        let mut l = line(
            path,
            &[
                (t(100), Effect::ForgeStamp { shift_s: -0.002 }),
                (t(200), Effect::Pass),
            ],
            1,
        );
        for (k, s) in run(&mut l, 300).into_iter().enumerate() {
            let k = k as u64;
            let want = if (100..200).contains(&k) {
                Sent::Forged {
                    payload: k,
                    shift_s: -0.002,
                }
            } else {
                live(k)
            };
            assert_eq!(s, want, "{path:?}, tick {k}");
            assert_eq!(s.usable().is_some(), !(100..200).contains(&k));
        }
    }
}

#[test]
fn replay_original_resends_the_recording_in_order_with_its_own_ticks_in_a_loop() {
    let (from, len) = (0.1, 0.05);
    let replay = Effect::ReplayOriginal {
        record_from_s: from,
        record_for_s: len,
    };
    let recorded: Vec<u64> = (0..1000)
        .filter(|&j| from <= t(j) && t(j) < from + len)
        .collect();
    // 50 ticks, or 51 when `t_150` rounds below `0.1 + 0.05`.
    let n = recorded.len() as u64;
    assert!((50..=51).contains(&n), "{n}");
    for path in [Path::Measurement, Path::Torque] {
        let mut l = line(path, &[(t(200), replay), (t(400), Effect::Pass)], 1);
        for (k, s) in run(&mut l, 600).into_iter().enumerate() {
            let k = k as u64;
            let want = if (200..400).contains(&k) {
                let j = recorded[((k - 200) % n) as usize];
                Sent::Replayed { k: j, payload: j }
            } else {
                live(k)
            };
            assert_eq!(s, want, "{path:?}, tick {k}");
        }
    }
    // Replayed payloads are what was sent then, not the tick numbers: record a payload
    // that differs from k.
    let mut l: MessageLine<f64> = MessageLine::compile(
        &attack(Path::Measurement, &[(t(200), replay)]),
        rng(1, Path::Measurement),
    );
    for k in 0..260u64 {
        let s = l.send(k, t(k), -(k as f64));
        if k >= 200 {
            let j = recorded[((k - 200) % n) as usize];
            assert_eq!(
                s,
                Sent::Replayed {
                    k: j,
                    payload: -(j as f64)
                }
            );
        }
    }
}

#[test]
fn replay_original_with_nothing_recorded_sends_nothing() {
    // A window between two ticks records nothing.
    let replay = Effect::ReplayOriginal {
        record_from_s: 0.1002,
        record_for_s: 0.0005,
    };
    let mut l = line(Path::Measurement, &[(t(200), replay)], 1);
    for (k, s) in run(&mut l, 300).into_iter().enumerate() {
        let want = if k >= 200 {
            Sent::Missing
        } else {
            live(k as u64)
        };
        assert_eq!(s, want, "tick {k}");
    }
}

#[test]
fn pass_and_the_time_before_the_first_segment_deliver_untouched() {
    for path in [Path::Measurement, Path::Torque] {
        let mut l = line(
            path,
            &[
                (t(500), Effect::Pass),
                (t(700), Effect::Drop { probability: 1.0 }),
                (t(800), Effect::Pass),
            ],
            1,
        );
        for (k, s) in run(&mut l, 1000).into_iter().enumerate() {
            let dropped = (700..800).contains(&k);
            let want = if dropped {
                Sent::Missing
            } else {
                live(k as u64)
            };
            assert_eq!(s, want, "{path:?}, tick {k}");
            assert_eq!(l.in_force(t(k as u64)), dropped, "{path:?}, tick {k}");
            assert_eq!(
                s.delivery(),
                if dropped {
                    Delivery::Missing
                } else {
                    Delivery::Delivered
                }
            );
        }
    }
}

fn fields(p: Vec<(String, String)>) -> Vec<String> {
    p.into_iter().map(|p| p.0).collect()
}

#[test]
fn effect_problems_name_every_bad_field() {
    let nan = f64::NAN;
    let inf = f64::INFINITY;
    let cases: Vec<(Effect, &[&str])> = vec![
        (Effect::Pass, &[]),
        (Effect::Drop { probability: 0.0 }, &[]),
        (Effect::Drop { probability: 1.0 }, &[]),
        (
            Effect::Drop {
                probability: 1.0 + 1e-12,
            },
            &["probability"],
        ),
        (Effect::Drop { probability: -0.1 }, &["probability"]),
        (Effect::Drop { probability: nan }, &["probability"]),
        (
            Effect::Burst {
                mean_gap_s: 1.0,
                mean_length_s: 0.05,
            },
            &[],
        ),
        (
            Effect::Burst {
                mean_gap_s: 0.0,
                mean_length_s: 0.05,
            },
            &["mean_gap_s"],
        ),
        (
            Effect::Burst {
                mean_gap_s: 1.0,
                mean_length_s: -1.0,
            },
            &["mean_length_s"],
        ),
        (
            Effect::Burst {
                mean_gap_s: inf,
                mean_length_s: nan,
            },
            &["mean_gap_s", "mean_length_s"],
        ),
        (delay(0.01, 0.0, 0.0), &[]),
        (delay(0.0, 0.0, 0.0), &[]),
        (delay(0.01, -0.01, 3.0), &[]),
        (delay(-0.001, 0.0, 0.0), &["by_s"]),
        (delay(0.01, 0.011, 3.0), &["by_s"]),
        (delay(0.01, -0.011, 3.0), &["by_s"]),
        (delay(nan, 0.0, 0.0), &["by_s"]),
        (delay(0.01, 0.0, nan), &["rate_rad_s"]),
        (delay(0.01, 0.0, inf), &["rate_rad_s"]),
        (delay(inf, inf, 0.0), &["by_s", "amplitude_s"]),
        (Effect::ForgeStamp { shift_s: 0.005 }, &[]),
        (Effect::ForgeStamp { shift_s: -0.005 }, &[]),
        (Effect::ForgeStamp { shift_s: 0.0 }, &["shift_s"]),
        (Effect::ForgeStamp { shift_s: nan }, &["shift_s"]),
        (
            Effect::ReplayOriginal {
                record_from_s: 0.0,
                record_for_s: 1.0,
            },
            &[],
        ),
        (
            Effect::ReplayOriginal {
                record_from_s: -1.0,
                record_for_s: 1.0,
            },
            &["record_from_s"],
        ),
        (
            Effect::ReplayOriginal {
                record_from_s: 1.0,
                record_for_s: 0.0,
            },
            &["record_for_s"],
        ),
        (
            Effect::ReplayOriginal {
                record_from_s: nan,
                record_for_s: inf,
            },
            &["record_from_s", "record_for_s"],
        ),
    ];
    for (effect, want) in cases {
        let problems = effect.problems();
        assert_eq!(fields(problems.clone()), want, "{effect:?}: {problems:?}");
        assert!(
            problems.iter().all(|p| p.1.starts_with("must be")),
            "{problems:?}"
        );
    }
    // A NaN amplitude cannot pass either check it takes part in.
    let f = fields(delay(0.01, nan, 1.0).problems());
    assert!(f.contains(&"amplitude_s".to_string()), "{f:?}");
}

#[test]
fn message_attack_problems_name_the_field_paths() {
    let replay = |record_from_s, record_for_s| Effect::ReplayOriginal {
        record_from_s,
        record_for_s,
    };
    type Case = (Vec<(f64, Effect)>, &'static [&'static str]);
    let cases: Vec<Case> = vec![
        (vec![(0.0, Effect::Pass)], &[]),
        (vec![], &["segments"]),
        (vec![(-1.0, Effect::Pass)], &["segments[0].from_s"]),
        (vec![(f64::NAN, Effect::Pass)], &["segments[0].from_s"]),
        (
            vec![(1.0, Effect::Pass), (1.0, Effect::Pass)],
            &["segments[1].from_s"],
        ),
        (
            vec![
                (1.0, Effect::Pass),
                (2.0, Effect::Pass),
                (0.5, Effect::Pass),
            ],
            &["segments[2].from_s"],
        ),
        (
            vec![
                (1.0, Effect::Pass),
                (2.0, Effect::Drop { probability: 2.0 }),
            ],
            &["segments[1].effect.probability"],
        ),
        (
            vec![
                (0.0, delay(0.01, 0.02, 1.0)),
                (1.0, Effect::ForgeStamp { shift_s: 0.0 }),
            ],
            &["segments[0].effect.by_s", "segments[1].effect.shift_s"],
        ),
        // The replay must start at or after the end of its recording.
        (vec![(2.0, replay(1.0, 1.0))], &[]),
        (vec![(1.999, replay(1.0, 1.0))], &["segments[0].from_s"]),
        (vec![(0.5, replay(1.0, 1.0))], &["segments[0].from_s"]),
        (
            vec![(0.5, replay(1.0, 0.0))],
            &["segments[0].effect.record_for_s", "segments[0].from_s"],
        ),
    ];
    for path in [Path::Measurement, Path::Torque] {
        for (segments, want) in &cases {
            let a = attack(path, segments);
            let problems = a.problems();
            assert_eq!(
                &fields(problems.clone()),
                want,
                "{segments:?}: {problems:?}"
            );
        }
    }
}

#[test]
fn message_attacks_parse_from_toml_with_their_defaults() {
    let text = r#"
        agent = 2
        path = "measurement"
        segments = [
          { from_s = 1.0, effect = { kind = "delay", by_s = 0.02 } },
          { from_s = 2.0, effect = { kind = "burst", mean_gap_s = 1.0, mean_length_s = 0.05 } },
          { from_s = 3.0, effect = { kind = "forge-stamp", shift_s = 0.005 } },
          { from_s = 4.0, effect = { kind = "replay-original", record_from_s = 0.0, record_for_s = 1.0 } },
          { from_s = 5.0, effect = { kind = "drop", probability = 0.5 } },
          { from_s = 6.0, effect = { kind = "pass" } },
        ]
    "#;
    let a: MessageAttack = toml::from_str(text).expect("parses");
    assert_eq!((a.agent, a.path), (2, Path::Measurement));
    assert_eq!(a.segments[0].effect, delay(0.02, 0.0, 0.0));
    assert!(a.problems().is_empty(), "{:?}", a.problems());
    let bad = text.replace("by_s = 0.02", "by_s = 0.02, jitter = 1");
    assert!(
        toml::from_str::<MessageAttack>(&bad).is_err(),
        "unknown fields are refused"
    );
}
