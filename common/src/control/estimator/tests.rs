use super::*;
use crate::rng::{stream, Purpose};

fn params() -> NnParams {
    NnParams {
        hidden: 3,
        gamma_w: 5000.0,
        gamma_v: 10.0,
        l1: 0.01,
        bound_w: 50.0,
        bound_v: 50.0,
        law: UpdateLaw::default(),
    }
}

#[test]
fn projection_keeps_weights_in_their_balls_under_adversarial_input() {
    let mut nn = NnEstimator::<2>::new(params(), 1.0, &mut stream(3, 1, Purpose::NnInit));
    // Huge, sign-alternating, occasionally enormous Ψ2: the raw Euler step would blow up.
    for k in 0..5000 {
        let s = if k % 2 == 0 { 1.0 } else { -1.0 };
        let mag = if k % 97 == 0 { 1e12 } else { 1e3 };
        let psi2 = Vector::<2>::new(s * mag, -s * mag * 0.5);
        let _ = nn.estimate(&psi2);
        nn.update(&psi2, 1e-3);
        assert!(nn.norm_w() <= 50.0 * (1.0 + 1e-12), "‖Ŵ‖ = {}", nn.norm_w());
        assert!(nn.norm_v() <= 50.0 * (1.0 + 1e-12), "‖V̂‖ = {}", nn.norm_v());
    }
}

#[test]
fn converges_to_a_constant_attack_in_the_error_loop() {
    // Closed error loop of the estimator alone: Ψ2 = S − Ŝ (observer error r̃ = 0). With
    // Γ1 L1 = 50 1/s the bias weight follows S with a time constant of about 20 ms, so
    // after 0.5 s the estimate must be within 1 % of S.
    let mut nn = NnEstimator::<2>::new(params(), 1.0, &mut stream(1, 1, Purpose::NnInit));
    let s = Vector::<2>::new(0.3, -0.12);
    let mut psi2 = Vector::<2>::zeros();
    let mut s_hat = Vector::<2>::zeros();
    for _ in 0..500 {
        s_hat = nn.estimate(&psi2);
        psi2 = s - s_hat;
        nn.update(&psi2, 1e-3);
    }
    assert!(
        (s_hat - s).norm() < 0.01 * s.norm(),
        "Ŝ = {s_hat:?}, S = {s:?}"
    );
}

/// Regression: a NaN passed the projection (`NaN > bound` is false) and stayed in the
/// weights for good.
#[test]
fn a_nan_reaching_the_weights_is_seen_and_a_reset_restores_the_initial_estimator() {
    let mut nn = NnEstimator::<2>::new(params(), 1.0, &mut stream(1, 1, Purpose::NnInit));
    let fresh = nn.clone();
    let psi2 = Vector::<2>::new(0.2, -0.1);
    for _ in 0..10 {
        let _ = nn.estimate(&psi2);
        nn.update(&psi2, 1e-3);
    }
    assert!(nn.is_finite());
    let nan = Vector::<2>::new(f64::NAN, 0.0);
    let _ = nn.estimate(&nan);
    nn.update(&nan, 1e-3);
    assert!(!nn.is_finite(), "a NaN Ψ2 must show in the weights' check");
    nn.reset();
    assert!(nn.is_finite());
    assert_eq!(nn.w, fresh.w);
    assert_eq!(nn.v, fresh.v);
    assert_eq!(nn.estimate(&psi2), Vector::<2>::zeros());
}

#[test]
fn projection_handles_weights_whose_squares_overflow() {
    let mut m = vec![1e200, -1e200, 3e199];
    project(&mut m, 50.0);
    assert!(m.iter().all(|x| x.is_finite()));
    assert!((frobenius(&m) - 50.0).abs() < 1e-9, "{m:?}");
}

/// The paper's (37), (38) as docs/model.md states them ("Control center", step 7), written out independently of
/// [`NnEstimator::update`] (same order of operations): Euler step of `V̂` with the old `Ŵ`,
/// then of `Ŵ`, then projection.
fn paper_step(nn: &NnEstimator<2>, w: &mut [f64], v: &mut [f64], psi2: &Vector<2>, dt: f64) {
    let p = params();
    let nh = p.hidden;
    let mut g = vec![0.0; nh];
    for (j, gj) in g.iter_mut().enumerate() {
        let h = nn.sigma[j + 1];
        let acc = psi2[0] * w[(j + 1) * 2] + psi2[1] * w[(j + 1) * 2 + 1];
        *gj = (1.0 - h * h) * acc;
    }
    for (r, d) in nn.delta.iter().enumerate() {
        for j in 0..nh {
            v[r * nh + j] += dt * p.gamma_v * p.l1 * d * g[j];
        }
    }
    for (r, sg) in nn.sigma.iter().enumerate() {
        for c in 0..2 {
            w[r * 2 + c] += dt * p.gamma_w * p.l1 * sg * psi2[c];
        }
    }
    project(w, p.bound_w);
    project(v, p.bound_v);
}

/// A deterministic, sign-changing `Ψ2` with occasional large values (reaching the
/// projection), rad/s.
fn psi2_at(k: u32) -> Vector<2> {
    let t = f64::from(k) * 1e-3;
    let big = if k.is_multiple_of(401) { 40.0 } else { 1.0 };
    Vector::<2>::new(0.3 * (7.0 * t).sin() * big, -0.2 * (3.0 * t).cos() + 0.05)
}

#[test]
fn with_every_modification_off_the_update_is_the_papers_bit_for_bit() {
    // The default UpdateLaw must leave the paper's law untouched: every weight equal to
    // the written-out (37), (38) to the last bit (assert_eq on f64, no tolerance), over
    // steps that also reach the projection.
    assert!(params().law.is_paper());
    let mut nn = NnEstimator::<2>::new(params(), 1.0, &mut stream(5, 2, Purpose::NnInit));
    let (mut w, mut v) = (nn.w.clone(), nn.v.clone());
    let mut psi2_prev = Vector::<2>::zeros();
    for k in 0..20_000 {
        let psi2 = psi2_at(k);
        let _ = nn.estimate(&psi2_prev);
        paper_step(&nn, &mut w, &mut v, &psi2, 1e-3);
        nn.update(&psi2, 1e-3);
        assert_eq!(nn.weights_w(), &w[..], "Ŵ differs at step {k}");
        assert_eq!(nn.weights_v(), &v[..], "V̂ differs at step {k}");
        psi2_prev = psi2;
    }
    assert!(nn.norm_w() > 1.0, "the sequence must move the weights");
}

#[test]
fn each_modification_changes_the_update_when_on() {
    // Guards the test above against a law that ignores its fields.
    for law in [
        UpdateLaw {
            innovation_time_constant_s: 1.0,
            ..UpdateLaw::default()
        },
        UpdateLaw {
            leakage_w_per_s: 1.0,
            ..UpdateLaw::default()
        },
        UpdateLaw {
            dead_zone_rad_s: 0.01,
            ..UpdateLaw::default()
        },
    ] {
        let mk = |law| {
            let p = NnParams { law, ..params() };
            NnEstimator::<2>::new(p, 1.0, &mut stream(5, 2, Purpose::NnInit))
        };
        let (mut paper, mut modified) = (mk(UpdateLaw::default()), mk(law));
        for k in 0..100 {
            let psi2 = psi2_at(k);
            let _ = (paper.estimate(&psi2), modified.estimate(&psi2));
            paper.update(&psi2, 1e-3);
            modified.update(&psi2, 1e-3);
        }
        assert_ne!(paper.weights_w(), modified.weights_w(), "{law:?}");
    }
}

#[test]
fn leakage_bounds_the_weights_under_a_persistent_bias() {
    // Open loop: Ψ2 stuck at a bias b (a mismatch the estimate never removes). The paper's
    // law integrates it until the projection stops it at W̄; with leakage λ every entry
    // settles at Γ1 L1 σ_r b_c / λ, so ‖Ŵ‖_F ≤ Γ1 L1 ‖σ‖ ‖b‖ / λ ≤ Γ1 L1 √(n_n+1) ‖b‖ / λ
    // (|σ_r| ≤ 1). The discrete leak has the same fixed point; 1e-9 relative covers the
    // rounding of 10⁵ steps.
    let b = Vector::<2>::new(0.05, -0.02);
    let lambda = 10.0;
    let run = |law| {
        let p = NnParams { law, ..params() };
        let mut nn = NnEstimator::<2>::new(p, 1.0, &mut stream(9, 1, Purpose::NnInit));
        let mut max_norm: f64 = 0.0;
        for _ in 0..100_000 {
            let _ = nn.estimate(&b);
            nn.update(&b, 1e-3);
            max_norm = max_norm.max(nn.norm_w());
        }
        (nn.norm_w(), max_norm)
    };
    let (paper_end, _) = run(UpdateLaw::default());
    assert!(
        paper_end > 0.99 * params().bound_w,
        "the paper's law must drift to the projection bound, got ‖Ŵ‖ = {paper_end}"
    );
    let leaky = UpdateLaw {
        leakage_w_per_s: lambda,
        ..UpdateLaw::default()
    };
    let (_, leaky_max) = run(leaky);
    let p = params();
    let bound = p.gamma_w * p.l1 * ((p.hidden + 1) as f64).sqrt() * b.norm() / lambda;
    assert!(
        leaky_max <= bound * (1.0 + 1e-9),
        "‖Ŵ‖ reached {leaky_max}, bound {bound}"
    );
    assert!(
        bound < 0.2 * p.bound_w,
        "the bound must be below the projection's"
    );
}

#[test]
fn a_persistent_innovation_fades_over_the_time_constant() {
    // Estimator-only error loop as above (Ψ2 = S − Ŝ), S constant. The paper's law keeps
    // Ŝ = S for ever. With T = 2 s, Ŝ ≈ (e^{−t/T} − e^{−Γ1 L1 t}) S: within 10 % of S after
    // 0.2 s (e^{−0.1} = 0.90, minus a 1 % lag of the fast pole), and below 2 % of S after
    // 10 s = 5 T (e^{−5} = 0.7 %, with margin for the discretization).
    let s = Vector::<2>::new(0.3, -0.12);
    let run = |law, steps| {
        let p = NnParams { law, ..params() };
        let mut nn = NnEstimator::<2>::new(p, 1.0, &mut stream(1, 1, Purpose::NnInit));
        let (mut psi2, mut s_hat) = (Vector::<2>::zeros(), Vector::<2>::zeros());
        for _ in 0..steps {
            s_hat = nn.estimate(&psi2);
            psi2 = s - s_hat;
            nn.update(&psi2, 1e-3);
        }
        s_hat
    };
    let paper = run(UpdateLaw::default(), 10_000);
    assert!((paper - s).norm() < 0.01 * s.norm(), "paper: Ŝ = {paper:?}");
    let law = UpdateLaw {
        innovation_time_constant_s: 2.0,
        ..UpdateLaw::default()
    };
    let early = run(law, 200);
    assert!(
        (early - s).norm() < 0.12 * s.norm(),
        "after 0.2 s: Ŝ = {early:?}"
    );
    let late = run(law, 10_000);
    assert!(late.norm() < 0.02 * s.norm(), "after 10 s: Ŝ = {late:?}");
}

#[test]
fn invalid_update_law_values_are_reported_with_their_field_paths() {
    let bad = UpdateLaw {
        innovation_time_constant_s: 1e-4,
        leakage_w_per_s: f64::NAN,
        dead_zone_rad_s: -0.01,
    };
    let problems = bad.problems("controller.update_law", 1e-3);
    let paths: Vec<&str> = problems.iter().map(|p| p.path.as_str()).collect();
    assert_eq!(
        paths,
        [
            "controller.update_law.leakage_w_per_s",
            "controller.update_law.dead_zone_rad_s",
            "controller.update_law.innovation_time_constant_s"
        ],
        "{problems:?}"
    );
    let too_leaky = UpdateLaw {
        leakage_w_per_s: 1000.0,
        ..UpdateLaw::default()
    };
    assert_eq!(too_leaky.problems("u", 1e-3).len(), 1);
    assert!(UpdateLaw::default().problems("u", 1e-3).is_empty());
    let negative = UpdateLaw {
        innovation_time_constant_s: -1.0,
        ..UpdateLaw::default()
    };
    assert_eq!(negative.problems("u", 1e-3).len(), 1);
}

#[test]
fn the_dead_zone_ignores_a_small_innovation_and_learns_only_the_part_beyond_it() {
    // Estimator-only error loop (Ψ2 = S − Ŝ), S constant. Below the dead zone ε the weights
    // never move; above it, Ŝ converges until ‖S − Ŝ‖ = ε, along S (the learning signal is
    // e (1 − ε/‖e‖), parallel to e).
    let eps = 0.02;
    let law = UpdateLaw {
        dead_zone_rad_s: eps,
        ..UpdateLaw::default()
    };
    let run = |s: Vector<2>| {
        let p = NnParams { law, ..params() };
        let mut nn = NnEstimator::<2>::new(p, 1.0, &mut stream(3, 1, Purpose::NnInit));
        let (mut psi2, mut s_hat) = (Vector::<2>::zeros(), Vector::<2>::zeros());
        for _ in 0..10_000 {
            s_hat = nn.estimate(&psi2);
            psi2 = s - s_hat;
            nn.update(&psi2, 1e-3);
        }
        (s_hat, nn.norm_w())
    };
    let small = Vector::<2>::new(0.012, -0.015); // ‖·‖ = 0.0192 < ε
    let (s_hat, w) = run(small);
    assert_eq!((s_hat, w), (Vector::<2>::zeros(), 0.0));
    let large = Vector::<2>::new(0.3, -0.12);
    let (s_hat, _) = run(large);
    let residual = (large - s_hat).norm();
    assert!(
        (residual - eps).abs() < 1e-3 * eps,
        "‖S − Ŝ‖ = {residual}, ε = {eps}"
    );
    let along = (large - s_hat).normalize().dot(&large.normalize());
    assert!(along > 1.0 - 1e-6, "residual not along S: cos = {along}");
}

#[test]
fn starts_with_zero_estimate() {
    let mut nn = NnEstimator::<2>::new(params(), 1.0, &mut stream(1, 1, Purpose::NnInit));
    assert_eq!(
        nn.estimate(&Vector::<2>::new(0.5, 0.5)),
        Vector::<2>::zeros()
    );
}
