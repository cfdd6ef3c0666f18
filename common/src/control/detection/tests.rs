use super::Detector;

#[test]
fn raises_after_the_hold_time_and_clears_below_threshold() {
    let mut d = Detector::new(0.1, 0.02);
    assert!(!d.update(0.0, 0.5));
    assert!(!d.update(0.019, 0.5));
    assert!(d.update(0.02, 0.5));
    assert!(!d.update(0.021, 0.05));
    assert!(!d.update(0.03, 0.5), "hold restarts after a drop");
}

#[test]
fn a_short_spike_does_not_alarm() {
    let mut d = Detector::new(0.1, 0.05);
    let alarms = (0..100)
        .filter(|k| d.update(f64::from(*k) * 1e-3, if k % 40 < 10 { 1.0 } else { 0.0 }))
        .count();
    assert_eq!(alarms, 0);
}
