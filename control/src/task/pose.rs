//! A chain's task rows: the tool point's position (m = 3) or its whole pose (m = 6), the
//! orientation held along the path, and the orientation error (docs/science.md, "Spatial arms").
//!
//! The path itself is every arm's ([`super::Path`]); only an arm whose tool can turn in space
//! has an orientation to hold, so this part is a chain's alone.

use super::{Path, Vec3};
use nalgebra::Rotation3;

/// Which task rows the law controls.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum TaskKind {
    /// The tool point's position: m = 3.
    #[default]
    Position,
    /// Position and orientation: m = 6, orientation error log(R_d Rᵀ) as a rotation vector.
    Pose,
}

impl TaskKind {
    /// The task dimension m.
    pub fn rows(self) -> usize {
        match self {
            TaskKind::Position => 3,
            TaskKind::Pose => 6,
        }
    }
}

/// The desired motion at one instant: tool position, velocity, acceleration, and the tool's
/// orientation with its angular velocity and acceleration (zero for a held orientation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Target {
    pub p: Vec3,
    pub v: Vec3,
    pub a: Vec3,
    pub rot: Rotation3<f64>,
    pub w: Vec3,
    pub wd: Vec3,
}

/// A path and the orientation to hold along it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialTask {
    pub kind: TaskKind,
    pub path: Path,
    /// The tool orientation for the pose task (in the base frame).
    pub orientation: Rotation3<f64>,
}

impl SpatialTask {
    #[inline]
    pub fn at(&self, t: f64) -> Target {
        let (p, v, a) = self.path.at(t);
        Target {
            p,
            v,
            a,
            rot: self.orientation,
            w: Vec3::zeros(),
            wd: Vec3::zeros(),
        }
    }
}

/// The orientation error e_o = log(R_d Rᵀ) as a rotation vector in the base frame.
///
/// θ = atan2(|v|, (tr R − 1)/2) with v the axial vector of the skew part, which is accurate at
/// every angle (acos of the trace loses everything near 0, and rounding can push it past 1 and
/// give NaN); near θ = π the axis comes from the symmetric part instead.
#[inline]
pub fn orientation_error(desired: &Rotation3<f64>, actual: &nalgebra::Matrix3<f64>) -> Vec3 {
    let r = desired.matrix() * actual.transpose();
    let v = Vec3::new(
        r[(2, 1)] - r[(1, 2)],
        r[(0, 2)] - r[(2, 0)],
        r[(1, 0)] - r[(0, 1)],
    ) * 0.5;
    let c = 0.5 * (r.trace() - 1.0);
    let s = v.norm();
    if c > -0.99 {
        return if s < 1e-300 {
            Vec3::zeros()
        } else {
            v * (s.atan2(c) / s)
        };
    }
    // Near π: the symmetric part is cI + (1 − c)aaᵀ; its largest column of aaᵀ gives a, and v
    // (= sin θ·a) gives the sign.
    let m = (r + r.transpose()) * 0.5 - nalgebra::Matrix3::identity() * c;
    let k = (0..3)
        .max_by(|&i, &j| m[(i, i)].total_cmp(&m[(j, j)]))
        .unwrap_or(0);
    let mut a = m.column(k).into_owned().normalize();
    if a.dot(&v) < 0.0 {
        a = -a;
    }
    a * s.atan2(c)
}

/// Calls `$body` with `const M: usize` bound to the task's row count (3 or 6).
#[macro_export]
macro_rules! with_task_rows {
    ($kind:expr, |$m:ident| $body:expr) => {
        match $kind {
            $crate::task::pose::TaskKind::Position => {
                const $m: usize = 3;
                $body
            }
            $crate::task::pose::TaskKind::Pose => {
                const $m: usize = 6;
                $body
            }
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orientation_error_is_the_rotation_vector() {
        let d = Rotation3::from_scaled_axis(Vec3::new(0.1, -0.2, 0.3));
        let a = Rotation3::from_scaled_axis(Vec3::new(0.0, 0.05, 0.0));
        let e = orientation_error(&d, a.matrix());
        let back = Rotation3::from_scaled_axis(e) * a;
        assert!((back.matrix() - d.matrix()).norm() < 1e-14);
        // Every angle, including 0 exactly and close to π.
        for angle in [0.0, 1e-9, 0.5, 3.0, 3.1, std::f64::consts::PI - 1e-9] {
            let axis = Vec3::new(0.3, -0.5, 0.8).normalize();
            let d = Rotation3::from_scaled_axis(axis * angle);
            let e = orientation_error(&d, Rotation3::identity().matrix());
            assert!((e - axis * angle).norm() < 1e-7, "{angle}: {e}");
        }
    }
}
