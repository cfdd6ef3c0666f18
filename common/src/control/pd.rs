//! `pd`: the paper's traditional law without its delay compensation (docs/model.md,
//! "Controllers"), `u = K (q̇_d − ẏ + β (q_d − y))`: a proportional-derivative controller on the
//! measurement, blind to the input delay (no `− A e_u`) and to the attack (no `Ŝ`), with the
//! scenario's `K` and `β`. An ablation: the difference to `traditional` is what the delay
//! compensation of the paper's (12) buys. No observer: its estimate is the measurement it used,
//! `q̂̈` the change of `ẏ` over the period.

use crate::model::{EulerLagrange, Vector};

use super::config::CenterParams;
use super::controller::{Command, Controller, Estimate, Tick};

/// The PD controller of one robot.
#[derive(Debug)]
pub struct Pd<const N: usize> {
    beta: f64,
    /// The diagonal of `K`.
    gains: Vector<N>,
    /// The measurement of the last tick (its estimate) and the one before's `ẏ`.
    used: Estimate<N>,
}

impl<const N: usize> Pd<N> {
    pub fn new(params: &CenterParams, model: &dyn EulerLagrange<N>) -> Option<Self> {
        let start = params.trajectory.start_position::<N>()?;
        Some(Self {
            beta: params.controller.beta,
            gains: params.gains(model),
            used: rest_at(start),
        })
    }
}

/// At `q`, at rest.
fn rest_at<const N: usize>(q: Vector<N>) -> Estimate<N> {
    Estimate {
        q_hat: q,
        qd_hat: Vector::zeros(),
        qdd_hat: Vector::zeros(),
        alarm: None,
    }
}

impl<const N: usize> Controller<N> for Pd<N> {
    fn command(&mut self, x: &Tick<'_, N>) -> Command<N> {
        let r = x.reference;
        let u = ((r.qd - x.yd) + (r.q - x.y) * self.beta).component_mul(&self.gains);
        Command {
            u,
            s_hat: Vector::zeros(),
        }
    }

    fn update(&mut self, x: &Tick<'_, N>, _: &Vector<N>) -> Estimate<N> {
        self.used = Estimate {
            q_hat: *x.y,
            qd_hat: *x.yd,
            qdd_hat: (x.yd - self.used.qd_hat) / x.dt,
            alarm: None,
        };
        self.used
    }

    fn is_finite(&self) -> bool {
        let e = &self.used;
        (e.q_hat
            .iter()
            .chain(e.qd_hat.iter())
            .chain(e.qdd_hat.iter()))
        .all(|v| v.is_finite())
    }

    fn reset(&mut self, y: &Vector<N>, yd: &Vector<N>) -> Estimate<N> {
        self.used = Estimate {
            qd_hat: *yd,
            ..rest_at(*y)
        };
        self.used
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario;

    /// The law on a hand-computed tick: `u_i = K_i (q̇_d,i − ẏ_i + β (q_d,i − y_i))`, whatever
    /// `e_u` (no delay compensation), and no attack estimate.
    #[test]
    fn the_torque_is_k_times_the_filtered_error_and_ignores_e_u() {
        let r = scenario::paper().expect("paper");
        let agent = &r.scenario.agents[0];
        let params = r.scenario.center_params(agent);
        let model = params.model.build::<2>().expect("two links");
        let mut pd = Pd::<2>::new(&params, model.as_ref()).expect("a PD");
        let reference = params.trajectory.reference::<2>(0.25);
        let (y, yd) = (Vector::<2>::new(0.1, -0.2), Vector::<2>::new(0.3, 0.05));
        let command = |pd: &mut Pd<2>, e_u: Vector<2>| {
            pd.command(&Tick {
                t: 0.25,
                dt: 0.001,
                y: &y,
                yd: &yd,
                reference: &reference,
                trajectory: &params.trajectory,
                e_u: &e_u,
                delay: &params.delay,
                model: model.as_ref(),
                s_override: None,
                answer: None,
            })
        };
        let c = command(&mut pd, Vector::zeros());
        let (k, beta) = (params.controller.gain_k, params.controller.beta);
        for i in 0..2 {
            let expected = k * (reference.qd[i] - yd[i] + beta * (reference.q[i] - y[i]));
            assert!((c.u[i] - expected).abs() <= 1e-12 * expected.abs().max(1.0));
        }
        assert_eq!(c.s_hat, Vector::<2>::zeros());
        assert_eq!(command(&mut pd, Vector::from_element(5.0)).u, c.u);
    }
}
