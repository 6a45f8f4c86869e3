//! The safety filter on a spatial arm (docs/science.md, "Keeping clear of obstacles" with §8's capsules): every link capsule
//! clear of every sphere, every joint inside its position, rate and acceleration limits.
//!
//! Only the rows are spatial. The joint box and the solver (null space first, whatever its
//! dimension, then the full joint space, then the acceleration clamp) are the planar filter's
//! own ([`crate::safety::rows::joint_box`], [`crate::safety::solve::smallest_change`]), so the
//! two filters cannot drift apart in behaviour.

use crate::arm::spatial::PointMotion;
use crate::arm::spatial::Points;
use crate::arm::spatial::SpatialArm;
use crate::arm::spatial::SpatialKinematics;
use crate::arm::spatial::VecN;
use crate::basics::MAX_JOINTS;
use crate::safety::rows::{joint_box, BarrierGains};
use crate::safety::{solve, Filtered, SafetyParams};
use crate::secondary::spatial::SphereSet;
use crate::task::spatial::Vec3;
use nalgebra::SMatrix;

/// The barrier h = d − reach of the segment [P_a, P_b] against a centre (reach: sphere radius +
/// link radius + clearance) with its second-order row: returns (h, a, b) for a·q̈ ≥ b.
///
/// On the interior piece the foot x = a + t e slides as t moves, but u = (x − c)/d is normal to
/// e there, so ḣ = u·(ȧ + t ė) and the slide enters ḧ only through ṫ (written out below).
pub fn capsule_row<const N: usize>(
    pa: &PointMotion<N>,
    pb: &PointMotion<N>,
    center: Vec3,
    reach: f64,
    g: BarrierGains,
) -> Option<(f64, VecN<N>, f64)> {
    let e = pb.pos - pa.pos;
    let l2 = e.norm_squared();
    let t = if l2 > 0.0 {
        (center - pa.pos).dot(&e) / l2
    } else {
        0.0
    };
    if t <= 0.0 {
        return point_row(pa, center, reach, g);
    }
    if t >= 1.0 {
        return point_row(pb, center, reach, g);
    }
    let w = pa.pos + e * t - center;
    let d = w.norm();
    if d < 1e-12 {
        return None;
    }
    let u = w / d;
    let h = d - reach;
    let edot = pb.vel - pa.vel;
    let xdot = pa.vel + edot * t;
    let tdot = ((center - pa.pos).dot(&edot) - pa.vel.dot(&e) - 2.0 * t * e.dot(&edot)) / l2;
    let wdot = xdot + e * tdot;
    let udot = (wdot - u * u.dot(&wdot)) / d;
    let hdot = u.dot(&xdot);
    let jx = pa.jac + (pb.jac - pa.jac) * t;
    let a = jx.transpose() * u;
    let drift_x = pa.drift + (pb.drift - pa.drift) * t;
    let drift = u.dot(&drift_x) + udot.dot(&xdot) + tdot * u.dot(&edot);
    Some((h, a, g.rhs(h, hdot) - drift))
}

/// The same for the distance to one point P: ḧ = u·P̈ + (|Ṗ|² − (u·Ṗ)²)/d.
fn point_row<const N: usize>(
    p: &PointMotion<N>,
    center: Vec3,
    reach: f64,
    g: BarrierGains,
) -> Option<(f64, VecN<N>, f64)> {
    let w = p.pos - center;
    let d = w.norm();
    if d < 1e-12 {
        return None;
    }
    let u = w / d;
    let h = d - reach;
    let un = u.dot(&p.vel);
    let curvature = (p.vel.norm_squared() - un * un) / d;
    let a = p.jac.transpose() * u;
    Some((h, a, g.rhs(h, un) - u.dot(&p.drift) - curvature))
}

/// Calls `f(a, b)` for the row of every link capsule against every sphere.
pub fn visit_spheres<const N: usize, F: FnMut(&VecN<N>, f64) + ?Sized>(
    p: &SafetyParams,
    arm: &SpatialArm<N>,
    spheres: &SphereSet,
    points: &Points<N>,
    f: &mut F,
) {
    for s in spheres.as_slice() {
        for j in 0..N {
            let reach = s.radius + arm.radii[j] + p.clearance;
            if let Some((_, a, b)) =
                capsule_row(&points[j], &points[j + 1], s.center, reach, p.gains())
            {
                f(&a, b);
            }
        }
    }
}

/// Filters the law's `qdd`: `j` are the task rows and `jpinv` the pseudo-inverse the law used.
#[allow(clippy::too_many_arguments)]
pub fn filter<const N: usize, const M: usize>(
    p: &SafetyParams,
    arm: &SpatialArm<N>,
    spheres: &SphereSet,
    kin: &SpatialKinematics<N>,
    q: &VecN<N>,
    qd: &VecN<N>,
    j: &SMatrix<f64, M, N>,
    jpinv: &SMatrix<f64, N, M>,
    qdd: &VecN<N>,
) -> Filtered<N> {
    if !p.enabled {
        return Filtered {
            qdd: *qdd,
            flags: 0,
        };
    }
    let (lo, hi) = joint_box(p, q, qd);
    if spheres.is_empty() {
        let none = |_: &mut dyn FnMut(&VecN<N>, f64)| {};
        return solve::smallest_change(&none, (&lo, &hi), j, jpinv, qdd, &p.qdd_max);
    }
    let mut points: Points<N> = [PointMotion::default(); MAX_JOINTS + 1];
    arm.capsule_points(kin, qd, &mut points);
    let visit = |f: &mut dyn FnMut(&VecN<N>, f64)| visit_spheres(p, arm, spheres, &points, f);
    solve::smallest_change(&visit, (&lo, &hi), j, jpinv, qdd, &p.qdd_max)
}
