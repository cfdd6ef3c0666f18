//! `[detectors]` of a scenario: the parameters of the classical detectors (docs/detectors.md).
//! Optional: without the table every detector runs with the defaults below.

use serde::{Deserialize, Serialize};

use crate::problem::Problem;

/// Default length of the calibration window, s.
pub const DEFAULT_CALIBRATION_S: f64 = 2.0;
/// A calibration needs at least this many residuals per residual dimension.
pub const MIN_SAMPLES_PER_DIMENSION: u64 = 10;
/// Largest χ² window, ticks (the window sum is recomputed every tick).
pub const MAX_WINDOW_TICKS: usize = 1000;

/// Which residual the χ² and CUSUM detectors test.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum ResidualKind {
    /// The observer's innovation, `2N` entries: `[y_k − q̂_k⁻, ẏ_k − q̂̇_k⁻]`, the tampered
    /// measurement the center received minus the observer's prediction of it (its state after
    /// the previous tick's step). Dominated by the observer's model mismatch, it outgrows its
    /// calibration within seconds, attack or not (docs/detectors.md).
    Innovation,
    /// The observer's `Ψ2` (23), `N` entries: `ẏ_k + β y_k − q̂̇_k⁻ − β q̂_k⁻ − Ŝ_k`, the innovation
    /// left after the NN's attack estimate. The default: near white at the noise floor without
    /// attack, so the detectors' thresholds mean what they say (docs/detectors.md).
    #[default]
    Psi2,
}

impl std::str::FromStr for ResidualKind {
    type Err = String;

    /// The names of a scenario file: `innovation` or `psi2`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|c| c.as_str() == s)
            .ok_or_else(|| format!("`{s}` is not a residual: innovation or psi2"))
    }
}

impl ResidualKind {
    /// Every residual, in the order of the docs.
    pub const ALL: [Self; 2] = [Self::Innovation, Self::Psi2];

    pub fn as_str(self) -> &'static str {
        match self {
            Self::Innovation => "innovation",
            Self::Psi2 => "psi2",
        }
    }

    /// Number of entries of the residual for a robot of `links` links.
    pub fn dimension(self, links: usize) -> usize {
        match self {
            Self::Innovation => 2 * links,
            Self::Psi2 => links,
        }
    }
}

/// `[detectors.chi2]`: `χ²_k = Σ over the last w ticks of rᵀ Σ⁻¹ r`, alarm while it exceeds the
/// threshold.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Chi2Config {
    /// `w`, ticks summed (1: the per-tick test).
    pub window_ticks: usize,
    /// Per-tick false-alarm probability under the null hypothesis (a white Gaussian residual
    /// of the calibrated covariance); the threshold is the χ² quantile with `dim · w` degrees
    /// of freedom at this upper-tail probability. Ignored when `threshold` is set.
    pub false_alarm_probability: f64,
    /// The threshold itself, instead of the quantile.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub threshold: Option<f64>,
}

impl Default for Chi2Config {
    fn default() -> Self {
        Self {
            window_ticks: 1,
            false_alarm_probability: 1e-6,
            threshold: None,
        }
    }
}

/// `[detectors.cusum]`: a two-sided CUSUM on each entry `z_i` of the whitened residual
/// `z = L⁻¹ r` (`L Lᵀ = Σ`): `S⁺ = max(0, S⁺ + z_i − drift)`, `S⁻ = max(0, S⁻ − z_i − drift)`,
/// each capped at `2 h`; alarm while any `S > h`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct CusumConfig {
    /// `drift` (ν), in standard deviations of the whitened residual: half the smallest shift
    /// to detect quickly.
    pub drift: f64,
    /// `h`, in standard deviations.
    pub threshold: f64,
}

impl Default for CusumConfig {
    fn default() -> Self {
        Self {
            drift: 0.5,
            threshold: 15.0,
        }
    }
}

/// The detectors of a run (`[detectors]`, optional).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct DetectorsConfig {
    /// Length of the calibration window at the start of the run, s: the residual's covariance
    /// is estimated over it, and the χ² and CUSUM detectors are silent during it. Absent:
    /// [`DEFAULT_CALIBRATION_S`], and a run shorter than that reports its detectors as not
    /// calibrated instead of being refused.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration_s: Option<f64>,
    /// The residual tested: `"psi2"` (default) or `"innovation"`.
    pub residual: ResidualKind,
    /// Ridge added to the calibrated covariance: `Σ + ε · (tr Σ / dim) · I`, ε this value
    /// (default 1e-6). Keeps a singular `Σ` (a channel without noise) invertible; 0 turns it
    /// off, and a singular `Σ` then fails the calibration.
    pub regularization: f64,
    /// `[detectors.chi2]`: the χ² test.
    pub chi2: Chi2Config,
    /// `[detectors.cusum]`: the CUSUM.
    pub cusum: CusumConfig,
}

impl Default for DetectorsConfig {
    fn default() -> Self {
        Self::defaults()
    }
}

impl DetectorsConfig {
    /// The default configuration: what a scenario without `[detectors]` runs.
    pub fn defaults() -> Self {
        Self {
            calibration_s: None,
            residual: ResidualKind::default(),
            regularization: 1e-6,
            chi2: Chi2Config::default(),
            cusum: CusumConfig::default(),
        }
    }

    /// True for [`Self::defaults`] (the scenario then leaves the table out when written).
    pub fn is_default(&self) -> bool {
        *self == Self::defaults()
    }

    /// The calibration window, s.
    pub fn calibration_s(&self) -> f64 {
        self.calibration_s.unwrap_or(DEFAULT_CALIBRATION_S)
    }

    /// Ticks of the calibration window: the ticks `k < round(calibration_s / Δ)`.
    pub fn calibration_ticks(&self, control_period_s: f64) -> u64 {
        let n = (self.calibration_s() / control_period_s).round();
        if n.is_finite() && n >= 0.0 {
            n as u64
        } else {
            0
        }
    }

    /// Every problem of the values, with field paths under `at` (`detectors`). `links`: the
    /// robots' number of links (`None` when the scenario has no agents).
    pub fn problems(
        &self,
        at: &str,
        duration_s: f64,
        control_period_s: f64,
        links: Option<usize>,
    ) -> Vec<Problem> {
        let mut out = Vec::new();
        let mut push = |name: &str, message: String| {
            out.push(Problem {
                path: format!("{at}.{name}"),
                message,
            })
        };
        if let Some(c) = self.calibration_s {
            if !(c.is_finite() && c > 0.0) {
                push("calibration_s", format!("must be finite and > 0, got {c}"));
            } else if duration_s.is_finite() && c >= duration_s {
                push(
                    "calibration_s",
                    format!("the calibration window ({c} s) must end before the run does (duration_s = {duration_s} s): the detectors would never watch"),
                );
            } else if let Some(links) = links {
                let dim = self.residual.dimension(links) as u64;
                let need = MIN_SAMPLES_PER_DIMENSION * dim + 1;
                if control_period_s > 0.0 && self.calibration_ticks(control_period_s) < need {
                    push(
                        "calibration_s",
                        format!("{c} s holds fewer than {need} control periods: the covariance of a {dim}-entry residual needs at least {MIN_SAMPLES_PER_DIMENSION} residuals per entry"),
                    );
                }
            }
        }
        let eps = self.regularization;
        if !(eps.is_finite() && (0.0..=1.0).contains(&eps)) {
            push(
                "regularization",
                format!("must be finite and in [0, 1], got {eps}"),
            );
        }
        let w = self.chi2.window_ticks;
        if !(1..=MAX_WINDOW_TICKS).contains(&w) {
            push(
                "chi2.window_ticks",
                format!("must be in 1..={MAX_WINDOW_TICKS}, got {w}"),
            );
        }
        let p = self.chi2.false_alarm_probability;
        if !(p.is_finite() && p > 0.0 && p < 1.0) {
            push(
                "chi2.false_alarm_probability",
                format!("must be in (0, 1), got {p}"),
            );
        }
        if let Some(t) = self.chi2.threshold {
            if !(t.is_finite() && t > 0.0) {
                push("chi2.threshold", format!("must be finite and > 0, got {t}"));
            }
        }
        let (nu, h) = (self.cusum.drift, self.cusum.threshold);
        if !(nu.is_finite() && nu >= 0.0) {
            push("cusum.drift", format!("must be finite and ≥ 0, got {nu}"));
        }
        if !(h.is_finite() && h > 0.0) {
            push(
                "cusum.threshold",
                format!("must be finite and > 0, got {h}"),
            );
        }
        out
    }
}

#[cfg(test)]
mod tests;
