use super::*;

#[test]
fn plays_the_recording_in_a_loop() {
    let dt = 1e-3;
    let len = 2000;
    let first = 2000.0 * dt;
    let last = 3999.0 * dt;
    let h = spacing(first, last, len);
    for k in 0..10_000u64 {
        let elapsed = 6.0 + k as f64 * dt - 6.0;
        let played = index(elapsed, h, len);
        assert_eq!(played, Some((k % 2000) as usize), "tick {k}");
    }
    assert_eq!(index(0.5, h, 0), None);
    assert_eq!(index(0.5, 0.0, 1), Some(0));
}
