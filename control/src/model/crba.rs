//! The joint-space mass matrix by the composite-rigid-body algorithm (Featherstone 2008, §6.2).
//!
//! In the base frame a subtree's composite inertia is the sum of its bodies' inertias, so the
//! backward pass is one addition per body, and M_ki = S_k · (I_i^c S_i) for k ≤ i.

use super::fixed::{Frames, Model, VecN};
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
        let mut frames = Frames::default();
        self.frames(q, &mut frames);
        let mut s = [Motion::ZERO; N];
        for i in 0..N {
            let fr = &frames.body[i];
            s[i] = Motion::axis(self.prismatic[i], &fr.rot.column(2).into_owned(), &fr.pos);
        }
        let mut m = SMatrix::<f64, N, N>::zeros();
        let mut composite = Inertia::default();
        for i in (0..N).rev() {
            composite.add(&Inertia::of(&self.body[i], &frames.body[i]));
            let f = composite.apply(&s[i]);
            for k in 0..=i {
                let mki = s[k].dot(&f);
                m[(k, i)] = mki;
                m[(i, k)] = mki;
            }
        }
        m
    }
}
