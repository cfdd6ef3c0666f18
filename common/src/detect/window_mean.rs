//! The windowed-mean test: `m_k = (1/√w) Σ over the last w ticks of z_j` (`z = L⁻¹ r`, the
//! whitened residual), alarm while `‖m_k‖²` exceeds its threshold.
//!
//! Under the null hypothesis (`z` white, unit covariance) `m_k ~ N(0, I)`, so `‖m_k‖² ~ χ²(dim)`
//! whatever `w`: the threshold is that quantile at the per-tick false-alarm probability of
//! `[detectors.chi2]`. Where χ² adds up squares (it sees a larger variance), the mean adds up
//! signed values first: a persistent bias of `b` standard deviations on an entry adds about
//! `w · b²` to the statistic, while white noise does not add up. The window is
//! [`WINDOW_TICKS`] ticks. The sum is kept running and taken afresh once per window, so rounding
//! never accumulates past one window.

use std::collections::VecDeque;

use nalgebra::DVector;

use super::config::DetectorsConfig;
use super::gamma;
use super::kind::{Kind, ResidualDetector};

/// `w`: the ticks averaged (0.1 s at the paper's Δ = 1 ms).
pub const WINDOW_TICKS: usize = 100;

/// The windowed-mean test: `window_mean` in every table.
pub const KIND: Kind = Kind {
    name: "window_mean",
    title: "mean",
    phrase: "a windowed-mean test",
    statistic:
        "squared norm of the mean of the whitened residual over its window, times the window",
    threshold_doc: "its configured threshold (null when none could be had)",
    describe,
    threshold,
    build: |_, dim| Box::new(WindowMean::new(dim)),
};

/// `the mean over w ticks (false-alarm probability p per tick)`.
fn describe(d: &DetectorsConfig) -> String {
    format!(
        "the mean over {WINDOW_TICKS} ticks (false-alarm probability {:e} per tick)",
        d.chi2.false_alarm_probability
    )
}

/// The χ² quantile of `dim` degrees of freedom at the χ² test's false-alarm probability.
fn threshold(d: &DetectorsConfig, dim: usize) -> Result<f64, String> {
    let p = d.chi2.false_alarm_probability;
    gamma::chi2_quantile_upper(dim, p)
        .ok_or_else(|| format!("no χ² quantile for {dim} degrees of freedom at probability {p}"))
}

/// The last [`WINDOW_TICKS`] whitened residuals and their sum.
#[derive(Debug, Clone)]
pub struct WindowMean {
    window: VecDeque<DVector<f64>>,
    sum: DVector<f64>,
    /// Ticks since the sum was last taken afresh.
    since_fresh: usize,
}

impl WindowMean {
    pub fn new(dim: usize) -> Self {
        Self {
            window: VecDeque::with_capacity(WINDOW_TICKS),
            sum: DVector::zeros(dim),
            since_fresh: 0,
        }
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
        (self.window.len() == WINDOW_TICKS).then(|| self.sum.dot(&self.sum) / WINDOW_TICKS as f64)
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

    #[test]
    fn no_statistic_until_the_window_is_full() {
        let s = statistics(&residuals(WINDOW_TICKS + 1, 0.0, 1));
        assert!(s[..WINDOW_TICKS - 1].iter().all(Option::is_none));
        assert!(s[WINDOW_TICKS - 1..].iter().all(Option::is_some));
    }

    /// Under the null hypothesis the statistic is χ²(dim): its mean is dim, and it stays under
    /// the threshold at 1e-6 per tick.
    #[test]
    fn white_noise_averages_to_the_dimension_and_raises_no_alarm() {
        let s: Vec<f64> = statistics(&residuals(20_000, 0.0, 2))
            .into_iter()
            .flatten()
            .collect();
        let mean = s.iter().sum::<f64>() / s.len() as f64;
        assert!((mean - 4.0).abs() < 0.4, "mean {mean}");
        let t = threshold(&DetectorsConfig::default(), 4).expect("quantile");
        assert!(
            s.iter().all(|x| *x < t),
            "max {:?} over {t}",
            s.iter().copied().reduce(f64::max)
        );
    }

    /// A bias of 0.8 σ on one entry: under χ²'s per-tick threshold nearly always, over the
    /// mean's once the window holds it.
    #[test]
    fn a_small_persistent_bias_is_found_where_the_per_tick_chi2_misses_it() {
        let config = DetectorsConfig::default();
        let zs = residuals(5_000, 0.8, 3);
        let t_mean = threshold(&config, 4).expect("quantile");
        let alarmed = statistics(&zs)
            .into_iter()
            .flatten()
            .filter(|s| *s > t_mean)
            .count();
        let t_chi2 =
            gamma::chi2_quantile_upper(4, config.chi2.false_alarm_probability).expect("quantile");
        let chi2_alarms = zs.iter().filter(|z| z.dot(z) > t_chi2).count();
        assert!(
            alarmed > 4_000,
            "the mean alarmed on {alarmed} of 4901 ticks"
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
