//! Classical detectors beside the paper's `‖Ŝ‖` alarm (docs/detectors.md). Pure: no I/O.
//!
//! They run per robot, tick by tick, on what the control center has: the tampered measurement
//! it received and its observer's state, read from the joined [`TickRecord`]s (so an
//! in-process and a lockstep IPC run give the same verdicts). Three detectors, by the names
//! every table uses:
//!
//! * `s_hat_norm`: the paper's alarm, `‖Ŝ‖` above a threshold for a hold time
//!   ([`crate::control::Detector`], read from `CenterRecord::alarm`, unchanged; [`s_hat`]
//!   replays it from the records as a statistic for the threshold sweeps);
//! * `chi2`: `Σ over w ticks of rᵀ Σ⁻¹ r` above a threshold ([`chi2`]);
//! * `cusum`: a two-sided CUSUM on each entry of the whitened residual ([`cusum`]).
//!
//! `r` is the observer's residual ([`residual`]), `Σ` its covariance over the calibration window
//! at the start of the run ([`calibration`]). During the window the χ² and CUSUM detectors give no
//! verdict. A residual or statistic that is not finite is counted and raises the alarm for its
//! tick (the measurement cannot be judged, which is itself an anomaly: staying silent would let
//! an attacker blind the detectors with NaN), and leaves the detectors' state as it was.

pub mod calibration;
pub mod chi2;
pub mod config;
pub mod cusum;
pub mod gamma;
pub mod residual;
pub mod s_hat;
pub mod sweep;

use nalgebra::DVector;

use crate::records::{CenterRecord, TickRecord};

pub use config::{Chi2Config, CusumConfig, DetectorsConfig, ResidualKind};

use calibration::{Accumulator, Whitener};
use chi2::Chi2;
use cusum::Cusum;

/// The paper's alarm.
pub const S_HAT_NORM: &str = "s_hat_norm";
/// The χ² test on the residual.
pub const CHI2: &str = "chi2";
/// The CUSUM on the whitened residual.
pub const CUSUM: &str = "cusum";
/// The detectors in the order of every table.
pub const NAMES: [&str; 3] = [S_HAT_NORM, CHI2, CUSUM];

/// Whether an attack is in force at this tick, on either path (the measurement, or the torque
/// when the run routes the agent's torques through the attacker): the ground truth of every
/// detection metric (onsets, coverage, false alarms) and of the threshold sweeps. The one place
/// that says it.
pub fn in_force(r: &TickRecord) -> bool {
    r.attack.active || r.actuation.is_some_and(|a| a.active)
}

/// Whether a detector's per-tick `statistic` raises the alarm at `threshold`: the alarm of
/// every detector for every threshold, in the metrics and in the sweeps alike.
pub fn exceeds(statistic: f64, threshold: f64) -> bool {
    statistic > threshold
}

/// What one detector says about one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// Inside the calibration window, or the χ² window still filling: no verdict, no alarm.
    Calibrating,
    /// The statistic of the tick, and the detector's configured threshold. The alarm at any
    /// threshold is a function of the statistic alone ([`Verdict::alarm_at`]).
    Watched { statistic: f64, threshold: f64 },
    /// The residual or the statistic was not finite: counted, alarm on for this tick.
    NonFinite,
    /// No residual could be formed (no record of the tick before, or a record of the wrong
    /// length): counted, the alarm keeps its state.
    Missing,
    /// The calibration failed (or no threshold could be had): never an alarm.
    Uncalibrated,
}

impl Verdict {
    /// Whether the alarm is on at this tick at the configured threshold, given whether it was
    /// on at the tick before.
    pub fn alarm(self, before: bool) -> bool {
        let threshold = match self {
            Self::Watched { threshold, .. } => threshold,
            _ => f64::NAN,
        };
        self.alarm_at(threshold, before)
    }

    /// Whether the alarm would be on at this tick with `threshold` instead of the configured
    /// one, given whether it was on at the tick before (at the same threshold).
    pub fn alarm_at(self, threshold: f64, before: bool) -> bool {
        match self {
            Self::Watched { statistic, .. } => exceeds(statistic, threshold),
            Self::NonFinite => true,
            Self::Missing => before,
            Self::Calibrating | Self::Uncalibrated => false,
        }
    }

    /// Whether the detector was watching (its alarm could have been raised).
    pub fn watched(self) -> bool {
        matches!(self, Self::Watched { .. } | Self::NonFinite | Self::Missing)
    }
}

/// The verdicts of the χ² and CUSUM detectors on one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Verdicts {
    pub chi2: Verdict,
    pub cusum: Verdict,
}

impl Verdicts {
    fn both(v: Verdict) -> Self {
        Self { chi2: v, cusum: v }
    }
}

#[derive(Debug, Clone)]
enum Phase {
    Calibrating(Accumulator),
    Ready(Whitener),
    Failed(String),
}

/// How a robot's calibration went.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationState {
    /// Residuals the covariance was estimated from.
    pub samples: u64,
    /// Ticks of the window whose residual was not finite (left out of the covariance).
    pub non_finite: u64,
    /// Ticks of the window without a residual (the first tick, gaps).
    pub missing: u64,
    /// `sqrt(diag Σ)` per residual entry (empty unless calibrated).
    pub rms: Vec<f64>,
    /// Why there is no calibration: it failed, or the run ended inside the window.
    pub failed: Option<String>,
}

/// The χ² and CUSUM detectors of one robot.
#[derive(Debug, Clone)]
pub struct RobotDetectors {
    kind: ResidualKind,
    links: usize,
    beta: f64,
    regularization: f64,
    calibration_ticks: u64,
    prev: Option<CenterRecord>,
    phase: Phase,
    chi2: Chi2,
    chi2_threshold: Result<f64, String>,
    cusum: Cusum,
    calibration_non_finite: u64,
    calibration_missing: u64,
    calibration_samples: u64,
}

impl RobotDetectors {
    /// Detectors for a robot of `links` links; `beta`: the controller's β (for the `psi2`
    /// residual); `control_period_s`: Δ (the calibration window in ticks).
    pub fn new(config: &DetectorsConfig, control_period_s: f64, beta: f64, links: usize) -> Self {
        let dim = config.residual.dimension(links);
        let c = config.chi2;
        let w = c.window_ticks.max(1);
        let chi2_threshold = match c.threshold {
            Some(t) => Ok(t),
            None => {
                gamma::chi2_quantile_upper(dim * w, c.false_alarm_probability).ok_or_else(|| {
                    format!(
                        "no χ² quantile for {} degrees of freedom at probability {}",
                        dim * w,
                        c.false_alarm_probability
                    )
                })
            }
        };
        Self {
            kind: config.residual,
            links,
            beta,
            regularization: config.regularization,
            calibration_ticks: config.calibration_ticks(control_period_s),
            prev: None,
            phase: Phase::Calibrating(Accumulator::new(dim)),
            chi2: Chi2::new(w),
            chi2_threshold,
            cusum: Cusum::new(dim, config.cusum.drift, config.cusum.threshold),
            calibration_non_finite: 0,
            calibration_missing: 0,
            calibration_samples: 0,
        }
    }

    /// Ticks `k` below this are the calibration window.
    pub fn calibration_ticks(&self) -> u64 {
        self.calibration_ticks
    }

    /// The χ² threshold in use, or why there is none.
    pub fn chi2_threshold(&self) -> Result<f64, &str> {
        self.chi2_threshold
            .as_ref()
            .copied()
            .map_err(String::as_str)
    }

    /// The CUSUM threshold `h`.
    pub fn cusum_threshold(&self) -> f64 {
        self.cusum.threshold()
    }

    /// The calibration as it stands.
    pub fn calibration(&self) -> CalibrationState {
        let (samples, rms, failed) = match &self.phase {
            Phase::Calibrating(acc) => (
                acc.samples(),
                Vec::new(),
                Some(format!(
                    "the record ended before the detectors could watch ({} ticks recorded, the calibration window is {})",
                    self.prev.map_or(0, |p| p.k + 1),
                    self.calibration_ticks
                )),
            ),
            Phase::Ready(w) => (self.calibration_samples, w.rms.clone(), None),
            Phase::Failed(why) => (self.calibration_samples, Vec::new(), Some(why.clone())),
        };
        CalibrationState {
            samples,
            non_finite: self.calibration_non_finite,
            missing: self.calibration_missing,
            rms,
            failed,
        }
    }

    /// Feeds the joined record of the robot's next tick (its ticks in order).
    pub fn push(&mut self, r: &TickRecord) -> Verdicts {
        let res = residual::residual(self.kind, self.links, self.beta, self.prev.as_ref(), r);
        self.prev = Some(r.center);
        let finite = |v: &DVector<f64>| v.iter().all(|x| x.is_finite());
        if r.center.k < self.calibration_ticks {
            match (&mut self.phase, res) {
                (Phase::Calibrating(acc), Ok(v)) if finite(&v) => acc.push(&v),
                (_, Ok(_)) => self.calibration_non_finite += 1,
                (_, Err(_)) => self.calibration_missing += 1,
            }
            return Verdicts::both(Verdict::Calibrating);
        }
        if let Phase::Calibrating(acc) = &self.phase {
            self.calibration_samples = acc.samples();
            self.phase = match acc.finish(self.regularization) {
                Ok(w) => Phase::Ready(w),
                Err(why) => Phase::Failed(why),
            };
        }
        let Phase::Ready(whitener) = &self.phase else {
            return Verdicts::both(Verdict::Uncalibrated);
        };
        let Ok(res) = res else {
            return Verdicts::both(Verdict::Missing);
        };
        let Some(z) = whitener.whiten(&res).filter(|_| finite(&res)) else {
            return Verdicts::both(Verdict::NonFinite);
        };
        let q = z.dot(&z);
        if !q.is_finite() {
            return Verdicts::both(Verdict::NonFinite);
        }
        let chi2 = match (&self.chi2_threshold, self.chi2.push(q)) {
            (Err(_), _) => Verdict::Uncalibrated,
            (Ok(_), None) => Verdict::Calibrating,
            (Ok(_), Some(sum)) if !sum.is_finite() => Verdict::NonFinite,
            (Ok(t), Some(sum)) => Verdict::Watched {
                statistic: sum,
                threshold: *t,
            },
        };
        let cusum = Verdict::Watched {
            statistic: self.cusum.push(&z),
            threshold: self.cusum.threshold(),
        };
        Verdicts { chi2, cusum }
    }
}

#[cfg(test)]
mod tests;
