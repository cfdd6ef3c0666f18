//! A model with some of its answers for one tick computed ahead: the in-process engine computes
//! the control centers' `M(q_d)⁻¹` and observer drifts of a team of one robot side by side
//! ([`EulerLagrange::inverse_inertias`], [`EulerLagrange::drifts`]) and hands each center its
//! own. An answer is used only for the very arguments it was computed at (bit for bit); any
//! other question goes to the model, so a prime never stands in for a number it is not.

use super::robot::{EulerLagrange, Forward, Matrix, Vector, LANES, SIDE_BY_SIDE_MIN};
use crate::memo::same_bits;

/// What a controller will ask its model in the tick under way
/// ([`crate::control::Controller::wants`]): where to compute ahead.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Wants<const N: usize> {
    /// `M(q)⁻¹` at this `q`.
    pub inverse_inertia: Option<Vector<N>>,
    /// `f(q, q̇)` ([`EulerLagrange::drift`]) at this `(q, q̇)`.
    pub drift: Option<(Vector<N>, Vector<N>)>,
}

/// Answers computed ahead, each with the arguments it answers.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Primes<const N: usize> {
    pub inverse_inertia: Option<(Vector<N>, Matrix<N>)>,
    pub drift: Option<((Vector<N>, Vector<N>), Vector<N>)>,
}

/// `model` answering from `primes` where their arguments are the question's, bit for bit.
#[derive(Debug, Clone, Copy)]
pub struct Primed<'a, const N: usize> {
    pub model: &'a dyn EulerLagrange<N>,
    pub primes: &'a Primes<N>,
}

/// The same bits ([`same_bits`]).
fn same<const N: usize>(a: &Vector<N>, b: &Vector<N>) -> bool {
    same_bits(a.iter().copied(), b.iter().copied())
}

impl<const N: usize> EulerLagrange<N> for Primed<'_, N> {
    fn problems(&self) -> Vec<(&'static str, String)> {
        self.model.problems()
    }
    fn inertia(&self, q: &Vector<N>) -> Matrix<N> {
        self.model.inertia(q)
    }
    fn inertia_rate(&self, q: &Vector<N>, qd: &Vector<N>) -> Matrix<N> {
        self.model.inertia_rate(q, qd)
    }
    fn coriolis(&self, q: &Vector<N>, qd: &Vector<N>) -> Matrix<N> {
        self.model.coriolis(q, qd)
    }
    fn gravity(&self, q: &Vector<N>) -> Vector<N> {
        self.model.gravity(q)
    }
    fn friction(&self, qd: &Vector<N>) -> Vector<N> {
        self.model.friction(qd)
    }
    fn inverse_inertia(&self, q: &Vector<N>) -> Matrix<N> {
        match &self.primes.inverse_inertia {
            Some((at, inverse)) if same(at, q) => *inverse,
            _ => self.model.inverse_inertia(q),
        }
    }
    fn bias_forces(&self, q: &Vector<N>, qd: &Vector<N>) -> Vector<N> {
        self.model.bias_forces(q, qd)
    }
    fn drift(&self, q: &Vector<N>, qd: &Vector<N>) -> Vector<N> {
        match &self.primes.drift {
            Some(((at_q, at_qd), drift)) if same(at_q, q) && same(at_qd, qd) => *drift,
            _ => self.model.drift(q, qd),
        }
    }
    fn acceleration(
        &self,
        q: &Vector<N>,
        qd: &Vector<N>,
        torque: &Vector<N>,
        disturbance: &Vector<N>,
    ) -> Vector<N> {
        self.model.acceleration(q, qd, torque, disturbance)
    }
    fn accelerations(&self, states: &[Forward<'_, N>; LANES]) -> [Vector<N>; LANES] {
        self.model.accelerations(states)
    }
    fn drifts(&self, states: &[(&Vector<N>, &Vector<N>); LANES]) -> [Vector<N>; LANES] {
        self.model.drifts(states)
    }
    fn inverse_inertias(&self, qs: &[&Vector<N>; LANES]) -> [Matrix<N>; LANES] {
        self.model.inverse_inertias(qs)
    }
    fn side_by_side(&self) -> bool {
        self.model.side_by_side()
    }
    fn kinetic_energy(&self, q: &Vector<N>, qd: &Vector<N>) -> f64 {
        self.model.kinetic_energy(q, qd)
    }
}

/// The answers `wants` asks of `model` for each controller, computed side by side, [`LANES`] at
/// a time (a missing lane repeats the first one; its answer is dropped); fewer than
/// [`SIDE_BY_SIDE_MIN`] left over are not computed ahead (the model answers them in the tick).
pub fn prime<const N: usize>(model: &dyn EulerLagrange<N>, wants: &[Wants<N>]) -> Vec<Primes<N>> {
    let mut primes = vec![Primes::default(); wants.len()];
    let inverses: Vec<(usize, Vector<N>)> = (wants.iter().enumerate())
        .filter_map(|(i, w)| w.inverse_inertia.map(|q| (i, q)))
        .collect();
    for lanes in inverses
        .chunks(LANES)
        .filter(|l| l.len() >= SIDE_BY_SIDE_MIN)
    {
        let qs: [&Vector<N>; LANES] = std::array::from_fn(|l| &lanes[l.min(lanes.len() - 1)].1);
        for ((i, q), inverse) in lanes.iter().zip(model.inverse_inertias(&qs)) {
            primes[*i].inverse_inertia = Some((*q, inverse));
        }
    }
    let drifts: Vec<(usize, (Vector<N>, Vector<N>))> = (wants.iter().enumerate())
        .filter_map(|(i, w)| w.drift.map(|s| (i, s)))
        .collect();
    for lanes in drifts.chunks(LANES).filter(|l| l.len() >= SIDE_BY_SIDE_MIN) {
        let states: [(&Vector<N>, &Vector<N>); LANES] = std::array::from_fn(|l| {
            let (q, qd) = &lanes[l.min(lanes.len() - 1)].1;
            (q, qd)
        });
        for ((i, state), drift) in lanes.iter().zip(model.drifts(&states)) {
            primes[*i].drift = Some((*state, drift));
        }
    }
    primes
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{TwoLink, TwoLinkParams};

    #[test]
    fn a_prime_answers_its_very_arguments_only() {
        let model = TwoLink::new(TwoLinkParams::PAPER);
        let (q, qd) = (Vector::<2>::new(0.0, 0.4), Vector::<2>::new(-0.3, 0.2));
        // Marked answers, to see which ones are used.
        let primes = Primes {
            inverse_inertia: Some((q, Matrix::<2>::identity() * 42.0)),
            drift: Some(((q, qd), Vector::<2>::new(7.0, 7.0))),
        };
        let primed = Primed {
            model: &model,
            primes: &primes,
        };
        assert_eq!(primed.inverse_inertia(&q), Matrix::<2>::identity() * 42.0);
        assert_eq!(primed.drift(&q, &qd), Vector::<2>::new(7.0, 7.0));
        // `−0` is another argument than `0`; so is another velocity.
        let minus_zero = Vector::<2>::new(-0.0, 0.4);
        assert_eq!(
            primed.inverse_inertia(&minus_zero),
            model.inverse_inertia(&minus_zero)
        );
        assert_eq!(
            primed.drift(&minus_zero, &qd),
            model.drift(&minus_zero, &qd)
        );
        assert_eq!(primed.drift(&q, &-qd), model.drift(&q, &-qd));
        // The rest is the model's.
        assert_eq!(primed.inertia(&q), model.inertia(&q));
        assert_eq!(primed.bias_forces(&q, &qd), model.bias_forces(&q, &qd));
    }

    #[test]
    fn primes_are_the_model_s_answers_for_what_each_controller_wants() {
        let model = TwoLink::new(TwoLinkParams::PAPER);
        // Nine controllers (lanes of four, four and one), one wanting no drift.
        let wants: Vec<Wants<2>> = (0..9)
            .map(|i| {
                let x = 0.1 * i as f64;
                Wants {
                    inverse_inertia: Some(Vector::<2>::new(x, -x)),
                    drift: (i != 2).then(|| (Vector::<2>::new(x, 0.5), Vector::<2>::new(-x, x))),
                }
            })
            .collect();
        let primes = prime(&model, &wants);
        assert_eq!(primes.len(), 9);
        for (i, (w, p)) in wants.iter().zip(&primes).enumerate() {
            // The inverses' lanes: 0–3, 4–7, and 8 alone, left to the model in the tick.
            let q = w.inverse_inertia.expect("wanted");
            let inverse = (i < 8).then(|| (q, model.inverse_inertia(&q)));
            assert_eq!(p.inverse_inertia, inverse, "controller {i}");
            // The drifts' lanes: 0, 1, 3, 4, then 5–8.
            let drift = w.drift.map(|(q, qd)| ((q, qd), model.drift(&q, &qd)));
            assert_eq!(p.drift, drift, "controller {i}");
        }
        assert_eq!(primes[8].inverse_inertia, None);
        assert!(primes[8].drift.is_some() && primes[2].drift.is_none());
    }
}
