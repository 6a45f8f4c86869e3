//! The safety filter: the smallest change to the commanded q̈ that keeps every link clear of every
//! obstacle and every joint inside its position, rate and acceleration limits (docs/science.md, "Keeping clear of obstacles").
//!
//! The paper's obstacle potential only *biases* the null-space motion; against the undamped,
//! chaotic self-motion it does not keep the links out (80 s of contact in 400 s at μ = 0). A
//! guarantee needs a constraint. Each limit is a barrier h(q) ≥ 0 of relative degree 2 (positions:
//! ḧ + k₁ḣ + k₀h ≥ 0) or 1 (rates: ḣ + k h ≥ 0), and each barrier condition is linear in q̈:
//! a·q̈ ≥ b ([`rows`]). The filter then solves, in this order ([`solve`]):
//!
//! 1. **Nothing to do**: the law's q̈ meets every row. It is returned bit for bit, so a filter
//!    that never binds changes nothing (the paper's results are reproduced exactly).
//! 2. **Null space**: q̈ + N z with N = I − J⁺J, the smallest z. Tracking is untouched. For the
//!    paper's 3-link arm N has rank 1 and this is a closed-form interval on one scalar.
//! 3. **Full joint space**: the smallest change of q̈ overall. Safety wins over tracking, and the
//!    output says so ([`crate::basics::flags::SAFETY_LEFT_NULL_SPACE`]).
//!
//! Whatever the solver returns, the acceleration limits are applied last as a clamp (they are the
//! actuator's), so the command is always finite and bounded. Everything is on the stack: the
//! filter never allocates.

pub mod config;
pub mod dual_qp;
pub mod policy;
pub mod rows;
pub mod screen;
pub mod solve;

use crate::arm::point::{Links, PointMotion, Points as PointsOf};
use crate::arm::spatial::{CapsulePoints, SpatialArm, SpatialKinematics};
use crate::arm::{ArmModel, Kinematics, VecN};
use crate::basics::MAX_JOINTS;
use crate::secondary::spatial::SphereSet;
use crate::secondary::{Balls, ObstacleSet};
use nalgebra::SMatrix;

pub use config::SafetySection;

/// The filter's parameters: a small `Copy` block, swapped with the law's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SafetyParams {
    /// Run the filter at all (the runaway guard in the daemon uses the limits either way).
    pub enabled: bool,
    /// Required distance (m) from every link to every obstacle's surface.
    pub clearance: f64,
    /// Joint position limits (rad); ±∞ where a joint is unlimited.
    pub q_min: [f64; MAX_JOINTS],
    pub q_max: [f64; MAX_JOINTS],
    /// Joint rate limits |q̇_i| ≤ qd_max_i (rad/s).
    pub qd_max: [f64; MAX_JOINTS],
    /// Joint acceleration limits |q̈_i| ≤ qdd_max_i (rad/s²).
    pub qdd_max: [f64; MAX_JOINTS],
    /// Joint jerk limits (rad/s³; +∞ where none is known). The filter does not use them (the
    /// command interface's limiter shapes the jerk); a run's statistics report against them.
    pub jerk_max: [f64; MAX_JOINTS],
    /// Position barriers: ḧ + k1 ḣ + k0 h ≥ 0 (s² + k1 s + k0 has real negative roots).
    pub k0: f64,
    pub k1: f64,
    /// The fastest a link is pushed out of an obstacle's clearance (m/s): see
    /// [`rows::BarrierGains::push_out_speed`].
    pub push_out_speed: f64,
    /// Rate barriers: ḣ + k_rate h ≥ 0.
    pub k_rate: f64,
    /// Daemon's runaway guard: a rate or the law's demand beyond its limit for this long (s).
    pub guard_time: f64,
    /// Daemon's runaway guard: a tracking error above this (m) that keeps growing …
    pub guard_tracking_error: f64,
    /// … for this long (s).
    pub guard_growth_time: f64,
}

impl SafetyParams {
    /// The obstacle barriers' gains.
    pub fn gains(&self) -> rows::BarrierGains {
        rows::BarrierGains {
            k0: self.k0,
            k1: self.k1,
            push_out_speed: self.push_out_speed,
        }
    }

    /// A filter that is off, with no limits.
    pub fn off() -> Self {
        Self {
            enabled: false,
            clearance: 0.0,
            q_min: [f64::NEG_INFINITY; MAX_JOINTS],
            q_max: [f64::INFINITY; MAX_JOINTS],
            qd_max: [f64::INFINITY; MAX_JOINTS],
            qdd_max: [f64::INFINITY; MAX_JOINTS],
            jerk_max: [f64::INFINITY; MAX_JOINTS],
            k0: 100.0,
            k1: 20.0,
            push_out_speed: 0.1,
            k_rate: 50.0,
            guard_time: 0.02,
            guard_tracking_error: 1.0,
            guard_growth_time: 0.5,
        }
    }

    /// Smallest distance (rad) from q to a position limit; +∞ without limits, negative outside.
    pub fn joint_margin<const N: usize>(&self, q: &VecN<N>) -> f64 {
        (0..N)
            .map(|i| (self.q_max[i] - q[i]).min(q[i] - self.q_min[i]))
            .fold(f64::INFINITY, f64::min)
    }
}

/// How fast a paused arm brakes (1/s): q̈ = −rate · q̇, so q̇ halves every 70 ms; the filter
/// then keeps every clearance, limit and rate as it does for the law's own command.
pub const PAUSE_BRAKE_RATE: f64 = 10.0;

/// The command of a paused arm (the daemon's blocked hold) before the filter: brake to rest,
/// within [`PAUSE_BRAKE_SHARE`] of every joint's acceleration limit `qdd_max` (scaled as a
/// whole, so the joints stop together; a brake past the limits would be clamped by the filter
/// anyway, and read by the runaway guard as a runaway). A plant's own HOLD brakes blind, and
/// an arm swinging past an obstacle could coast into it; braking through the filter cannot.
#[inline]
pub fn pause_brake<const N: usize>(qd: &VecN<N>, qdd_max: &[f64]) -> VecN<N> {
    let brake = -qd * PAUSE_BRAKE_RATE;
    let over = (0..N)
        .map(|i| brake[i].abs() / (PAUSE_BRAKE_SHARE * qdd_max[i]))
        .fold(1.0, f64::max);
    brake / over
}

/// The share of a joint's acceleration limit a paused arm brakes with, at most.
pub const PAUSE_BRAKE_SHARE: f64 = 0.9;

/// What the filter did to one command.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Filtered<const N: usize> {
    pub qdd: VecN<N>,
    /// `law::flags` bits: SAFETY_ACTIVE, SAFETY_LEFT_NULL_SPACE, SAFETY_INFEASIBLE.
    pub flags: u32,
}

impl<const N: usize> Filtered<N> {
    /// The command as the law gave it: nothing bound.
    pub fn unchanged(qdd: &VecN<N>) -> Self {
        Self {
            qdd: *qdd,
            flags: 0,
        }
    }
}

/// Filters the law's `qdd` at state (φ, q, q̇). `kin` holds the kinematics at that state and
/// `jpinv` the (damped) pseudo-inverse the law used.
///
/// ```
/// use control::{Config, Kinematics, VecN};
/// use control::safety::{filter, SafetyParams};
///
/// let cfg = Config::preset("paper-obstacle").unwrap();
/// let model = cfg.model::<3>();
/// let mut p = SafetyParams::off();
/// p.enabled = true;
/// p.qdd_max = [100.0; control::MAX_JOINTS];
/// let (q, qd) = (VecN::<3>::new(0.0, 1.5, 1.5), VecN::<3>::zeros());
/// let mut kin = Kinematics::default();
/// model.kinematics(0.0, &q, &qd, &mut kin);
/// let (jpinv, _, _) = control::resolve::damped_pinv(&kin.j, 0.05, 0.05);
/// let wild = VecN::<3>::new(1e4, -1e4, 0.0);
/// let out = filter(&p, &model, &cfg.law_params().obstacles, &kin, 0.0, &q, &qd, &jpinv, &wild);
/// assert!(out.qdd.amax() <= 100.0);
/// ```
#[allow(clippy::too_many_arguments)]
pub fn filter<const N: usize>(
    p: &SafetyParams,
    model: &ArmModel<N>,
    obstacles: &ObstacleSet,
    kin: &Kinematics<N>,
    phi: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
    jpinv: &SMatrix<f64, N, 2>,
    qdd: &VecN<N>,
) -> Filtered<N> {
    let fill = |out: &mut rows::Points<N>| rows::point_motions(model, kin, phi, q, qd, out);
    filter_with(
        p,
        obstacles,
        &rows::SEGMENTS,
        fill,
        (q, qd),
        (&kin.j, jpinv),
        qdd,
    )
}

/// Filters a spatial arm's `qdd` (its links capsules against spheres): `j` are the task rows
/// and `jpinv` the pseudo-inverse the law used.
#[allow(clippy::too_many_arguments)]
pub fn filter_spatial<const N: usize, const M: usize>(
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
        return Filtered::unchanged(qdd);
    }
    let (lo, hi) = rows::joint_box(p, q, qd);
    let mut store = CapsulePoints::<N>::default();
    let links = if spheres.is_empty() {
        match &store {
            CapsulePoints::Chain(points) | CapsulePoints::Pairs(points, _) => Links::chain(points),
        }
    } else {
        arm.capsule_points(kin, qd, &mut store)
    };
    // Nothing binds (the common case): one pass over the barriers without their rows.
    if !solve::box_missed((&lo, &hi), qdd)
        && !rows::any_ball_missed(p, spheres, &arm.radii, &links, qdd, solve::misses)
    {
        return Filtered::unchanged(qdd);
    }
    let visit =
        |f: &mut dyn FnMut(&VecN<N>, f64)| rows::visit_balls(p, spheres, &arm.radii, &links, f);
    solve::smallest_change(&visit, (&lo, &hi), j, jpinv, qdd, &p.qdd_max)
}

/// The planar arm's filter once its points are known: the rows of every link against every
/// ball ([`rows::visit_balls`]) and each joint's box, solved null space first ([`solve`]). The
/// points are filled only when there is a ball.
fn filter_with<const N: usize, const M: usize, const D: usize>(
    p: &SafetyParams,
    balls: &Balls<D>,
    link_radii: &[f64],
    fill: impl FnOnce(&mut PointsOf<N, D>),
    (q, qd): (&VecN<N>, &VecN<N>),
    (j, jpinv): (&SMatrix<f64, M, N>, &SMatrix<f64, N, M>),
    qdd: &VecN<N>,
) -> Filtered<N>
where
    rows::Geometry: rows::Interior<N, D>,
{
    if !p.enabled {
        return Filtered::unchanged(qdd);
    }
    let (lo, hi) = rows::joint_box(p, q, qd);
    if balls.is_empty() {
        let none = |_: &mut dyn FnMut(&VecN<N>, f64)| {};
        return solve::smallest_change(&none, (&lo, &hi), j, jpinv, qdd, &p.qdd_max);
    }
    let mut points: PointsOf<N, D> = [PointMotion::default(); MAX_JOINTS + 1];
    fill(&mut points);
    let links = Links::chain(&points);
    let visit =
        |f: &mut dyn FnMut(&VecN<N>, f64)| rows::visit_balls(p, balls, link_radii, &links, f);
    solve::smallest_change(&visit, (&lo, &hi), j, jpinv, qdd, &p.qdd_max)
}
