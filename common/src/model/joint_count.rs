//! Work over the joint count of each robot, chosen at run time: a team may mix arms of
//! different joint counts (two Pandas and two paper arms), and each robot's plant, control
//! center and attack run with its own `N`. The joint counts a robot may have are listed here
//! once, in the three macros (the models' own list is [`super::ModelConfig::with_links`]; a
//! test checks both agree).

/// Evaluates `$body` with `$n` a `const usize` equal to the joint count `$dof`: `Some(body)`,
/// or `None` for a count no robot model has.
///
/// ```
/// use fdi_common::model::Vector;
/// let zeros = |dof: usize| fdi_common::with_joint_count!(dof, N => Vector::<N>::zeros().len());
/// assert_eq!((zeros(1), zeros(12), zeros(13)), (Some(1), Some(12), None));
/// ```
#[macro_export]
macro_rules! with_joint_count {
    ($dof:expr, $n:ident => $body:expr) => {
        match $dof {
            1 => {
                const $n: usize = 1;
                Some($body)
            }
            2 => {
                const $n: usize = 2;
                Some($body)
            }
            3 => {
                const $n: usize = 3;
                Some($body)
            }
            4 => {
                const $n: usize = 4;
                Some($body)
            }
            5 => {
                const $n: usize = 5;
                Some($body)
            }
            6 => {
                const $n: usize = 6;
                Some($body)
            }
            7 => {
                const $n: usize = 7;
                Some($body)
            }
            8 => {
                const $n: usize = 8;
                Some($body)
            }
            9 => {
                const $n: usize = 9;
                Some($body)
            }
            10 => {
                const $n: usize = 10;
                Some($body)
            }
            11 => {
                const $n: usize = 11;
                Some($body)
            }
            12 => {
                const $n: usize = 12;
                Some($body)
            }
            _ => None,
        }
    };
}

/// Declares `enum $name` with one variant per joint count, each holding a boxed `$ty<N>`, and
/// `From<$ty<N>>` for each: a value whose type depends on a robot's joint count, in a list of
/// robots of different counts. [`on_joint_count!`] works on the value inside.
#[macro_export]
macro_rules! per_joint_count {
    ($(#[$meta:meta])* $vis:vis enum $name:ident = $ty:ident) => {
        $(#[$meta])*
        $vis enum $name {
            J1(Box<$ty<1>>),
            J2(Box<$ty<2>>),
            J3(Box<$ty<3>>),
            J4(Box<$ty<4>>),
            J5(Box<$ty<5>>),
            J6(Box<$ty<6>>),
            J7(Box<$ty<7>>),
            J8(Box<$ty<8>>),
            J9(Box<$ty<9>>),
            J10(Box<$ty<10>>),
            J11(Box<$ty<11>>),
            J12(Box<$ty<12>>),
        }
        $crate::per_joint_count!(
            @from $name $ty J1 1, J2 2, J3 3, J4 4, J5 5, J6 6, J7 7, J8 8, J9 9, J10 10, J11 11, J12 12
        );
    };
    (@from $name:ident $ty:ident $($v:ident $n:literal),*) => {
        $(impl From<$ty<$n>> for $name {
            fn from(x: $ty<$n>) -> Self {
                Self::$v(Box::new(x))
            }
        })*
    };
}

/// Evaluates `$body` with `$x` bound to the value inside `$value`, an enum of
/// [`per_joint_count!`] named `$name` (by value, or through `&` / `&mut`).
#[macro_export]
macro_rules! on_joint_count {
    ($name:ident, $value:expr, $x:ident => $body:expr) => {
        match $value {
            $name::J1($x) => $body,
            $name::J2($x) => $body,
            $name::J3($x) => $body,
            $name::J4($x) => $body,
            $name::J5($x) => $body,
            $name::J6($x) => $body,
            $name::J7($x) => $body,
            $name::J8($x) => $body,
            $name::J9($x) => $body,
            $name::J10($x) => $body,
            $name::J11($x) => $body,
            $name::J12($x) => $body,
        }
    };
}

#[cfg(test)]
mod tests {
    use crate::model::Vector;

    struct Zeros<const N: usize>(Vector<N>);

    crate::per_joint_count!(enum AnyZeros = Zeros);

    fn any_zeros(dof: usize) -> Option<AnyZeros> {
        crate::with_joint_count!(dof, N => AnyZeros::from(Zeros::<N>(Vector::<N>::zeros())))
    }

    #[test]
    fn every_joint_count_of_a_model_is_one_of_the_macros_and_keeps_its_n() {
        for dof in 0..=16 {
            let made = any_zeros(dof).map(|z| crate::on_joint_count!(AnyZeros, z, x => x.0.len()));
            let expected = (1..=crate::limits::MAX_DOF).contains(&dof).then_some(dof);
            assert_eq!(made, expected, "{dof} joints");
        }
        #[cfg(feature = "urdf")]
        for dof in crate::model::urdf::JOINT_COUNTS {
            assert!(
                any_zeros(dof).is_some(),
                "{dof} joints: a URDF arm may have them"
            );
        }
    }
}
