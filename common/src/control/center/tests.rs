use super::*;
use crate::control::Command;
use crate::delay::DelayProfile;
use crate::scenario::paper;

/// Agent 1 of the paper's scenario, as the control-center process builds it.
fn agent1() -> CenterAgent<2> {
    let r = paper().expect("the embedded paper scenario is valid");
    let s = &r.scenario;
    CenterAgent::<2>::new(s.center_params(&s.agents[0])).expect("a two-link model")
}

/// Agent 1 with a constant delay of 2.5 periods and the given observer input.
fn agent1_with(input: ObserverInputMode) -> CenterAgent<2> {
    let r = paper().expect("the embedded paper scenario is valid");
    let s = &r.scenario;
    let mut p = s.center_params(&s.agents[0]);
    p.delay = DelayProfile::Constant { value_s: 2.5e-3 };
    p.controller.observer_input = input;
    CenterAgent::<2>::new(p).expect("a two-link model")
}

#[test]
fn the_observer_input_is_the_step_mean_or_the_sample_of_the_delayed_input() {
    // τ = 2.5 Δ: at tick k the step's queries are (k − 2.5) Δ and (k − 1.5) Δ, so the mean
    // of the delayed input over the step is (u_{k−3} + u_{k−2}) / 2, its sample at
    // t_k − τ is u_{k−3}.
    let dt = 1e-3;
    for input in [ObserverInputMode::StepMean, ObserverInputMode::Sample] {
        let mut c = agent1_with(input);
        let mut sent = Vec::new();
        for k in 0..40u32 {
            let t = f64::from(k) * dt;
            let y = Vector::<2>::new(0.01 * (t * 50.0).sin(), -0.02 * f64::from(k % 7));
            let out = c.tick(t, &y, &(y * 3.0));
            sent.push(out.u);
            if k < 3 {
                continue;
            }
            let k = k as usize;
            let want = match input {
                ObserverInputMode::StepMean => (sent[k - 3] + sent[k - 2]) / 2.0,
                ObserverInputMode::Sample => sent[k - 3],
            };
            assert!(
                (out.u_tau - want).norm() <= 1e-9 * want.norm().max(1.0),
                "{input:?}, tick {k}: u_τ {:?}, want {want:?}",
                out.u_tau
            );
        }
        assert!(sent.windows(2).any(|w| w[0] != w[1]), "the torque varies");
    }
}

fn finite(v: &Vector<2>) -> bool {
    v.iter().all(|x| x.is_finite())
}

#[test]
fn a_nan_measurement_is_counted_and_never_yields_a_non_finite_torque() {
    let dt = 1e-3;
    // Two identical pipelines: `clean` sees the good measurement twice, `hit` sees it once,
    // then a NaN. Holding the last good value means both compute the same torque.
    let (mut clean, mut hit) = (agent1(), agent1());
    let y = Vector::<2>::new(0.01, -0.02);
    let yd = Vector::<2>::new(0.1, 0.05);
    for k in 0..50 {
        let t = f64::from(k) * dt;
        assert_eq!(clean.tick(t, &y, &yd), hit.tick(t, &y, &yd));
    }
    let t = 50.0 * dt;
    let want = clean.tick(t, &y, &yd);
    let nan = Vector::<2>::new(f64::NAN, 0.0);
    let got = hit.tick(t, &nan, &yd);
    assert!(got.rejected_input && !want.rejected_input);
    assert_eq!(hit.rejected_inputs, 1);
    assert_eq!(clean.rejected_inputs, 0);
    assert!(finite(&got.u), "torque {:?}", got.u);
    assert_eq!(got.u, want.u, "the last good measurement is held");
    assert_eq!(got.q_hat, want.q_hat);
}

#[test]
fn every_kind_of_bad_value_is_rejected_and_counted_and_boundary_values_are_not() {
    let mut c = agent1();
    let ok = Vector::<2>::new(0.01, 0.02);
    let mut expected_rejections = 0;
    let mut k = 0u32;
    let mut tick = |c: &mut CenterAgent<2>, y: Vector<2>, yd: Vector<2>| {
        k += 1;
        c.tick(f64::from(k) * 1e-3, &y, &yd)
    };
    for bad in [
        f64::NAN,
        -f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        1e300,
        -1e300,
        f64::MAX,
        MAX_ABS_MEASUREMENT * (1.0 + f64::EPSILON),
        -1e7,
    ] {
        for (y, yd) in [
            (Vector::<2>::new(bad, 0.0), ok),
            (ok, Vector::<2>::new(0.0, bad)),
            (Vector::<2>::new(bad, bad), Vector::<2>::new(bad, bad)),
        ] {
            let out = tick(&mut c, y, yd);
            expected_rejections += 1;
            assert!(out.rejected_input, "{bad} not rejected");
            assert!(finite(&out.u) && finite(&out.s_hat) && finite(&out.q_hat));
            assert_eq!(c.rejected_inputs, expected_rejections);
        }
    }
    // Large but allowed, subnormal, negative zero: accepted (finite torque all the same).
    for fine in [
        MAX_ABS_MEASUREMENT,
        -MAX_ABS_MEASUREMENT,
        f64::MIN_POSITIVE / 2.0,
        -0.0,
    ] {
        let out = tick(&mut c, Vector::<2>::new(fine, 0.0), ok);
        assert!(!out.rejected_input, "{fine} rejected");
        assert!(finite(&out.u), "{fine}: torque {:?}", out.u);
    }
    assert_eq!(c.rejected_inputs, expected_rejections);
    assert_eq!(c.rejected_torques, 0);
}

/// Regression: a NaN in the estimator or observer stuck for good, and the center re-sent
/// its last good torque to the end of the run.
#[test]
fn non_finite_observer_or_estimator_state_is_reset_counted_and_recovered_from() {
    let dt = 1e-3;
    let mut c = agent1();
    let y = Vector::<2>::new(0.01, -0.02);
    let yd = Vector::<2>::new(0.1, 0.05);
    for k in 0..100 {
        assert!(!c.tick(f64::from(k) * dt, &y, &yd).state_reset);
    }
    // A NaN estimate (the oracle hook stands in for any numerical failure) poisons Ψ2 and
    // through it the observer.
    let nan = Vector::<2>::new(f64::NAN, 0.0);
    let hit = c.tick_with_estimate(100.0 * dt, &y, &yd, Some(&nan));
    assert!(hit.state_reset && hit.rejected_torque, "{hit:?}");
    assert_eq!(c.state_resets, 1);
    assert_eq!(hit.q_hat, y, "the observer restarts from the measurement");
    let mut torques = Vec::new();
    for k in 101..300 {
        let out = c.tick(f64::from(k) * dt, &y, &yd);
        assert!(
            !out.state_reset && !out.rejected_torque,
            "tick {k}: {out:?}"
        );
        assert!(finite(&out.s_hat) && finite(&out.q_hat) && finite(&out.u));
        torques.push(out.u);
    }
    assert_eq!(c.state_resets, 1);
    assert!(
        torques.windows(2).any(|w| w[0] != w[1]),
        "the center computes torques again instead of re-sending one"
    );
}

#[test]
fn a_non_finite_computed_torque_is_replaced_by_the_last_good_one() {
    let mut c = agent1();
    let y = Vector::<2>::new(0.01, 0.02);
    let good = c.tick(0.0, &y, &y);
    assert!(finite(&good.u));
    // An estimate that blows up (the oracle hook stands in for any numerical failure).
    let inf = Vector::<2>::new(f64::INFINITY, 0.0);
    for k in 1..20 {
        let out = c.tick_with_estimate(f64::from(k) * 1e-3, &y, &y, Some(&inf));
        assert!(out.rejected_torque);
        assert!(finite(&out.u));
        assert_eq!(out.u, good.u, "the last good torque is sent again");
    }
    assert_eq!(c.rejected_torques, 19);
    assert_eq!(c.rejected_inputs, 0);
}

/// A measurement that changes every tick.
fn measured(k: u32) -> (Vector<2>, Vector<2>) {
    let t = f64::from(k) * 1e-3;
    (
        Vector::<2>::new(0.02 * (7.0 * t).sin(), -0.01 * t),
        Vector::<2>::new(0.14 * (7.0 * t).cos(), -0.01),
    )
}

#[test]
fn a_missing_measurement_holds_the_last_good_one_bit_for_bit() {
    let dt = 1e-3;
    // `gaps` gets nothing in the gaps; `held` gets the last measurement `gaps` got again.
    let (mut gaps, mut held) = (agent1(), agent1());
    let missing = |k: u32| (100..130).contains(&k) || k == 200 || k == 201 || k == 350;
    let mut last = measured(0);
    let mut count = 0;
    for k in 0..400u32 {
        let t = f64::from(k) * dt;
        let gap = missing(k);
        if !gap {
            last = measured(k);
        }
        let want = held.tick(t, &last.0, &last.1);
        let got = if gap {
            count += 1;
            gaps.tick_missing(t)
        } else {
            gaps.tick(t, &last.0, &last.1)
        };
        assert_eq!(got.missing_input, gap, "tick {k}");
        assert!(!want.missing_input && !got.rejected_input);
        assert_eq!(
            CenterOutput {
                missing_input: false,
                ..got
            },
            want,
            "tick {k}"
        );
        assert_eq!(gaps.missing_inputs, count);
    }
    assert_eq!(count, 33);
    assert_eq!((held.missing_inputs, gaps.rejected_inputs), (0, 0));
}

#[test]
fn a_missing_measurement_after_a_rejected_one_holds_the_last_good_one() {
    let dt = 1e-3;
    let (mut gaps, mut held) = (agent1(), agent1());
    let nan = Vector::<2>::new(f64::NAN, 0.0);
    for k in 0..60u32 {
        let t = f64::from(k) * dt;
        let (y, yd) = measured(k.min(39));
        let want = held.tick(t, &y, &yd);
        let got = match k {
            40 => gaps.tick(t, &nan, &yd),
            41.. => gaps.tick_missing(t),
            _ => gaps.tick(t, &y, &yd),
        };
        assert_eq!((got.rejected_input, got.missing_input), (k == 40, k > 40));
        assert_eq!(
            CenterOutput {
                rejected_input: false,
                missing_input: false,
                ..got
            },
            want,
            "tick {k}"
        );
    }
    assert_eq!((gaps.rejected_inputs, gaps.missing_inputs), (1, 19));
}

#[test]
fn a_missing_first_measurement_holds_the_initial_zero() {
    let (mut gaps, mut held) = (agent1(), agent1());
    let zero = Vector::<2>::zeros();
    let got = gaps.tick_missing(0.0);
    assert!(got.missing_input);
    assert_eq!(
        CenterOutput {
            missing_input: false,
            ..got
        },
        held.tick(0.0, &zero, &zero)
    );
    assert_eq!(gaps.missing_inputs, 1);
}

#[test]
fn inertia_gain_scaling_gives_each_joint_k_times_its_inertia_at_the_reference_s_start() {
    let r = paper().expect("the embedded paper scenario is valid");
    let s = &r.scenario;
    let mut p = s.center_params(&s.agents[0]);
    use crate::control::{paper::Paper, ControllerMode, GainScaling};
    p.controller.mode = ControllerMode::Traditional;
    let model = p.model.build::<2>().expect("two links");
    let unit = CenterAgent::<2>::new(p.clone()).expect("a two-link model");
    let unit_gains = *Paper::traditional(&p, model.as_ref())
        .expect("made")
        .gains();
    p.controller.gain_scaling = GainScaling::Inertia;
    let scaled = CenterAgent::<2>::new(p.clone()).expect("a two-link model");
    let scaled_gains = *Paper::traditional(&p, model.as_ref())
        .expect("made")
        .gains();
    let q0 = p.trajectory.reference::<2>(0.0).q;
    let m = model.inertia(&q0);
    assert_eq!(unit_gains, Vector::<2>::from_element(p.controller.gain_k));
    assert_eq!(scaled_gains, m.diagonal() * p.controller.gain_k);
    // The joints' inertias differ, so do their gains: the torques are r̂ scaled joint by joint.
    assert!(m[(0, 0)] > 2.0 * m[(1, 1)], "{m}");
    let (mut unit, mut scaled) = (unit, scaled);
    let y = Vector::<2>::new(0.05, -0.03);
    let (a, b) = (unit.tick(0.0, &y, &y), scaled.tick(0.0, &y, &y));
    for i in 0..2 {
        assert!(
            (b.u[i] - a.u[i] * m[(i, i)]).abs() <= 1e-12 * b.u[i].abs().max(1.0),
            "joint {i}: {} against {} · {}",
            b.u[i],
            a.u[i],
            m[(i, i)]
        );
    }
}

/// Agent 1 of the paper's scenario with the controller `mode`.
fn agent1_of(mode: ControllerMode) -> CenterAgent<2> {
    let r = paper().expect("the embedded paper scenario is valid");
    let s = &r.scenario;
    let mut p = s.center_params(&s.agents[0]);
    p.controller.mode = mode;
    CenterAgent::<2>::new(p).expect("a two-link model")
}

/// A controller program answering what the traditional law computes from each question
/// (`u = K (q̇_d − ẏ + β (q_d − y) − A e_u)`, with the question's `A`) gives the traditional
/// controller's ticks exactly, missing and rejected measurements included; a tick without a
/// usable answer holds the last good torque and counts it.
#[test]
fn asking_a_program_that_answers_the_traditional_law_gives_the_traditional_ticks() {
    let (mut builtin, mut asked) = (
        agent1_of(ControllerMode::Traditional),
        agent1_of(ControllerMode::External),
    );
    let c = builtin.params.controller;
    let dt = 1e-3;
    for k in 0..300u32 {
        let t = f64::from(k) * dt;
        let y = Vector::<2>::new(0.3 * (t * 7.0).sin(), -0.2 + 0.1 * t);
        let yd = Vector::<2>::new(2.1 * (t * 7.0).cos(), 0.1);
        let input = match k % 50 {
            10 => None,
            20 => Some((Vector::<2>::from_element(f64::NAN), yd)),
            _ => Some((y, yd)),
        };
        let want = match &input {
            Some((y, yd)) => builtin.tick(t, y, yd),
            None => builtin.tick_missing(t),
        };
        let q = asked.ask(t, input.as_ref().map(|(y, yd)| (y, yd)));
        assert_eq!((q.missing, q.rejected), (k % 50 == 10, k % 50 == 20));
        let r = q.reference;
        let u = ((r.qd - q.yd) + (r.q - q.y) * c.beta - q.inverse_inertia_ref * q.e_u)
            .component_mul(&Vector::<2>::from_element(c.gain_k));
        let answer = Answer {
            command: Command {
                u,
                s_hat: Vector::zeros(),
            },
            alarm: None,
        };
        let got = asked.answer(Some(&answer)).expect("a tick was open");
        assert_eq!(got, want, "tick {k}");
    }
    assert_eq!(asked.answer(None), None, "no tick is open");
    let last = asked.ask(0.3, None);
    let held = asked.answer(None).expect("a tick was open");
    assert!(held.rejected_torque && finite(&held.u), "{held:?}");
    assert_eq!(asked.rejected_torques, 1);
    assert_eq!(last.inertia_ref, asked.model.inertia(&last.reference.q));
}

/// A torque correction (a learned defence's action) is added to the controller's torque: it is
/// what is sent and what enters the history; zeros leave the ticks bit for bit as they were.
#[test]
fn a_correction_is_added_to_the_commanded_torque_and_zeros_change_nothing() {
    let (mut plain, mut zeroed, mut corrected) = (agent1(), agent1(), agent1());
    zeroed.set_correction(Some(Vector::zeros()));
    let c = Vector::<2>::new(0.5, -0.25);
    corrected.set_correction(Some(c));
    let (y, yd) = (Vector::<2>::new(0.1, -0.1), Vector::<2>::new(0.0, 0.2));
    let (a, b, d) = (
        plain.tick(0.0, &y, &yd),
        zeroed.tick(0.0, &y, &yd),
        corrected.tick(0.0, &y, &yd),
    );
    assert_eq!(a, b);
    assert_eq!(d.u, a.u + c);
    for k in 1..50u32 {
        let t = f64::from(k) * 1e-3;
        assert_eq!(plain.tick(t, &y, &yd), zeroed.tick(t, &y, &yd), "tick {k}");
        corrected.tick(t, &y, &yd);
    }
    corrected.set_correction(None);
    let (a, d) = (plain.tick(0.05, &y, &yd), corrected.tick(0.05, &y, &yd));
    assert_ne!(a.e_u, d.e_u, "the corrected torques are in the history");
}
