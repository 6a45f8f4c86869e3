//! The end-effector task: a circle traced at constant speed (docs/science.md, "The planar arm and its task").

pub mod spatial;

use crate::arm::Vec2;
use std::f64::consts::TAU;

/// p_d(t) = c + r (cos ωt, sin ωt), ω = 2π / period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Circle {
    pub center: Vec2,
    pub radius: f64,
    pub period: f64,
    /// Seconds over which the path speeds up from rest ([`ramp`]); 0: it starts at full speed.
    pub ramp: f64,
}

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

/// Desired position, velocity and acceleration at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TaskPoint {
    pub p: Vec2,
    pub v: Vec2,
    pub a: Vec2,
}

impl Circle {
    pub fn omega(&self) -> f64 {
        TAU / self.period
    }

    #[inline]
    pub fn at(&self, t: f64) -> TaskPoint {
        if self.ramp <= 0.0 {
            return self.at_full_speed(t);
        }
        let (s, ds, dds) = ramp(t, self.ramp);
        let b = self.at_full_speed(s);
        TaskPoint {
            p: b.p,
            v: b.v * ds,
            a: b.a * (ds * ds) + b.v * dds,
        }
    }

    /// The circle without its ramp: at full speed from t = 0.
    #[inline]
    fn at_full_speed(&self, t: f64) -> TaskPoint {
        let w = self.omega();
        let (s, c) = (w * t).sin_cos();
        let r = self.radius;
        TaskPoint {
            p: self.center + Vec2::new(c, s) * r,
            v: Vec2::new(-s, c) * (r * w),
            a: Vec2::new(c, s) * (-r * w * w),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ramped_circle_starts_at_rest_and_its_derivatives_match() {
        let c = Circle {
            center: Vec2::new(1.0, 2.0),
            radius: 0.5,
            period: 1.0,
            ramp: 0.8,
        };
        let start = c.at(0.0);
        assert_eq!(start.v, Vec2::zeros());
        assert_eq!(start.a, Vec2::zeros());
        let h = 1e-6;
        for &t in &[0.1, 0.4, 0.79, 0.81, 1.7] {
            let (a, b, m) = (c.at(t - h), c.at(t + h), c.at(t));
            assert!(((b.p - a.p) / (2.0 * h) - m.v).norm() < 1e-7, "t = {t}");
            assert!(((b.v - a.v) / (2.0 * h) - m.a).norm() < 1e-6, "t = {t}");
        }
        // After the ramp: the circle at full speed, half a ramp behind.
        let full = Circle { ramp: 0.0, ..c };
        assert!((c.at(2.0).p - full.at(1.6).p).norm() < 1e-12);
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let c = Circle {
            center: Vec2::new(1.0, 2.0),
            radius: 0.5,
            period: 1.0,
            ramp: 0.0,
        };
        let h = 1e-6;
        for &t in &[0.0, 0.13, 0.77, 3.4] {
            let (a, b, m) = (c.at(t - h), c.at(t + h), c.at(t));
            assert!(((b.p - a.p) / (2.0 * h) - m.v).norm() < 1e-7);
            assert!(((b.v - a.v) / (2.0 * h) - m.a).norm() < 1e-6);
            assert!(((m.p - c.center).norm() - 0.5).abs() < 1e-15);
        }
    }
}
