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
use serde::{Deserialize, Serialize};

use crate::model::Vector;
use crate::problem::Problem;
use crate::scenario::ControllerConfig;

/// Robust modifications of the update laws (37), (38) (beyond the paper): the scenario's
/// `[controller.update_law]`. Every field defaults to 0, which is the paper's law, bit for bit.
///
/// With `T = innovation_time_constant_s` and `λ = leakage_w_per_s`, the estimator learns from
/// `Ψ2 − b` instead of `Ψ2`, where `b` is the part of the innovation `Ψ2 + Ŝ` (what the observer
/// cannot explain) older than about `T`:
/// `ḃ = (Ψ2 + Ŝ − b) / T`, `b(0) = 0` (`b ≡ 0` when `T = 0`),
/// `Ŵ̇ = Γ1 L1 σ (Ψ2 − b)ᵀ − λ Ŵ` ((37) with σ-modification) and
/// `V̂̇ = Γ2 L1 δ ((Ψ2 − b)ᵀ Ŵᵀ σ')` ((38)).
/// `T > 0` makes `Ŝ` forget a persistent innovation over `T` instead of absorbing it for ever
/// (docs/model.md, "Long horizons"); `λ > 0` bounds `Ŵ` under a persistent bias.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct UpdateLaw {
    /// `T`, s: time over which a persistent innovation is attributed to model mismatch rather
    /// than to an attack. 0 = off (the paper). Typical 20–120 s (the shipped
    /// `paper-long-horizon.toml`: 120 s); must be 0 or ≥ the control period.
    pub innovation_time_constant_s: f64,
    /// `λ`, 1/s: leakage rate of `Ŵ` towards 0. In steady state a constant `S` is then
    /// compensated to `1 / (1 + λ / (Γ1 L1))` of its value (`Γ1 L1 = 50 1/s` in the
    /// calibration). 0 = off (the paper). Typical 5–20 1/s (`paper-long-horizon.toml`: 20);
    /// `λ Δ` must stay below 1.
    pub leakage_w_per_s: f64,
    /// `ε`, rad/s: dead zone on the learning signal. The laws learn from
    /// `e · max(0, 1 − ε/‖e‖)` (`e = Ψ2`, or `Ψ2 − b`): nothing while `‖e‖ ≤ ε`, only the part
    /// beyond ε otherwise (continuous in e). An innovation smaller than ε is left to the
    /// measurement feedback instead of being absorbed by `Ŝ`. 0 = off (the paper). The sensor
    /// noise puts `‖Ψ2‖` at ~0.0045 rad/s RMS in the calibration; ε must be finite and ≥ 0.
    pub dead_zone_rad_s: f64,
}

impl UpdateLaw {
    /// All modifications off: the paper's (37), (38).
    pub fn is_paper(&self) -> bool {
        *self == Self::default()
    }

    /// Every problem of the values, with field paths below `at`, for a control period
    /// `control_period_s` (s).
    pub fn problems(&self, at: &str, control_period_s: f64) -> Vec<Problem> {
        let mut out = Vec::new();
        let mut push = |name: &str, message: String| {
            out.push(Problem {
                path: format!("{at}.{name}"),
                message,
            })
        };
        let (t, l) = (self.innovation_time_constant_s, self.leakage_w_per_s);
        for (name, v) in [
            ("innovation_time_constant_s", t),
            ("leakage_w_per_s", l),
            ("dead_zone_rad_s", self.dead_zone_rad_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                push(name, format!("must be finite and ≥ 0, got {v}"));
            }
        }
        if t > 0.0 && t < control_period_s {
            push(
                "innovation_time_constant_s",
                format!("must be 0 (off) or ≥ control_period_s ({control_period_s} s), got {t}"),
            );
        }
        if l.is_finite() && l * control_period_s >= 1.0 {
            push(
                "leakage_w_per_s",
                format!("leakage_w_per_s × control_period_s must stay below 1 (one Euler step must not overshoot zero), got {l} × {control_period_s}"),
            );
        }
        out
    }
}

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
            law: UpdateLaw::default(),
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

    /// The paper's (37), (38) as SPEC §4.7 states them, written out independently of
    /// [`NnEstimator::update`] (same order of operations): Euler step of `V̂` with the old `Ŵ`,
    /// then of `Ŵ`, then projection.
    fn paper_step(nn: &NnEstimator<2>, w: &mut [f64], v: &mut [f64], psi2: &Vector<2>, dt: f64) {
        let p = params();
        let nh = p.hidden;
        let mut g = vec![0.0; nh];
        for (j, gj) in g.iter_mut().enumerate() {
            let h = nn.sigma[j + 1];
            let acc = psi2[0] * w[(j + 1) * 2] + psi2[1] * w[(j + 1) * 2 + 1];
            *gj = (1.0 - h * h) * acc;
        }
        for (r, d) in nn.delta.iter().enumerate() {
            for j in 0..nh {
                v[r * nh + j] += dt * p.gamma_v * p.l1 * d * g[j];
            }
        }
        for (r, sg) in nn.sigma.iter().enumerate() {
            for c in 0..2 {
                w[r * 2 + c] += dt * p.gamma_w * p.l1 * sg * psi2[c];
            }
        }
        project(w, p.bound_w);
        project(v, p.bound_v);
    }

    /// A deterministic, sign-changing `Ψ2` with occasional large values (reaching the
    /// projection), rad/s.
    fn psi2_at(k: u32) -> Vector<2> {
        let t = f64::from(k) * 1e-3;
        let big = if k.is_multiple_of(401) { 40.0 } else { 1.0 };
        Vector::<2>::new(0.3 * (7.0 * t).sin() * big, -0.2 * (3.0 * t).cos() + 0.05)
    }

    #[test]
    fn with_every_modification_off_the_update_is_the_papers_bit_for_bit() {
        // The default UpdateLaw must leave the paper's law untouched: every weight equal to
        // the written-out (37), (38) to the last bit (assert_eq on f64, no tolerance), over
        // steps that also reach the projection.
        assert!(params().law.is_paper());
        let mut nn = NnEstimator::<2>::new(params(), 1.0, &mut stream(5, 2, Purpose::NnInit));
        let (mut w, mut v) = (nn.w.clone(), nn.v.clone());
        let mut psi2_prev = Vector::<2>::zeros();
        for k in 0..20_000 {
            let psi2 = psi2_at(k);
            let _ = nn.estimate(&psi2_prev);
            paper_step(&nn, &mut w, &mut v, &psi2, 1e-3);
            nn.update(&psi2, 1e-3);
            assert_eq!(nn.weights_w(), &w[..], "Ŵ differs at step {k}");
            assert_eq!(nn.weights_v(), &v[..], "V̂ differs at step {k}");
            psi2_prev = psi2;
        }
        assert!(nn.norm_w() > 1.0, "the sequence must move the weights");
    }

    #[test]
    fn each_modification_changes_the_update_when_on() {
        // Guards the test above against a law that ignores its fields.
        for law in [
            UpdateLaw {
                innovation_time_constant_s: 1.0,
                ..UpdateLaw::default()
            },
            UpdateLaw {
                leakage_w_per_s: 1.0,
                ..UpdateLaw::default()
            },
            UpdateLaw {
                dead_zone_rad_s: 0.01,
                ..UpdateLaw::default()
            },
        ] {
            let mk = |law| {
                let p = NnParams { law, ..params() };
                NnEstimator::<2>::new(p, 1.0, &mut stream(5, 2, Purpose::NnInit))
            };
            let (mut paper, mut modified) = (mk(UpdateLaw::default()), mk(law));
            for k in 0..100 {
                let psi2 = psi2_at(k);
                let _ = (paper.estimate(&psi2), modified.estimate(&psi2));
                paper.update(&psi2, 1e-3);
                modified.update(&psi2, 1e-3);
            }
            assert_ne!(paper.weights_w(), modified.weights_w(), "{law:?}");
        }
    }

    #[test]
    fn leakage_bounds_the_weights_under_a_persistent_bias() {
        // Open loop: Ψ2 stuck at a bias b (a mismatch the estimate never removes). The paper's
        // law integrates it until the projection stops it at W̄; with leakage λ every entry
        // settles at Γ1 L1 σ_r b_c / λ, so ‖Ŵ‖_F ≤ Γ1 L1 ‖σ‖ ‖b‖ / λ ≤ Γ1 L1 √(n_n+1) ‖b‖ / λ
        // (|σ_r| ≤ 1). The discrete leak has the same fixed point; 1e-9 relative covers the
        // rounding of 10⁵ steps.
        let b = Vector::<2>::new(0.05, -0.02);
        let lambda = 10.0;
        let run = |law| {
            let p = NnParams { law, ..params() };
            let mut nn = NnEstimator::<2>::new(p, 1.0, &mut stream(9, 1, Purpose::NnInit));
            let mut max_norm: f64 = 0.0;
            for _ in 0..100_000 {
                let _ = nn.estimate(&b);
                nn.update(&b, 1e-3);
                max_norm = max_norm.max(nn.norm_w());
            }
            (nn.norm_w(), max_norm)
        };
        let (paper_end, _) = run(UpdateLaw::default());
        assert!(
            paper_end > 0.99 * params().bound_w,
            "the paper's law must drift to the projection bound, got ‖Ŵ‖ = {paper_end}"
        );
        let leaky = UpdateLaw {
            leakage_w_per_s: lambda,
            ..UpdateLaw::default()
        };
        let (_, leaky_max) = run(leaky);
        let p = params();
        let bound = p.gamma_w * p.l1 * ((p.hidden + 1) as f64).sqrt() * b.norm() / lambda;
        assert!(
            leaky_max <= bound * (1.0 + 1e-9),
            "‖Ŵ‖ reached {leaky_max}, bound {bound}"
        );
        assert!(
            bound < 0.2 * p.bound_w,
            "the bound must be below the projection's"
        );
    }

    #[test]
    fn a_persistent_innovation_fades_over_the_time_constant() {
        // Estimator-only error loop as above (Ψ2 = S − Ŝ), S constant. The paper's law keeps
        // Ŝ = S for ever. With T = 2 s, Ŝ ≈ (e^{−t/T} − e^{−Γ1 L1 t}) S: within 10 % of S after
        // 0.2 s (e^{−0.1} = 0.90, minus a 1 % lag of the fast pole), and below 2 % of S after
        // 10 s = 5 T (e^{−5} = 0.7 %, with margin for the discretization).
        let s = Vector::<2>::new(0.3, -0.12);
        let run = |law, steps| {
            let p = NnParams { law, ..params() };
            let mut nn = NnEstimator::<2>::new(p, 1.0, &mut stream(1, 1, Purpose::NnInit));
            let (mut psi2, mut s_hat) = (Vector::<2>::zeros(), Vector::<2>::zeros());
            for _ in 0..steps {
                s_hat = nn.estimate(&psi2);
                psi2 = s - s_hat;
                nn.update(&psi2, 1e-3);
            }
            s_hat
        };
        let paper = run(UpdateLaw::default(), 10_000);
        assert!((paper - s).norm() < 0.01 * s.norm(), "paper: Ŝ = {paper:?}");
        let law = UpdateLaw {
            innovation_time_constant_s: 2.0,
            ..UpdateLaw::default()
        };
        let early = run(law, 200);
        assert!(
            (early - s).norm() < 0.12 * s.norm(),
            "after 0.2 s: Ŝ = {early:?}"
        );
        let late = run(law, 10_000);
        assert!(late.norm() < 0.02 * s.norm(), "after 10 s: Ŝ = {late:?}");
    }

    #[test]
    fn invalid_update_law_values_are_reported_with_their_field_paths() {
        let bad = UpdateLaw {
            innovation_time_constant_s: 1e-4,
            leakage_w_per_s: f64::NAN,
            dead_zone_rad_s: -0.01,
        };
        let problems = bad.problems("controller.update_law", 1e-3);
        let paths: Vec<&str> = problems.iter().map(|p| p.path.as_str()).collect();
        assert_eq!(
            paths,
            [
                "controller.update_law.leakage_w_per_s",
                "controller.update_law.dead_zone_rad_s",
                "controller.update_law.innovation_time_constant_s"
            ],
            "{problems:?}"
        );
        let too_leaky = UpdateLaw {
            leakage_w_per_s: 1000.0,
            ..UpdateLaw::default()
        };
        assert_eq!(too_leaky.problems("u", 1e-3).len(), 1);
        assert!(UpdateLaw::default().problems("u", 1e-3).is_empty());
        let negative = UpdateLaw {
            innovation_time_constant_s: -1.0,
            ..UpdateLaw::default()
        };
        assert_eq!(negative.problems("u", 1e-3).len(), 1);
    }

    #[test]
    fn the_dead_zone_ignores_a_small_innovation_and_learns_only_the_part_beyond_it() {
        // Estimator-only error loop (Ψ2 = S − Ŝ), S constant. Below the dead zone ε the weights
        // never move; above it, Ŝ converges until ‖S − Ŝ‖ = ε, along S (the learning signal is
        // e (1 − ε/‖e‖), parallel to e).
        let eps = 0.02;
        let law = UpdateLaw {
            dead_zone_rad_s: eps,
            ..UpdateLaw::default()
        };
        let run = |s: Vector<2>| {
            let p = NnParams { law, ..params() };
            let mut nn = NnEstimator::<2>::new(p, 1.0, &mut stream(3, 1, Purpose::NnInit));
            let (mut psi2, mut s_hat) = (Vector::<2>::zeros(), Vector::<2>::zeros());
            for _ in 0..10_000 {
                s_hat = nn.estimate(&psi2);
                psi2 = s - s_hat;
                nn.update(&psi2, 1e-3);
            }
            (s_hat, nn.norm_w())
        };
        let small = Vector::<2>::new(0.012, -0.015); // ‖·‖ = 0.0192 < ε
        let (s_hat, w) = run(small);
        assert_eq!((s_hat, w), (Vector::<2>::zeros(), 0.0));
        let large = Vector::<2>::new(0.3, -0.12);
        let (s_hat, _) = run(large);
        let residual = (large - s_hat).norm();
        assert!(
            (residual - eps).abs() < 1e-3 * eps,
            "‖S − Ŝ‖ = {residual}, ε = {eps}"
        );
        let along = (large - s_hat).normalize().dot(&large.normalize());
        assert!(along > 1.0 - 1e-6, "residual not along S: cos = {along}");
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
