//! The end-effector task: a closed path traced at constant speed, the same for every arm
//! (docs/science.md, "The planar arm and its task" and "Spatial arms").
//!
//! A path is a curve in a plane of the base frame. The paper's planar arm traces one in its own
//! plane (normal z, so u = x and v = y and the circle is c + r(cos ωt, sin ωt) to the last bit);
//! a chain's may lie in any plane. So a new shape is written once, in [`Shape`] and
//! [`Path::at`], and every arm can trace it. A chain's pose task adds an orientation to hold
//! ([`pose`]).

pub mod pose;

use nalgebra::{Vector2, Vector3};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

pub type Vec3 = Vector3<f64>;

/// A path's own time σ(t) and its first two derivatives, for a start from rest over `t_r` s.
///
/// A path that starts at full speed asks a hand at rest for a jump in velocity, which the law
/// turns into its largest acceleration of the run (on the Panda, above the joint limits for the
/// first 0.1 s from half of its starts). Over [0, t_r] the path's speed rises as
/// σ̇ = (1 − cos(πt/t_r))/2, so the hand starts at rest and the acceleration is continuous;
/// after it σ = t − t_r/2, the path at its own speed, half a ramp behind. Before t = 0 the path
/// waits at its start. With t_r = 0, σ = t.
///
/// ```
/// use control::task::ramp;
/// assert_eq!(ramp(0.7, 0.0), (0.7, 1.0, 0.0));
/// let (s, ds, dds) = ramp(0.0, 2.0);
/// assert_eq!((s, ds, dds), (0.0, 0.0, 0.0));
/// let (s, ds, dds) = ramp(2.0, 2.0);
/// assert!((s - 1.0).abs() < 1e-15 && (ds - 1.0).abs() < 1e-15 && dds.abs() < 1e-15);
/// assert_eq!(ramp(5.0, 2.0), (4.0, 1.0, 0.0));
/// ```
#[inline]
pub fn ramp(t: f64, t_r: f64) -> (f64, f64, f64) {
    if t_r <= 0.0 {
        return (t, 1.0, 0.0);
    }
    if t >= t_r {
        return (t - 0.5 * t_r, 1.0, 0.0);
    }
    if t <= 0.0 {
        return (0.0, 0.0, 0.0);
    }
    let x = std::f64::consts::PI * t / t_r;
    let (sin, cos) = x.sin_cos();
    (
        0.5 * t - 0.5 * t_r / std::f64::consts::PI * sin,
        0.5 * (1.0 - cos),
        0.5 * std::f64::consts::PI / t_r * sin,
    )
}

/// The closed curve the tool point follows; both have period T = 2π/ω. A file names it in
/// `task.path` (`"circle"`, `"eight"`), the same on every arm.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Shape {
    /// c + r(cos ωt·u + sin ωt·v).
    #[default]
    Circle,
    /// c + r(sin ωt·u + ½ sin 2ωt·v).
    Eight,
}

impl Shape {
    /// Whether this is the default shape (a file that leaves `task.path` out means it).
    pub fn is_circle(&self) -> bool {
        *self == Shape::Circle
    }
}

impl std::fmt::Display for Shape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Shape::Circle => "circle",
            Shape::Eight => "eight",
        })
    }
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
    /// Seconds over which the path speeds up from rest ([`ramp`]); 0 unless
    /// [`Self::with_ramp`] sets it.
    pub ramp: f64,
}

impl Path {
    /// `normal` need not be unit length but must not be zero.
    ///
    /// ```
    /// use control::task::{Path, Shape, Vec3};
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

    /// A path in the plane of the paper's planar arm (z = 0, normal z, so u = x and v = y).
    ///
    /// ```
    /// use control::task::{Path, Shape, Vec3};
    /// let p = Path::in_the_plane(Shape::Circle, [1.0, 2.0], 0.5, 1.0);
    /// assert_eq!(Some(p), Path::new(Shape::Circle, Vec3::new(1.0, 2.0, 0.0), Vec3::z(), 0.5, 1.0));
    /// assert_eq!(p.at_xy(0.0).0, nalgebra::Vector2::new(1.5, 2.0));
    /// ```
    pub fn in_the_plane(shape: Shape, center: [f64; 2], radius: f64, period: f64) -> Self {
        Self {
            shape,
            center: Vec3::new(center[0], center[1], 0.0),
            radius,
            period,
            u: Vec3::x(),
            v: Vec3::y(),
            ramp: 0.0,
        }
    }

    /// The same path starting from rest, up to speed over `seconds` ([`ramp`]).
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

    /// Position, velocity and acceleration at time t in the base's xy plane, for an arm that
    /// moves in it.
    #[inline]
    pub fn at_xy(&self, t: f64) -> (Vector2<f64>, Vector2<f64>, Vector2<f64>) {
        let (p, v, a) = self.at(t);
        (p.xy(), v.xy(), a.xy())
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

    /// The planar arm's path is the paper's circle to the last bit: u = x and v = y exactly,
    /// so every product with a zero component adds an exact zero.
    #[test]
    fn a_path_in_the_arms_plane_is_the_papers_circle_bit_for_bit() {
        let c = Vec3::new(1.0, 2.0, 0.0);
        let (r, period) = (0.5, 1.3);
        let path = Path::new(Shape::Circle, c, Vec3::z(), r, period).unwrap();
        assert_eq!((path.u, path.v), (Vec3::x(), Vec3::y()));
        let w = TAU / period;
        for &t in &[0.0, 0.1, 0.25, 0.77, 3.4, 1e3] {
            let (s, co) = (w * t).sin_cos();
            let (p, v, a) = path.at(t);
            assert_eq!((p.x, p.y, p.z), (c.x + co * r, c.y + s * r, 0.0), "t = {t}");
            assert_eq!((v.x, v.y), (-s * (r * w), co * (r * w)), "t = {t}");
            assert_eq!((a.x, a.y), (co * (-r * w * w), s * (-r * w * w)), "t = {t}");
        }
    }
}
