//! Spatial (6-D) motion, force and inertia, all in the base frame about its origin.
//!
//! The dynamics run in the base frame rather than in each body's frame (Featherstone's usual
//! choice): a body's inertia is turned into the base frame once per call, and then the
//! recursions never transform a vector or an inertia between frames again. Accumulating a
//! subtree's inertia is a plain sum, which is what makes CRBA and ABA cheap here.

use super::chain::Body;
use super::pose::Pose;
use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

/// A twist or an acceleration: angular part `w`, linear part `v` of the point at the origin.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Motion {
    pub w: Vector3<f64>,
    pub v: Vector3<f64>,
}

/// A wrench: moment `n` about the origin and force `f`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Force {
    pub n: Vector3<f64>,
    pub f: Vector3<f64>,
}

impl Motion {
    pub const ZERO: Motion = Motion {
        w: Vector3::new(0.0, 0.0, 0.0),
        v: Vector3::new(0.0, 0.0, 0.0),
    };

    /// A joint's motion subspace: rotation about, or sliding along, the unit axis `z` at `o`.
    #[inline(always)]
    pub fn axis(prismatic: bool, z: &Vector3<f64>, o: &Vector3<f64>) -> Motion {
        if prismatic {
            Motion {
                w: Vector3::zeros(),
                v: *z,
            }
        } else {
            Motion {
                w: *z,
                v: o.cross(z),
            }
        }
    }

    #[inline(always)]
    pub fn scaled(&self, s: f64) -> Motion {
        Motion {
            w: self.w * s,
            v: self.v * s,
        }
    }

    #[inline(always)]
    pub fn plus(&self, o: &Motion) -> Motion {
        Motion {
            w: self.w + o.w,
            v: self.v + o.v,
        }
    }

    /// `self ×ₘ m`: the rate of change of `m` carried along by the motion `self`.
    #[inline(always)]
    pub fn cross(&self, m: &Motion) -> Motion {
        Motion {
            w: self.w.cross(&m.w),
            v: self.w.cross(&m.v) + self.v.cross(&m.w),
        }
    }

    /// `self ×* f`: the rate of change of a wrench carried along by the motion `self`.
    #[inline(always)]
    pub fn cross_force(&self, f: &Force) -> Force {
        Force {
            n: self.w.cross(&f.n) + self.v.cross(&f.f),
            f: self.w.cross(&f.f),
        }
    }

    /// The power of a wrench on this motion (a joint torque when `self` is the joint axis).
    #[inline(always)]
    pub fn dot(&self, f: &Force) -> f64 {
        self.w.dot(&f.n) + self.v.dot(&f.f)
    }

    /// [`Motion::dot`] summed as one 6-vector, term after term from the angular part on (the
    /// order of nalgebra's `dot` and `tr_mul`, so that results stay the same to the bit).
    #[inline(always)]
    pub fn power(&self, f: &Force) -> f64 {
        let mut r = 0.0;
        r += self.w.x * f.n.x;
        r += self.w.y * f.n.y;
        r += self.w.z * f.n.z;
        r += self.v.x * f.f.x;
        r += self.v.y * f.f.y;
        r += self.v.z * f.f.z;
        r
    }

    #[inline(always)]
    pub fn to_vector(self) -> Vector6<f64> {
        Vector6::new(self.w.x, self.w.y, self.w.z, self.v.x, self.v.y, self.v.z)
    }
}

impl Force {
    pub const ZERO: Force = Force {
        n: Vector3::new(0.0, 0.0, 0.0),
        f: Vector3::new(0.0, 0.0, 0.0),
    };

    #[inline(always)]
    pub fn plus(&self, o: &Force) -> Force {
        Force {
            n: self.n + o.n,
            f: self.f + o.f,
        }
    }

    #[inline(always)]
    pub fn to_vector(self) -> Vector6<f64> {
        Vector6::new(self.n.x, self.n.y, self.n.z, self.f.x, self.f.y, self.f.z)
    }
}

/// A rigid body's inertia about the base origin: mass, first moment m·c and the rotational
/// inertia about the origin (symmetric).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Inertia {
    pub m: f64,
    pub h: Vector3<f64>,
    pub i: Matrix3<f64>,
}

impl Inertia {
    /// `body` (given in a frame at `pose`) in the base frame.
    #[inline(always)]
    pub fn of(body: &Body, pose: &Pose) -> Inertia {
        let c = pose.apply(&body.com);
        let m = body.mass;
        // R I Rᵀ is symmetric: R·I in full, then only the upper triangle of (R·I)·Rᵀ.
        let r = &pose.rot;
        let ri = r * body.inertia;
        let e = |a: usize, b: usize| {
            ri[(a, 0)] * r[(b, 0)] + ri[(a, 1)] * r[(b, 1)] + ri[(a, 2)] * r[(b, 2)]
        };
        let (xx, yy, zz) = (
            c.y * c.y + c.z * c.z,
            c.x * c.x + c.z * c.z,
            c.x * c.x + c.y * c.y,
        );
        let (ixx, iyy, izz) = (e(0, 0) + m * xx, e(1, 1) + m * yy, e(2, 2) + m * zz);
        let ixy = e(0, 1) - m * c.x * c.y;
        let ixz = e(0, 2) - m * c.x * c.z;
        let iyz = e(1, 2) - m * c.y * c.z;
        Inertia {
            m,
            h: c * m,
            i: Matrix3::new(ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz),
        }
    }

    #[inline(always)]
    pub fn add(&mut self, o: &Inertia) {
        self.m += o.m;
        self.h += o.h;
        self.i += o.i;
    }

    /// The momentum (wrench) of this body moving with `v`.
    #[inline(always)]
    pub fn apply(&self, v: &Motion) -> Force {
        Force {
            n: self.i * v.w + self.h.cross(&v.v),
            f: v.v * self.m - self.h.cross(&v.w),
        }
    }

    /// The 6×6 matrix taking (w, v) to (n, f).
    pub fn matrix(&self) -> Matrix6<f64> {
        let hx = self.h.cross_matrix();
        let mut out = Matrix6::zeros();
        out.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.i);
        out.fixed_view_mut::<3, 3>(0, 3).copy_from(&hx);
        out.fixed_view_mut::<3, 3>(3, 0).copy_from(&hx.transpose());
        out.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(Matrix3::identity() * self.m));
        out
    }
}
