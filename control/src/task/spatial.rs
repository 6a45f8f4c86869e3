//! Spatial tasks: where the tool point should be, and (pose task) how the tool should be turned
//! (docs/science.md, "Spatial arms").
//!
//! A path lies in a plane given by its normal, so the same description fits an arm of any
//! orientation; the in-plane basis is fixed by a rule (below) rather than by the user, so that a
//! config of centre, normal and radius names exactly one trajectory.

use nalgebra::{Rotation3, Vector3};
use std::f64::consts::TAU;

pub type Vec3 = Vector3<f64>;

/// The closed curve the tool point follows; both have period T = 2π/ω.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Shape {
    /// c + r(cos ωt·u + sin ωt·v).
    #[default]
    Circle,
    /// c + r(sin ωt·u + ½ sin 2ωt·v).
    Eight,
}

/// A path in the plane through `center` normal to `normal`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Path {
    pub shape: Shape,
    pub center: Vec3,
    pub radius: f64,
    pub period: f64,
    /// In-plane basis: u is the base z axis projected onto the plane (the base x axis when the
    /// plane is nearly horizontal), v = n × u.
    pub u: Vec3,
    pub v: Vec3,
    /// Seconds over which the path speeds up from rest ([`crate::task::ramp`]); 0 unless
    /// [`Self::with_ramp`] sets it.
    pub ramp: f64,
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

impl Path {
    /// `normal` need not be unit length but must not be zero.
    ///
    /// ```
    /// use control::task::spatial::{Path, Shape, Vec3};
    /// let p = Path::new(Shape::Circle, Vec3::new(0.5, 0.0, 0.5), Vec3::x(), 0.1, 2.0).unwrap();
    /// assert!((p.position(0.0) - Vec3::new(0.5, 0.0, 0.6)).norm() < 1e-15); // u = z
    /// assert!(Path::new(Shape::Circle, Vec3::zeros(), Vec3::zeros(), 0.1, 2.0).is_none());
    /// ```
    pub fn new(shape: Shape, center: Vec3, normal: Vec3, radius: f64, period: f64) -> Option<Self> {
        let n = normal.try_normalize(1e-12)?;
        let up = if n.z.abs() > 0.9 {
            Vec3::x()
        } else {
            Vec3::z()
        };
        let u = (up - n * n.dot(&up)).normalize();
        Some(Self {
            shape,
            center,
            radius,
            period,
            u,
            v: n.cross(&u),
            ramp: 0.0,
        })
    }

    /// The same path starting from rest, up to speed over `seconds` ([`crate::task::ramp`]).
    pub fn with_ramp(mut self, seconds: f64) -> Self {
        self.ramp = seconds;
        self
    }

    pub fn normal(&self) -> Vec3 {
        self.u.cross(&self.v)
    }

    pub fn omega(&self) -> f64 {
        TAU / self.period
    }

    pub fn position(&self, t: f64) -> Vec3 {
        self.at(t).0
    }

    /// Position, velocity and acceleration at time t.
    #[inline]
    pub fn at(&self, t: f64) -> (Vec3, Vec3, Vec3) {
        if self.ramp <= 0.0 {
            return self.at_full_speed(t);
        }
        let (s, ds, dds) = crate::task::ramp(t, self.ramp);
        let (p, v, a) = self.at_full_speed(s);
        (p, v * ds, a * (ds * ds) + v * dds)
    }

    /// The path without its ramp: at full speed from t = 0.
    #[inline]
    fn at_full_speed(&self, t: f64) -> (Vec3, Vec3, Vec3) {
        let w = self.omega();
        let r = self.radius;
        let (s, c) = (w * t).sin_cos();
        match self.shape {
            Shape::Circle => (
                self.center + (self.u * c + self.v * s) * r,
                (self.v * c - self.u * s) * (r * w),
                (self.u * c + self.v * s) * (-r * w * w),
            ),
            Shape::Eight => {
                let (s2, c2) = (2.0 * w * t).sin_cos();
                (
                    self.center + (self.u * s + self.v * (0.5 * s2)) * r,
                    (self.u * c + self.v * c2) * (r * w),
                    (self.u * (-s) - self.v * (2.0 * s2)) * (r * w * w),
                )
            }
        }
    }
}

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
            $crate::task::spatial::TaskKind::Position => {
                const $m: usize = 3;
                $body
            }
            $crate::task::spatial::TaskKind::Pose => {
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
    fn derivatives_match_finite_differences() {
        for shape in [Shape::Circle, Shape::Eight] {
            let n = Vec3::new(1.0, 0.3, -0.2);
            let c = Path::new(shape, Vec3::new(0.4, 0.1, 0.5), n, 0.15, 2.0).unwrap();
            assert!(c.u.dot(&n).abs() < 1e-15 && c.v.dot(&n).abs() < 1e-15);
            let h = 1e-6;
            for &t in &[0.0, 0.13, 0.77, 3.4] {
                let ((a, va, _), (b, vb, _), (_, v, acc)) = (c.at(t - h), c.at(t + h), c.at(t));
                assert!(((b - a) / (2.0 * h) - v).norm() < 1e-8, "{shape:?}");
                assert!(((vb - va) / (2.0 * h) - acc).norm() < 1e-6, "{shape:?}");
            }
            assert!((c.position(0.0) - c.position(2.0)).norm() < 1e-14);
            // Ramped: the same start point, at rest, the same derivatives' consistency, and the
            // path at full speed half a ramp behind once it is up to speed.
            let r = c.with_ramp(1.0);
            let (p0, v0, a0) = r.at(0.0);
            assert_eq!(
                (p0, v0, a0),
                (c.position(0.0), Vec3::zeros(), Vec3::zeros())
            );
            for &t in &[0.2, 0.6, 0.99, 1.01, 2.5] {
                let ((a, va, _), (b, vb, _), (_, v, acc)) = (r.at(t - h), r.at(t + h), r.at(t));
                assert!(((b - a) / (2.0 * h) - v).norm() < 1e-8, "{shape:?} {t}");
                assert!(((vb - va) / (2.0 * h) - acc).norm() < 1e-6, "{shape:?} {t}");
            }
            assert!((r.position(3.0) - c.position(2.5)).norm() < 1e-14);
        }
    }

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
