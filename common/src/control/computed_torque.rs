//! `computed-torque`: a baseline a reviewer asks for, model-based and without an attack
//! estimate (docs/model.md, "Controllers"). The torque sent at `t` acts at `t + τ(t)` (the
//! known delay), so the law is written for then: the measured state is predicted over the
//! delay, `ŷ = y + τ ẏ`, `ŷ̇ = ẏ`, and with the reference at `t' = t + τ(t)`,
//!
//! `u = M(ŷ) (q̈_d(t') + K_d (q̇_d(t') − ŷ̇) + K_p (q_d(t') − ŷ)) + V(ŷ, ŷ̇) ŷ̇ + G(ŷ) + F(ŷ̇)`,
//!
//! `K_p = ω_n² I`, `K_d = 2 ζ ω_n I`: the computed-torque (inverse dynamics) law of Spong,
//! Hutchinson and Vidyasagar, *Robot Modeling and Control* (Wiley, 2006), section 8.3, on a
//! state predicted over the known input delay as a Smith predictor does (O. J. M. Smith, "A
//! controller to overcome dead time", ISA Journal 6, 1959). It trusts the measurement: an
//! attack on it reaches the torque whole.

use crate::model::{EulerLagrange, Vector};

use super::config::CenterParams;
use super::controller::{Command, Controller, Estimate, Tick};

/// The computed-torque controller of one robot: no state but what it predicted last.
#[derive(Debug)]
pub struct ComputedTorque<const N: usize> {
    kp: f64,
    kd: f64,
    /// The predicted state and the commanded acceleration of the last tick (its estimate).
    predicted: Estimate<N>,
}

impl<const N: usize> ComputedTorque<N> {
    pub fn new(params: &CenterParams, _: &dyn EulerLagrange<N>) -> Option<Self> {
        let c = params.controller.computed_torque;
        let start = params.trajectory.start_position::<N>()?;
        Some(Self {
            kp: c.omega_n_rad_s * c.omega_n_rad_s,
            kd: 2.0 * c.zeta * c.omega_n_rad_s,
            predicted: Estimate {
                q_hat: start,
                qd_hat: Vector::zeros(),
                qdd_hat: Vector::zeros(),
                alarm: None,
            },
        })
    }
}

impl<const N: usize> Controller<N> for ComputedTorque<N> {
    fn command(&mut self, x: &Tick<'_, N>) -> Command<N> {
        let tau = x.delay.tau(x.t);
        let r = x.trajectory.reference::<N>(x.t + tau);
        let (q, qd) = (x.y + x.yd * tau, *x.yd);
        let v = r.qdd + (r.qd - qd) * self.kd + (r.q - q) * self.kp;
        let u = x.model.inertia(&q) * v + x.model.bias_forces(&q, &qd);
        self.predicted = Estimate {
            q_hat: q,
            qd_hat: qd,
            qdd_hat: v,
            alarm: None,
        };
        Command {
            u,
            s_hat: Vector::zeros(),
        }
    }

    fn update(&mut self, _: &Tick<'_, N>, _: &Vector<N>) -> Estimate<N> {
        self.predicted
    }

    fn is_finite(&self) -> bool {
        let p = &self.predicted;
        (p.q_hat
            .iter()
            .chain(p.qd_hat.iter())
            .chain(p.qdd_hat.iter()))
        .all(|x| x.is_finite())
    }

    fn reset(&mut self, y: &Vector<N>, yd: &Vector<N>) -> Estimate<N> {
        self.predicted = Estimate {
            q_hat: *y,
            qd_hat: *yd,
            qdd_hat: Vector::zeros(),
            alarm: None,
        };
        self.predicted
    }
}
