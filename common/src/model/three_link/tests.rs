use super::*;
use approx::assert_relative_eq;

fn arm() -> ThreeLink {
    ThreeLink::new(ThreeLinkParams::DEFAULT)
}

/// The same arm in a vertical plane, so that `G` is exercised.
fn vertical() -> ThreeLink {
    ThreeLink::new(ThreeLinkParams {
        gravity_m_s2: 9.81,
        ..ThreeLinkParams::DEFAULT
    })
}

fn grid() -> impl Iterator<Item = Vector<3>> {
    (-4..=4).flat_map(|i| {
        (-4..=4).flat_map(move |j| {
            (-4..=4).map(move |k| {
                Vector::<3>::new(
                    f64::from(i) * 0.71,
                    f64::from(j) * 0.83,
                    f64::from(k) * 0.77,
                )
            })
        })
    })
}

/// RK4 of the free arm (u = 0, d = 0), returning the total energy after each step.
fn free_energies(arm: &ThreeLink, q0: Vector<3>, qd0: Vector<3>, steps: usize) -> Vec<f64> {
    let energy =
        |q: &Vector<3>, qd: &Vector<3>| arm.kinetic_energy(q, qd) + arm.potential_energy(q);
    std::iter::once(energy(&q0, &qd0))
        .chain(
            crate::model::robot::free_motion(arm, (q0, qd0), 1e-3, steps)
                .iter()
                .map(|(q, qd)| energy(q, qd)),
        )
        .collect()
}

#[test]
fn inertia_is_symmetric_positive_definite_over_a_grid() {
    let arm = arm();
    for q in grid() {
        let m = arm.inertia(&q);
        assert_relative_eq!(m, m.transpose(), epsilon = 1e-15);
        let eig = m.symmetric_eigenvalues();
        assert!(eig.min() > 0.0, "M not PD at {q:?}: {eig:?}");
    }
    assert!(ThreeLinkParams::DEFAULT.problems().is_empty());
}

#[test]
fn inertia_matches_the_kinetic_energy_of_the_centres_of_mass() {
    // ½ q̇ᵀ M q̇ = Σ ½ m_i |v_i|² + ½ I_i ω_i², with v_i differentiated numerically from the
    // positions of the centres of mass: checks M against an independent formula.
    let arm = arm();
    let p = arm.params;
    let com = |q: &Vector<3>, i: usize| {
        let th = ThreeLink::absolute(q);
        (0..=i).fold((0.0, 0.0), |(x, y), a| {
            let l = if a == i { p.com_m[a] } else { p.length_m[a] };
            (x + l * th[a].cos(), y + l * th[a].sin())
        })
    };
    let h = 1e-6;
    for q in grid().step_by(11) {
        for qd in [
            Vector::<3>::new(0.7, -1.3, 2.1),
            Vector::<3>::new(-2.0, 0.4, -0.9),
        ] {
            let (qa, qb) = (q + qd * h, q - qd * h);
            let mut energy = 0.0;
            for i in 0..3 {
                let (xa, ya) = com(&qa, i);
                let (xb, yb) = com(&qb, i);
                let (vx, vy) = ((xa - xb) / (2.0 * h), (ya - yb) / (2.0 * h));
                let omega: f64 = qd.iter().take(i + 1).sum();
                energy += 0.5 * p.mass_kg[i] * (vx * vx + vy * vy)
                    + 0.5 * p.inertia_kg_m2[i] * omega * omega;
            }
            assert_relative_eq!(arm.kinetic_energy(&q, &qd), energy, max_relative = 1e-8);
        }
    }
}

#[test]
fn inertia_rate_minus_twice_coriolis_is_skew_symmetric() {
    let arm = arm();
    for q in grid().step_by(5) {
        for qd in grid().step_by(97) {
            let s = arm.inertia_rate(&q, &qd) - 2.0 * arm.coriolis(&q, &qd);
            assert_relative_eq!(s, -s.transpose(), epsilon = 1e-12);
            for x in grid().step_by(131) {
                let v = x.dot(&(s * x));
                assert!(v.abs() < 1e-11, "xᵀ(Ṁ−2V)x = {v} at q={q:?} q̇={qd:?}");
            }
        }
    }
}

#[test]
fn inertia_rate_matches_finite_difference() {
    let arm = arm();
    let h = 1e-6;
    for q in grid().step_by(23) {
        let qd = Vector::<3>::new(1.1, -2.3, 0.6);
        let fd = (arm.inertia(&(q + qd * h)) - arm.inertia(&(q - qd * h))) / (2.0 * h);
        assert_relative_eq!(arm.inertia_rate(&q, &qd), fd, epsilon = 1e-8);
    }
}

#[test]
fn gravity_is_the_gradient_of_the_potential_energy() {
    let arm = vertical();
    let h = 1e-6;
    for q in grid().step_by(13) {
        let g = arm.gravity(&q);
        for k in 0..3 {
            let mut e = Vector::<3>::zeros();
            e[k] = h;
            let fd = (arm.potential_energy(&(q + e)) - arm.potential_energy(&(q - e))) / (2.0 * h);
            assert_relative_eq!(g[k], fd, epsilon = 1e-7);
        }
    }
    assert_eq!(
        self::arm().gravity(&Vector::<3>::new(0.3, 0.2, 0.1)),
        Vector::<3>::zeros()
    );
}

#[test]
fn unforced_arm_with_friction_loses_energy() {
    // dE/dt = −q̇ᵀ F q̇ < 0 for q̇ ≠ 0 with E = kinetic + potential (Ṁ − 2V skew): the total
    // energy falls at every step, horizontal or vertical.
    for arm in [arm(), vertical()] {
        let e = free_energies(
            &arm,
            Vector::<3>::new(0.4, -1.0, 0.8),
            Vector::<3>::new(2.0, -3.0, 4.0),
            3000,
        );
        for w in e.windows(2) {
            assert!(
                w[1] < w[0],
                "energy rose from {} to {} (g = {})",
                w[0],
                w[1],
                arm.params.gravity_m_s2
            );
        }
    }
    // Without gravity the arm comes to rest: friction removes nearly all the energy.
    let e = free_energies(
        &arm(),
        Vector::<3>::new(0.4, -1.0, 0.8),
        Vector::<3>::new(2.0, -3.0, 4.0),
        5000,
    );
    assert!(
        e[e.len() - 1] < 0.01 * e[0],
        "after 5 s friction should remove >99% of {}, left {}",
        e[0],
        e[e.len() - 1]
    );
}

#[test]
fn without_friction_or_input_the_energy_is_conserved() {
    let arm = ThreeLink::new(ThreeLinkParams {
        friction_n_m_s: [0.0; 3],
        gravity_m_s2: 9.81,
        ..ThreeLinkParams::DEFAULT
    });
    let e = free_energies(
        &arm,
        Vector::<3>::new(0.4, -1.0, 0.8),
        Vector::<3>::new(2.0, -3.0, 4.0),
        2000,
    );
    let drift = e.iter().map(|x| (x - e[0]).abs()).fold(0.0, f64::max);
    assert!(
        drift < 1e-6 * e[0].abs().max(1.0),
        "energy drifted by {drift} from {}",
        e[0]
    );
}

#[test]
fn meaningless_parameters_are_named() {
    let bad = ThreeLinkParams {
        mass_kg: [1.0, 0.0, 1.0],
        com_m: [0.1, 0.5, 0.1],
        friction_n_m_s: [1.0, 1.0, f64::NAN],
        ..ThreeLinkParams::DEFAULT
    };
    let fields: Vec<&str> = bad.problems().iter().map(|(f, _)| *f).collect();
    assert_eq!(
        fields,
        ["mass_kg", "friction_n_m_s", "com_m"],
        "{:?}",
        bad.problems()
    );
    assert!(bad.problems()[0].1.contains("link 2"));
}
