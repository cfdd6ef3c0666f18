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
mod tests;
