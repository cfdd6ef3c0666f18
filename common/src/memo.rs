//! [`Recent`]: the last few values of a pure function of one `f64`, looked up by the argument's
//! bits. A pure function evaluated again at the very same argument gives the very same bits, so
//! a hit returns exactly what the call would have: memoising changes no result, only the number
//! of `sin`s the engine evaluates (the plant asks for `τ(t)` and `d(t)` at the same instants
//! from neighbouring steps and RK stages).

/// The last `K` `(argument, value)` pairs of a pure function, the oldest replaced first.
#[derive(Debug, Clone)]
pub struct Recent<V: Copy, const K: usize> {
    entries: [Option<(u64, V)>; K],
    next: usize,
}

impl<V: Copy, const K: usize> Default for Recent<V, K> {
    fn default() -> Self {
        Self {
            entries: [None; K],
            next: 0,
        }
    }
}

impl<V: Copy, const K: usize> Recent<V, K> {
    /// `f(x)`: the value kept for the bits of `x`, or `f(x)` evaluated and kept.
    pub fn get_or(&mut self, x: f64, f: impl FnOnce(f64) -> V) -> V {
        let key = x.to_bits();
        if let Some((_, v)) = self.entries.iter().flatten().find(|(k, _)| *k == key) {
            return *v;
        }
        let v = f(x);
        if K > 0 {
            self.entries[self.next] = Some((key, v));
            self.next = (self.next + 1) % K;
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Whatever the order and repetition of the arguments, every answer is the function's.
        #[test]
        fn every_answer_is_the_function_s(xs in proptest::collection::vec(
            prop_oneof![Just(0.0), Just(-0.0), Just(1e-3), Just(0.1 + 0.2), Just(0.3), -10.0..10.0f64],
            0..64,
        )) {
            let mut memo = Recent::<f64, 3>::default();
            for &x in &xs {
                let got = memo.get_or(x, |x| (x * 0.7).sin());
                prop_assert_eq!(got.to_bits(), (x * 0.7).sin().to_bits());
            }
        }
    }

    #[test]
    fn a_repeated_argument_is_evaluated_once_and_minus_zero_is_not_zero() {
        let mut memo = Recent::<f64, 2>::default();
        let mut calls = 0;
        for x in [1.5, 1.5, 1.5] {
            memo.get_or(x, |x| {
                calls += 1;
                x
            });
        }
        assert_eq!(calls, 1);
        assert_eq!(memo.get_or(-0.0, |x| x).to_bits(), (-0.0f64).to_bits());
        assert_eq!(memo.get_or(0.0, |x| x).to_bits(), 0.0f64.to_bits());
    }
}
