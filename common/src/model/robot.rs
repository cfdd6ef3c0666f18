//! What every robot model is: the known dynamics [`EulerLagrange`] of an `N`-link arm, over the
//! [`Vector`]s and [`Matrix`]es of its generalized coordinates. The models ([`super::two_link`],
//! [`super::three_link`]) implement it; [`super::ModelConfig`] picks one.

use nalgebra::{SMatrix, SVector};

/// Column vector of generalized coordinates (or torques) of an `N`-dof robot.
pub type Vector<const N: usize> = SVector<f64, N>;
/// Square matrix over the generalized coordinates of an `N`-dof robot.
pub type Matrix<const N: usize> = SMatrix<f64, N, N>;

/// How many states [`EulerLagrange::accelerations`] takes at once.
pub const LANES: usize = 4;

/// The fewest states worth computing side by side: [`LANES`] of them cost about as much as three
/// alone (a Panda's forward dynamics, `cargo bench -p fdi-common --bench urdf`), so fewer are
/// computed one by one.
pub const SIDE_BY_SIDE_MIN: usize = 3;

/// One state of the forward dynamics: `q`, `q̇`, the torque and the disturbance
/// ([`EulerLagrange::acceleration`]'s arguments).
pub type Forward<'a, const N: usize> = (&'a Vector<N>, &'a Vector<N>, &'a Vector<N>, &'a Vector<N>);

/// The known dynamics of one agent. Pure: no state, no I/O.
pub trait EulerLagrange<const N: usize>: Send + Sync + std::fmt::Debug {
    /// Every way the parameters are physically meaningless, as `(field, why)`; empty for a
    /// model whose inertia is positive definite everywhere and whose friction is dissipative.
    fn problems(&self) -> Vec<(&'static str, String)>;
    /// Generalized inertia `M(q)`, symmetric positive definite.
    fn inertia(&self, q: &Vector<N>) -> Matrix<N>;
    /// Time derivative `Ṁ(q, q̇)` (used by the passivity property tests).
    fn inertia_rate(&self, q: &Vector<N>, qd: &Vector<N>) -> Matrix<N>;
    /// Centripetal–Coriolis matrix `V(q, q̇)`.
    fn coriolis(&self, q: &Vector<N>, qd: &Vector<N>) -> Matrix<N>;
    /// Gravity vector `G(q)`.
    fn gravity(&self, q: &Vector<N>) -> Vector<N>;
    /// Friction `F(q̇)`.
    fn friction(&self, qd: &Vector<N>) -> Vector<N>;

    /// `M(q)⁻¹`. A validated model is positive definite everywhere, so the inverse exists; a
    /// singular matrix (only reachable with unvalidated parameters) yields zeros rather than NaN.
    fn inverse_inertia(&self, q: &Vector<N>) -> Matrix<N> {
        self.inertia(q)
            .try_inverse()
            .unwrap_or_else(Matrix::<N>::zeros)
    }

    /// Non-input terms `V q̇ + G + F`.
    fn bias_forces(&self, q: &Vector<N>, qd: &Vector<N>) -> Vector<N> {
        self.coriolis(q, qd) * qd + self.gravity(q) + self.friction(qd)
    }

    /// `f(q, q̇) = −M⁻¹ (V q̇ + G + F)` (paper eq. 21), the drift the observer uses.
    fn drift(&self, q: &Vector<N>, qd: &Vector<N>) -> Vector<N> {
        -(self.inverse_inertia(q) * self.bias_forces(q, qd))
    }

    /// `q̈ = M⁻¹ (u − V q̇ − G − F − d)`: the plant's forward dynamics.
    fn acceleration(
        &self,
        q: &Vector<N>,
        qd: &Vector<N>,
        torque: &Vector<N>,
        disturbance: &Vector<N>,
    ) -> Vector<N> {
        self.inverse_inertia(q) * (torque - self.bias_forces(q, qd) - disturbance)
    }

    /// [`Self::acceleration`] of [`LANES`] states, each to the bit as it gives it alone: a
    /// model may compute them side by side (the plants of a team of the same robot step
    /// together).
    fn accelerations(&self, states: &[Forward<'_, N>; LANES]) -> [Vector<N>; LANES] {
        states.map(|(q, qd, u, d)| self.acceleration(q, qd, u, d))
    }

    /// [`Self::drift`] of [`LANES`] states, each to the bit as it gives it alone.
    fn drifts(&self, states: &[(&Vector<N>, &Vector<N>); LANES]) -> [Vector<N>; LANES] {
        states.map(|(q, qd)| self.drift(q, qd))
    }

    /// [`Self::inverse_inertia`] at [`LANES`] poses, each to the bit as it gives it alone.
    fn inverse_inertias(&self, qs: &[&Vector<N>; LANES]) -> [Matrix<N>; LANES] {
        qs.map(|q| self.inverse_inertia(q))
    }

    /// Whether [`Self::accelerations`], [`Self::drifts`] and [`Self::inverse_inertias`]
    /// compute their states side by side (faster than one by one); else they ask the
    /// single-state method of each.
    fn side_by_side(&self) -> bool {
        false
    }

    /// Kinetic energy `½ q̇ᵀ M q̇`.
    fn kinetic_energy(&self, q: &Vector<N>, qd: &Vector<N>) -> f64 {
        0.5 * qd.dot(&(self.inertia(q) * qd))
    }
}

/// The states `(q, q̇)` of the free arm (`u = 0`, `d = 0`) from `(q0, q̇0)` after each of
/// `steps` classic RK4 steps of `dt`: what the models' energy property tests integrate.
#[cfg(test)]
pub(crate) fn free_motion<const N: usize>(
    arm: &dyn EulerLagrange<N>,
    (q0, qd0): (Vector<N>, Vector<N>),
    dt: f64,
    steps: usize,
) -> Vec<(Vector<N>, Vector<N>)> {
    let zero = Vector::<N>::zeros();
    let f = |q: &Vector<N>, qd: &Vector<N>| arm.acceleration(q, qd, &zero, &zero);
    let (mut q, mut qd) = (q0, qd0);
    let mut out = Vec::with_capacity(steps);
    for _ in 0..steps {
        let k1 = (qd, f(&q, &qd));
        let k2 = (
            qd + k1.1 * (dt / 2.0),
            f(&(q + k1.0 * (dt / 2.0)), &(qd + k1.1 * (dt / 2.0))),
        );
        let k3 = (
            qd + k2.1 * (dt / 2.0),
            f(&(q + k2.0 * (dt / 2.0)), &(qd + k2.1 * (dt / 2.0))),
        );
        let k4 = (qd + k3.1 * dt, f(&(q + k3.0 * dt), &(qd + k3.1 * dt)));
        q += (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0) * (dt / 6.0);
        qd += (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1) * (dt / 6.0);
        out.push((q, qd));
    }
    out
}
