//! The dynamics of a [`Chain`] of `N` joints without a heap, for the run's hot path (the
//! plant's integrator, the observer and the controller ask them every tick): the links riding
//! on a joint merged into one rigid body, `M(q)` by the composite-rigid-body algorithm and
//! `V(q, q̇) q̇ + G(q)` by the recursive Newton–Euler algorithm at `q̈ = 0` (`V q̇` is the same
//! vector for every factorization of the Coriolis terms, the Christoffel one included), and the
//! Christoffel `V` itself from the bodies' Jacobians and their rates ([`Rigid::coriolis`]).
//! [`Chain`]'s own methods are the reference the tests hold these to.

use nalgebra::{Matrix3, SMatrix, Scalar, Vector3};

use super::chain::{Chain, Frame, Motion};
use super::lanes::{identity33, mul3, mul33, zero3, zero33, zero33s, zero3s, Lane};
use crate::model::robot::{Matrix, Vector};

/// A [`Chain`] of `N` joints, one rigid body per joint.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Rigid<const N: usize> {
    placement: [Frame; N],
    axis: [Vector3<f64>; N],
    motion: [Motion; N],
    /// Each joint's axis when it is one of its frame's own (most URDFs' joints turn about `z`):
    /// its rotation is then a few products, not a general one.
    along: [Along; N],
    /// The body riding on each joint: its mass, its centre of mass and its inertia about it,
    /// in the frame of the joint's child.
    mass: [f64; N],
    com: [Vector3<f64>; N],
    inertia: [Matrix3<f64>; N],
    gravity: Vector3<f64>,
}

/// Which of its frame's own axes (0 = x, 1 = y, 2 = z) a joint's axis is, if any.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Along {
    Own(usize),
    /// Another direction.
    Other,
}

impl Along {
    fn of(axis: &Vector3<f64>) -> Self {
        match (0..3).find(|&i| *axis == Vector3::ith(i, 1.0)) {
            Some(i) => Self::Own(i),
            None => Self::Other,
        }
    }

    /// The joint's axis in the frame `r` is turned from: `r axis`.
    #[inline(always)]
    fn axis_of<T: Lane>(self, r: &Matrix3<T>, axis: &Vector3<f64>) -> Vector3<T> {
        match self {
            Self::Own(i) => r.column(i).into_owned(),
            Self::Other => mul3(r, &axis.map(T::splat)),
        }
    }

    /// `r` turned by `q` about the joint's axis: `r R(axis, q)`, given `(sin q, cos q)`. About
    /// its frame's own axis `i`, the two other columns of `r` mix and column `i` stays.
    #[inline(always)]
    fn turned<T: Lane>(
        self,
        r: &Matrix3<T>,
        axis: &Vector3<f64>,
        q: T,
        (s, c): (T, T),
    ) -> Matrix3<T> {
        let Self::Own(i) = self else {
            return mul33(r, &q.each(|q| Frame::motion(Motion::Revolute, axis, q).r));
        };
        let (a, b) = ((i + 1) % 3, (i + 2) % 3);
        let (ra, rb) = (r.column(a).into_owned(), r.column(b).into_owned());
        let mut c3 = [r.column(i).into_owned(); 3];
        c3[a] = ra * c + rb * s;
        c3[b] = rb * c - ra * s;
        #[rustfmt::skip]
        let out = Matrix3::new(
            c3[0][0], c3[1][0], c3[2][0],
            c3[0][1], c3[1][1], c3[2][1],
            c3[0][2], c3[1][2], c3[2][2],
        );
        out
    }
}

/// Where the joints and bodies are at one `q`, in the root link's frame (of one arm, or of
/// several side by side: [`Lane`]).
struct Placed<const N: usize, T: Scalar = f64> {
    /// Each joint's origin and unit axis, and their product `axis × origin` (the joint's
    /// moment arm in [`unit_rate_momentum`] and [`felt`]).
    origin: [Vector3<T>; N],
    axis: [Vector3<T>; N],
    arm: [Vector3<T>; N],
    /// Each joint's child's origin.
    child: [Vector3<T>; N],
    /// Each body's centre of mass and inertia about it.
    com: [Vector3<T>; N],
    inertia: [Matrix3<T>; N],
}

impl<const N: usize> Rigid<N> {
    /// `chain`, which moves `N` joints (the caller checked).
    pub(crate) fn new(chain: &Chain) -> Self {
        let mut r = Self {
            placement: std::array::from_fn(|j| chain.joints[j].placement),
            axis: std::array::from_fn(|j| chain.joints[j].axis),
            motion: std::array::from_fn(|j| chain.joints[j].motion),
            along: std::array::from_fn(|j| Along::of(&chain.joints[j].axis)),
            mass: [0.0; N],
            com: [Vector3::zeros(); N],
            inertia: [Matrix3::zeros(); N],
            gravity: chain.gravity,
        };
        for j in 0..N {
            let riding = || chain.bodies.iter().filter(move |b| b.rides_on == j);
            let mass: f64 = riding().map(|b| b.mass).sum();
            if mass > 0.0 {
                let com = riding().map(|b| b.mass * b.com).sum::<Vector3<f64>>() / mass;
                r.com[j] = com;
                r.mass[j] = mass;
            }
            // Each body's inertia moved to the common centre of mass (parallel axes).
            r.inertia[j] = riding()
                .map(|b| {
                    let d = b.com - r.com[j];
                    b.inertia
                        + b.mass * (d.norm_squared() * Matrix3::identity() - d * d.transpose())
                })
                .sum();
        }
        r
    }

    #[inline(always)]
    fn place<T: Lane>(&self, q: &[T; N]) -> Placed<N, T> {
        let mut p = Placed {
            origin: zero3s(),
            axis: zero3s(),
            arm: zero3s(),
            child: zero3s(),
            com: zero3s(),
            inertia: zero33s(),
        };
        // Every joint's sine and cosine first: a call to the maths library inside the loop
        // below would make the loop keep its frame in memory across the call at every joint.
        let turns: [(T, T); N] = std::array::from_fn(|j| q[j].sin_cos());
        let mut at = Frame::IDENTITY.lift::<T>();
        for j in 0..N {
            let frame = at.then(&self.placement[j].lift());
            let axis = self.along[j].axis_of(&frame.r, &self.axis[j]);
            p.origin[j] = frame.p;
            p.axis[j] = axis;
            p.arm[j] = axis.cross(&frame.p);
            at = match self.motion[j] {
                Motion::Revolute => Frame {
                    r: self.along[j].turned(&frame.r, &self.axis[j], q[j], turns[j]),
                    p: frame.p,
                },
                Motion::Prismatic => Frame {
                    r: frame.r,
                    p: frame.p + axis * q[j],
                },
            };
            p.child[j] = at.p;
            p.com[j] = mul3(&at.r, &self.com[j].map(T::splat)) + at.p;
            p.inertia[j] = mul33(
                &mul33(&at.r, &self.inertia[j].map(T::splat)),
                &at.r.transpose(),
            );
        }
        p
    }

    /// `M(q)`.
    pub(crate) fn inertia(&self, q: &Vector<N>) -> Matrix<N> {
        let m = self.inertia_rows(q);
        Matrix::<N>::from_fn(|i, j| m[i][j])
    }

    /// `M(q)` by rows.
    #[inline(always)]
    pub(crate) fn inertia_rows(&self, q: &Vector<N>) -> [[f64; N]; N] {
        self.inertia_rows_of(&q.data.0[0])
    }

    /// `M(q)` by rows, of one arm (`f64`) or of several side by side ([`Lane`]).
    #[inline(always)]
    pub(crate) fn inertia_rows_of<T: Lane>(&self, q: &[T; N]) -> [[T; N]; N] {
        self.inertia_placed(&self.place(q))
    }

    /// `M(q)` as rows.
    #[inline(always)]
    // Row `i` and column `j` of one matrix, written twice (it is symmetric).
    #[allow(clippy::needless_range_loop)]
    fn inertia_placed<T: Lane>(&self, p: &Placed<N, T>) -> [[T; N]; N] {
        let mut m = [[T::zero(); N]; N];
        // The composite body of joint j: mass, first moment and inertia about the root's origin.
        let (mut mass, mut first, mut second) = (T::zero(), zero3(), zero33());
        for j in (0..N).rev() {
            let (mb, c) = (T::splat(self.mass[j]), p.com[j]);
            mass += mb;
            first += c * mb;
            second += p.inertia[j] + (identity33() * c.dot(&c) - c * c.transpose()) * mb;
            let joint = |k: usize| (self.motion[k], p.axis[k], p.arm[k]);
            let momentum = unit_rate_momentum(joint(j), (mass, &first, &second));
            for i in 0..=j {
                m[i][j] = felt(joint(i), momentum);
                m[j][i] = m[i][j];
            }
        }
        m
    }

    /// `V(q, q̇) q̇ + G(q)`: the joint forces that hold the arm at `q̈ = 0`.
    pub(crate) fn coriolis_and_gravity(&self, q: &Vector<N>, qd: &Vector<N>) -> Vector<N> {
        Vector::<N>::from(
            self.coriolis_and_gravity_placed(&self.place(&q.data.0[0]), &qd.data.0[0]),
        )
    }

    #[inline(always)]
    fn coriolis_and_gravity_placed<T: Lane>(&self, p: &Placed<N, T>, qd: &[T; N]) -> [T; N] {
        // Forward: each body's angular velocity and acceleration, and the acceleration of its
        // joint's child's origin, the root accelerating by −g (gravity as an inertial force).
        let (mut w, mut alpha) = (zero3::<T>(), zero3::<T>());
        let mut a = -self.gravity.map(T::splat);
        let mut before = zero3();
        let (mut force, mut moment): ([Vector3<T>; N], [Vector3<T>; N]) = (zero3s(), zero3s());
        for j in 0..N {
            let (z, r) = (p.axis[j], p.child[j] - before);
            // The child's origin as a point of the previous body, then its own motion.
            a += alpha.cross(&r) + w.cross(&w.cross(&r));
            let rate = z * qd[j];
            match self.motion[j] {
                Motion::Revolute => {
                    alpha += w.cross(&rate);
                    w += rate;
                }
                Motion::Prismatic => a += w.cross(&rate) * T::splat(2.0),
            }
            before = p.child[j];
            let d = p.com[j] - p.child[j];
            let at_com = a + alpha.cross(&d) + w.cross(&w.cross(&d));
            force[j] = at_com * T::splat(self.mass[j]);
            let i = p.inertia[j];
            moment[j] = mul3(&i, &alpha) + w.cross(&mul3(&i, &w));
        }
        // Backward: what joint j carries, the bodies from j to the tip, about its axis.
        let mut out = [T::zero(); N];
        let (mut total, mut about_origin) = (zero3(), zero3());
        for j in (0..N).rev() {
            total += force[j];
            about_origin += p.com[j].cross(&force[j]) + moment[j];
            let (z, o) = (p.axis[j], p.origin[j]);
            out[j] = match self.motion[j] {
                Motion::Revolute => z.dot(&(about_origin - o.cross(&total))),
                Motion::Prismatic => z.dot(&total),
            };
        }
        out
    }

    /// `V(q, q̇)`, the Christoffel-symbol Coriolis matrix, without `∂M/∂q`: summed over the
    /// bodies, `m Jᵥᵀ J̇ᵥ` (the Jacobian of a point is a gradient, so this part is the
    /// Christoffel one) and `J_ωᵀ I J̇_ω + J_ωᵀ B J_ω` with
    /// `B = ½ (ω× I − I ω× − (I ω)×)`, the rotational part whose `B ω = ω × I ω` and for
    /// which `Ṁ − 2V` is skew-symmetric (the tests hold it to the chain's Christoffel `V`).
    pub(crate) fn coriolis(&self, q: &Vector<N>, qd: &Vector<N>) -> Matrix<N> {
        let p = self.place(&q.data.0[0]);
        // The angular velocity of the body before each joint (the one its axis is fixed in),
        // and of each joint's own body.
        let mut before = [Vector3::zeros(); N];
        let mut own = [Vector3::zeros(); N];
        let mut w = Vector3::zeros();
        for j in 0..N {
            before[j] = w;
            if self.motion[j] == Motion::Revolute {
                w += p.axis[j] * qd[j];
            }
            own[j] = w;
        }
        let axis_rate: [Vector3<f64>; N] = std::array::from_fn(|j| before[j].cross(&p.axis[j]));
        // The velocity of a point fixed in the body of joint `k` (every joint up to `k` moves it).
        let velocity = |x: &Vector3<f64>, k: usize| -> Vector3<f64> {
            (0..=k).fold(Vector3::zeros(), |v, i| {
                v + match self.motion[i] {
                    Motion::Revolute => p.axis[i].cross(&(x - p.origin[i])) * qd[i],
                    Motion::Prismatic => p.axis[i] * qd[i],
                }
            })
        };
        // Each joint's origin is fixed in the body before it.
        let origin_rate: [Vector3<f64>; N] = std::array::from_fn(|j| match j {
            0 => Vector3::zeros(),
            _ => velocity(&p.origin[j], j - 1),
        });
        let mut out = Matrix::<N>::zeros();
        for (b, w) in own.iter().enumerate() {
            let c = p.com[b];
            let c_rate = velocity(&c, b);
            let (mut jv, mut jv_rate) =
                (SMatrix::<f64, 3, N>::zeros(), SMatrix::<f64, 3, N>::zeros());
            let (mut jw, mut jw_rate) =
                (SMatrix::<f64, 3, N>::zeros(), SMatrix::<f64, 3, N>::zeros());
            for j in 0..=b {
                let (z, z_rate) = (p.axis[j], axis_rate[j]);
                match self.motion[j] {
                    Motion::Revolute => {
                        let r = c - p.origin[j];
                        jv.set_column(j, &z.cross(&r));
                        jv_rate.set_column(
                            j,
                            &(z_rate.cross(&r) + z.cross(&(c_rate - origin_rate[j]))),
                        );
                        jw.set_column(j, &z);
                        jw_rate.set_column(j, &z_rate);
                    }
                    Motion::Prismatic => {
                        jv.set_column(j, &z);
                        jv_rate.set_column(j, &z_rate);
                    }
                }
            }
            let i = p.inertia[b];
            let half = 0.5 * (skew(w) * i - i * skew(w) - skew(&(i * w)));
            out += self.mass[b] * jv.transpose() * jv_rate
                + jw.transpose() * (i * jw_rate + half * jw);
        }
        out
    }

    /// `M(q)` and `V(q, q̇) q̇ + G(q)` from one placement, as rows and a list: of one arm
    /// (`f64`) or of several side by side ([`Lane`]).
    #[inline(always)]
    pub(crate) fn inertia_and_bias<T: Lane>(
        &self,
        q: &[T; N],
        qd: &[T; N],
    ) -> ([[T; N]; N], [T; N]) {
        let p = self.place(q);
        (
            self.inertia_placed(&p),
            self.coriolis_and_gravity_placed(&p, qd),
        )
    }
}

/// The skew matrix of `v`: `skew(v) x = v × x`.
#[inline(always)]
fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// The momentum of a composite body (its mass, first moment and inertia about the root's
/// origin) when one joint (how it moves, its unit axis `z`, and `z × o` for its origin `o`)
/// alone moves at a unit rate: linear, and angular about the root's origin. The column of `M`
/// that joint owns, before [`felt`] projects it on each joint.
#[inline(always)]
pub(super) fn unit_rate_momentum<T: Lane>(
    (motion, z, arm): (Motion, Vector3<T>, Vector3<T>),
    (mass, first, second): (T, &Vector3<T>, &Matrix3<T>),
) -> (Vector3<T>, Vector3<T>) {
    match motion {
        Motion::Revolute => (
            z.cross(first) - arm * mass,
            mul3(second, &z) - first.cross(&arm),
        ),
        Motion::Prismatic => (z * mass, first.cross(&z)),
    }
}

/// What a joint (how it moves, its unit axis `z`, and `z × o` for its origin `o`) bears of a
/// momentum (linear, and angular about the root's origin): an entry of `M`,
/// `z · (angular − o × linear)`.
#[inline(always)]
pub(super) fn felt<T: Lane>(
    (motion, z, arm): (Motion, Vector3<T>, Vector3<T>),
    (linear, angular): (Vector3<T>, Vector3<T>),
) -> T {
    match motion {
        Motion::Revolute => z.dot(&angular) - arm.dot(&linear),
        Motion::Prismatic => z.dot(&linear),
    }
}
