//! `[controller]` of a scenario: the gains and choices of the control center's math.

use serde::{Deserialize, Serialize};

use super::UpdateLaw;

/// Controller variant (SPEC §4.8).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ControllerMode {
    /// Observer + NN attack estimate `Ŝ` in (12) and (23).
    Proposed,
    /// The paper's baseline: `Ŝ ≡ 0`, weights not updated.
    Traditional,
}

impl ControllerMode {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Proposed => "proposed",
            Self::Traditional => "traditional",
        }
    }
}

/// What the observer (22) takes as its input `u_τ` over its Euler step `[t_k, t_k + Δ]`
/// (docs/model.md, "Numerics of the delayed input").
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum ObserverInput {
    /// The mean of the delayed input `u(s − τ(s))` over the step: the input the plant
    /// integrates over that step.
    StepMean,
    /// The single sample `u(t_k − τ(t_k))` held over the step (SPEC §4.6 as written; the
    /// numerics of the SPEC's prototype; the default: it reproduces the paper's Table I). It
    /// lags the plant's input by about half a period.
    #[default]
    Sample,
}

impl ObserverInput {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::StepMean => "step-mean",
            Self::Sample => "sample",
        }
    }

    pub(crate) fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// Every choice, in the order of the documentation.
    pub const ALL: [Self; 2] = [Self::Sample, Self::StepMean];
}

impl std::str::FromStr for ObserverInput {
    type Err = String;

    /// The names of a scenario file: `sample` or `step-mean`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|c| c.as_str() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Self::ALL.iter().map(|c| c.as_str()).collect();
                format!("`{s}` is not an observer input: {}", names.join(" or "))
            })
    }
}

/// Alarm when `‖Ŝ‖` stays above a threshold for a hold time (beyond the paper, SPEC §4.9).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DetectionConfig {
    /// Threshold on `‖Ŝ‖` (rad/s, the units of `S = S2 + β S1`).
    pub threshold: f64,
    /// How long `‖Ŝ‖` must stay above the threshold before the alarm is raised, s.
    pub hold_s: f64,
}

/// Gains of the control center (SPEC §4, calibration there).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ControllerConfig {
    /// `"proposed"` (observer and NN attack estimate) or `"traditional"` (the baseline).
    pub mode: ControllerMode,
    /// `k` of `u = k r̂` (14), typical 21.
    pub gain_k: f64,
    /// `β` of (7), (12), (23), 1/s; typical 30.
    pub beta: f64,
    /// Observer gain `L1` of (22), typical 0.01.
    pub observer_gain_l1: f64,
    /// Observer gain `L2` of (22), typical 0.012.
    pub observer_gain_l2: f64,
    /// Hidden neurons `n_n` of the NN (32), typical 3.
    pub hidden_neurons: usize,
    /// `Γ1 = value · I` of (37), typical 5000.
    pub learning_rate_w: f64,
    /// `Γ2 = value · I` of (38), typical 10.
    pub learning_rate_v: f64,
    /// Frobenius-ball radius `W̄` of the projection of `Ŵ`, typical 50.
    pub weight_bound_w: f64,
    /// Frobenius-ball radius `V̄` of the projection of `V̂`, typical 50.
    pub weight_bound_v: f64,
    /// `V̂(0) ~ U(−a, a)` elementwise, typical 1.
    pub initial_v_range: f64,
    /// The alarm on `‖Ŝ‖`: `{ threshold, hold_s }`.
    pub detection: DetectionConfig,
    /// `[controller.update_law]`: robust modifications of (37), (38) for long horizons (a slow
    /// innovation baseline, leakage of `Ŵ`; units and typical values at [`UpdateLaw`]). Absent
    /// or all 0: the paper's laws.
    #[serde(default, skip_serializing_if = "UpdateLaw::is_paper")]
    pub update_law: UpdateLaw,
    /// `observer_input`: `"sample"` (default, SPEC §4.6) or `"step-mean"`, the discretization
    /// of the observer's input `u_τ` ([`ObserverInput`]).
    #[serde(default, skip_serializing_if = "ObserverInput::is_default")]
    pub observer_input: ObserverInput,
}
