use super::*;
use proptest::prelude::*;

proptest! {
    /// The tampered value is the transformed one: to within one rounding for scale and
    /// freeze, exactly for the sign flip.
    #[test]
    fn the_center_sees_the_transformed_value(c in -1e3f64..1e3, f in -10.0f64..10.0, h in -1e3f64..1e3) {
        let ulp = |x: f64| f64::EPSILON * x.abs().max(f64::MIN_POSITIVE);
        let scaled = c + scale(c, f);
        prop_assert!((scaled - f * c).abs() <= 2.0 * ulp(f * c) + 2.0 * ulp(c), "{scaled} vs {}", f * c);
        prop_assert_eq!(c + sign_flip(c), -c);
        let frozen = c + freeze(c, h);
        prop_assert!((frozen - h).abs() <= 2.0 * ulp(h) + 2.0 * ulp(c), "{frozen} vs {h}");
    }
}

#[test]
fn a_factor_of_one_and_a_freeze_at_the_current_value_inject_nothing() {
    assert_eq!(scale(0.3, 1.0), 0.0);
    assert_eq!(freeze(0.3, 0.3), 0.0);
}
