//! Euler–Lagrange robot models, `M(q) q̈ + V(q, q̇) q̇ + G(q) + F(q̇) + d(t) = u` (paper eq. 1).
//!
//! A new robot is one new file implementing [`EulerLagrange`] plus one variant in
//! [`crate::scenario::ModelConfig`].

pub mod two_link;

use nalgebra::{SMatrix, SVector};

pub use two_link::{TwoLink, TwoLinkParams};

/// Column vector of generalized coordinates (or torques) of an `N`-dof robot.
pub type Vector<const N: usize> = SVector<f64, N>;
/// Square matrix over the generalized coordinates of an `N`-dof robot.
pub type Matrix<const N: usize> = SMatrix<f64, N, N>;

/// The known dynamics of one agent. Pure: no state, no I/O.
pub trait EulerLagrange<const N: usize>: Send + Sync + std::fmt::Debug {
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

    /// Kinetic energy `½ q̇ᵀ M q̇`.
    fn kinetic_energy(&self, q: &Vector<N>, qd: &Vector<N>) -> f64 {
        0.5 * qd.dot(&(self.inertia(q) * qd))
    }
}
