//! `[controller]` of a scenario: the gains and choices of the control center's math.

use serde::{Deserialize, Serialize};

use crate::problem::Problem;

use crate::delay::DelayProfile;
use crate::model::{EulerLagrange, ModelConfig, Vector};
use crate::trajectory::TrajectoryConfig;

use super::list::with_controllers;

/// Declares [`ControllerMode`] of the list of controllers.
macro_rules! declare_mode {
    ($($(#[$doc:meta])* $variant:ident = $name:literal => $module:ident :: $ty:ident :: $make:ident;)*) => {
        /// The controller of a scenario (`[controller] mode`): one of the registered ones
        /// (docs/model.md, "Controllers").
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
        pub enum ControllerMode {
            $($(#[$doc])* #[serde(rename = $name)] $variant,)*
        }

        impl ControllerMode {
            /// Every controller, in the order of the list.
            pub const ALL: [Self; [$($name),*].len()] = [$(Self::$variant),*];

            pub fn as_str(self) -> &'static str {
                match self {
                    $(Self::$variant => $name,)*
                }
            }
        }
    };
}
with_controllers!(declare_mode);

impl std::str::FromStr for ControllerMode {
    type Err = String;

    /// A registered controller's name.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|c| c.as_str() == s)
            .ok_or_else(|| {
                let known: Vec<&str> = Self::ALL.iter().map(|c| c.as_str()).collect();
                format!("`{s}` is not a controller: {}", known.join(", "))
            })
    }
}

/// Everything that configures one agent's pipeline ([`crate::scenario::Scenario::center_params`]
/// takes it from a scenario).
#[derive(Debug, Clone)]
pub struct CenterParams {
    pub agent_id: u32,
    pub run_seed: u64,
    pub control_period_s: f64,
    pub controller: ControllerConfig,
    pub model: ModelConfig,
    pub trajectory: TrajectoryConfig,
    pub delay: DelayProfile,
}

impl CenterParams {
    /// The diagonal of `K` in a law `u = K r` of the robot `model`: `k` per joint, or
    /// `k diag(M(q_d(0)))` ([`GainScaling`]).
    pub fn gains<const N: usize>(&self, model: &dyn EulerLagrange<N>) -> Vector<N> {
        let c = &self.controller;
        match c.gain_scaling {
            GainScaling::Unit => Vector::<N>::from_element(c.gain_k),
            GainScaling::Inertia => {
                let q0 = self.trajectory.reference::<N>(0.0).q;
                model.inertia(&q0).diagonal() * c.gain_k
            }
        }
    }
}

/// How the gain `k` of `u = K r̂` (14) becomes the diagonal matrix `K` of an agent.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum GainScaling {
    /// `K = k I`: the paper's (the default).
    #[default]
    Unit,
    /// `K = k diag(M(q_d(0)))`: each joint's gain scaled by its own inertia at the start of
    /// its reference, so that one `k` serves joints whose inertias differ a hundredfold (an
    /// arm's wrist and its shoulder) and arms of different sizes (docs/model.md, "Gains of
    /// other arms").
    Inertia,
}

impl GainScaling {
    pub(crate) fn is_default(&self) -> bool {
        *self == Self::default()
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
    /// The single sample `u(t_k − τ(t_k))` held over the step (the default: it reproduces the
    /// paper's Table I; docs/model.md, "Numerics of the delayed input"). It
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

/// Alarm when `‖Ŝ‖` stays above a threshold for a hold time (beyond the paper: docs/model.md, "Control center", step 9).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DetectionConfig {
    /// Threshold on `‖Ŝ‖` (rad/s, the units of `S = S2 + β S1`).
    pub threshold: f64,
    /// How long `‖Ŝ‖` must stay above the threshold before the alarm is raised, s.
    pub hold_s: f64,
}

/// Gains of the control center (docs/model.md, "Gains (the calibration)").
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
    /// `observer_input`: `"sample"` (default; docs/model.md, "Numerics of the delayed input") or `"step-mean"`, the discretization
    /// of the observer's input `u_τ` ([`ObserverInput`]).
    #[serde(default, skip_serializing_if = "ObserverInput::is_default")]
    pub observer_input: ObserverInput,
    /// `gain_scaling`: `"unit"` (default, `K = k I`, the paper's) or `"inertia"`
    /// (`K = k diag(M(q_d(0)))` per agent, for arms whose joints' inertias differ widely).
    #[serde(default, skip_serializing_if = "GainScaling::is_default")]
    pub gain_scaling: GainScaling,
    /// `[controller.computed_torque]`: the `computed-torque` controller's `omega_n_rad_s` and
    /// `zeta` (used by that controller only).
    #[serde(default, skip_serializing_if = "ComputedTorqueConfig::is_default")]
    pub computed_torque: ComputedTorqueConfig,
    /// `[controller.gated]`: the `gated` controller's `threshold_rad` and `hold_s` (used by
    /// that controller only).
    #[serde(default, skip_serializing_if = "GatedConfig::is_default")]
    pub gated: GatedConfig,
}

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

/// `[controller.computed_torque]`: the closed loop's natural frequency and damping.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct ComputedTorqueConfig {
    /// `ω_n`, rad/s: `K_p = ω_n²`, `K_d = 2 ζ ω_n` (default 20).
    pub omega_n_rad_s: f64,
    /// `ζ`: damping ratio (default 1, critically damped).
    pub zeta: f64,
}

impl Default for ComputedTorqueConfig {
    fn default() -> Self {
        Self {
            omega_n_rad_s: 20.0,
            zeta: 1.0,
        }
    }
}

impl ComputedTorqueConfig {
    pub(crate) fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// Every problem of the values, with field paths below `at`.
    pub fn problems(&self, at: &str) -> Vec<Problem> {
        [("omega_n_rad_s", self.omega_n_rad_s), ("zeta", self.zeta)]
            .into_iter()
            .filter(|(_, v)| !(v.is_finite() && *v > 0.0))
            .map(|(name, v)| Problem {
                path: format!("{at}.{name}"),
                message: format!("must be finite and > 0, got {v}"),
            })
            .collect()
    }
}

/// `[controller.gated]`: the gate's threshold and hold time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct GatedConfig {
    /// The residual `‖y − q̂‖` above which the gate starts to shut, rad (default 0.01).
    pub threshold_rad: f64,
    /// How long the residual must stay above the threshold, s (default 0.01).
    pub hold_s: f64,
}

impl Default for GatedConfig {
    fn default() -> Self {
        Self {
            threshold_rad: 0.01,
            hold_s: 0.01,
        }
    }
}

impl GatedConfig {
    pub(crate) fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// Every problem of the values, with field paths below `at`.
    pub fn problems(&self, at: &str) -> Vec<Problem> {
        let mut out = Vec::new();
        if !(self.threshold_rad.is_finite() && self.threshold_rad > 0.0) {
            out.push(Problem {
                path: format!("{at}.threshold_rad"),
                message: format!("must be finite and > 0, got {}", self.threshold_rad),
            });
        }
        if !(self.hold_s.is_finite() && self.hold_s >= 0.0) {
            out.push(Problem {
                path: format!("{at}.hold_s"),
                message: format!("must be finite and ≥ 0, got {}", self.hold_s),
            });
        }
        out
    }
}
