//! A bound that clears a link against a far ball without building its barrier row.
//!
//! The check that nothing binds ([`super::rows::any_ball_missed`]) computes every link's foot
//! point against every ball: a square root, one or two divisions and some sixty flops a pair, 28
//! pairs on the Panda with four spheres, on every evaluation. Most pairs are far apart, and for
//! them the row's slack b − a·q̈ is bounded by terms known per link, before any ball is looked at.
//!
//! For a link from A to B (e = B − A) and a ball at c, with d the distance from c to the link and
//! h = d − reach, the row of [`super::rows::segment_foot`] has, on every piece of the segment,
//!
//! b − a·q̈ ≤ k₁V + D + Q − k₀h + 2d·|ė|²/|e|² + 2V²/d
//!
//! where V, D and Q bound the speed, the drift J̇q̇ and the image J q̈ of every point of the link
//! (the larger of the two end points': each point of the link is a convex combination of them).
//! The end-point pieces need only the first four terms (their curvature term only lowers b). On
//! the interior piece the foot slides, and its terms add up to −(|ẋ|² − (u·ẋ)²)/d ≤ 0 plus
//! (d u·ė + e·ẋ)²/(|e|²d) ≤ 2d|ė|²/|e|² + 2|ẋ|²/d, the second the centripetal pull of a
//! turning line (−dω² for a line turning at ω about a point near it). Below k₀/2 the bound falls
//! with d, so a lower bound on d (the distance to the segment's bounding sphere) clears the pair
//! when the bound is negative there: the row is then met by more than the check's tolerance, and
//! the check's answer is the one it would have computed.

use crate::arm::point::Links;
use crate::arm::VecN;
use crate::basics::MAX_JOINTS;
use nalgebra::Vector3;

/// One link's share of the bound, computed once per evaluation.
#[derive(Clone, Copy, Debug, Default)]
pub struct LinkBound {
    /// The midpoint and half the length: every point of the link lies within `half` of `mid`.
    mid: Vector3<f64>,
    half: f64,
    /// k₁V + D + Q.
    push: f64,
    /// 2V².
    speed2: f64,
    /// k₀ − 2|ė|²/|e|²; the bound clears nothing where it is not positive.
    fall: f64,
}

impl LinkBound {
    /// The bound of the link from `points[j]` to `points[j + 1]`, given the images J q̈ of the
    /// end points and the barrier gains (k₀, k₁).
    #[inline]
    pub fn of<const N: usize>(
        links: &Links<'_, N, 3>,
        image: &[Vector3<f64>],
        j: usize,
        (k0, k1): (f64, f64),
    ) -> Self {
        let (ia, ib) = links.ends(j);
        let (a, b) = links.link(j);
        let e = b.pos - a.pos;
        let l2 = e.norm_squared();
        let speed2 = a.vel.norm_squared().max(b.vel.norm_squared());
        let drift2 = a.drift.norm_squared().max(b.drift.norm_squared());
        let image2 = image[ia].norm_squared().max(image[ib].norm_squared());
        // A segment of no length has only its end-point piece: no slide, no spin term.
        let spin = if l2 > 0.0 {
            (b.vel - a.vel).norm_squared() / l2
        } else {
            0.0
        };
        Self {
            mid: (a.pos + b.pos) * 0.5,
            half: 0.5 * l2.sqrt(),
            push: k1 * speed2.sqrt() + drift2.sqrt() + image2.sqrt(),
            speed2: 2.0 * speed2,
            fall: k0 - 2.0 * spin,
        }
    }

    /// True when the link's row against a ball at `center` is surely met: b − a·q̈ < 0 with a
    /// margin, so the exact check could not call it missed. False says nothing.
    #[inline]
    pub fn clears(&self, center: &Vector3<f64>, reach: f64, k0: f64) -> bool {
        let d = (center - self.mid).norm() - self.half;
        if d <= reach || self.fall <= 0.0 {
            return false;
        }
        // (k₀ − 2|ė|²/|e|²)d − 2V²/d − k₀·reach − push > margin, times d > 0.
        let need = k0 * reach + self.push;
        self.fall * d * d - need * d - self.speed2 > 1e-9 * (1.0 + need) * d
    }
}

/// Every link's bound, for an arm of N joints.
pub fn link_bounds<const N: usize>(
    links: &Links<'_, N, 3>,
    image: &[Vector3<f64>],
    gains: (f64, f64),
) -> [LinkBound; MAX_JOINTS] {
    let mut out = [LinkBound::default(); MAX_JOINTS];
    for (j, b) in out.iter_mut().enumerate().take(N) {
        *b = LinkBound::of(links, image, j, gains);
    }
    out
}

/// The images J q̈ of the links' end points, in [`Links::points`]' order.
#[inline]
pub fn images<const N: usize>(
    links: &Links<'_, N, 3>,
    qdd: &VecN<N>,
) -> [Vector3<f64>; 2 * MAX_JOINTS] {
    let mut image = [Vector3::zeros(); 2 * MAX_JOINTS];
    for (im, pt) in image.iter_mut().zip(links.points()) {
        *im = pt.jac * qdd;
    }
    image
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arm::point::PointMotion;
    use crate::arm::spatial::{CapsulePoints, SpatialArm, SpatialKinematics};
    use crate::model::{builtin, Chain};
    use crate::safety::rows::{segment_foot, BarrierGains};
    use crate::safety::solve::misses;

    /// On random Panda states, rates up to 4 rad/s, accelerations up to 30 rad/s² and balls
    /// anywhere in the workspace, every pair the bound clears has a row met with room to spare
    /// (so the check, which skips it, gives the answer it would have computed), and the bound
    /// clears at least half the pairs more than 0.4 m apart (two thirds at these rates; the
    /// arm's own runs are slower), so it saves work.
    #[test]
    fn a_cleared_pair_never_misses_its_row_and_far_pairs_are_cleared() {
        let chain = Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap();
        let arm = SpatialArm::new(chain.model::<7>().unwrap());
        let g = BarrierGains {
            k0: 100.0,
            k1: 20.0,
            push_out_speed: 0.1,
        };
        let mut rnd = crate::basics::rng::uniform(0x5eed_u64);
        let (mut cleared, mut far, mut far_cleared, mut slack_min) = (0, 0, 0, f64::INFINITY);
        let mut kin = SpatialKinematics::default();
        for k in 0..4000 {
            // Half the states fast, half braking hard (large q̈, slow q̇): each term of the
            // bound is the one that decides somewhere.
            let (rate, acc) = if k % 2 == 0 {
                (4.0, 30.0)
            } else {
                (0.3, 600.0)
            };
            let q = VecN::<7>::from_fn(|_, _| 2.5 * rnd());
            let qd = VecN::<7>::from_fn(|_, _| rate * rnd());
            let qdd = VecN::<7>::from_fn(|_, _| acc * rnd());
            arm.kinematics(&q, &qd, &mut kin);
            let mut store = CapsulePoints::default();
            let links = arm.capsule_points(&kin, &qd, &mut store);
            let image = images(&links, &qdd);
            let bounds = link_bounds(&links, &image, (g.k0, g.k1));
            let center = Vector3::new(rnd(), rnd(), 0.5 + 0.6 * rnd());
            let reach = 0.05 + 0.1 * rnd().abs();
            for j in 0..7 {
                let ((a, b), (ia, ib)) = (links.link(j), links.ends(j));
                let Some(foot) = segment_foot(a, b, center, reach, g) else {
                    continue;
                };
                let slack = foot.b - foot.applied(&image[ia], &image[ib]);
                let is_far = foot.h > 0.4 && k % 2 == 0;
                far += is_far as usize;
                if bounds[j].clears(&center, reach, g.k0) {
                    cleared += 1;
                    far_cleared += is_far as usize;
                    slack_min = slack_min.min(-slack);
                    assert!(
                        !misses(foot.b, foot.applied(&image[ia], &image[ib])) && slack < 0.0,
                        "link {j} cleared with slack {slack} at h = {}",
                        foot.h
                    );
                }
            }
        }
        assert!(cleared > 1000, "the bound cleared {cleared} pairs");
        assert!(
            far_cleared * 2 >= far,
            "{far_cleared} of {far} pairs more than 0.4 m apart cleared (fast states)"
        );
        assert!(slack_min > 0.0);
    }

    /// A link turning faster than the barrier's k₀ allows clears nothing: the centripetal term
    /// could outgrow the distance.
    #[test]
    fn a_fast_turning_link_is_never_cleared() {
        let mut points = [PointMotion::<1, 3>::default(); MAX_JOINTS + 1];
        points[1].pos = Vector3::new(0.1, 0.0, 0.0);
        points[1].vel = Vector3::new(0.0, 1.0, 0.0); // |ė|²/|e|² = 100 /s²
        let image = [Vector3::zeros(); MAX_JOINTS + 1];
        let b = LinkBound::of(&Links::chain(&points), &image, 0, (100.0, 20.0));
        assert!(!b.clears(&Vector3::new(0.0, 50.0, 0.0), 0.1, 100.0));
        let slow = LinkBound::of(&Links::chain(&points), &image, 0, (300.0, 20.0));
        assert!(slow.clears(&Vector3::new(0.0, 50.0, 0.0), 0.1, 300.0));
    }
}
