//! [`Recent`]: the last few values of a pure function of `f64`s, looked up by the arguments'
//! bits. A pure function evaluated again at the very same arguments gives the very same bits, so
//! a hit returns exactly what the call would have: memoising changes no result, only the number
//! of `sin`s the engine evaluates (the plant asks for `τ(t)` and `d(t)` at the same instants
//! from neighbouring steps and RK stages, and the plants of a lane for the same instants where
//! commands take over).

/// Whether `a` and `b` are the same numbers to the bit, as many and in the same order (a −0 is
/// not a 0, a NaN is the NaN of its bits): then a pure function of them gives the same bits.
pub fn same_bits(a: impl IntoIterator<Item = f64>, b: impl IntoIterator<Item = f64>) -> bool {
    (a.into_iter().map(f64::to_bits)).eq(b.into_iter().map(f64::to_bits))
}

/// An argument of [`Recent`]'s function, looked up by its bits (−0 is not 0; a NaN finds the
/// NaN of its bits).
pub trait Bits: Copy {
    type Key: Copy + PartialEq + std::fmt::Debug;
    fn bits(self) -> Self::Key;
}

impl Bits for f64 {
    type Key = u64;
    fn bits(self) -> u64 {
        self.to_bits()
    }
}

impl<const M: usize> Bits for [f64; M] {
    type Key = [u64; M];
    fn bits(self) -> [u64; M] {
        self.map(f64::to_bits)
    }
}

/// The last `K` `(argument, value)` pairs of a pure function of `A`, the oldest replaced first.
#[derive(Debug, Clone)]
pub struct Recent<V: Copy, const K: usize, A: Bits = f64> {
    entries: [Option<(A::Key, V)>; K],
    next: usize,
}

impl<V: Copy, const K: usize, A: Bits> Default for Recent<V, K, A> {
    fn default() -> Self {
        Self {
            entries: [None; K],
            next: 0,
        }
    }
}

impl<V: Copy, const K: usize, A: Bits> Recent<V, K, A> {
    /// `f(x)`: the value kept for the bits of `x`, or `f(x)` evaluated and kept.
    pub fn get_or(&mut self, x: A, f: impl FnOnce(A) -> V) -> V {
        let key = x.bits();
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

    /// Arguments of several numbers: a hit needs every one's bits.
    #[test]
    fn several_arguments_hit_only_all_together() {
        let mut memo = Recent::<f64, 4, [f64; 3]>::default();
        let mut calls = 0;
        let mut f = |x: [f64; 3]| {
            calls += 1;
            x[0] + 2.0 * x[1] + 4.0 * x[2]
        };
        for x in [
            [1.0, 2.0, 3.0],
            [1.0, 2.0, 3.0],
            [1.0, 2.0, -3.0],
            [1.0, 2.0, 3.0],
        ] {
            assert_eq!(memo.get_or(x, &mut f), x[0] + 2.0 * x[1] + 4.0 * x[2]);
        }
        // −0 is not 0: the second is evaluated, not served the first's value.
        memo.get_or([0.0, 0.0, -0.0], &mut f);
        memo.get_or([0.0, 0.0, 0.0], &mut f);
        assert_eq!(calls, 4);
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
