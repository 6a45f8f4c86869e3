//! Forward dynamics by the articulated-body algorithm (Featherstone 2008, §7.3).
//!
//! O(N) and without forming M. In the base frame an articulated inertia passes to its parent
//! unchanged (no 6×6 transform), which leaves a rank-one downdate per joint as the main cost.

use super::fixed::{Model, VecN};
use super::spatial::{Inertia, Motion};
use nalgebra::{Matrix6, Vector6};

impl<const N: usize> Model<N> {
    /// q̈ from the joint torques τ: the q̈ for which [`Model::rnea`] gives back τ.
    #[inline]
    pub fn aba(&self, q: &VecN<N>, qd: &VecN<N>, tau: &VecN<N>) -> VecN<N> {
        let sines = self.sines(q);
        let mut pose = super::Pose::IDENTITY;
        let mut s = [Vector6::zeros(); N];
        let mut c = [Vector6::zeros(); N];
        let mut ia = [Matrix6::zeros(); N];
        let mut pa = [Vector6::zeros(); N];
        let mut v = Motion::ZERO;
        for i in 0..N {
            pose = self.body_pose(i, &pose, q[i], sines[i]);
            let fr = &pose;
            let si = Motion::axis(self.prismatic[i], &fr.rot.column(2).into_owned(), &fr.pos);
            let vj = si.scaled(qd[i]);
            v = v.plus(&vj);
            let inertia = Inertia::of(&self.body[i], fr);
            s[i] = si.to_vector();
            c[i] = v.cross(&vj).to_vector();
            ia[i] = inertia.matrix();
            pa[i] = v.cross_force(&inertia.apply(&v)).to_vector();
        }
        let mut u = [Vector6::zeros(); N];
        let mut d = [0.0; N];
        let mut uu = [0.0; N];
        for i in (0..N).rev() {
            u[i] = ia[i] * s[i];
            d[i] = s[i].dot(&u[i]);
            uu[i] = tau[i] - s[i].dot(&pa[i]);
            if i > 0 {
                // The parent sees Ia = IA − u uᵀ/d and pa = pA + Ia c + u·uu/d, folded so that
                // Ia is never formed: one rank-one update of the parent's matrix.
                let uc = u[i].dot(&c[i]);
                let bias = pa[i] + ia[i] * c[i] + u[i] * ((uu[i] - uc) / d[i]);
                let inv = 1.0 / d[i];
                let (parent, rest) = ia.split_at_mut(i);
                let (p, a, ui) = (&mut parent[i - 1], &rest[0], &u[i]);
                for col in 0..6 {
                    let k = ui[col] * inv;
                    for row in 0..6 {
                        p[(row, col)] += a[(row, col)] - ui[row] * k;
                    }
                }
                pa[i - 1] += bias;
            }
        }
        let g = -self.gravity;
        let mut a = Vector6::new(0.0, 0.0, 0.0, g.x, g.y, g.z);
        let mut qdd = VecN::zeros();
        for i in 0..N {
            let ai = a + c[i];
            qdd[i] = (uu[i] - u[i].dot(&ai)) / d[i];
            a = ai + s[i] * qdd[i];
        }
        qdd
    }
}
