//! What the relaxation pushes a posture away from: the spheres and the joint limits, as
//! one-sided quadratics that start a buffer beyond what the check demands, so a relaxed cycle
//! keeps a little more than the margin instead of grazing it.

use super::SpatialProblem;
use crate::arm::spatial::SpatialKinematics;
use crate::arm::spatial::VecN;
use crate::secondary::spatial::segment_parameter;

/// How far beyond the demanded clearance the obstacle cost starts (m).
pub const SPHERE_BUFFER: f64 = 0.1;
/// How far inside the demanded joint margin the limit cost starts (rad).
pub const JOINT_BUFFER: f64 = 0.1;
/// The costs' weights: per m² of missing clearance and per rad² of missing joint margin.
const SPHERE_WEIGHT: f64 = 40.0;
const JOINT_WEIGHT: f64 = 4.0;

/// Where one posture stands against the spheres: the nearest link surface to any sphere's
/// surface (m) and which sphere and link that is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Nearest {
    pub clearance: f64,
    pub sphere: usize,
    pub link: usize,
}

impl<const N: usize> SpatialProblem<N> {
    /// The gradient of the obstacle and joint-limit costs at a posture whose kinematics `kin`
    /// holds, for the demanded clearance `need` (m) and joint margin `joint_margin` (rad).
    pub(super) fn cost_gradient(
        &self,
        kin: &SpatialKinematics<N>,
        q: &VecN<N>,
        need: f64,
        joint_margin: f64,
    ) -> VecN<N> {
        let mut g = VecN::<N>::zeros();
        let zero = VecN::<N>::zeros();
        let segments = self.arm.capsule_segments(kin);
        for s in self.law.spheres.as_slice() {
            for j in 0..N {
                let [a, b] = segments[j];
                let t = segment_parameter(&a, &b, &s.center);
                let x = a + (b - a) * t;
                let rel = x - s.center;
                let d = rel.norm();
                let short = need + SPHERE_BUFFER + s.radius + self.arm.radii[j] - d;
                if short <= 0.0 || d <= 1e-12 {
                    continue;
                }
                // The foot moves with link j (its slide along the link is ⟂ to rel).
                let m = self.arm.point_motion(kin, j, x, &zero);
                g -= m.jac.transpose() * (rel / d) * (SPHERE_WEIGHT * short);
            }
        }
        for i in 0..N {
            let lo = self.law.core.safety.q_min[i] + joint_margin + JOINT_BUFFER;
            let hi = self.law.core.safety.q_max[i] - joint_margin - JOINT_BUFFER;
            if q[i] < lo {
                g[i] -= JOINT_WEIGHT * (lo - q[i]);
            } else if q[i] > hi {
                g[i] += JOINT_WEIGHT * (q[i] - hi);
            }
        }
        g
    }

    /// The nearest sphere to any link at a posture whose kinematics `kin` holds (+∞ without
    /// spheres).
    pub fn nearest(&self, kin: &SpatialKinematics<N>) -> Nearest {
        let segments = self.arm.capsule_segments(kin);
        let mut best = Nearest {
            clearance: f64::INFINITY,
            sphere: 0,
            link: 0,
        };
        for (i, s) in self.law.spheres.as_slice().iter().enumerate() {
            for j in 0..N {
                let [a, b] = segments[j];
                let x = a + (b - a) * segment_parameter(&a, &b, &s.center);
                let c = (x - s.center).norm() - s.radius - self.arm.radii[j];
                if c < best.clearance {
                    best = Nearest {
                        clearance: c,
                        sphere: i,
                        link: j,
                    };
                }
            }
        }
        best
    }
}
