//! Attacks that transform the clean signal instead of adding a waveform of time: scaling
//! (multiplicative), sign flip, and freeze (stuck-at: the value seen at the segment's onset is
//! held). Like every attack they are applied as an injection `α` added to the clean value, so
//! the tampered value is the transformed one to within one rounding, and `α` is what the
//! attacker's trace records. The compiled channel keeps the state (the frozen value); these are
//! the pure parts.

/// `α` of a scaling by `factor`: `(factor − 1) · clean`, so the center sees `factor · clean`.
pub fn scale(clean: f64, factor: f64) -> f64 {
    (factor - 1.0) * clean
}

/// `α` of a sign flip: `−2 · clean`, so the center sees `−clean` (exactly: doubling is exact).
pub fn sign_flip(clean: f64) -> f64 {
    -2.0 * clean
}

/// `α` of a freeze at `held` (the clean value of the segment's first tick): `held − clean`, so
/// the center sees `held` for the whole segment.
pub fn freeze(clean: f64, held: f64) -> f64 {
    held - clean
}

#[cfg(test)]
mod tests {
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
}
