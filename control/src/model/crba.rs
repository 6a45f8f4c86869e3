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
        // Forward: each joint's axis (the column S_i) and body inertia, base frame.
        let sines = self.sines(q);
        let mut axes = [Motion::ZERO; N];
        let mut bodies = [Inertia::default(); N];
        let mut pose = Pose::IDENTITY;
        for i in 0..N {
            pose = self.body_pose(i, &pose, q[i], sines[i]);
            axes[i] = Motion::axis(
                self.prismatic[i],
                &pose.rot.column(2).into_owned(),
                &pose.pos,
            );
            bodies[i] = Inertia::of(&self.body[i], &pose);
        }
        // Backward: M_ki = S_k · (I_i^c S_i) for k ≤ i, and M_ik the same. An entry below the
        // diagonal would need the composite of a later body, so only the upper triangle is
        // computed (28 of 49 products on the Panda).
        let mut m = SMatrix::<f64, N, N>::zeros();
        let mut composite = Inertia::default();
        for i in (0..N).rev() {
            composite.add(&bodies[i]);
            let f = composite.apply(&axes[i]);
            for k in 0..=i {
                let v = axes[k].power(&f);
                m[(k, i)] = v;
                m[(i, k)] = v;
            }
        }
        m
    }
}
