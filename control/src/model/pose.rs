//! Rigid transforms as a rotation matrix and a translation.
//!
//! Matrices rather than quaternions: the chain composes a handful of them per tick and hands
//! rotation columns (joint axes) straight to the Jacobian, and users compare poses with
//! pinocchio's `SE3`, which is stored the same way.

use nalgebra::{Matrix3, Matrix4, Vector3};

/// `x_parent = rot · x_child + pos`: the child frame's axes and origin in the parent frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub rot: Matrix3<f64>,
    pub pos: Vector3<f64>,
}

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose {
    pub const IDENTITY: Pose = Pose {
        rot: Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        pos: Vector3::new(0.0, 0.0, 0.0),
    };

    /// URDF's `<origin xyz rpy>`: R = Rz(yaw)·Ry(pitch)·Rx(roll), fixed axes.
    ///
    /// ```
    /// # use control::model::Pose;
    /// # use nalgebra::Vector3;
    /// let p = Pose::from_xyz_rpy(Vector3::new(1.0, 0.0, 0.0), Vector3::new(0.0, 0.0, std::f64::consts::FRAC_PI_2));
    /// let x = p.apply(&Vector3::new(1.0, 0.0, 0.0));
    /// assert!((x - Vector3::new(1.0, 1.0, 0.0)).norm() < 1e-15);
    /// ```
    pub fn from_xyz_rpy(xyz: Vector3<f64>, rpy: Vector3<f64>) -> Self {
        let (sr, cr) = rpy.x.sin_cos();
        let (sp, cp) = rpy.y.sin_cos();
        let (sy, cy) = rpy.z.sin_cos();
        let rot = Matrix3::new(
            cy * cp,
            cy * sp * sr - sy * cr,
            cy * sp * cr + sy * sr,
            sy * cp,
            sy * sp * sr + cy * cr,
            sy * sp * cr - cy * sr,
            -sp,
            cp * sr,
            cp * cr,
        );
        Self { rot, pos: xyz }
    }

    /// `self · other`: `other` expressed in `self`'s parent frame.
    #[inline]
    pub fn then(&self, other: &Pose) -> Pose {
        Pose {
            rot: self.rot * other.rot,
            pos: self.rot * other.pos + self.pos,
        }
    }

    pub fn inverse(&self) -> Pose {
        let rt = self.rot.transpose();
        Pose {
            rot: rt,
            pos: -(rt * self.pos),
        }
    }

    /// A point given in the child frame, in the parent frame.
    #[inline(always)]
    pub fn apply(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.rot * x + self.pos
    }

    /// The homogeneous 4×4 matrix.
    pub fn matrix(&self) -> Matrix4<f64> {
        let mut m = Matrix4::identity();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.rot);
        m.fixed_view_mut::<3, 1>(0, 3).copy_from(&self.pos);
        m
    }
}

/// A rotation taking the z axis onto the unit vector `a` (any one: the angle about `a` is free).
pub fn z_onto(a: &Vector3<f64>) -> Matrix3<f64> {
    if a.z < 0.0 {
        // Near −z the formula below divides by ~0: go through the half turn about x instead.
        let flip = Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0);
        return flip * z_onto(&Vector3::new(a.x, -a.y, -a.z));
    }
    // Rodrigues with k = z × a (|k| = sin θ, c = cos θ): R = I + [k]× + [k]×² / (1 + c).
    let k = Vector3::z().cross(a);
    let kx = k.cross_matrix();
    Matrix3::identity() + kx + kx * kx / (1.0 + a.z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn z_onto_maps_z_to_the_axis_and_is_a_rotation() {
        for a in [
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::new(0.0, 0.0, -1.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.3, -0.4, 0.5).normalize(),
            Vector3::new(0.0, 1e-9, -1.0).normalize(),
        ] {
            let r = z_onto(&a);
            assert!((r * Vector3::z() - a).norm() < 1e-14, "{a:?}");
            assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-14);
            assert!((r.determinant() - 1.0).abs() < 1e-14);
        }
    }

    #[test]
    fn inverse_undoes_then() {
        let p = Pose::from_xyz_rpy(Vector3::new(0.1, -0.2, 0.3), Vector3::new(0.4, -1.1, 2.0));
        let e = p.then(&p.inverse());
        assert!((e.rot - Matrix3::identity()).norm() < 1e-14 && e.pos.norm() < 1e-15);
    }
}
