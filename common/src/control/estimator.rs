//! Two-layer NN estimate of the attack term `S = S2 + β S1`:
//! `δ = [1; Ψ2]`, `h = tanh(V̂ᵀ δ)`, `σ = [1; h]`, `Ŝ = Ŵᵀ σ` (32), (33), with the update laws
//! (37), (38) integrated by one Euler step per tick and followed by a projection onto a
//! Frobenius ball (a discrete stand-in for the Lipschitz projection of the paper's [47]).
//!
//! Beyond the paper, [`UpdateLaw`] holds optional robust modifications of (37), (38) for long
//! horizons (docs/model.md, "Long horizons"); all of them off is the paper's law, bit for bit.
//!
//! Weights are stored row-major in plain vectors sized once at construction: no allocation
//! per tick, and a fixed order of floating-point operations.

use rand::Rng;
use rand_chacha::ChaCha12Rng;

use crate::model::Vector;

use super::config::ControllerConfig;
/// The robust modifications of (37), (38) ([`super::config`], with the rest of `[controller]`).
pub use super::config::UpdateLaw;

/// Sizes and gains of the estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NnParams {
    /// Hidden neurons `n_n`.
    pub hidden: usize,
    /// `Γ1 = gamma_w · I`.
    pub gamma_w: f64,
    /// `Γ2 = gamma_v · I`.
    pub gamma_v: f64,
    /// Observer gain `L1` (it scales both update laws).
    pub l1: f64,
    /// `W̄`.
    pub bound_w: f64,
    /// `V̄`.
    pub bound_v: f64,
    /// Robust modifications of (37), (38); the default is the paper's law.
    pub law: UpdateLaw,
}

impl NnParams {
    /// The estimator's part of a controller configuration.
    pub fn from_controller(c: &ControllerConfig) -> Self {
        Self {
            hidden: c.hidden_neurons,
            gamma_w: c.learning_rate_w,
            gamma_v: c.learning_rate_v,
            l1: c.observer_gain_l1,
            bound_w: c.weight_bound_w,
            bound_v: c.weight_bound_v,
            law: c.update_law,
        }
    }
}

/// The estimator of one agent.
#[derive(Debug, Clone)]
pub struct NnEstimator<const N: usize> {
    params: NnParams,
    /// `Ŵ ∈ R^{(n_n+1)×N}`, row-major.
    w: Vec<f64>,
    /// `V̂ ∈ R^{(N+1)×n_n}`, row-major.
    v: Vec<f64>,
    /// `V̂(0)`, for [`Self::reset`].
    v0: Vec<f64>,
    /// `b` of [`UpdateLaw`]: the slow part of the innovation (stays 0 when off).
    baseline: Vector<N>,
    /// `Ŝ` of the last [`Self::estimate`].
    s_hat: Vector<N>,
    /// `δ` of the last [`Self::estimate`].
    delta: Vec<f64>,
    /// `σ` of the last [`Self::estimate`] (`σ[0] = 1`, `σ[1..] = h`).
    sigma: Vec<f64>,
    /// Scratch for the `V̂` update: `(Ψ2ᵀ Ŵᵀ σ')_j`.
    grad_v: Vec<f64>,
}

impl<const N: usize> NnEstimator<N> {
    /// `Ŵ(0) = 0`, `V̂(0) ~ U(−init_range, init_range)` drawn from `rng` in row-major order.
    pub fn new(params: NnParams, init_range: f64, rng: &mut ChaCha12Rng) -> Self {
        let nh = params.hidden;
        let v: Vec<f64> = (0..(N + 1) * nh)
            .map(|_| {
                if init_range > 0.0 {
                    rng.random_range(-init_range..init_range)
                } else {
                    0.0
                }
            })
            .collect();
        Self {
            params,
            w: vec![0.0; (nh + 1) * N],
            v0: v.clone(),
            v,
            baseline: Vector::<N>::zeros(),
            s_hat: Vector::<N>::zeros(),
            delta: vec![0.0; N + 1],
            sigma: vec![0.0; nh + 1],
            grad_v: vec![0.0; nh],
        }
    }

    /// `Ŝ = Ŵᵀ σ(V̂ᵀ δ)` with `δ = [1; psi2]`. Caches `δ`, `σ` and `Ŝ` for [`Self::update`].
    pub fn estimate(&mut self, psi2: &Vector<N>) -> Vector<N> {
        let nh = self.params.hidden;
        self.delta[0] = 1.0;
        for i in 0..N {
            self.delta[i + 1] = psi2[i];
        }
        self.sigma[0] = 1.0;
        for j in 0..nh {
            let mut z = 0.0;
            for (r, d) in self.delta.iter().enumerate() {
                z += self.v[r * nh + j] * d;
            }
            self.sigma[j + 1] = z.tanh();
        }
        let mut s = Vector::<N>::zeros();
        for c in 0..N {
            let mut acc = 0.0;
            for (r, sg) in self.sigma.iter().enumerate() {
                acc += self.w[r * N + c] * sg;
            }
            s[c] = acc;
        }
        self.s_hat = s;
        s
    }

    /// One Euler step of (37) and (38) with the `δ`, `σ`, `Ŝ` of the last estimate and the
    /// current `Ψ2`, then projection. (38) uses `Ŵ` before this step's update of (37). With an
    /// [`UpdateLaw`] other than the default, the step is the modified law's; every term reads
    /// the state before the step.
    pub fn update(&mut self, psi2: &Vector<N>, dt: f64) {
        let NnParams {
            hidden: nh,
            gamma_w,
            gamma_v,
            l1,
            bound_w,
            bound_v,
            law,
        } = self.params;
        let slow = law.innovation_time_constant_s > 0.0;
        // The learning signal: Ψ2 (the paper), or Ψ2 − b.
        let mut e = if slow { psi2 - self.baseline } else { *psi2 };
        if law.dead_zone_rad_s > 0.0 {
            let norm = e.norm();
            e *= if norm > law.dead_zone_rad_s {
                1.0 - law.dead_zone_rad_s / norm
            } else {
                0.0
            };
        }
        // (eᵀ Ŵᵀ σ')_j = (1 − h_j²) Σ_l e_l Ŵ[j+1, l]; σ' = [0ᵀ; diag(1 − h²)].
        for j in 0..nh {
            let h = self.sigma[j + 1];
            let mut acc = 0.0;
            for l in 0..N {
                acc += e[l] * self.w[(j + 1) * N + l];
            }
            self.grad_v[j] = (1.0 - h * h) * acc;
        }
        let kv = dt * gamma_v * l1;
        for (r, d) in self.delta.iter().enumerate() {
            for j in 0..nh {
                self.v[r * nh + j] += kv * d * self.grad_v[j];
            }
        }
        if law.leakage_w_per_s > 0.0 {
            let keep = 1.0 - dt * law.leakage_w_per_s;
            self.w.iter_mut().for_each(|w| *w *= keep);
        }
        let kw = dt * gamma_w * l1;
        for (r, sg) in self.sigma.iter().enumerate() {
            for c in 0..N {
                self.w[r * N + c] += kw * sg * e[c];
            }
        }
        if slow {
            let k = dt / law.innovation_time_constant_s;
            self.baseline += (psi2 + self.s_hat - self.baseline) * k;
        }
        project(&mut self.w, bound_w);
        project(&mut self.v, bound_v);
    }

    /// Every weight is finite. The projection cannot tell: `NaN > bound` is false, so a NaN
    /// passes it; the caller checks this after [`Self::update`] and resets.
    pub fn is_finite(&self) -> bool {
        self.w.iter().chain(&self.v).all(|x| x.is_finite())
    }

    /// Back to the initial weights `Ŵ = 0`, `V̂ = V̂(0)`.
    pub fn reset(&mut self) {
        self.w.iter_mut().for_each(|x| *x = 0.0);
        self.v.copy_from_slice(&self.v0);
        self.delta.iter_mut().for_each(|x| *x = 0.0);
        self.sigma.iter_mut().for_each(|x| *x = 0.0);
        self.baseline = Vector::<N>::zeros();
        self.s_hat = Vector::<N>::zeros();
    }

    /// `Ŵ`, row-major `(n_n+1) × N`; row 0 multiplies the bias unit `σ[0] = 1`.
    pub fn weights_w(&self) -> &[f64] {
        &self.w
    }

    /// `V̂`, row-major `(N+1) × n_n`.
    pub fn weights_v(&self) -> &[f64] {
        &self.v
    }

    /// `‖Ŵ‖_F`.
    pub fn norm_w(&self) -> f64 {
        frobenius(&self.w)
    }

    /// `‖V̂‖_F`.
    pub fn norm_v(&self) -> f64 {
        frobenius(&self.v)
    }
}

fn frobenius(m: &[f64]) -> f64 {
    let norm = m.iter().map(|x| x * x).sum::<f64>().sqrt();
    if norm.is_infinite() && m.iter().all(|x| x.is_finite()) {
        // The squares overflowed although every entry is finite: scale first.
        let scale = m.iter().fold(0.0_f64, |a, x| a.max(x.abs()));
        scale * m.iter().map(|x| (x / scale).powi(2)).sum::<f64>().sqrt()
    } else {
        norm
    }
}

/// Scales `m` back onto the Frobenius ball of radius `bound` if it left it. A non-finite norm
/// is left alone (scaling would spread a NaN or an infinity over every weight): the caller
/// sees it through [`NnEstimator::is_finite`].
fn project(m: &mut [f64], bound: f64) {
    let norm = frobenius(m);
    if norm.is_finite() && norm > bound {
        let k = bound / norm;
        m.iter_mut().for_each(|x| *x *= k);
    }
}

#[cfg(test)]
mod tests;
