//! Barrier conditions as linear rows a·q̈ ≥ b (docs/science.md, "Keeping clear of obstacles").
//!
//! A barrier h(q, q̇) ≥ 0 is kept by asking its derivatives to fall no faster than an exponential:
//! ḧ + k₁ḣ + k₀h ≥ 0 for positions (obstacle distance, joint angle) and ḣ + k h ≥ 0 for rates.
//! ḧ = a·q̈ + (the part that does not depend on q̈), so every condition is one row. The rows are
//! produced by a visitor instead of being stored, so the common case (no row binds) costs one pass
//! and no buffer; in space that pass does not even build the rows' normals
//! ([`any_ball_missed`]).
//!
//! One builder serves every arm: a link is the segment between two points (with a radius: a
//! capsule) and an obstacle a ball, in the plane (D = 2) or in space (D = 3). The distance from a
//! centre to a segment switches between "closest to an end point" and "closest to the interior".
//! Both pieces are smooth and agree (with their gradients) at the switch, so the condition is
//! written for whichever piece is active. The end-point piece is the same in every dimension; the
//! interior piece is written per dimension ([`Interior`]): in the plane the link length L is
//! constant, so d = |σ|/L with σ = (B − A) × (c − A), and σ̈ follows from the end points'
//! accelerations Ä = J_A q̈ + D_A (D = J̇ q̇, the drift); in space through the sliding foot point.
//! Each is the formula its arm's reference numbers were computed with.

use super::SafetyParams;
use crate::arm::point::{Links, PointMotion as Pt};
use crate::arm::{ArmModel, Kinematics, Vec2, VecN};
use crate::basics::MAX_JOINTS;
use crate::secondary::{Balls, ObstacleSet};
use nalgebra::{SVector, Vector3};

/// Position, Jacobian, velocity and drift (J̇q̇) of one point of the planar arm.
pub type PointMotion<const N: usize> = crate::arm::point::PointMotion<N, 2>;

/// The arm's N + 1 points (joints 1 … n, then the end effector): P_k for k = 0 … N.
pub type Points<const N: usize> = crate::arm::point::Points<N, 2>;

/// A barrier value h with its row a·q̈ ≥ b: (h, a, b).
pub type Row<const N: usize> = (f64, VecN<N>, f64);

#[inline(always)]
fn cross(a: Vec2, b: Vec2) -> f64 {
    a.x * b.y - a.y * b.x
}

#[inline(always)]
fn perp(v: Vec2) -> Vec2 {
    Vec2::new(-v.y, v.x)
}

/// Positions and Jacobians at fixed base attitude, from `kin` (k = N is the end effector).
fn geometry<const N: usize>(kin: &Kinematics<N>, out: &mut Points<N>) {
    for k in 0..N {
        out[k].pos = kin.points[k];
        out[k].jac = kin.point_jac[k];
    }
    out[N].pos = kin.p;
    out[N].jac = kin.ee_jac;
}

/// Adds the base's rotation about the system's centre of mass (the origin): J* = J + S P gᵀ,
/// with g the base-rate row (φ̇ = g·q̇).
fn add_base_rotation<const N: usize>(kin: &Kinematics<N>, out: &mut Points<N>) {
    for pt in out.iter_mut().take(N + 1) {
        let s = perp(pt.pos);
        for k in 0..N {
            let c = pt.jac.column(k) + s * kin.base_rate_row[k];
            pt.jac.set_column(k, &c);
        }
    }
}

/// Every point's motion at (φ, q, q̇). Closed form for the fixed base; for the floating base
/// the drift is a forward difference of J* along the motion (one more kinematics evaluation).
pub fn point_motions<const N: usize>(
    model: &ArmModel<N>,
    kin: &Kinematics<N>,
    phi: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
    out: &mut Points<N>,
) {
    geometry(kin, out);
    match model {
        ArmModel::Fixed(_) => {
            // D_k = −Σ_{m<k} seg_m θ̇_m²: each segment turns at its absolute rate θ̇_m.
            let mut theta_rate = 0.0;
            let mut d = Vec2::zeros();
            out[0].drift = d;
            for m in 0..N {
                theta_rate += qd[m];
                d -= (out[m + 1].pos - out[m].pos) * (theta_rate * theta_rate);
                out[m + 1].drift = d;
            }
        }
        ArmModel::Floating(_) => {
            add_base_rotation(kin, out);
            const H: f64 = 1e-6;
            let mut k2 = Kinematics::<N>::default();
            model.kinematics(phi + H * kin.base_rate, &(q + qd * H), qd, &mut k2);
            let mut ahead: Points<N> = [PointMotion::default(); MAX_JOINTS + 1];
            geometry(&k2, &mut ahead);
            add_base_rotation(&k2, &mut ahead);
            for k in 0..=N {
                out[k].drift = (ahead[k].jac - out[k].jac) * qd / H;
            }
        }
    }
    for pt in out.iter_mut().take(N + 1) {
        pt.vel = pt.jac * qd;
    }
}

/// The gains of an obstacle barrier's condition ḧ + k1 ḣ + k0 h ≥ 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BarrierGains {
    pub k0: f64,
    pub k1: f64,
    /// Inside the clearance (h < 0) the plain condition pushes out at ḣ → k0|h|/k1, which grows
    /// with the depth: a link that starts (or has an obstacle appear) deep inside would leave at
    /// up to 1 m/s and fly into the next obstacle faster than the acceleration limits can brake.
    /// So the push term k0·h is held above −k1·`push_out_speed`: the way out is taken at no more
    /// than this speed (m/s). It changes nothing while h ≥ −push_out_speed·k1/k0.
    pub push_out_speed: f64,
}

impl BarrierGains {
    /// b of the row a·q̈ ≥ b, before the motion terms: −k1 ḣ − max(k0 h, −k1 v_out).
    pub fn rhs(&self, h: f64, hdot: f64) -> f64 {
        let push = self.k0 * h;
        let floor = -self.k1 * self.push_out_speed;
        -self.k1 * hdot - if push < floor { floor } else { push }
    }
}

/// The barrier h = d − reach of the segment [P_a, P_b] against a centre (reach: the obstacle's
/// radius + the link's radius + the clearance) with its second-order row, in the plane or in
/// space: returns (h, a, b) for a·q̈ ≥ b. Near an end point the distance is to that point; on
/// the interior piece [`Geometry`] writes it out for the dimension.
pub fn segment_row<const N: usize, const D: usize>(
    a_pt: &Pt<N, D>,
    b_pt: &Pt<N, D>,
    center: SVector<f64, D>,
    reach: f64,
    g: BarrierGains,
) -> Option<Row<N>>
where
    Geometry: Interior<N, D>,
{
    let (e, l2, t) = foot_on_line(a_pt, b_pt, center);
    if t <= 0.0 {
        return point_row(a_pt, center, reach, g);
    }
    if t >= 1.0 {
        return point_row(b_pt, center, reach, g);
    }
    Geometry::interior(a_pt, b_pt, center, reach, g, (e, l2, t))
}

/// Where the perpendicular from `center` meets the segment's line: (e = B − A, |e|², t) with the
/// foot at A + t e (t = 0 for a segment of no length).
#[inline(always)]
fn foot_on_line<const N: usize, const D: usize>(
    a_pt: &Pt<N, D>,
    b_pt: &Pt<N, D>,
    center: SVector<f64, D>,
) -> (SVector<f64, D>, f64, f64) {
    let e = b_pt.pos - a_pt.pos;
    let l2 = e.norm_squared();
    let t = if l2 > 0.0 {
        (center - a_pt.pos).dot(&e) / l2
    } else {
        0.0
    };
    (e, l2, t)
}

/// The dimensions a segment's interior piece is written for.
pub struct Geometry;

/// The interior piece of a segment row: the foot of the perpendicular from the centre lies
/// strictly inside the segment, at `a + t e` (`e = b − a`, `l2 = |e|²`).
pub trait Interior<const N: usize, const D: usize> {
    fn interior(
        a_pt: &Pt<N, D>,
        b_pt: &Pt<N, D>,
        center: SVector<f64, D>,
        reach: f64,
        g: BarrierGains,
        foot: (SVector<f64, D>, f64, f64),
    ) -> Option<Row<N>>;
}

impl<const N: usize> Interior<N, 2> for Geometry {
    /// In the plane the link length L is constant, so d = |σ|/L with σ = e × (c − A), and σ̈
    /// follows from the end points' accelerations.
    fn interior(
        a_pt: &PointMotion<N>,
        b_pt: &PointMotion<N>,
        center: Vec2,
        reach: f64,
        g: BarrierGains,
        (e, l2, _): (Vec2, f64, f64),
    ) -> Option<Row<N>> {
        let l = l2.sqrt();
        let rel = center - a_pt.pos;
        let sigma = cross(e, rel);
        let side = if sigma >= 0.0 { 1.0 } else { -1.0 };
        let s = side / l;
        let h = s * sigma - reach;
        let edot = b_pt.vel - a_pt.vel;
        let hdot = s * (cross(edot, rel) - cross(e, a_pt.vel));
        let je = b_pt.jac - a_pt.jac;
        let a = VecN::<N>::from_fn(|k, _| {
            s * (cross(je.column(k).into_owned(), rel) - cross(e, a_pt.jac.column(k).into_owned()))
        });
        let drift = s
            * (cross(b_pt.drift - a_pt.drift, rel)
                - 2.0 * cross(edot, a_pt.vel)
                - cross(e, a_pt.drift));
        Some((h, a, g.rhs(h, hdot) - drift))
    }
}

impl<const N: usize> Interior<N, 3> for Geometry {
    fn interior(
        pa: &Pt<N, 3>,
        pb: &Pt<N, 3>,
        center: Vector3<f64>,
        reach: f64,
        g: BarrierGains,
        foot: (Vector3<f64>, f64, f64),
    ) -> Option<Row<N>> {
        let f = interior_foot(pa, pb, center, reach, g, foot)?;
        Some((f.h, f.normal(pa, pb), f.b))
    }
}

/// A barrier whose row's normal is a = J_xᵀ u: u the unit direction from the obstacle's centre
/// to the closest point x of the link, J_x that point's Jacobian. So a·v = u·(J_x v), which a
/// check can take from the end points' J v without building a.
#[derive(Clone, Copy, Debug)]
pub struct Foot<const D: usize> {
    pub h: f64,
    /// The row's right-hand side: a·q̈ ≥ b.
    pub b: f64,
    u: SVector<f64, D>,
    at: At,
}

/// Where on the segment the closest point x lies.
#[derive(Clone, Copy, Debug)]
enum At {
    /// An end point: A (false) or B (true).
    End(bool),
    /// Strictly inside, at A + t (B − A).
    Interior(f64),
}

impl<const D: usize> Foot<D> {
    /// The row's normal a = J_xᵀ u.
    #[inline(always)]
    pub fn normal<const N: usize>(&self, pa: &Pt<N, D>, pb: &Pt<N, D>) -> VecN<N> {
        match self.at {
            At::End(false) => pa.jac.transpose() * self.u,
            At::End(true) => pb.jac.transpose() * self.u,
            At::Interior(t) => (pa.jac + (pb.jac - pa.jac) * t).transpose() * self.u,
        }
    }

    /// a·v from J_A v and J_B v (equal to `normal(..).dot(v)` up to rounding).
    #[inline(always)]
    pub fn applied(&self, ja_v: &SVector<f64, D>, jb_v: &SVector<f64, D>) -> f64 {
        match self.at {
            At::End(false) => self.u.dot(ja_v),
            At::End(true) => self.u.dot(jb_v),
            At::Interior(t) => self.u.dot(&(ja_v + (jb_v - ja_v) * t)),
        }
    }
}

/// In space the foot x = a + t e slides as t moves, but u = (x − c)/d is normal to e there, so
/// ḣ = u·(ȧ + t ė) and the slide enters ḧ only through ṫ.
#[inline(always)]
fn interior_foot<const N: usize>(
    pa: &Pt<N, 3>,
    pb: &Pt<N, 3>,
    center: Vector3<f64>,
    reach: f64,
    g: BarrierGains,
    (e, l2, t): (Vector3<f64>, f64, f64),
) -> Option<Foot<3>> {
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
    let drift_x = pa.drift + (pb.drift - pa.drift) * t;
    let drift = u.dot(&drift_x) + udot.dot(&xdot) + tdot * u.dot(&edot);
    Some(Foot {
        h,
        b: g.rhs(h, hdot) - drift,
        u,
        at: At::Interior(t),
    })
}

/// The barrier of a link in space, [`segment_row`] without its normal.
pub fn segment_foot<const N: usize>(
    pa: &Pt<N, 3>,
    pb: &Pt<N, 3>,
    center: Vector3<f64>,
    reach: f64,
    g: BarrierGains,
) -> Option<Foot<3>> {
    let (e, l2, t) = foot_on_line(pa, pb, center);
    if t <= 0.0 {
        return point_foot(pa, center, reach, g, false);
    }
    if t >= 1.0 {
        return point_foot(pb, center, reach, g, true);
    }
    interior_foot(pa, pb, center, reach, g, (e, l2, t))
}

/// The same for the distance to one point P: ḧ = u·P̈ + (|Ṗ|² − (u·Ṗ)²)/d.
fn point_row<const N: usize, const D: usize>(
    p: &Pt<N, D>,
    center: SVector<f64, D>,
    reach: f64,
    g: BarrierGains,
) -> Option<Row<N>> {
    let f = point_foot(p, center, reach, g, false)?;
    Some((f.h, f.normal(p, p), f.b))
}

/// [`point_row`] without its normal; `end` says which end point P is.
#[inline(always)]
fn point_foot<const N: usize, const D: usize>(
    p: &Pt<N, D>,
    center: SVector<f64, D>,
    reach: f64,
    g: BarrierGains,
    end: bool,
) -> Option<Foot<D>> {
    let w = p.pos - center;
    let d = w.norm();
    if d < 1e-12 {
        return None; // no direction to push in; the interior piece covers this case
    }
    let u = w / d;
    let h = d - reach;
    let un = u.dot(&p.vel);
    let hdot = un;
    let curvature = (p.vel.norm_squared() - un * un) / d;
    Some(Foot {
        h,
        b: g.rhs(h, hdot) - u.dot(&p.drift) - curvature,
        u,
        at: At::End(end),
    })
}

/// Calls `f(a, b)` for the row a·q̈ ≥ b of every link against every ball; link j is a capsule
/// of radius `link_radii[j]` (0: a segment).
pub fn visit_balls<const N: usize, const D: usize, F: FnMut(&VecN<N>, f64) + ?Sized>(
    p: &SafetyParams,
    balls: &Balls<D>,
    link_radii: &[f64],
    links: &Links<'_, N, D>,
    f: &mut F,
) where
    Geometry: Interior<N, D>,
{
    for o in balls.as_slice() {
        for j in 0..N {
            let reach = o.radius + link_radii[j] + p.clearance;
            let (a, b) = links.link(j);
            if let Some((_, a, b)) = segment_row(a, b, o.center, reach, p.gains()) {
                f(&a, b);
            }
        }
    }
}

/// Whether q̈ misses the row of any link against any ball in space (`misses(b, a·q̈)`), from the
/// end points' J q̈ alone: no row's normal is built. The common case, nothing binds, costs this
/// pass and no buffer; the rows themselves are built only when something binds.
pub fn any_ball_missed<const N: usize>(
    p: &SafetyParams,
    balls: &Balls<3>,
    link_radii: &[f64],
    links: &Links<'_, N, 3>,
    qdd: &VecN<N>,
    misses: impl Fn(f64, f64) -> bool,
) -> bool {
    if balls.is_empty() {
        return false;
    }
    let image = super::screen::images(links, qdd);
    // A pair the link's bound clears cannot miss its row: only the others are computed.
    let bounds = super::screen::link_bounds(links, &image, (p.k0, p.k1));
    for o in balls.as_slice() {
        for j in 0..N {
            let reach = o.radius + link_radii[j] + p.clearance;
            if bounds[j].clears(&o.center, reach, p.k0) {
                continue;
            }
            let ((ia, ib), (a, b)) = (links.ends(j), links.link(j));
            let foot = segment_foot(a, b, o.center, reach, p.gains());
            if foot.is_some_and(|f| misses(f.b, f.applied(&image[ia], &image[ib]))) {
                return true;
            }
        }
    }
    false
}

/// The planar arm's links are segments: no radius of their own.
pub const SEGMENTS: [f64; MAX_JOINTS] = [0.0; MAX_JOINTS];

/// Every joint's own rows folded into one box lo_i ≤ q̈_i ≤ hi_i: the position barriers
/// (ḧ + k1 ḣ + k0 h ≥ 0 with h = q_max − q and q − q_min), the rate barriers (ḣ + k_rate h ≥ 0
/// with h = qd_max ∓ q̇) and the acceleration limits. ±∞ where nothing limits; lo > hi where the
/// limits conflict.
pub fn joint_box<const N: usize>(
    p: &SafetyParams,
    q: &VecN<N>,
    qd: &VecN<N>,
) -> ([f64; MAX_JOINTS], [f64; MAX_JOINTS]) {
    let mut lo = [f64::NEG_INFINITY; MAX_JOINTS];
    let mut hi = [f64::INFINITY; MAX_JOINTS];
    for i in 0..N {
        let mut l = -p.qdd_max[i];
        let mut h = p.qdd_max[i];
        if p.qd_max[i].is_finite() {
            l = l.max(-p.k_rate * (p.qd_max[i] + qd[i]));
            h = h.min(p.k_rate * (p.qd_max[i] - qd[i]));
        }
        if p.q_min[i].is_finite() {
            l = l.max(-p.k1 * qd[i] - p.k0 * (q[i] - p.q_min[i]));
        }
        if p.q_max[i].is_finite() {
            h = h.min(-p.k1 * qd[i] + p.k0 * (p.q_max[i] - q[i]));
        }
        (lo[i], hi[i]) = (l, h);
    }
    (lo, hi)
}

/// Calls `f(a, b)` for every row a·q̈ ≥ b: the obstacle rows, then each joint's box as two rows.
pub fn visit<const N: usize, F: FnMut(&VecN<N>, f64) + ?Sized>(
    p: &SafetyParams,
    obstacles: &ObstacleSet,
    points: &Points<N>,
    q: &VecN<N>,
    qd: &VecN<N>,
    f: &mut F,
) {
    visit_balls(p, obstacles, &SEGMENTS, &Links::chain(points), f);
    let (lo, hi) = joint_box(p, q, qd);
    for i in 0..N {
        let e = VecN::<N>::from_fn(|r, _| if r == i { 1.0 } else { 0.0 });
        if lo[i].is_finite() {
            f(&e, lo[i]);
        }
        if hi[i].is_finite() {
            f(&-e, -hi[i]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::SMatrix;

    /// The check's a·v from the end points' J v is the row's own a·v, on every piece of the
    /// segment (end A, interior, end B), so the check and the rows judge alike.
    #[test]
    fn a_foot_applied_to_images_is_its_normal_applied() {
        let mut rnd = crate::basics::rng::uniform(7u64);
        let g = BarrierGains {
            k0: 100.0,
            k1: 20.0,
            push_out_speed: 0.5,
        };
        let mut point = |x: f64| Pt::<7, 3> {
            pos: Vector3::new(x, 0.1 * rnd(), 0.1 * rnd()),
            jac: SMatrix::<f64, 3, 7>::from_fn(|_, _| rnd()),
            vel: Vector3::new(rnd(), rnd(), rnd()),
            drift: Vector3::new(rnd(), rnd(), rnd()),
        };
        let (pa, pb) = (point(0.0), point(1.0));
        let v = VecN::<7>::from_fn(|_, _| 10.0 * rnd());
        let (ia, ib) = (pa.jac * v, pb.jac * v);
        for cx in [-0.5, 0.3, 0.7, 1.5] {
            let c = Vector3::new(cx, 0.4, -0.3);
            let f = segment_foot(&pa, &pb, c, 0.1, g).expect("a foot");
            let row = segment_row(&pa, &pb, c, 0.1, g).expect("a row");
            assert_eq!(
                (f.h, f.b),
                (row.0, row.2),
                "the check's barrier is the row's"
            );
            let (cheap, exact) = (f.applied(&ia, &ib), row.1.dot(&v));
            assert!(
                (cheap - exact).abs() <= 1e-12 * (1.0 + exact.abs()),
                "{cheap} vs {exact}"
            );
        }
    }
}
