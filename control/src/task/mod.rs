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
    fn derivatives_match_finite_differences() {
        let c = Circle {
            center: Vec2::new(1.0, 2.0),
            radius: 0.5,
            period: 1.0,
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
