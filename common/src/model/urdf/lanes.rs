//! Four arms' numbers computed side by side: [`F64x4`] holds one `f64` of each in a lane, and
//! every operation on it is the `f64` operation lane by lane — the same bits as four scalar
//! computations, whose loops the compiler turns into vector instructions. [`Lane`] is what the
//! dynamics ask of a number, so one generic code serves one arm (`f64`) and four ([`F64x4`]).

use std::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

use nalgebra::{Matrix3, Scalar, Vector3};
use num_traits::{One, Zero};

pub(crate) use crate::model::robot::LANES;

/// What the dynamics ask of a number: arithmetic (nalgebra's vectors and matrices of it),
/// a constant, the sine and cosine, the square root and a sign test. Every operation rounds
/// as `f64`'s does.
pub(crate) trait Lane:
    Scalar
    + Copy
    + Zero
    + One
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + DivAssign
{
    /// `x` in every lane.
    fn splat(x: f64) -> Self;
    /// `(sin x, cos x)`, lane by lane, as `f64::sin_cos`.
    fn sin_cos(self) -> (Self, Self);
    fn sqrt(self) -> Self;
    /// Every lane greater than zero (none NaN).
    fn positive(self) -> bool;
    /// `f` of each lane's number.
    fn each(self, f: impl Fn(f64) -> Matrix3<f64>) -> Matrix3<Self>;
}

impl Lane for f64 {
    #[inline(always)]
    fn splat(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        f64::sin_cos(self)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn positive(self) -> bool {
        self > 0.0
    }
    #[inline(always)]
    fn each(self, f: impl Fn(f64) -> Matrix3<f64>) -> Matrix3<Self> {
        f(self)
    }
}

/// `fn $wide(&self, …)`, the inherent method `$here` (`#[inline(always)]`) compiled for
/// processors with 256-bit vectors (AVX2), and `fn $name(&self, …)` that calls it where this
/// processor has them and `$here` elsewhere: the dynamics' hot paths. The same bits either way
/// (the instructions differ, the roundings do not: no operation is fused).
macro_rules! wide {
    ($(#[$meta:meta])* fn $name:ident / $wide:ident / $here:ident (&self $(, $a:ident: $t:ty)*) -> $r:ty) => {
        $(#[$meta])*
        fn $name(&self $(, $a: $t)*) -> $r {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the processor has the instructions `$wide` is compiled for (checked
                // just above); the method itself is safe code.
                #[allow(unsafe_code)]
                return unsafe { self.$wide($($a),*) };
            }
            self.$here($($a),*)
        }
    };
    (@wide fn $wide:ident / $here:ident (&self $(, $a:ident: $t:ty)*) -> $r:ty) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        fn $wide(&self $(, $a: $t)*) -> $r {
            self.$here($($a),*)
        }
    };
}
pub(crate) use wide;

/// Four `f64`, one per lane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct F64x4(pub [f64; LANES]);

impl F64x4 {
    #[inline(always)]
    fn zip(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        Self(std::array::from_fn(|i| f(self.0[i], other.0[i])))
    }
}

macro_rules! lane_op {
    ($op:ident, $f:ident, $assign:ident, $fa:ident, $sym:tt) => {
        impl $op for F64x4 {
            type Output = Self;
            #[inline(always)]
            fn $f(self, other: Self) -> Self {
                self.zip(other, |a, b| a $sym b)
            }
        }
        impl $assign for F64x4 {
            #[inline(always)]
            fn $fa(&mut self, other: Self) {
                *self = *self $sym other;
            }
        }
    };
}

lane_op!(Add, add, AddAssign, add_assign, +);
lane_op!(Sub, sub, SubAssign, sub_assign, -);
lane_op!(Mul, mul, MulAssign, mul_assign, *);
lane_op!(Div, div, DivAssign, div_assign, /);

impl Neg for F64x4 {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Self(self.0.map(|a| -a))
    }
}

impl Zero for F64x4 {
    #[inline(always)]
    fn zero() -> Self {
        Self([0.0; LANES])
    }
    #[inline(always)]
    fn is_zero(&self) -> bool {
        self.0.iter().all(|a| *a == 0.0)
    }
}

impl One for F64x4 {
    #[inline(always)]
    fn one() -> Self {
        Self([1.0; LANES])
    }
}

impl Lane for F64x4 {
    #[inline(always)]
    fn splat(x: f64) -> Self {
        Self([x; LANES])
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        let sc = self.0.map(f64::sin_cos);
        (Self(sc.map(|(s, _)| s)), Self(sc.map(|(_, c)| c)))
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        Self(self.0.map(f64::sqrt))
    }
    #[inline(always)]
    fn positive(self) -> bool {
        self.0.iter().all(|a| *a > 0.0)
    }
    fn each(self, f: impl Fn(f64) -> Matrix3<f64>) -> Matrix3<Self> {
        let each = self.0.map(f);
        Matrix3::from_fn(|i, j| Self(each.map(|m| m[(i, j)])))
    }
}

/// The zero vector, written out so that it is inlined for every [`Lane`].
#[inline(always)]
pub(crate) fn zero3<T: Lane>() -> Vector3<T> {
    let z = T::zero();
    Vector3::new(z, z, z)
}

/// The zero matrix, as [`zero3`].
#[inline(always)]
pub(crate) fn zero33<T: Lane>() -> Matrix3<T> {
    let z = T::zero();
    Matrix3::new(z, z, z, z, z, z, z, z, z)
}

/// `N` zero vectors, each written in place (an array of copies of one zero is copied through
/// memory, a call per element for [`F64x4`]'s).
#[inline(always)]
pub(crate) fn zero3s<T: Lane, const N: usize>() -> [Vector3<T>; N] {
    std::array::from_fn(|_| zero3())
}

/// `N` zero matrices, as [`zero3s`].
#[inline(always)]
pub(crate) fn zero33s<T: Lane, const N: usize>() -> [Matrix3<T>; N] {
    std::array::from_fn(|_| zero33())
}

/// The identity matrix, as [`zero3`].
#[inline(always)]
pub(crate) fn identity33<T: Lane>() -> Matrix3<T> {
    let (z, o) = (T::zero(), T::one());
    Matrix3::new(o, z, z, z, o, z, z, z, o)
}

/// `a b`, each entry `(a_i0 b_0j + a_i1 b_1j) + a_i2 b_2j` as nalgebra's product sums it (the
/// same bits), written out so that it is inlined for every [`Lane`].
#[inline(always)]
pub(crate) fn mul33<T: Lane>(a: &Matrix3<T>, b: &Matrix3<T>) -> Matrix3<T> {
    let e =
        |i: usize, j: usize| a[(i, 0)] * b[(0, j)] + a[(i, 1)] * b[(1, j)] + a[(i, 2)] * b[(2, j)];
    Matrix3::new(
        e(0, 0),
        e(0, 1),
        e(0, 2),
        e(1, 0),
        e(1, 1),
        e(1, 2),
        e(2, 0),
        e(2, 1),
        e(2, 2),
    )
}

/// `a x`, as [`mul33`] sums it.
#[inline(always)]
pub(crate) fn mul3<T: Lane>(a: &Matrix3<T>, x: &Vector3<T>) -> Vector3<T> {
    let e = |i: usize| a[(i, 0)] * x[0] + a[(i, 1)] * x[1] + a[(i, 2)] * x[2];
    Vector3::new(e(0), e(1), e(2))
}
