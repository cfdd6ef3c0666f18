//! Nonlinear observer (22)–(24):
//! `Ψ2 = ẏ + β y − q̂̇ − β q̂ − Ŝ`, `Ψ3 = q̇_d − q̂̇ + β (q_d − q̂) − A e_u`,
//! `q̂̈ = f(q̂, q̂̇) + A u_τ − L1 Ψ2 + L2 Ψ3`.
//! Integrated with one semi-implicit Euler step per control period (`q̂̇ += Δ q̂̈`, then
//! `q̂ += Δ q̂̇`): at 1 kHz the observer's own dynamics are far slower than Δ, and the step keeps
//! the operation order trivially identical in every process.

use crate::model::{EulerLagrange, Matrix, Vector};
use crate::trajectory::Reference;

/// Observer state of one agent. Starts at `q̂ = q̂̇ = 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observer<const N: usize> {
    pub q: Vector<N>,
    pub qd: Vector<N>,
    /// `q̂̈` of the last step.
    pub qdd: Vector<N>,
}

impl<const N: usize> Default for Observer<N> {
    fn default() -> Self {
        Self {
            q: Vector::<N>::zeros(),
            qd: Vector::<N>::zeros(),
            qdd: Vector::<N>::zeros(),
        }
    }
}

/// Everything one observer step reads.
#[derive(Debug, Clone, Copy)]
pub struct ObserverInput<'a, const N: usize> {
    pub y: &'a Vector<N>,
    pub yd: &'a Vector<N>,
    pub s_hat: &'a Vector<N>,
    pub reference: &'a Reference<N>,
    /// `A = M(q_d)⁻¹`.
    pub a: &'a Matrix<N>,
    /// `e_u = ∫_{t−τ}^{t} u ds`.
    pub e_u: &'a Vector<N>,
    /// `u_τ`: the delayed input over the step (its mean, or its sample at `t − τ(t)`; the
    /// scenario's `controller.observer_input`).
    pub u_tau: &'a Vector<N>,
    pub beta: f64,
    pub l1: f64,
    pub l2: f64,
}

impl<const N: usize> Observer<N> {
    /// An observer at `q̂ = q`, `q̂̇ = qd`, `q̂̈ = 0` (the recovery from non-finite state).
    pub fn at(q: Vector<N>, qd: Vector<N>) -> Self {
        Self {
            q,
            qd,
            qdd: Vector::<N>::zeros(),
        }
    }

    /// Every component of the state is finite.
    pub fn is_finite(&self) -> bool {
        self.q
            .iter()
            .chain(self.qd.iter())
            .chain(self.qdd.iter())
            .all(|x| x.is_finite())
    }

    /// `Ψ2` (23) at the current estimate.
    pub fn psi2(&self, y: &Vector<N>, yd: &Vector<N>, beta: f64, s_hat: &Vector<N>) -> Vector<N> {
        yd + y * beta - self.qd - self.q * beta - s_hat
    }

    /// One step of length `dt`; returns `Ψ2` (evaluated before the step).
    pub fn step(
        &mut self,
        model: &dyn EulerLagrange<N>,
        input: &ObserverInput<'_, N>,
        dt: f64,
    ) -> Vector<N> {
        let psi2 = self.psi2(input.y, input.yd, input.beta, input.s_hat);
        let r = input.reference;
        let psi3 = r.qd - self.qd + (r.q - self.q) * input.beta - input.a * input.e_u;
        self.qdd = model.drift(&self.q, &self.qd) + input.a * input.u_tau - psi2 * input.l1
            + psi3 * input.l2;
        self.qd += self.qdd * dt;
        self.q += self.qd * dt;
        psi2
    }
}
