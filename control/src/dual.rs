//! Forward-mode automatic differentiation, just enough for the floating-base model.
//!
//! The free-floating arm's generalized Jacobian J* is a rational function of q (it contains the
//! inverse of the base inertia H_b). Writing dJ*/dt by hand is long and easy to get wrong, so the
//! model is written once, generic over [`Real`], and evaluated with [`Dual`] numbers when a
//! directional derivative is needed (J̇*q̇, ∇w). The result is exact to rounding, unlike finite
//! differences, and costs no allocation.

use core::ops::{Add, Div, Mul, Neg, Sub};

/// The scalar operations the generic kinematics need.
pub trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    fn cst(v: f64) -> Self;
    fn re(self) -> f64;
    fn sin_cos(self) -> (Self, Self);
    fn sqrt(self) -> Self;
    fn scale(self, k: f64) -> Self;
}

impl Real for f64 {
    #[inline(always)]
    fn cst(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn re(self) -> f64 {
        self
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        f64::sin_cos(self)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn scale(self, k: f64) -> Self {
        self * k
    }
}

/// A dual number `re + du·ε` with `ε² = 0`.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Dual {
    pub re: f64,
    pub du: f64,
}

impl Dual {
    #[inline(always)]
    pub const fn new(re: f64, du: f64) -> Self {
        Self { re, du }
    }
}

impl Add for Dual {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Self::new(self.re + o.re, self.du + o.du)
    }
}
impl Sub for Dual {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Self::new(self.re - o.re, self.du - o.du)
    }
}
impl Mul for Dual {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        Self::new(self.re * o.re, self.re * o.du + self.du * o.re)
    }
}
impl Div for Dual {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        let inv = 1.0 / o.re;
        Self::new(self.re * inv, (self.du * o.re - self.re * o.du) * inv * inv)
    }
}
impl Neg for Dual {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Self::new(-self.re, -self.du)
    }
}

impl Real for Dual {
    #[inline(always)]
    fn cst(v: f64) -> Self {
        Self::new(v, 0.0)
    }
    #[inline(always)]
    fn re(self) -> f64 {
        self.re
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        let (s, c) = self.re.sin_cos();
        (Self::new(s, c * self.du), Self::new(c, -s * self.du))
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        let r = self.re.sqrt();
        let d = if r > 0.0 { self.du / (2.0 * r) } else { 0.0 };
        Self::new(r, d)
    }
    #[inline(always)]
    fn scale(self, k: f64) -> Self {
        Self::new(self.re * k, self.du * k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dual_matches_calculus() {
        // f(x) = sin(x) * x / (1 + x²), f'(x) by hand.
        let x = 0.7_f64;
        let d = Dual::new(x, 1.0);
        let (s, _) = d.sin_cos();
        let f = s * d / (Dual::cst(1.0) + d * d);
        let fp =
            (x.cos() * x + x.sin()) / (1.0 + x * x) - x.sin() * x * 2.0 * x / (1.0 + x * x).powi(2);
        assert!((f.re - x.sin() * x / (1.0 + x * x)).abs() < 1e-15);
        assert!((f.du - fp).abs() < 1e-14, "{} vs {}", f.du, fp);
        let r = Dual::new(4.0, 1.0).sqrt();
        assert_eq!(r, Dual::new(2.0, 0.25));
    }
}
