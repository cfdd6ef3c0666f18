use super::*;
use crate::rng::{stream, Purpose};

fn rng() -> ChaCha12Rng {
    stream(1, 1, Purpose::AttackNoise { channel: 0 })
}

#[test]
fn paper_pulse_is_high_for_five_percent_of_two_seconds() {
    let w = Waveform::Pulse {
        amplitude: 1.0,
        period_s: 2.0,
        width_percent: 5.0,
        delay_s: 0.0,
    };
    let mut r = rng();
    let high = (0..20_000)
        .filter(|k| w.value(f64::from(*k) * 1e-3, 0.0, &mut r) == 1.0)
        .count();
    // 10 periods × 100 ms high at 1 kHz; a tick that lands on an edge may fall either side
    // by round-off of k·1e-3 mod 2, hence ±1 tick per edge (20 edges).
    assert!((980..=1020).contains(&high), "high for {high} ticks");
    assert_eq!(w.value(0.05, 0.0, &mut r), 1.0);
    assert_eq!(w.value(0.15, 0.0, &mut r), 0.0);
    assert_eq!(w.value(2.05, 0.0, &mut r), 1.0);
}

#[test]
fn ramp_counts_from_its_segment_start_and_sine_from_absolute_time() {
    let mut r = rng();
    let ramp = Waveform::Ramp {
        slope_per_s: 2.0,
        start: 1.0,
    };
    assert_eq!(ramp.value(10.5, 10.0, &mut r), 2.0);
    let sine = Waveform::Sine {
        amplitude: -1.0,
        omega_rad_s: 2.0,
        phase_rad: 0.0,
        offset: 0.0,
    };
    assert_eq!(sine.value(25.0, 25.0, &mut r), -(50.0f64).sin());
}

#[test]
fn gaussian_noise_has_the_requested_moments() {
    let w = Waveform::Gaussian {
        std: 0.5,
        mean: 2.0,
    };
    let mut r = rng();
    let xs: Vec<f64> = (0..40_000).map(|_| w.value(0.0, 0.0, &mut r)).collect();
    let mean = xs.iter().sum::<f64>() / xs.len() as f64;
    let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64;
    // Standard error of the mean 0.5/200 = 0.0025: 5 σ bound.
    assert!((mean - 2.0).abs() < 0.0125, "mean {mean}");
    assert!((var.sqrt() - 0.5).abs() < 0.01, "std {}", var.sqrt());
}

#[test]
fn invalid_parameters_are_named() {
    let w = Waveform::Pulse {
        amplitude: f64::NAN,
        period_s: 0.0,
        width_percent: 150.0,
        delay_s: 0.0,
    };
    let names: Vec<_> = w.problems().into_iter().map(|p| p.0).collect();
    assert!(
        names.contains(&"amplitude")
            && names.contains(&"period_s")
            && names.contains(&"width_percent")
    );
}
