//! The tip's pose, its geometric Jacobian and J̇q̇, in one pass.
//!
//! J̇q̇ is the tip origin's classical acceleration at q̈ = 0 (what the acceleration-level law
//! subtracts), not the spatial acceleration: they differ by ω × v. It comes from a forward
//! recursion of angular velocity and of each joint origin's acceleration, so the Jacobian is
//! never differentiated explicitly.

use super::fixed::{Frames, Model, VecN};
use nalgebra::{SMatrix, Vector3, Vector6};

/// The tip's pose, Jacobian and J̇q̇ at one state, in the base frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipKinematics<const N: usize> {
    pub frames: Frames<N>,
    /// 6×N: rows vx vy vz (the tip origin's velocity) then wx wy wz.
    pub jacobian: SMatrix<f64, 6, N>,
    /// The tip origin's classical linear acceleration, then the angular one, at q̈ = 0.
    pub jdot_qd: Vector6<f64>,
}

impl<const N: usize> Default for TipKinematics<N> {
    fn default() -> Self {
        Self {
            frames: Frames::default(),
            jacobian: SMatrix::zeros(),
            jdot_qd: Vector6::zeros(),
        }
    }
}

impl<const N: usize> Model<N> {
    /// Pose, Jacobian and J̇q̇ of the tip.
    ///
    /// ```
    /// # use control::model::{builtin, Chain, TipKinematics};
    /// # use nalgebra::SVector;
    /// let model = Chain::from_urdf(builtin("planar3").unwrap(), None, None).unwrap().model::<3>().unwrap();
    /// let mut k = TipKinematics::default();
    /// model.tip_kinematics(&SVector::zeros(), &SVector::zeros(), &mut k);
    /// assert!((k.frames.tip.pos.x - 3.0).abs() < 1e-15); // stretched along x
    /// assert!((k.jacobian[(1, 0)] - 3.0).abs() < 1e-15); // ∂y/∂q1 = reach
    /// ```
    #[inline]
    pub fn tip_kinematics(&self, q: &VecN<N>, qd: &VecN<N>, out: &mut TipKinematics<N>) {
        self.frames(q, &mut out.frames);
        let p = out.frames.tip.pos;
        let mut w = Vector3::zeros();
        let mut wd = Vector3::zeros();
        let mut acc = Vector3::zeros();
        let mut o_prev = Vector3::zeros();
        for i in 0..N {
            let f = &out.frames.body[i];
            let z: Vector3<f64> = f.rot.column(2).into_owned();
            let o = f.pos;
            let r = o - o_prev;
            acc += wd.cross(&r) + w.cross(&w.cross(&r));
            if self.prismatic[i] {
                acc += w.cross(&z) * (2.0 * qd[i]);
                out.jacobian.fixed_view_mut::<3, 1>(0, i).copy_from(&z);
                out.jacobian.fixed_view_mut::<3, 1>(3, i).fill(0.0);
            } else {
                wd += w.cross(&z) * qd[i];
                w += z * qd[i];
                out.jacobian
                    .fixed_view_mut::<3, 1>(0, i)
                    .copy_from(&z.cross(&(p - o)));
                out.jacobian.fixed_view_mut::<3, 1>(3, i).copy_from(&z);
            }
            o_prev = o;
        }
        let r = p - o_prev;
        acc += wd.cross(&r) + w.cross(&w.cross(&r));
        out.jdot_qd = Vector6::new(acc.x, acc.y, acc.z, wd.x, wd.y, wd.z);
    }
}
