//! The windowed-mean test: `m_k = (1/√w) Σ over the last w ticks of z_j` (`z = L⁻¹ r`, the
//! whitened residual), statistic `‖m_k‖² / κ`, alarm while it exceeds its threshold.
//!
//! For a white residual (`z` unit covariance, uncorrelated in time) `m_k ~ N(0, I)`, so
//! `‖m_k‖² ~ χ²(dim)` whatever `w`: the threshold is that quantile at the per-tick false-alarm
//! probability of `[detectors.chi2]`. Where χ² adds up squares (it sees a larger variance), the
//! mean adds up signed values first: a persistent bias of `b` standard deviations on an entry
//! adds about `w · b²` to the statistic, while white noise does not add up.
//!
//! Neither residual of the paper's system is white in time: a residual correlated over the
//! window makes `‖m_k‖²` many times `dim` (on `psi2` without attack, 410 false alarms per
//! minute on robot 1 with `κ = 1`). So the detector calibrates `κ` itself: the median of
//! `‖m_k‖²` over its first [`CALIBRATION_TICKS`] full windows divided by the median of
//! χ²(dim) (at least 1: a white residual keeps its χ² threshold), and gives no verdict until
//! then. For a Gaussian residual correlated in time `‖m_k‖² / κ` is again about χ²(dim). The
//! median, not the mean: this window may hold an attack (robot 4's pulses at 2 and 4 s on the
//! paper's run), and the windows an attack reaches (fewer than half) leave the median almost
//! where it was, where they would make the mean, and so `κ`, many times too large.
//! The window is [`WINDOW_TICKS`] ticks. The sum is kept running and taken afresh once per
//! window, so rounding never accumulates past one window.

use std::collections::VecDeque;

use nalgebra::DVector;

use super::config::DetectorsConfig;
use super::gamma;
use super::kind::{Kind, ResidualDetector};

/// `w`: the ticks averaged (0.1 s at the paper's Δ = 1 ms).
pub const WINDOW_TICKS: usize = 100;

/// The full windows `κ` is the mean over (2 s at the paper's Δ, as the covariance's window).
pub const CALIBRATION_TICKS: usize = 2_000;

/// The windowed-mean test: `window_mean` in every table.
pub const KIND: Kind = Kind {
    name: "window_mean",
    title: "mean",
    phrase: "a windowed-mean test",
    statistic: "squared norm of the mean of the whitened residual over its window, times the \
         window, over κ (its calibrated scale, at least 1)",
    threshold_doc: "its configured threshold (null when none could be had)",
    describe,
    threshold,
    build: |_, dim| Box::new(WindowMean::new(dim)),
};

/// `the mean over w ticks (false-alarm probability p per tick)`.
fn describe(d: &DetectorsConfig) -> String {
    format!(
        "the mean over {WINDOW_TICKS} ticks, scaled by its own median over its first \
         {CALIBRATION_TICKS} windows (false-alarm probability {:e} per tick)",
        d.chi2.false_alarm_probability
    )
}

/// The χ² quantile of `dim` degrees of freedom at the χ² test's false-alarm probability.
fn threshold(d: &DetectorsConfig, dim: usize) -> Result<f64, String> {
    let p = d.chi2.false_alarm_probability;
    gamma::chi2_quantile_upper(dim, p)
        .ok_or_else(|| format!("no χ² quantile for {dim} degrees of freedom at probability {p}"))
}

/// The last [`WINDOW_TICKS`] whitened residuals, their sum, and `κ`.
#[derive(Debug, Clone)]
pub struct WindowMean {
    window: VecDeque<DVector<f64>>,
    sum: DVector<f64>,
    /// Ticks since the sum was last taken afresh.
    since_fresh: usize,
    /// While calibrating: `‖m‖²` of each full window so far.
    calibrating: Vec<f64>,
    /// `κ`, once calibrated.
    kappa: Option<f64>,
}

impl WindowMean {
    pub fn new(dim: usize) -> Self {
        Self {
            window: VecDeque::with_capacity(WINDOW_TICKS),
            sum: DVector::zeros(dim),
            since_fresh: 0,
            calibrating: Vec::new(),
            kappa: None,
        }
    }

    /// `κ`, once calibrated.
    pub fn kappa(&self) -> Option<f64> {
        self.kappa
    }

    /// The statistic of a full window `squared` (`‖m‖²`): scaled by `κ`, or `None` while `κ`
    /// is calibrated (a non-finite `squared` is handed on: the tick's verdict says so).
    fn scaled(&mut self, squared: f64) -> Option<f64> {
        if let Some(kappa) = self.kappa {
            return Some(squared / kappa);
        }
        if !squared.is_finite() {
            return Some(squared);
        }
        self.calibrating.push(squared);
        if self.calibrating.len() == CALIBRATION_TICKS {
            let mut v = std::mem::take(&mut self.calibrating);
            v.sort_by(f64::total_cmp);
            let median = (v[CALIBRATION_TICKS / 2 - 1] + v[CALIBRATION_TICKS / 2]) / 2.0;
            // χ²(dim)'s median; none for a residual of no entries (then κ = 1).
            let null = gamma::chi2_quantile_upper(self.sum.len(), 0.5).unwrap_or(median);
            self.kappa = Some((median / null).max(1.0));
        }
        None
    }
}

impl ResidualDetector for WindowMean {
    fn push(&mut self, z: &DVector<f64>) -> Option<f64> {
        if z.len() != self.sum.len() {
            return None;
        }
        // The oldest entry's buffer takes the newest residual (no allocation per tick).
        let mut slot = None;
        if self.window.len() == WINDOW_TICKS {
            if let Some(old) = self.window.pop_front() {
                self.sum -= &old;
                slot = Some(old);
            }
        }
        self.sum += z;
        self.window.push_back(match slot {
            Some(mut old) => {
                old.copy_from(z);
                old
            }
            None => z.clone(),
        });
        self.since_fresh += 1;
        if self.since_fresh >= WINDOW_TICKS {
            self.sum = self.window.iter().sum();
            self.since_fresh = 0;
        }
        if self.window.len() < WINDOW_TICKS {
            return None;
        }
        let squared = self.sum.dot(&self.sum) / WINDOW_TICKS as f64;
        self.scaled(squared)
    }

    fn boxed_clone(&self) -> Box<dyn ResidualDetector> {
        Box::new(self.clone())
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_chacha::ChaCha12Rng;
    use rand_distr::{Distribution, StandardNormal};

    use super::*;

    /// `n` whitened residuals of 4 entries: white unit noise, `bias` added to the first entry.
    fn residuals(n: usize, bias: f64, seed: u64) -> Vec<DVector<f64>> {
        let mut rng = ChaCha12Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                let mut z = DVector::from_fn(4, |_, _| StandardNormal.sample(&mut rng));
                z[0] += bias;
                z
            })
            .collect()
    }

    fn statistics(zs: &[DVector<f64>]) -> Vec<Option<f64>> {
        let mut d = WindowMean::new(4);
        zs.iter().map(|z| d.push(z)).collect()
    }

    /// The ticks without a statistic: the window filling, then `κ`'s calibration.
    const SILENT: usize = WINDOW_TICKS - 1 + CALIBRATION_TICKS;

    #[test]
    fn no_statistic_until_the_window_is_full_and_kappa_calibrated() {
        let s = statistics(&residuals(SILENT + 2, 0.0, 1));
        assert!(s[..SILENT].iter().all(Option::is_none));
        assert!(s[SILENT..].iter().all(Option::is_some));
    }

    /// Under the null hypothesis the statistic is χ²(dim) (κ stays about 1): its mean is dim,
    /// and it stays under the threshold at 1e-6 per tick.
    #[test]
    fn white_noise_averages_to_the_dimension_and_raises_no_alarm() {
        let s: Vec<f64> = statistics(&residuals(SILENT + 20_000, 0.0, 2))
            .into_iter()
            .flatten()
            .collect();
        let mean = s.iter().sum::<f64>() / s.len() as f64;
        // κ ≥ 1 is estimated over 2000 overlapping windows (20 apart): about 1 ± 0.2.
        assert!(mean > 3.0 && mean < 4.5, "mean {mean}");
        let t = threshold(&DetectorsConfig::default(), 4).expect("quantile");
        assert!(
            s.iter().all(|x| *x < t),
            "max {:?} over {t}",
            s.iter().copied().reduce(f64::max)
        );
    }

    /// A residual correlated in time (AR(1), lag-1 correlation 0.95, unit variance): its
    /// windowed mean is many times χ²(dim), which alarmed for good with κ = 1; κ calibrates
    /// that away, and a bias that comes later is still found.
    #[test]
    fn a_residual_correlated_in_time_is_calibrated_away_and_a_later_bias_still_found() {
        let rho: f64 = 0.95;
        let mut rng = ChaCha12Rng::seed_from_u64(5);
        let mut x = DVector::<f64>::zeros(4);
        let n = SILENT + 40_000;
        let zs: Vec<DVector<f64>> = (0..n)
            .map(|i| {
                let e = DVector::from_fn(4, |_, _| StandardNormal.sample(&mut rng));
                x = &x * rho + e * (1.0 - rho * rho).sqrt();
                let mut z = x.clone();
                if i >= n - 5_000 {
                    z[0] += 5.0;
                }
                z
            })
            .collect();
        let t = threshold(&DetectorsConfig::default(), 4).expect("quantile");
        let mut d = WindowMean::new(4);
        let s: Vec<Option<f64>> = zs.iter().map(|z| d.push(z)).collect();
        let kappa = d.kappa().expect("calibrated");
        // (1 + ρ) / (1 − ρ) = 39 for a long window; about 30 over 100 ticks.
        assert!(kappa > 15.0 && kappa < 50.0, "κ {kappa}");
        let before: Vec<f64> = s[..n - 5_000].iter().flatten().copied().collect();
        let alarms = before.iter().filter(|x| **x > t).count();
        assert_eq!(
            alarms,
            0,
            "false alarms on {alarms} of {} ticks",
            before.len()
        );
        let unscaled = before.iter().filter(|x| **x * kappa > t).count();
        assert!(unscaled > 100, "with κ = 1: {unscaled} alarms");
        let after = s[n - 5_000 + WINDOW_TICKS..].iter().flatten();
        assert!(after.clone().all(|x| *x > t), "the bias of 5 σ is missed");
    }

    /// Two pulses of 20 σ in its calibration (as robot 4's attack on the paper's run): the
    /// median leaves κ near 1, and a later pulse of 3 σ is found.
    #[test]
    fn pulses_in_the_calibration_leave_kappa_near_that_of_the_clean_residual() {
        let mut zs = residuals(SILENT + 3_000, 0.0, 7);
        for start in [WINDOW_TICKS + 200, WINDOW_TICKS + 1_200, SILENT + 1_000] {
            let size = if start > SILENT { 3.0 } else { 20.0 };
            for z in &mut zs[start..start + 100] {
                z[0] += size;
            }
        }
        let mut d = WindowMean::new(4);
        let s: Vec<Option<f64>> = zs.iter().map(|z| d.push(z)).collect();
        let kappa = d.kappa().expect("calibrated");
        assert!(kappa < 1.5, "κ {kappa}");
        let t = threshold(&DetectorsConfig::default(), 4).expect("quantile");
        let peak = s[SILENT + 1_000..SILENT + 1_200]
            .iter()
            .flatten()
            .copied()
            .fold(0.0, f64::max);
        assert!(peak > t, "the later pulse peaks at {peak}, threshold {t}");
    }

    /// A bias of 0.8 σ on one entry after the calibration: under χ²'s per-tick threshold nearly
    /// always, over the mean's once the window holds it.
    #[test]
    fn a_small_persistent_bias_is_found_where_the_per_tick_chi2_misses_it() {
        let config = DetectorsConfig::default();
        let mut zs = residuals(SILENT, 0.0, 3);
        let biased = residuals(5_000, 0.8, 6);
        zs.extend(biased.iter().cloned());
        let t_mean = threshold(&config, 4).expect("quantile");
        let alarmed = statistics(&zs)[SILENT..]
            .iter()
            .flatten()
            .filter(|s| **s > t_mean)
            .count();
        let t_chi2 =
            gamma::chi2_quantile_upper(4, config.chi2.false_alarm_probability).expect("quantile");
        let chi2_alarms = biased.iter().filter(|z| z.dot(z) > t_chi2).count();
        assert!(
            alarmed > 4_000,
            "the mean alarmed on {alarmed} of 5000 ticks"
        );
        assert!(
            chi2_alarms < 50,
            "χ² alarmed on {chi2_alarms} of 5000 ticks"
        );
    }

    /// The running sum taken afresh once per window equals the window's sum.
    #[test]
    fn the_running_sum_is_the_window_sum() {
        let zs = residuals(1_234, 0.1, 4);
        let mut d = WindowMean::new(4);
        for z in &zs {
            d.push(z);
        }
        let exact: DVector<f64> = zs[zs.len() - WINDOW_TICKS..].iter().sum();
        assert!((d.sum - exact).amax() < 1e-12);
    }

    #[test]
    fn it_is_listed_among_the_residual_detectors() {
        assert!(super::super::RESIDUAL.iter().any(|k| k.name == KIND.name));
        assert_eq!(super::super::title(KIND.name), Some(KIND.title));
    }
}
