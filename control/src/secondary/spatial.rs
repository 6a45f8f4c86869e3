//! Secondary tasks for a spatial arm's null space (docs/science.md, "The control law" and "Spatial arms"): manipulability ascent,
//! joint-limit centring and the obstacle potential of spheres against link capsules.
//!
//! Each returns its value and gradient. The manipulability gradient is analytic: for revolute
//! joints ∂J_i/∂q_k is a cross product of columns already in J (below), so it costs O(n²m) and
//! no second kinematics pass; `tests` check every gradient against finite differences.

use crate::arm::point::Links;
use crate::arm::spatial::Segments;
use crate::arm::spatial::SpatialArm;
use crate::arm::spatial::SpatialKinematics;
use crate::arm::spatial::VecN;
use crate::arm::MANIPULABILITY_FLOOR;
use crate::task::Vec3;
use nalgebra::{SMatrix, SVector};

/// The most spheres one parameter block holds.
pub const MAX_SPHERES: usize = crate::secondary::MAX_OBSTACLES;

/// A spherical obstacle with the safety margin its potential starts at.
pub type Sphere = crate::secondary::Ball<3>;

/// Up to [`MAX_SPHERES`] spheres.
pub type SphereSet = crate::secondary::Balls<3>;

/// The first M rows of the tool Jacobian's column i.
#[inline(always)]
fn col6<const N: usize>(kin: &SpatialKinematics<N>, i: usize) -> (Vec3, Vec3) {
    let c = kin.jac.column(i);
    (Vec3::new(c[0], c[1], c[2]), Vec3::new(c[3], c[4], c[5]))
}

/// w = √det(J Jᵀ) of the task rows `j` (the first M rows of `kin.jac`) and ∇w.
///
/// ∂w/∂q_k = w·Σ_i (A⁻¹J)_i · ∂J_i/∂q_k with A = JJᵀ, and for a revolute joint k
/// ∂J_i/∂q_k = z_k × J_i (k ≤ i), [z_i × J_v,k; 0] (k > i, i revolute); 0 otherwise.
pub fn manipulability<const N: usize, const M: usize>(
    arm: &SpatialArm<N>,
    kin: &SpatialKinematics<N>,
    j: &SMatrix<f64, M, N>,
) -> (f64, VecN<N>) {
    let mut grad = VecN::<N>::zeros();
    // det(A) = Π L_rr² from A = LLᵀ; A is only semi-definite at a singularity.
    let Some(chol) = (j * j.transpose()).cholesky() else {
        return (0.0, grad);
    };
    let w = chol.l_dirty().diagonal().iter().product::<f64>().abs();
    if w < MANIPULABILITY_FLOOR {
        return (w, grad);
    }
    let p = chol.solve(j);
    let prism = &arm.model.prismatic;
    for k in 0..N {
        let zk = kin.axis(k);
        let (jvk, _) = col6(kin, k);
        let mut tr = 0.0;
        for i in 0..N {
            let h = if k <= i {
                if prism[k] {
                    continue;
                }
                let (jv, jw) = col6(kin, i);
                (zk.cross(&jv), zk.cross(&jw))
            } else {
                if prism[i] {
                    continue;
                }
                (kin.axis(i).cross(&jvk), Vec3::zeros())
            };
            let h6 = [h.0.x, h.0.y, h.0.z, h.1.x, h.1.y, h.1.z];
            tr += (0..M).map(|r| p[(r, i)] * h6[r]).sum::<f64>();
        }
        grad[k] = w * tr;
    }
    (w, grad)
}

/// Joint-limit centring: c = ½ Σ ((q_i − q̄_i)/(q_max,i − q_min,i))² over the joints with
/// finite limits, and ∇c. Its descent (η = −∇c) pulls each joint to the middle of its range.
pub fn centring<const N: usize>(q: &VecN<N>, q_min: &[f64], q_max: &[f64]) -> (f64, VecN<N>) {
    let mut c = 0.0;
    let mut grad = VecN::<N>::zeros();
    for i in 0..N {
        let range = q_max[i] - q_min[i];
        if !range.is_finite() || range <= 0.0 {
            continue;
        }
        let e = (q[i] - 0.5 * (q_max[i] + q_min[i])) / range;
        c += 0.5 * e * e;
        grad[i] = e / range;
    }
    (c, grad)
}

/// The closest point of segment [a, b] to c, as the parameter t ∈ [0, 1].
#[inline(always)]
pub fn segment_parameter(a: &Vec3, b: &Vec3, c: &Vec3) -> f64 {
    let e = b - a;
    let l2 = e.norm_squared();
    if l2 > 0.0 {
        ((c - a).dot(&e) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// The obstacle potential h = ½W Σ (d − r_s − s − r_link)² over every capsule closer than its
/// zone (d: centre to segment), and ∇h. The one-sided quadratic of §2 with the point-to-segment
/// distance of §8, so its gradient is the closest point's Jacobian along the push direction.
pub fn potential<const N: usize>(
    arm: &SpatialArm<N>,
    links: &Links<'_, N, 3>,
    spheres: &SphereSet,
    weight: f64,
) -> (f64, VecN<N>) {
    let mut h = 0.0;
    let mut grad = VecN::<N>::zeros();
    for s in spheres.as_slice() {
        for j in 0..N {
            let (pa, pb) = links.link(j);
            let t = segment_parameter(&pa.pos, &pb.pos, &s.center);
            let x = pa.pos + (pb.pos - pa.pos) * t;
            let rel = x - s.center;
            let d = rel.norm();
            let e = d - (s.radius + s.margin + arm.radii[j]);
            if e >= 0.0 || d <= 0.0 {
                continue;
            }
            h += 0.5 * weight * e * e;
            // The foot moves with the segment; its own slide along the segment is ⟂ to rel.
            let jx = pa.jac + (pb.jac - pa.jac) * t;
            grad += jx.transpose() * (rel / d) * (weight * e);
        }
    }
    (h, grad)
}

/// Smallest distance from a sphere's surface to a capsule's surface (negative: penetration), and
/// whether any capsule is inside a sphere's zone r + margin.
pub fn clearance<const N: usize>(
    arm: &SpatialArm<N>,
    segments: &Segments,
    spheres: &SphereSet,
) -> (f64, bool) {
    crate::secondary::balls::clearance(spheres, N, |j| (segments[j][0], segments[j][1]), &arm.radii)
}

/// Selects the task rows: the first M of a 6-vector.
#[inline(always)]
pub fn rows<const M: usize>(v: &nalgebra::Vector6<f64>) -> SVector<f64, M> {
    SVector::<f64, M>::from_fn(|r, _| v[r])
}
