use super::*;

#[test]
fn ln_gamma_matches_factorials_and_the_half_integers() {
    let mut fact = 1.0f64;
    for n in 1..30u32 {
        // Γ(n) = (n − 1)!
        assert!((ln_gamma(f64::from(n)) - fact.ln()).abs() < 1e-12 * fact.ln().max(1.0));
        fact *= f64::from(n);
    }
    let half = ln_gamma(0.5);
    assert!((half - std::f64::consts::PI.sqrt().ln()).abs() < 1e-14);
}

#[test]
fn the_quantile_matches_tabulated_values() {
    // (dof, upper-tail probability, tabulated quantile).
    for (dof, p, want) in [
        (1, 0.05, 3.841_459),
        (1, 0.01, 6.634_897),
        (2, 0.05, 5.991_465),
        (3, 0.01, 11.344_867),
        (4, 0.01, 13.276_704),
        (4, 0.001, 18.466_827),
        (5, 0.5, 4.351_460),
        (10, 0.05, 18.307_038),
        (100, 0.01, 135.806_723),
        (100, 0.99, 70.064_895),
    ] {
        let got = chi2_quantile_upper(dof, p).expect("defined");
        assert!(
            (got - want).abs() < 2e-6 * want,
            "χ²({dof}) upper {p}: {got} against {want}"
        );
    }
}

/// For even dof, `Q(k/2, x/2) = e^{−x/2} Σ_{i<k/2} (x/2)^i / i!` exactly: an independent
/// formula for the tails the tables do not reach.
#[test]
fn the_quantile_matches_the_closed_form_for_even_dof_down_to_tiny_probabilities() {
    let closed = |dof: usize, x: f64| {
        let h = x / 2.0;
        let mut term = (-h).exp();
        let mut sum = term;
        for i in 1..dof / 2 {
            term *= h / i as f64;
            sum += term;
        }
        sum
    };
    for dof in [2usize, 4, 6, 12, 40, 120] {
        for p in [0.5, 1e-2, 1e-6, 1e-12] {
            let x = chi2_quantile_upper(dof, p).expect("defined");
            let q = closed(dof, x);
            assert!(
                (q / p - 1.0).abs() < 1e-9,
                "dof {dof}, p {p}: Q at the quantile {x} is {q}"
            );
        }
    }
}

#[test]
fn out_of_domain_arguments_give_no_number() {
    assert_eq!(chi2_quantile_upper(0, 0.01), None);
    for p in [0.0, 1.0, -0.1, f64::NAN, f64::INFINITY] {
        assert_eq!(chi2_quantile_upper(4, p), None, "{p}");
    }
    assert!(ln_upper_regularized_gamma(-1.0, 1.0).is_nan());
    assert!(ln_upper_regularized_gamma(1.0, f64::NAN).is_nan());
}
