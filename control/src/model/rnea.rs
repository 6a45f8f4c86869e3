//! Inverse dynamics by the recursive Newton-Euler algorithm (Featherstone 2008, §5.3).
//!
//! Run in the base frame (see `spatial`): velocities and accelerations go out along the chain,
//! body wrenches come back as plain sums. Gravity enters as an upward acceleration of the base.

use super::fixed::{Frames, Model, VecN};
use super::spatial::{Force, Inertia, Motion};

impl<const N: usize> Model<N> {
    /// τ = M(q)q̈ + C(q,q̇)q̇ + g(q).
    ///
    /// ```
    /// # use control::model::{builtin, Chain};
    /// # use nalgebra::SVector;
    /// let model = Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap().model::<7>().unwrap();
    /// let (q, qd, qdd) = (SVector::from([0.1; 7]), SVector::from([0.2; 7]), SVector::from([0.3; 7]));
    /// let tau = model.rnea(&q, &qd, &qdd);
    /// let back = model.aba(&q, &qd, &tau);
    /// assert!((back - qdd).norm() < 1e-10);
    /// ```
    #[inline]
    pub fn rnea(&self, q: &VecN<N>, qd: &VecN<N>, qdd: &VecN<N>) -> VecN<N> {
        let mut frames = Frames::default();
        self.frames(q, &mut frames);
        let mut f = [Force::ZERO; N];
        let mut s = [Motion::ZERO; N];
        let mut v = Motion::ZERO;
        let mut a = Motion {
            w: nalgebra::Vector3::zeros(),
            v: -self.gravity,
        };
        for i in 0..N {
            let fr = &frames.body[i];
            s[i] = Motion::axis(self.prismatic[i], &fr.rot.column(2).into_owned(), &fr.pos);
            let vj = s[i].scaled(qd[i]);
            v = v.plus(&vj);
            a = a.plus(&s[i].scaled(qdd[i])).plus(&v.cross(&vj));
            let inertia = Inertia::of(&self.body[i], fr);
            f[i] = inertia.apply(&a).plus(&v.cross_force(&inertia.apply(&v)));
        }
        let mut tau = VecN::zeros();
        let mut child = Force::ZERO;
        for i in (0..N).rev() {
            child = child.plus(&f[i]);
            tau[i] = s[i].dot(&child);
        }
        tau
    }

    /// The gravity torques g(q): RNEA at rest.
    #[inline]
    pub fn gravity_torques(&self, q: &VecN<N>) -> VecN<N> {
        self.rnea(q, &VecN::zeros(), &VecN::zeros())
    }
}
