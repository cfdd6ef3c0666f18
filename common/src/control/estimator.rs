//! Two-layer NN estimate of the attack term `S = S2 + β S1`:
//! `δ = [1; Ψ2]`, `h = tanh(V̂ᵀ δ)`, `σ = [1; h]`, `Ŝ = Ŵᵀ σ` (32), (33), with the update laws
//! (37), (38) integrated by one Euler step per tick and followed by a projection onto a
//! Frobenius ball (a discrete stand-in for the Lipschitz projection of the paper's [47]).
//!
//! Weights are stored row-major in plain vectors sized once at construction: no allocation
//! per tick, and a fixed order of floating-point operations.

use rand::Rng;
use rand_chacha::ChaCha12Rng;

use crate::model::Vector;

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
            delta: vec![0.0; N + 1],
            sigma: vec![0.0; nh + 1],
            grad_v: vec![0.0; nh],
        }
    }

    /// `Ŝ = Ŵᵀ σ(V̂ᵀ δ)` with `δ = [1; psi2]`. Caches `δ` and `σ` for [`Self::update`].
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
        s
    }

    /// One Euler step of (37) and (38) with the `δ`, `σ` of the last estimate and the current
    /// `Ψ2`, then projection. (38) uses `Ŵ` before this step's update of (37).
    pub fn update(&mut self, psi2: &Vector<N>, dt: f64) {
        let NnParams {
            hidden: nh,
            gamma_w,
            gamma_v,
            l1,
            bound_w,
            bound_v,
        } = self.params;
        // (Ψ2ᵀ Ŵᵀ σ')_j = (1 − h_j²) Σ_l Ψ2_l Ŵ[j+1, l]; σ' = [0ᵀ; diag(1 − h²)].
        for j in 0..nh {
            let h = self.sigma[j + 1];
            let mut acc = 0.0;
            for l in 0..N {
                acc += psi2[l] * self.w[(j + 1) * N + l];
            }
            self.grad_v[j] = (1.0 - h * h) * acc;
        }
        let kv = dt * gamma_v * l1;
        for (r, d) in self.delta.iter().enumerate() {
            for j in 0..nh {
                self.v[r * nh + j] += kv * d * self.grad_v[j];
            }
        }
        let kw = dt * gamma_w * l1;
        for (r, sg) in self.sigma.iter().enumerate() {
            for c in 0..N {
                self.w[r * N + c] += kw * sg * psi2[c];
            }
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
mod tests {
    use super::*;
    use crate::rng::{stream, Purpose};

    fn params() -> NnParams {
        NnParams {
            hidden: 3,
            gamma_w: 5000.0,
            gamma_v: 10.0,
            l1: 0.01,
            bound_w: 50.0,
            bound_v: 50.0,
        }
    }

    #[test]
    fn projection_keeps_weights_in_their_balls_under_adversarial_input() {
        let mut nn = NnEstimator::<2>::new(params(), 1.0, &mut stream(3, 1, Purpose::NnInit));
        // Huge, sign-alternating, occasionally enormous Ψ2: the raw Euler step would blow up.
        for k in 0..5000 {
            let s = if k % 2 == 0 { 1.0 } else { -1.0 };
            let mag = if k % 97 == 0 { 1e12 } else { 1e3 };
            let psi2 = Vector::<2>::new(s * mag, -s * mag * 0.5);
            let _ = nn.estimate(&psi2);
            nn.update(&psi2, 1e-3);
            assert!(nn.norm_w() <= 50.0 * (1.0 + 1e-12), "‖Ŵ‖ = {}", nn.norm_w());
            assert!(nn.norm_v() <= 50.0 * (1.0 + 1e-12), "‖V̂‖ = {}", nn.norm_v());
        }
    }

    #[test]
    fn converges_to_a_constant_attack_in_the_error_loop() {
        // Closed error loop of the estimator alone: Ψ2 = S − Ŝ (observer error r̃ = 0). With
        // Γ1 L1 = 50 1/s the bias weight follows S with a time constant of about 20 ms, so
        // after 0.5 s the estimate must be within 1 % of S.
        let mut nn = NnEstimator::<2>::new(params(), 1.0, &mut stream(1, 1, Purpose::NnInit));
        let s = Vector::<2>::new(0.3, -0.12);
        let mut psi2 = Vector::<2>::zeros();
        let mut s_hat = Vector::<2>::zeros();
        for _ in 0..500 {
            s_hat = nn.estimate(&psi2);
            psi2 = s - s_hat;
            nn.update(&psi2, 1e-3);
        }
        assert!(
            (s_hat - s).norm() < 0.01 * s.norm(),
            "Ŝ = {s_hat:?}, S = {s:?}"
        );
    }

    /// Regression: a NaN passed the projection (`NaN > bound` is false) and stayed in the
    /// weights for good.
    #[test]
    fn a_nan_reaching_the_weights_is_seen_and_a_reset_restores_the_initial_estimator() {
        let mut nn = NnEstimator::<2>::new(params(), 1.0, &mut stream(1, 1, Purpose::NnInit));
        let fresh = nn.clone();
        let psi2 = Vector::<2>::new(0.2, -0.1);
        for _ in 0..10 {
            let _ = nn.estimate(&psi2);
            nn.update(&psi2, 1e-3);
        }
        assert!(nn.is_finite());
        let nan = Vector::<2>::new(f64::NAN, 0.0);
        let _ = nn.estimate(&nan);
        nn.update(&nan, 1e-3);
        assert!(!nn.is_finite(), "a NaN Ψ2 must show in the weights' check");
        nn.reset();
        assert!(nn.is_finite());
        assert_eq!(nn.w, fresh.w);
        assert_eq!(nn.v, fresh.v);
        assert_eq!(nn.estimate(&psi2), Vector::<2>::zeros());
    }

    #[test]
    fn projection_handles_weights_whose_squares_overflow() {
        let mut m = vec![1e200, -1e200, 3e199];
        project(&mut m, 50.0);
        assert!(m.iter().all(|x| x.is_finite()));
        assert!((frobenius(&m) - 50.0).abs() < 1e-9, "{m:?}");
    }

    #[test]
    fn starts_with_zero_estimate() {
        let mut nn = NnEstimator::<2>::new(params(), 1.0, &mut stream(1, 1, Purpose::NnInit));
        assert_eq!(
            nn.estimate(&Vector::<2>::new(0.5, 0.5)),
            Vector::<2>::zeros()
        );
    }
}
