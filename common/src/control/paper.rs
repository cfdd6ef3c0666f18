//! The paper's controllers (docs/model.md, "Control center", steps 2–8): `proposed`, with the
//! observer (22)–(24) and the NN attack estimate `Ŝ` (32), (37), (38) in the torque (12), (14);
//! and `traditional`, the same observer with `Ŝ ≡ 0` and no learning.

use crate::model::primed::Wants;
use crate::model::{EulerLagrange, Matrix, Vector};
use crate::rng::{stream, Purpose};
use crate::trajectory::Reference;

use super::config::{CenterParams, ControllerConfig};
use super::controller::{Command, Controller, Estimate, Tick};
use super::estimator::{NnEstimator, NnParams};
use super::observer::{Observer, ObserverInput};

/// The paper's controller of one robot.
#[derive(Debug)]
pub struct Paper<const N: usize> {
    /// `proposed`: `Ŝ` from the estimator, which learns; `traditional`: `Ŝ ≡ 0`.
    estimating: bool,
    config: ControllerConfig,
    /// The diagonal of `K` in `u = K r̂`.
    gains: Vector<N>,
    observer: Observer<N>,
    estimator: NnEstimator<N>,
    /// `Ψ2` of the last tick: the NN's input (no algebraic loop).
    psi2_prev: Vector<N>,
    /// `A = M(q_d)⁻¹` and `Ŝ` of the tick under way, from its command to its update.
    a: Matrix<N>,
    s_hat: Vector<N>,
}

impl<const N: usize> Paper<N> {
    /// The proposed controller of `params`' robot.
    pub fn proposed(params: &CenterParams, model: &dyn EulerLagrange<N>) -> Option<Self> {
        Self::new(params, model, true)
    }

    /// The traditional controller of `params`' robot.
    pub fn traditional(params: &CenterParams, model: &dyn EulerLagrange<N>) -> Option<Self> {
        Self::new(params, model, false)
    }

    /// The observer starts at the trajectory's start pose, at rest; `None` when the start pose
    /// has another number of links than `N`.
    fn new(params: &CenterParams, model: &dyn EulerLagrange<N>, estimating: bool) -> Option<Self> {
        let c = &params.controller;
        let mut rng = stream(params.run_seed, params.agent_id, Purpose::NnInit);
        let estimator = NnEstimator::new(NnParams::from_controller(c), c.initial_v_range, &mut rng);
        let gains = params.gains(model);
        let observer = Observer::at(params.trajectory.start_position::<N>()?, Vector::zeros());
        Some(Self {
            estimating,
            config: *c,
            gains,
            observer,
            estimator,
            psi2_prev: Vector::<N>::zeros(),
            a: Matrix::<N>::zeros(),
            s_hat: Vector::<N>::zeros(),
        })
    }

    /// The observer's prediction of the next measurement: its `(q̂, q̂̇)`.
    pub fn prediction(&self) -> (Vector<N>, Vector<N>) {
        (self.observer.q, self.observer.qd)
    }

    /// The observer's state as the estimate.
    fn estimate(&self) -> Estimate<N> {
        Estimate {
            q_hat: self.observer.q,
            qd_hat: self.observer.qd,
            qdd_hat: self.observer.qdd,
            alarm: None,
        }
    }

    /// The diagonal of `K` (tests).
    #[cfg(test)]
    pub(crate) fn gains(&self) -> &Vector<N> {
        &self.gains
    }
}

impl<const N: usize> Controller<N> for Paper<N> {
    /// Steps 2, 4, 5: `A = M(q_d)⁻¹`, the NN estimate from the last tick's `Ψ2`, and
    /// `u = K (Ψ̇1 + β Ψ1 − A e_u + Ŝ)`.
    fn command(&mut self, x: &Tick<'_, N>) -> Command<N> {
        self.a = x.model.inverse_inertia(&x.reference.q);
        self.s_hat = match (x.s_override, self.estimating) {
            (Some(s), _) => *s,
            (None, true) => self.estimator.estimate(&self.psi2_prev),
            (None, false) => Vector::<N>::zeros(),
        };
        let psi1 = x.reference.q - x.y;
        let psi1_dot = x.reference.qd - x.yd;
        let r_hat = psi1_dot + psi1 * self.config.beta - self.a * x.e_u + self.s_hat;
        Command {
            u: r_hat.component_mul(&self.gains),
            s_hat: self.s_hat,
        }
    }

    /// Steps 6, 7: the observer's step over `[t, t + Δ]` with the delayed input `u_tau`, then
    /// the weights (proposed, unless `Ŝ` is forced) from its `Ψ2`.
    fn update(&mut self, x: &Tick<'_, N>, u_tau: &Vector<N>) -> Estimate<N> {
        let c = &self.config;
        let input = ObserverInput {
            y: x.y,
            yd: x.yd,
            s_hat: &self.s_hat,
            reference: x.reference,
            a: &self.a,
            e_u: x.e_u,
            u_tau,
            beta: c.beta,
            l1: c.observer_gain_l1,
            l2: c.observer_gain_l2,
        };
        let psi2 = self.observer.step(x.model, &input, x.dt);
        if self.estimating && x.s_override.is_none() {
            self.estimator.update(&psi2, x.dt);
        }
        self.psi2_prev = psi2;
        self.estimate()
    }

    fn is_finite(&self) -> bool {
        self.observer.is_finite()
            && self.estimator.is_finite()
            && self.psi2_prev.iter().all(|x| x.is_finite())
    }

    /// Step 10's policy: the estimator from its initial weights (`Ŵ = 0`, `V̂ = V̂(0)`), the
    /// observer from the measurement (`q̂ = y`, `q̂̇ = ẏ`), the next NN input from `Ψ2 = 0`.
    fn reset(&mut self, y: &Vector<N>, yd: &Vector<N>) -> Estimate<N> {
        self.estimator.reset();
        self.observer = Observer::at(*y, *yd);
        self.psi2_prev = Vector::<N>::zeros();
        self.estimate()
    }

    /// `A = M(q_d)⁻¹` ([`Self::command`]) and the observer's drift at its state
    /// ([`Self::update`]).
    fn wants(&self, reference: &Reference<N>) -> Wants<N> {
        Wants {
            inverse_inertia: Some(reference.q),
            drift: Some((self.observer.q, self.observer.qd)),
        }
    }
}
