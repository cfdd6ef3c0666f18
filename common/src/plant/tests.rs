use super::*;
use crate::scenario::paper;

const DT: f64 = 1e-3;

/// Robot 1 of the paper's scenario (τ = 2 sin(t/2) + 3 ms), with `substeps` per period.
fn robot1(substeps: u32) -> Plant<2> {
    let r = paper().expect("the embedded paper scenario is valid");
    let s = &r.scenario;
    let mut p = s.plant_params(&s.agents[0]);
    p.substeps = substeps;
    assert_eq!(p.control_period_s, DT);
    Plant::<2>::new(p).expect("a two-link model")
}

/// A torque that changes every tick.
fn u(k: u64) -> Vector<2> {
    let t = tick_time(k, DT);
    Vector::<2>::new(2.0 * (9.0 * t).sin() + 0.5, -1.5 * (4.0 * t).cos())
}

/// Whether the command stamped `t_gap` (the next one stamped one period later) is in force
/// at some query of step `k`: the step needs it.
fn needs(p: &Plant<2>, k: u64, t_gap: f64) -> bool {
    p.boundaries(k).any(|b| {
        let q = p.query(b);
        in_force_at(t_gap, q) && !in_force_at(t_gap + DT, q)
    })
}

/// Runs ticks `0..n` as the engines do (the command of tick `k`, then step `k`), `feed`
/// delivering each command; the states and reports after every step.
fn run(
    p: &mut Plant<2>,
    n: u64,
    mut feed: impl FnMut(&mut Plant<2>, u64),
) -> Vec<(Vector<2>, Vector<2>, StepReport<2>)> {
    (0..n)
        .map(|k| {
            feed(p, k);
            let r = p.advance(k);
            (p.q, p.qd, r)
        })
        .collect()
}

#[test]
fn a_missing_command_is_counted_and_the_steps_that_need_it_report_a_miss() {
    let gap = 200u64;
    let t_gap = tick_time(gap, DT);
    for substeps in [1, 3] {
        let mut holed = robot1(substeps);
        let mut expected = Vec::new();
        let mut states = Vec::new();
        for k in 0..400 {
            let command = (k != gap).then(|| (u(k), 0.0));
            holed
                .take_command(tick_time(k, DT), command)
                .expect("a finite command in order");
            if needs(&holed, k, t_gap) {
                expected.push(k);
            }
            let r = holed.advance(k);
            assert_eq!(r.missed, expected.last() == Some(&k), "step {k}");
            states.push((holed.q, holed.qd, r.u_applied));
        }
        assert!(!expected.is_empty(), "some step needs the missing command");
        assert!(expected.iter().all(|&k| k > gap), "{expected:?}");
        assert_eq!(holed.missing_commands, 1);
        assert_eq!(holed.deadline_misses, expected.len() as u64);
        assert_eq!(holed.refused_commands, 0);

        // The command before the missing one stays in force: the same states, to the bit,
        // as a plant that simply never got it, which reports no miss.
        let mut absent = robot1(substeps);
        let quiet = run(&mut absent, 400, |p, k| {
            if k != gap {
                p.receive(tick_time(k, DT), u(k)).expect("in order");
            }
        });
        for (k, (s, q)) in states.iter().zip(&quiet).enumerate() {
            assert_eq!(*s, (q.0, q.1, q.2.u_applied), "step {k}");
            assert!(!q.2.missed, "step {k}");
        }
        assert_eq!((absent.deadline_misses, absent.missing_commands), (0, 0));
        // And the missing command mattered.
        let mut full = robot1(substeps);
        let all = run(&mut full, 400, |p, k| {
            p.take_command(tick_time(k, DT), Some((u(k), 0.0)))
                .expect("in order");
        });
        assert_ne!(all.last().map(|s| s.0), quiet.last().map(|s| s.0));
        assert_eq!(full.deadline_misses + full.missing_commands, 0);
    }
}

#[test]
fn a_command_held_back_takes_effect_that_much_later_bit_for_bit() {
    let held = |k: u64| 0.0025 + 0.001 * (7.0 * tick_time(k, DT)).sin();
    for substeps in [1, 4] {
        let mut taken = robot1(substeps);
        let a = run(&mut taken, 500, |p, k| {
            p.take_command(tick_time(k, DT), Some((u(k), held(k))))
                .expect("in order");
        });
        let mut pushed = robot1(substeps);
        let b = run(&mut pushed, 500, |p, k| {
            p.receive(tick_time(k, DT) + held(k), u(k))
                .expect("in order");
        });
        assert_eq!(a, b, "{substeps} substeps");
        assert_eq!(taken.missing_commands, 0);
        assert_eq!(taken.newest_command_stamp(), pushed.newest_command_stamp());
        // Not the same as without the hold.
        let mut now = robot1(substeps);
        let c = run(&mut now, 500, |p, k| {
            p.take_command(tick_time(k, DT), Some((u(k), 0.0)))
                .expect("in order");
        });
        assert_ne!(a.last().map(|s| s.0), c.last().map(|s| s.0));
    }
}

#[test]
fn a_refused_command_counts_as_missing_and_acts_as_one() {
    let gap = 150u64;
    let nan = Vector::<2>::new(f64::NAN, 0.0);
    let inf = Vector::<2>::new(0.0, f64::NEG_INFINITY);
    let refused: [(Vector<2>, f64); 4] = [
        (nan, 0.0),
        (inf, 0.0),
        (u(gap), f64::INFINITY),
        // A stamp not after the newest one.
        (u(gap), -1.5 * DT),
    ];
    let mut dropped = robot1(1);
    let want = run(&mut dropped, 300, |p, k| {
        let command = (k != gap).then(|| (u(k), 0.0));
        p.take_command(tick_time(k, DT), command).expect("in order");
    });
    assert!(want.iter().any(|s| s.2.missed));
    for bad in refused {
        let mut p = robot1(1);
        let got = run(&mut p, 300, |p, k| {
            let command = if k == gap { bad } else { (u(k), 0.0) };
            let r = p.take_command(tick_time(k, DT), Some(command));
            assert_eq!(r.is_err(), k == gap, "tick {k}: {r:?}");
        });
        assert_eq!(got, want, "{bad:?}");
        assert_eq!((p.missing_commands, p.refused_commands), (1, 1), "{bad:?}");
        assert_eq!(p.deadline_misses, dropped.deadline_misses);
    }
}

/// Plants of the shipped Panda team (each its own delay, noise and disturbance), stepped side
/// by side and each alone, fed the same commands (one a tick, some ticks' missing, so their
/// steps are cut into different pieces): every state and report has the same bits. The
/// plants share the team's disturbance but two: one has another, one differs from the team's
/// in the sign of a zero amplitude only (`==` to it, not the same bits), so the disturbance a
/// lane evaluates once for the plants that share it is tried with plants that do not; and they
/// share the team's delay but one (the instants where commands take over, computed once for
/// the plants that share them).
#[cfg(feature = "urdf")]
#[test]
fn plants_stepped_side_by_side_are_each_stepped_alone() {
    let folder = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
    let text = std::fs::read_to_string(folder.join("panda-team.toml")).expect("read");
    let r = crate::scenario::load_str(&text, "panda-team.toml", Some(&folder)).expect("valid");
    let s = &r.scenario;
    let plants = |substeps: u32| -> Vec<Plant<7>> {
        (s.agents.iter().cycle().take(5).enumerate())
            .map(|(i, a)| {
                let mut p = s.plant_params(a);
                p.substeps = substeps;
                let links = &mut p.disturbance.links;
                links[6].amplitude = 0.0;
                match i {
                    1 => links[3].amplitude *= 1.5,
                    3 => links[6].amplitude = -0.0,
                    _ => {}
                }
                // Another delay: its commands take over at other instants.
                if let (2, DelayProfile::Sine { offset_s, .. }) = (i, &mut p.delay) {
                    *offset_s *= 1.2;
                }
                Plant::<7>::new(p).expect("a Panda")
            })
            .collect()
    };
    let torque = |k: u64, i: usize| -> Vector<7> {
        let t = tick_time(k, DT);
        Vector::<7>::from_fn(|j, _| (3.0 + j as f64) * ((2.0 + i as f64) * t + j as f64).sin())
    };
    // Five plants: a lane of four and one alone, with one and two sub-steps.
    for substeps in [1, 2] {
        let (mut alone, mut together) = (plants(substeps), plants(substeps));
        let (team, zero) = (&alone[0].params.disturbance, &alone[3].params.disturbance);
        assert!(
            team == zero && !team.same_bits(zero) && team.same_bits(&alone[2].params.disturbance)
        );
        assert!(!alone[2].params.delay.same_bits(&alone[0].params.delay));
        assert!(alone[0].side_by_side());
        for k in 0..400 {
            let t = tick_time(k, DT);
            for (i, (a, b)) in alone.iter_mut().zip(&mut together).enumerate() {
                let command = (k % (7 + i as u64) != 3).then(|| (torque(k, i), 0.0));
                assert_eq!(a.take_command(t, command), b.take_command(t, command));
            }
            let each: Vec<StepReport<7>> = alone.iter_mut().map(|p| p.advance(k)).collect();
            let mut lanes: Vec<&mut Plant<7>> = together.iter_mut().collect();
            let side = Plant::advance_side_by_side(&mut lanes, k);
            assert_eq!(each, side, "tick {k}");
            for (i, (a, b)) in alone.iter().zip(&together).enumerate() {
                let same = |x: &Vector<7>, y: &Vector<7>| {
                    x.iter()
                        .zip(y.iter())
                        .all(|(x, y)| x.to_bits() == y.to_bits())
                };
                assert!(
                    same(&a.q, &b.q) && same(&a.qd, &b.qd),
                    "plant {i}, tick {k}"
                );
            }
        }
        assert!(together.iter().all(|p| p.q.iter().all(|x| x.is_finite())));
    }
}
