//! Attack waveforms: pure functions of time (and, for noise, of a seeded stream). A new waveform
//! is one file here and one variant of [`Waveform`].
//!
//! Periodic waveforms (sine, pulse) use absolute time `t`, as the paper's profiles do
//! (`−sin 2t` for `t ≥ 25`); the ramp uses the time since its segment began.

mod constant;
mod corrupt;
mod noise;
mod pulse;
mod ramp;
pub mod replay;
mod sine;
pub mod stealthy;
pub mod transform;

use rand_chacha::ChaCha12Rng;
use serde::{Deserialize, Serialize};

pub use corrupt::CorruptValue;

/// One segment's waveform. Values are in the channel's units (rad or deg for positions, rad/s
/// or deg/s for velocities).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Waveform {
    /// Pure relay: nothing injected.
    None,
    /// `value`.
    Constant {
        /// The injected value, channel units.
        value: f64,
    },
    /// `amplitude · sin(omega t + phase) + offset`.
    Sine {
        /// Channel units.
        amplitude: f64,
        /// Angular frequency, rad/s.
        omega_rad_s: f64,
        /// Phase, rad (default 0).
        #[serde(default)]
        phase_rad: f64,
        /// Added constant, channel units (default 0).
        #[serde(default)]
        offset: f64,
    },
    /// `amplitude` during the first `width_percent` % of every `period_s`, zero otherwise,
    /// starting at `delay_s` (the paper's `pulse(a, b, c)`).
    Pulse {
        /// Height of the pulses, channel units.
        amplitude: f64,
        /// Period, s (> 0).
        period_s: f64,
        /// Share of every period the pulse is on, % (0–100).
        width_percent: f64,
        /// Time of the first pulse, s (default 0).
        #[serde(default)]
        delay_s: f64,
    },
    /// `start + slope · (t − segment start)`.
    Ramp {
        /// Channel units per second.
        slope_per_s: f64,
        /// Value at the segment's start, channel units (default 0).
        #[serde(default)]
        start: f64,
    },
    /// Gaussian noise `N(mean, std²)`, one draw per tick from the attacker's seeded stream.
    Gaussian {
        /// Standard deviation, channel units (≥ 0).
        std: f64,
        /// Mean, channel units (default 0).
        #[serde(default)]
        mean: f64,
    },
    /// Fault injection: `value` as is, NaN, ±∞ or absurdly large (`{ kind = "corrupt", value =
    /// "nan" }`, `"inf"`, `"-inf"` or a number such as `1e300`). The only waveform exempt from the
    /// finiteness check; the control center must reject what it produces (docs/model.md, "Control center", step 10).
    Corrupt {
        /// A number, or "nan", "inf", "+inf", "-inf".
        value: CorruptValue,
    },
    /// Replay attack: the clean signal recorded over `[record_from_s, record_from_s +
    /// record_for_s)` is played back in a loop from the segment's start, in place of the live
    /// one. Evaluated by the compiled channel, which holds the recording
    /// ([`crate::attack::AgentAttack::observe`]); the segment must start at or after the end of
    /// the recording window.
    Replay {
        /// Start of the recording window, s.
        record_from_s: f64,
        /// Length of the recording window, s (> 0).
        record_for_s: f64,
    },
    /// Multiplicative attack: the center sees `factor ·` the clean signal
    /// ([`transform::scale`]). Dimensionless: the channel's `units` do not apply.
    Scale {
        /// The multiplier of the clean signal (dimensionless).
        factor: f64,
    },
    /// The center sees the clean signal with its sign flipped ([`transform::sign_flip`]).
    SignFlip,
    /// Stuck-at: the center sees the clean value of the segment's first tick for the whole
    /// segment ([`transform::freeze`]).
    Freeze,
    /// Stealthy bias (docs/stealthy.md): from zero at the segment's start it grows at the
    /// fastest slope that keeps a χ² test on the observer's residual under its threshold,
    /// `slope = residual_std · (√threshold − √noise_peak) / (sensitivity · √(window_ticks ·
    /// shifted_entries))` ([`stealthy::slope`]), until it reaches `bias`, then holds.
    /// `threshold`, `window_ticks`: the χ² detector's (white-box attacker); `noise_peak`: the
    /// level its attack-free statistic stays under; `shifted_entries`: the residual entries the
    /// bias moves (the channel's links); `residual_std`: the residual's attack-free standard
    /// deviation per entry; `sensitivity`: its steady offset per unit slope of the bias
    /// (residual units per channel unit per s); `bias`: the level held, channel units.
    StealthyBias {
        /// The χ² detector's threshold.
        threshold: f64,
        /// The level the attack-free χ² statistic stays under.
        noise_peak: f64,
        /// The χ² detector's window, ticks (default 1).
        #[serde(default = "stealthy::one_tick")]
        window_ticks: u32,
        /// Residual entries the bias moves (the channel's links).
        shifted_entries: u32,
        /// The residual's attack-free standard deviation per entry.
        residual_std: f64,
        /// The residual's steady offset per unit slope of the bias (residual units per channel unit per s).
        sensitivity: f64,
        /// The level held, channel units.
        bias: f64,
    },
}

impl Waveform {
    /// Value at absolute time `t` in a segment that began at `segment_start`. `replay` and the
    /// transforms ([`Self::transforms`]) depend on the clean signal, not on time alone: the
    /// compiled channel evaluates them, and this function gives 0 for them.
    pub fn value(&self, t: f64, segment_start: f64, rng: &mut ChaCha12Rng) -> f64 {
        match *self {
            Self::None => 0.0,
            Self::Constant { value } => constant::value(value),
            Self::Sine {
                amplitude,
                omega_rad_s,
                phase_rad,
                offset,
            } => sine::value(t, amplitude, omega_rad_s, phase_rad, offset),
            Self::Pulse {
                amplitude,
                period_s,
                width_percent,
                delay_s,
            } => pulse::value(t, amplitude, period_s, width_percent, delay_s),
            Self::Ramp { slope_per_s, start } => ramp::value(t - segment_start, slope_per_s, start),
            Self::Gaussian { std, mean } => noise::value(rng, mean, std),
            Self::Corrupt { value } => corrupt::value(value),
            Self::StealthyBias { bias, .. } => stealthy::value(
                t - segment_start,
                self.stealthy_slope().unwrap_or(0.0),
                bias,
            ),
            Self::Replay { .. } | Self::Scale { .. } | Self::SignFlip | Self::Freeze => 0.0,
        }
    }

    /// The slope of a `stealthy-bias`, derived from its design ([`stealthy::slope`]); `None`
    /// for the other waveforms.
    pub fn stealthy_slope(&self) -> Option<f64> {
        match *self {
            Self::StealthyBias {
                threshold,
                noise_peak,
                window_ticks,
                shifted_entries,
                residual_std,
                sensitivity,
                ..
            } => Some(stealthy::slope(
                threshold,
                noise_peak,
                window_ticks,
                shifted_entries,
                residual_std,
                sensitivity,
            )),
            _ => None,
        }
    }

    /// True for the waveforms that transform the clean signal (scale, sign flip, freeze): they
    /// are in force for their whole segment, whatever the injection is at a tick (a scaled
    /// signal crossing zero injects zero there, and is still attacked).
    pub fn transforms(&self) -> bool {
        matches!(self, Self::Scale { .. } | Self::SignFlip | Self::Freeze)
    }

    /// The recording window `[from, to)` of a `replay`, s.
    pub fn replay_window(&self) -> Option<(f64, f64)> {
        match *self {
            Self::Replay {
                record_from_s,
                record_for_s,
            } => Some((record_from_s, record_from_s + record_for_s)),
            _ => None,
        }
    }

    /// The size of what the waveform injects at its start or at its peak, in its channel's units
    /// (a ramp: its start; noise: mean plus four standard deviations; a stealthy bias: the level
    /// it grows to; corrupt and replay:
    /// zero, they have no magnitude of their own). For the implausibility warnings of
    /// `validate`.
    pub fn magnitude(&self) -> f64 {
        match *self {
            Self::None
            | Self::Corrupt { .. }
            | Self::Replay { .. }
            | Self::Scale { .. }
            | Self::SignFlip
            | Self::Freeze => 0.0,
            Self::Constant { value } => value.abs(),
            Self::Sine {
                amplitude, offset, ..
            } => amplitude.abs() + offset.abs(),
            Self::Pulse { amplitude, .. } => amplitude.abs(),
            Self::Ramp { start, .. } => start.abs(),
            Self::Gaussian { std, mean } => mean.abs() + 4.0 * std.abs(),
            Self::StealthyBias { bias, .. } => bias.abs(),
        }
    }

    /// True for `none`: the segment injects nothing.
    pub fn is_none(&self) -> bool {
        matches!(self, Self::None)
    }

    /// Every numeric parameter with its name, and the problems of this waveform's values.
    /// Parameters must be finite, except the value of `corrupt`, whose form parsing has
    /// already checked (any `f64` is a deliberate fault).
    pub fn problems(&self) -> Vec<(&'static str, String)> {
        let mut out = Vec::new();
        let params: Vec<(&'static str, f64)> = match *self {
            Self::None | Self::Corrupt { .. } | Self::SignFlip | Self::Freeze => vec![],
            Self::Scale { factor } => vec![("factor", factor)],
            Self::Constant { value } => vec![("value", value)],
            Self::Sine {
                amplitude,
                omega_rad_s,
                phase_rad,
                offset,
            } => vec![
                ("amplitude", amplitude),
                ("omega_rad_s", omega_rad_s),
                ("phase_rad", phase_rad),
                ("offset", offset),
            ],
            Self::Pulse {
                amplitude,
                period_s,
                width_percent,
                delay_s,
            } => {
                if period_s <= 0.0 {
                    out.push(("period_s", format!("must be > 0, got {period_s}")));
                }
                if !(width_percent > 0.0 && width_percent <= 100.0) {
                    out.push((
                        "width_percent",
                        format!("must be in (0, 100], got {width_percent}"),
                    ));
                }
                vec![
                    ("amplitude", amplitude),
                    ("period_s", period_s),
                    ("width_percent", width_percent),
                    ("delay_s", delay_s),
                ]
            }
            Self::Ramp { slope_per_s, start } => {
                vec![("slope_per_s", slope_per_s), ("start", start)]
            }
            Self::Replay {
                record_from_s,
                record_for_s,
            } => {
                if record_from_s < 0.0 {
                    out.push(("record_from_s", format!("must be ≥ 0, got {record_from_s}")));
                }
                if record_for_s <= 0.0 {
                    out.push(("record_for_s", format!("must be > 0, got {record_for_s}")));
                }
                vec![
                    ("record_from_s", record_from_s),
                    ("record_for_s", record_for_s),
                ]
            }
            Self::StealthyBias { .. } => self.stealthy_bias_problems(&mut out),
            Self::Gaussian { std, mean } => {
                if std < 0.0 {
                    out.push(("std", format!("must be ≥ 0, got {std}")));
                }
                vec![("std", std), ("mean", mean)]
            }
        };
        for (name, v) in params {
            if !v.is_finite() {
                out.push((name, format!("must be finite, got {v}")));
            }
        }
        out
    }

    /// The problems and the parameters of a `stealthy-bias` waveform (nothing for another).
    fn stealthy_bias_problems(
        &self,
        out: &mut Vec<(&'static str, String)>,
    ) -> Vec<(&'static str, f64)> {
        let Self::StealthyBias {
            threshold,
            noise_peak,
            window_ticks,
            shifted_entries,
            residual_std,
            sensitivity,
            bias,
        } = *self
        else {
            return vec![];
        };
        if threshold <= 0.0 {
            out.push(("threshold", format!("must be > 0, got {threshold}")));
        }
        if noise_peak < 0.0 {
            out.push(("noise_peak", format!("must be ≥ 0, got {noise_peak}")));
        } else if noise_peak >= threshold && threshold.is_finite() {
            out.push((
                "noise_peak",
                format!(
                    "must be below threshold ({threshold}), got {noise_peak}: the \
                     attack-free statistic leaves no room under the threshold"
                ),
            ));
        }
        if window_ticks == 0 {
            out.push(("window_ticks", "must be ≥ 1, got 0".into()));
        }
        if shifted_entries == 0 {
            out.push(("shifted_entries", "must be ≥ 1, got 0".into()));
        }
        if residual_std <= 0.0 {
            out.push(("residual_std", format!("must be > 0, got {residual_std}")));
        }
        if sensitivity <= 0.0 {
            out.push(("sensitivity", format!("must be > 0, got {sensitivity}")));
        }
        if bias == 0.0 {
            out.push((
                "bias",
                "must be non-zero: a zero bias injects nothing".into(),
            ));
        }
        vec![
            ("threshold", threshold),
            ("noise_peak", noise_peak),
            ("residual_std", residual_std),
            ("sensitivity", sensitivity),
            ("bias", bias),
        ]
    }
}

#[cfg(test)]
mod tests;
