//! Statistics over the seeds of one point: mean, sample standard deviation and the 95 %
//! confidence interval of the mean with the Student t quantile (`t(0.975, n − 1)`, from
//! statrs).

use serde::Serialize;
use statrs::distribution::{ContinuousCDF, StudentsT};

/// Confidence level of every interval.
pub const LEVEL: f64 = 0.95;

/// The statistics of one sample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Stats {
    /// Values in the sample (finite ones only).
    pub n: usize,
    pub mean: f64,
    /// Sample standard deviation (`n − 1` in the denominator); `None` for `n = 1`.
    pub sd: Option<f64>,
    /// The 95 % confidence interval of the mean; `None` for `n = 1`.
    pub ci_low: Option<f64>,
    pub ci_high: Option<f64>,
}

impl Stats {
    /// Half the width of the confidence interval, when there is one.
    pub fn half_width(&self) -> Option<f64> {
        Some((self.ci_high? - self.ci_low?) / 2.0)
    }
}

/// The Student t quantile of the two-sided interval at [`LEVEL`] with `dof` degrees of freedom.
pub fn t_quantile(dof: usize) -> Option<f64> {
    let t = StudentsT::new(0.0, 1.0, dof as f64).ok()?;
    Some(t.inverse_cdf(1.0 - (1.0 - LEVEL) / 2.0))
}

/// The statistics of the finite values of `values`; `None` when there are none. The mean and
/// the deviations are taken about the first value, so that a constant sample has exactly its
/// value as mean and a standard deviation of exactly 0.
pub fn describe(values: &[f64]) -> Option<Stats> {
    let xs: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    let &x0 = xs.first()?;
    let n = xs.len();
    let shift = xs.iter().map(|x| x - x0).sum::<f64>() / n as f64;
    let mean = x0 + shift;
    if n < 2 {
        return Some(Stats {
            n,
            mean,
            sd: None,
            ci_low: None,
            ci_high: None,
        });
    }
    let ss: f64 = xs.iter().map(|x| (x - x0 - shift).powi(2)).sum();
    let sd = (ss / (n - 1) as f64).sqrt();
    let half = t_quantile(n - 1).map(|t| t * sd / (n as f64).sqrt());
    Some(Stats {
        n,
        mean,
        sd: Some(sd),
        ci_low: half.map(|h| mean - h),
        ci_high: half.map(|h| mean + h),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn matches_the_textbook_interval() {
        // t(0.975, 4) = 2.776445; sd of 1..5 = sqrt(2.5).
        let s = describe(&[1.0, 2.0, 3.0, 4.0, 5.0]).expect("stats");
        assert_eq!(s.n, 5);
        assert!((s.mean - 3.0).abs() < 1e-12);
        assert!((s.sd.expect("sd") - 2.5_f64.sqrt()).abs() < 1e-12);
        let half = 2.776_445 * 2.5_f64.sqrt() / 5.0_f64.sqrt();
        assert!((s.half_width().expect("ci") - half).abs() < 1e-5, "{s:?}");
        assert!((t_quantile(1).expect("t") - 12.706_205).abs() < 1e-5);
    }

    #[test]
    fn one_value_has_no_interval_and_non_finite_values_are_left_out() {
        let s = describe(&[f64::NAN, 2.0, f64::INFINITY]).expect("stats");
        assert_eq!(
            s,
            Stats {
                n: 1,
                mean: 2.0,
                sd: None,
                ci_low: None,
                ci_high: None
            }
        );
        assert_eq!(describe(&[]), None);
        assert_eq!(describe(&[f64::NAN]), None);
    }

    proptest! {
        #[test]
        fn the_mean_lies_inside_its_interval(xs in prop::collection::vec(-1e6f64..1e6, 2..40)) {
            let s = describe(&xs).expect("stats");
            let (lo, hi) = (s.ci_low.expect("lo"), s.ci_high.expect("hi"));
            prop_assert!(lo <= s.mean && s.mean <= hi, "{s:?}");
            let min = xs.iter().copied().fold(f64::INFINITY, f64::min);
            let max = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            prop_assert!(s.mean >= min - 1e-9 * min.abs().max(1.0) && s.mean <= max + 1e-9 * max.abs().max(1.0));
        }

        #[test]
        fn the_interval_shrinks_with_n(xs in prop::collection::vec(-1e3f64..1e3, 2..30)) {
            let s = describe(&xs).expect("stats");
            prop_assume!(s.sd.expect("sd") > 1e-9);
            // The same values twice: the same spread, twice the number of values.
            let twice: Vec<f64> = xs.iter().chain(xs.iter()).copied().collect();
            let d = describe(&twice).expect("stats");
            prop_assert!(d.half_width().expect("ci") < s.half_width().expect("ci"), "{s:?} {d:?}");
        }

        #[test]
        fn a_constant_sample_has_sd_zero(x in -1e9f64..1e9, n in 2usize..50) {
            let s = describe(&vec![x; n]).expect("stats");
            prop_assert_eq!(s.mean, x);
            prop_assert_eq!(s.sd, Some(0.0));
            prop_assert_eq!(s.ci_low, Some(x));
            prop_assert_eq!(s.ci_high, Some(x));
        }
    }
}
