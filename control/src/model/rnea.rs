//! Inverse dynamics by the recursive Newton-Euler algorithm (Featherstone 2008, §5.3).
//!
//! Velocities and accelerations go out along the chain in the base frame; each body's wrench is
//! Newton-Euler about its centre of mass (the inertia tensor applied in the body's own frame, so
//! it is never rotated whole), and the wrenches come back as plain sums. Gravity enters as an
//! upward acceleration of the base.

use super::fixed::{Model, VecN};
use super::spatial::{Force, Motion};
use nalgebra::Vector3;

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
        let sines = self.sines(q);
        let mut pose = super::Pose::IDENTITY;
        let mut f = [Force::ZERO; N];
        let mut s = [Motion::ZERO; N];
        let mut v = Motion::ZERO;
        let mut a = Motion {
            w: Vector3::zeros(),
            v: -self.gravity,
        };
        for i in 0..N {
            pose = self.body_pose(i, &pose, q[i], sines[i]);
            let fr = &pose;
            s[i] = Motion::axis(self.prismatic[i], &fr.rot.column(2).into_owned(), &fr.pos);
            let vj = s[i].scaled(qd[i]);
            v = v.plus(&vj);
            a = a.plus(&s[i].scaled(qdd[i])).plus(&v.cross(&vj));
            f[i] = self.body_wrench(i, fr, &v, &a);
        }
        let mut tau = VecN::zeros();
        let mut child = Force::ZERO;
        for i in (0..N).rev() {
            child = child.plus(&f[i]);
            tau[i] = s[i].dot(&child);
        }
        tau
    }

    /// The wrench (about the base origin) that moves body `i`, at pose `fr`, with spatial
    /// velocity `v` and acceleration `a`: Newton about the centre of mass c, Euler in the body's
    /// frame, N + c × F.
    #[inline(always)]
    fn body_wrench(&self, i: usize, fr: &super::Pose, v: &Motion, a: &Motion) -> Force {
        let b = &self.body[i];
        let c = fr.apply(&b.com);
        let vc = v.v + v.w.cross(&c);
        let ac = a.v + a.w.cross(&c) + v.w.cross(&vc);
        let force = ac * b.mass;
        let rt = fr.rot.transpose();
        let (wl, wdl) = (rt * v.w, rt * a.w);
        let euler = b.inertia * wdl + wl.cross(&(b.inertia * wl));
        Force {
            n: fr.rot * euler + c.cross(&force),
            f: force,
        }
    }

    /// The gravity torques g(q): RNEA at rest.
    #[inline]
    pub fn gravity_torques(&self, q: &VecN<N>) -> VecN<N> {
        self.rnea(q, &VecN::zeros(), &VecN::zeros())
    }
}
