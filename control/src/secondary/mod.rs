//! Secondary tasks for the null space: the obstacle-avoidance potential of docs/science.md, "The control law".
//!
//! The potential is a sum of one-sided quadratic penalties, so its gradient is written out by
//! the chain rule over the joint positions and their Jacobians, which both arm models provide.
//! Obstacles live in a fixed-capacity array so a parameter block stays `Copy` and can be handed to
//! the real-time loop without allocating.

pub mod balls;
pub mod custom;
pub mod spatial;

use crate::arm::{Jac, Kinematics, Vec2, VecN};

pub use balls::{Ball, Balls, ObstaclesFull, MAX_OBSTACLES};

/// A circular obstacle O_i with radius r_i and safety margin s_i.
pub type Obstacle = Ball<2>;

/// Up to [`MAX_OBSTACLES`] discs.
pub type ObstacleSet = Balls<2>;

/// Weights W₁ (link-distance terms) and W₂ (joint-distance terms).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PotentialWeights {
    pub w1: f64,
    pub w2: f64,
}

#[inline(always)]
fn cross(a: Vec2, b: Vec2) -> f64 {
    a.x * b.y - a.y * b.x
}

/// Link j's end points and their Jacobians.
#[inline(always)]
fn link<const N: usize>(kin: &Kinematics<N>, j: usize) -> (Vec2, Vec2, &Jac<N>, &Jac<N>) {
    if j + 1 < N {
        (
            kin.points[j],
            kin.points[j + 1],
            &kin.point_jac[j],
            &kin.point_jac[j + 1],
        )
    } else {
        (kin.points[j], kin.p, &kin.point_jac[j], &kin.ee_jac)
    }
}

/// The potential h(q) and its gradient ∇h (at fixed base attitude).
pub fn potential<const N: usize>(
    kin: &Kinematics<N>,
    obstacles: &ObstacleSet,
    w: PotentialWeights,
) -> (f64, VecN<N>) {
    let mut h = 0.0;
    let mut grad = VecN::<N>::zeros();
    for o in obstacles.as_slice() {
        let reach = o.radius + o.margin;
        for j in 0..N {
            let (a, b, ja, jb) = link(kin, j);
            // F¹: distance to the line of link j, when the foot lies on the link.
            let d = b - a;
            let l2 = d.norm_squared();
            if l2 > 0.0 {
                let rel = o.center - a;
                let t = rel.dot(&d) / l2;
                if (0.0..=1.0).contains(&t) {
                    let l = l2.sqrt();
                    let sigma = cross(d, rel);
                    let e = sigma.abs() / l - reach;
                    if e < 0.0 {
                        h += 0.5 * w.w1 * e * e;
                        let sgn = sigma.signum() / l;
                        for k in 0..N {
                            let dd = jb.column(k) - ja.column(k);
                            let da = ja.column(k).into_owned();
                            // The link length is constant, so only σ moves.
                            let dsigma = cross(dd, rel) - cross(d, da);
                            grad[k] += w.w1 * e * sgn * dsigma;
                        }
                    }
                }
            }
            // F²: distance to joint j+1 (P_2 … P_{n+1}).
            let rel = b - o.center;
            let d2 = rel.norm();
            let e = d2 - reach;
            if e < 0.0 && d2 > 0.0 {
                h += 0.5 * w.w2 * e * e;
                let g = jb.transpose() * (rel / d2);
                grad += g * (w.w2 * e);
            }
        }
    }
    (h, grad)
}

/// Smallest distance from an obstacle's surface to the arm (negative: penetration), and
/// whether any part of the arm is inside an obstacle's safety zone r_i + s_i.
pub fn clearance<const N: usize>(kin: &Kinematics<N>, obstacles: &ObstacleSet) -> (f64, bool) {
    let point = |k: usize| if k < N { kin.points[k] } else { kin.p };
    balls::clearance(obstacles, N, |j| (point(j), point(j + 1)), &[0.0; N])
}
