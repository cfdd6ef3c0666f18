use super::super::Waveform;
use super::*;
use crate::rng::{stream, Purpose};

/// The shipped preset's design: the paper's Ψ2 χ² test at a per-tick false-alarm
/// probability of 1e-6 (τ = 27.631), both links shifted.
fn shipped() -> Waveform {
    Waveform::StealthyBias {
        threshold: 27.631,
        noise_peak: 25.0,
        window_ticks: 1,
        shifted_entries: 2,
        residual_std: 3.0e-3,
        sensitivity: 0.36,
        bias: 0.05,
    }
}

#[test]
fn slope_follows_the_formula() {
    // By hand: (√27.631 − 5) = 0.256521…, × 3e-3 / √2 = 5.44161e-4 rad/s of Ψ2 per entry,
    // / 0.36 = 1.51156e-3 rad/s.
    let r = residual_offset(27.631, 25.0, 1, 2, 3.0e-3);
    assert!((r - 5.441_61e-4).abs() < 1e-9, "offset {r}");
    let s = slope(27.631, 25.0, 1, 2, 3.0e-3, 0.36);
    assert!((s - 1.511_56e-3).abs() < 1e-8, "slope {s}");
    // A wider window or more entries share the same budget: √(w m) slower.
    assert!((slope(27.631, 25.0, 4, 2, 3.0e-3, 0.36) - s / 2.0).abs() < 1e-15);
    assert!((slope(27.631, 25.0, 1, 8, 3.0e-3, 0.36) - s / 2.0).abs() < 1e-15);
    // No room under the threshold: no growth.
    assert_eq!(offset_budget(20.0, 25.0, 1), 0.0);
}

#[test]
fn grows_linearly_from_its_segment_start_then_holds() {
    let w = shipped();
    let mut r = stream(1, 1, Purpose::AttackNoise { channel: 0 });
    let s = slope(27.631, 25.0, 1, 2, 3.0e-3, 0.36);
    assert_eq!(w.value(5.0, 5.0, &mut r), 0.0, "zero at its start");
    assert_eq!(w.value(4.0, 5.0, &mut r), 0.0);
    let v = w.value(15.0, 5.0, &mut r);
    assert!((v - 10.0 * s).abs() < 1e-15, "{v} after 10 s");
    // 0.05 / 1.51156e-3 = 33.08 s after the start: held from there on.
    assert!(w.value(38.0, 5.0, &mut r) < 0.05);
    assert_eq!(w.value(38.2, 5.0, &mut r), 0.05);
    assert_eq!(w.value(1e6, 5.0, &mut r), 0.05);
    let Waveform::StealthyBias {
        threshold,
        noise_peak,
        window_ticks,
        shifted_entries,
        residual_std,
        sensitivity,
        ..
    } = w
    else {
        unreachable!()
    };
    let negative = Waveform::StealthyBias {
        threshold,
        noise_peak,
        window_ticks,
        shifted_entries,
        residual_std,
        sensitivity,
        bias: -0.05,
    };
    assert_eq!(
        negative.value(15.0, 5.0, &mut r),
        -w.value(15.0, 5.0, &mut r)
    );
    assert_eq!(negative.value(100.0, 5.0, &mut r), -0.05);
    assert_eq!(w.magnitude(), 0.05);
    assert!(!w.transforms() && !w.is_none());
}

#[test]
fn the_shipped_design_has_no_problems_and_bad_values_are_named() {
    assert!(
        shipped().problems().is_empty(),
        "{:?}",
        shipped().problems()
    );
    let bad = Waveform::StealthyBias {
        threshold: 20.0,
        noise_peak: 25.0,
        window_ticks: 0,
        shifted_entries: 0,
        residual_std: 0.0,
        sensitivity: -1.0,
        bias: f64::NAN,
    };
    let names: Vec<_> = bad.problems().into_iter().map(|p| p.0).collect();
    for field in [
        "noise_peak",
        "window_ticks",
        "shifted_entries",
        "residual_std",
        "sensitivity",
        "bias",
    ] {
        assert!(names.contains(&field), "{field} not in {names:?}");
    }
    let zero = Waveform::StealthyBias {
        threshold: f64::INFINITY,
        noise_peak: -1.0,
        window_ticks: 1,
        shifted_entries: 1,
        residual_std: 1e-3,
        sensitivity: 0.3,
        bias: 0.0,
    };
    let names: Vec<_> = zero.problems().into_iter().map(|p| p.0).collect();
    for field in ["threshold", "noise_peak", "bias"] {
        assert!(names.contains(&field), "{field} not in {names:?}");
    }
}

#[test]
fn parses_from_a_profile_with_the_default_window() {
    let w: Waveform = toml::from_str(
        "kind = \"stealthy-bias\"\nthreshold = 27.631\nnoise_peak = 25.0\n\
         shifted_entries = 2\nresidual_std = 3e-3\nsensitivity = 0.36\nbias = 0.05\n",
    )
    .expect("parses");
    assert_eq!(w, shipped());
    let unknown: Result<Waveform, _> = toml::from_str(
        "kind = \"stealthy-bias\"\nthreshold = 27.631\nnoise_peak = 25.0\nwindow = 3\n\
         shifted_entries = 2\nresidual_std = 3e-3\nsensitivity = 0.36\nbias = 0.05\n",
    );
    assert!(unknown.is_err());
}
