//! Classical detectors beside the paper's `‖Ŝ‖` alarm (docs/detectors.md). Pure: no I/O.
//!
//! They run per robot, tick by tick, on what the control center has: the tampered measurement
//! it received and its observer's state, read from the joined [`TickRecord`]s (so an
//! in-process and a lockstep IPC run give the same verdicts). The detectors, by the names
//! every table uses (the residual ones listed in [`RESIDUAL`]):
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
pub mod kind;
pub mod residual;
pub mod s_hat;
pub mod sweep;
pub mod window_mean;

use nalgebra::DVector;

use crate::records::{CenterRecord, TickRecord};

pub use config::{Chi2Config, CusumConfig, DetectorsConfig, ResidualKind};

use calibration::{Accumulator, Whitener};
pub use kind::{Kind, ResidualDetector};

/// The detectors on the observer's residual, in the order of every table, export and figure.
/// A new detector: its own file with its [`Kind`], and one entry here.
pub const RESIDUAL: &[Kind] = &[chi2::KIND, cusum::KIND, window_mean::KIND];

/// The paper's alarm.
pub const S_HAT_NORM: &str = "s_hat_norm";
/// Its title in tables and figure legends.
pub const S_HAT_NORM_TITLE: &str = "‖Ŝ‖";
/// The χ² test on the residual.
pub const CHI2: &str = chi2::KIND.name;
/// The CUSUM on the whitened residual.
pub const CUSUM: &str = cusum::KIND.name;

/// Every detector's name in the order of every table: the paper's alarm, then [`RESIDUAL`].
pub fn names() -> Vec<&'static str> {
    std::iter::once(S_HAT_NORM)
        .chain(RESIDUAL.iter().map(|k| k.name))
        .collect()
}

/// The title of the detector `name` in tables and figure legends (`‖Ŝ‖`, `χ²`, …).
pub fn title(name: &str) -> Option<&'static str> {
    if name == S_HAT_NORM {
        return Some(S_HAT_NORM_TITLE);
    }
    RESIDUAL.iter().find(|k| k.name == name).map(|k| k.title)
}

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

/// The residual detectors of one robot ([`RESIDUAL`], in that order).
#[derive(Debug, Clone)]
pub struct RobotDetectors {
    kind: ResidualKind,
    links: usize,
    beta: f64,
    regularization: f64,
    calibration_ticks: u64,
    prev: Option<CenterRecord>,
    phase: Phase,
    detectors: Vec<Box<dyn ResidualDetector>>,
    thresholds: Vec<Result<f64, String>>,
    /// The verdicts of the last tick, one per detector.
    verdicts: Vec<Verdict>,
    /// The tick's residual and its whitening: buffers reused every tick.
    residual: DVector<f64>,
    whitened: DVector<f64>,
    calibration_non_finite: u64,
    calibration_missing: u64,
    calibration_samples: u64,
}

impl RobotDetectors {
    /// Detectors for a robot of `links` links; `beta`: the controller's β (for the `psi2`
    /// residual); `control_period_s`: Δ (the calibration window in ticks).
    pub fn new(config: &DetectorsConfig, control_period_s: f64, beta: f64, links: usize) -> Self {
        let dim = config.residual.dimension(links);
        Self {
            kind: config.residual,
            links,
            beta,
            regularization: config.regularization,
            calibration_ticks: config.calibration_ticks(control_period_s),
            prev: None,
            phase: Phase::Calibrating(Accumulator::new(dim)),
            detectors: RESIDUAL.iter().map(|k| (k.build)(config, dim)).collect(),
            thresholds: RESIDUAL
                .iter()
                .map(|k| (k.threshold)(config, dim))
                .collect(),
            verdicts: vec![Verdict::Calibrating; RESIDUAL.len()],
            residual: DVector::zeros(dim),
            whitened: DVector::zeros(dim),
            calibration_non_finite: 0,
            calibration_missing: 0,
            calibration_samples: 0,
        }
    }

    /// Ticks `k` below this are the calibration window.
    pub fn calibration_ticks(&self) -> u64 {
        self.calibration_ticks
    }

    /// The threshold in use of the `i`-th detector of [`RESIDUAL`], or why there is none.
    pub fn threshold(&self, i: usize) -> Result<f64, &str> {
        match self.thresholds.get(i) {
            Some(t) => t.as_ref().copied().map_err(String::as_str),
            None => Err("no such detector"),
        }
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

    /// Feeds the joined record of the robot's next tick (its ticks in order); the verdict of
    /// every detector of [`RESIDUAL`] on it, in that order.
    pub fn push(&mut self, r: &TickRecord) -> &[Verdict] {
        match self.whiten(r) {
            Ok(()) => {
                for ((d, t), v) in self
                    .detectors
                    .iter_mut()
                    .zip(&self.thresholds)
                    .zip(&mut self.verdicts)
                {
                    *v = match (t, d.push(&self.whitened)) {
                        (Err(_), _) => Verdict::Uncalibrated,
                        (Ok(_), None) => Verdict::Calibrating,
                        (Ok(_), Some(s)) if !s.is_finite() => Verdict::NonFinite,
                        (Ok(t), Some(s)) => Verdict::Watched {
                            statistic: s,
                            threshold: *t,
                        },
                    };
                }
            }
            Err(all) => self.verdicts.fill(all),
        }
        &self.verdicts
    }

    /// The whitened residual of the tick into `self.whitened`, or the verdict every detector
    /// gives without one (calibrating, uncalibrated, missing, non-finite).
    fn whiten(&mut self, r: &TickRecord) -> Result<(), Verdict> {
        let res = residual::residual_into(
            self.kind,
            self.links,
            self.beta,
            self.prev.as_ref(),
            r,
            &mut self.residual,
        );
        self.prev = Some(r.center);
        let finite = |v: &DVector<f64>| v.iter().all(|x| x.is_finite());
        if r.center.k < self.calibration_ticks {
            match (&mut self.phase, res) {
                (Phase::Calibrating(acc), Ok(())) if finite(&self.residual) => {
                    acc.push(&self.residual)
                }
                (_, Ok(())) => self.calibration_non_finite += 1,
                (_, Err(_)) => self.calibration_missing += 1,
            }
            return Err(Verdict::Calibrating);
        }
        if let Phase::Calibrating(acc) = &self.phase {
            self.calibration_samples = acc.samples();
            self.phase = match acc.finish(self.regularization) {
                Ok(w) => Phase::Ready(w),
                Err(why) => Phase::Failed(why),
            };
        }
        let Phase::Ready(whitener) = &self.phase else {
            return Err(Verdict::Uncalibrated);
        };
        if res.is_err() {
            return Err(Verdict::Missing);
        }
        if !(whitener.whiten_into(&self.residual, &mut self.whitened) && finite(&self.residual)) {
            return Err(Verdict::NonFinite);
        }
        if !self.whitened.dot(&self.whitened).is_finite() {
            return Err(Verdict::NonFinite);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
