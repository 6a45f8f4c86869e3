//! The joint-space mass matrix by the composite-rigid-body algorithm (Featherstone 2008, §6.2).
//!
//! In the base frame a subtree's composite inertia is the sum of its bodies' inertias, so the
//! backward pass is one addition per body, and M_ki = S_k · (I_i^c S_i) for k ≤ i.

use super::fixed::{Model, VecN};
use super::pose::Pose;
use super::spatial::{Inertia, Motion};
use nalgebra::SMatrix;

impl<const N: usize> Model<N> {
    /// M(q), symmetric positive definite for a chain whose every joint moves some inertia.
    ///
    /// ```
    /// # use control::model::{builtin, Chain};
    /// # use nalgebra::SVector;
    /// let model = Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap().model::<7>().unwrap();
    /// let m = model.mass_matrix(&SVector::from([0.3; 7]));
    /// assert!((m - m.transpose()).norm() < 1e-12);
    /// assert!(m.cholesky().is_some());
    /// ```
    #[inline]
    pub fn mass_matrix(&self, q: &VecN<N>) -> SMatrix<f64, N, N> {
        // Forward: each joint's axis (as a 6-vector column of S) and body inertia, base frame.
        let mut axes = SMatrix::<f64, 6, N>::zeros();
        let mut bodies = [Inertia::default(); N];
        let mut pose = Pose::IDENTITY;
        for i in 0..N {
            pose = self.body_pose(i, &pose, q[i]);
            let s = Motion::axis(
                self.prismatic[i],
                &pose.rot.column(2).into_owned(),
                &pose.pos,
            );
            axes.set_column(i, &s.to_vector());
            bodies[i] = Inertia::of(&self.body[i], &pose);
        }
        // Backward: column i is Sᵀ·(I_i^c S_i). Its entries below the diagonal would need the
        // composite of a later body; they are taken from the upper triangle at the end.
        let mut m = SMatrix::<f64, N, N>::zeros();
        let mut composite = Inertia::default();
        for i in (0..N).rev() {
            composite.add(&bodies[i]);
            let s = Motion {
                w: axes.fixed_view::<3, 1>(0, i).into_owned(),
                v: axes.fixed_view::<3, 1>(3, i).into_owned(),
            };
            let f = composite.apply(&s).to_vector();
            m.set_column(i, &axes.tr_mul(&f));
        }
        for i in 0..N {
            for k in i + 1..N {
                m[(k, i)] = m[(i, k)];
            }
        }
        m
    }
}
