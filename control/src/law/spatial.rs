//! The control law of docs/science.md, "The control law" on a spatial arm, for a task of m = 3 or 6 rows.
//!
//! Only the task side is spatial: the tool point's error (and for the pose task the orientation
//! error as a rotation vector) with its feed-forward. Everything after the task acceleration is
//! [`crate::resolve`], the code the planar law runs, and the filter is the planar filter's solver
//! with capsule rows. One extra, optional term: null-space joint damping −k_d(I − J⁺J)q̇, the
//! classical remedy for the undamped self-motion of acceleration-level resolved-rate control
//! (Hsu, Hauser & Sastry 1989); it is off (k_d = 0) unless configured, so that the study can
//! compare it with the Pyragas term.

use crate::arm::spatial::Points;
use crate::arm::spatial::SpatialArm;
use crate::arm::spatial::SpatialKinematics;
use crate::arm::spatial::VecN;
use crate::basics::flags;
use crate::resolve::ControlOutput;
use crate::resolve::Projection;
use crate::resolve::{damped_pinv_m, resolve, NullTerms};
use crate::safety::SafetyParams;
use crate::secondary::spatial as sec;
use crate::secondary::spatial::SphereSet;
use crate::task::spatial::orientation_error;
use crate::task::spatial::SpatialTask;
use crate::task::spatial::Vec3;
use nalgebra::{SMatrix, SVector, Vector6};

/// Which secondary task drives a spatial arm's null space.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum SpatialSecondary {
    #[default]
    None,
    /// η = +∇w, w = √det(JJᵀ) of the task rows.
    Manipulability,
    /// η = −∇c, c the joint-limit centring cost.
    Centring,
    /// η = −∇h, the sphere-capsule potential.
    Obstacles,
    /// A task the program registered ([`crate::secondary::custom`]), by its index there.
    Custom(u8),
}

/// Every tunable of the spatial law: a `Copy` block, like the planar [`crate::LawParams`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialParams {
    pub task: SpatialTask,
    pub kp: f64,
    pub kv: f64,
    pub alpha: f64,
    pub secondary: SpatialSecondary,
    pub spheres: SphereSet,
    /// The obstacle potential's weight W.
    pub weight: f64,
    /// Null-space joint damping k_d ≥ 0 (0: the paper's law).
    pub null_damping: f64,
    pub damping_threshold: f64,
    pub damping_max: f64,
    pub mu: f64,
    pub tau: f64,
    pub t_on: f64,
    pub feedback: bool,
    pub projection: Projection,
    pub safety: SafetyParams,
    /// Position error (m) above which tracking counts as lost.
    pub track_loss: f64,
    /// Tracking paused (the daemon's blocked hold): the arm brakes to rest, the filter keeping
    /// clearance as ever ([`crate::safety::pause_brake`]).
    pub pause: bool,
    /// `feedback.mu = "auto"`: the caller adapts `mu` after each step ([`crate::adapt`]).
    pub auto_mu: Option<crate::adapt::AutoMu>,
    /// A planned clean cycle to steer the self-motion onto ([`crate::plan::spatial`]); it
    /// replaces the secondary task, as on the planar arm.
    pub steer: Option<crate::steer::SpatialSteer>,
}

impl SpatialParams {
    pub fn feedback_active(&self, t: f64) -> bool {
        self.feedback && (self.mu != 0.0 || self.auto_mu.is_some()) && t >= self.t_on
    }
}

/// A registered task's value and η, on the kinematics the law already computed.
fn custom_eta<const N: usize>(
    index: u8,
    params: &SpatialParams,
    kin: &SpatialKinematics<N>,
    t: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
) -> (f64, Option<VecN<N>>) {
    let input = crate::secondary::custom::NullTaskInput {
        t,
        q: q.as_slice(),
        qd: qd.as_slice(),
        tip: [kin.p.x, kin.p.y, kin.p.z],
        jacobian: kin.jac.as_slice(),
        q_min: &params.safety.q_min[..N],
        q_max: &params.safety.q_max[..N],
    };
    let mut eta = VecN::<N>::zeros();
    let value = crate::secondary::custom::call(index, &input, eta.as_mut_slice());
    (value, Some(eta))
}

/// Evaluates the law at time t for state (q, q̇) with delayed velocity q̇(t − τ); `M` must be
/// the task's row count (3: position, 6: pose). `kin` is scratch.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn evaluate<const N: usize, const M: usize>(
    params: &SpatialParams,
    arm: &SpatialArm<N>,
    t: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
    qd_delayed: &VecN<N>,
    kin: &mut SpatialKinematics<N>,
) -> ControlOutput<N> {
    debug_assert_eq!(M, params.task.kind.rows());
    arm.kinematics(q, qd, kin);
    let target = params.task.at(t);
    let j: SMatrix<f64, M, N> = kin.jac.fixed_rows::<M>(0).into_owned();
    let mut flag = 0u32;
    let (jpinv, smin, lambda) = damped_pinv_m(&j, params.damping_threshold, params.damping_max);
    if lambda > 0.0 {
        flag |= flags::SINGULAR;
    }
    let ep = target.p - kin.p;
    let eo = if M == 6 {
        orientation_error(&target.rot, &kin.rot)
    } else {
        Vec3::zeros()
    };
    let vel = kin.jac * qd;
    let desired = Vector6::new(
        target.a.x,
        target.a.y,
        target.a.z,
        target.wd.x,
        target.wd.y,
        target.wd.z,
    ) + (Vector6::new(
        target.v.x, target.v.y, target.v.z, target.w.x, target.w.y, target.w.z,
    ) - vel)
        * params.kv
        + Vector6::new(ep.x, ep.y, ep.z, eo.x, eo.y, eo.z) * params.kp
        - kin.jdot_qd;
    let task_acc: SVector<f64, M> = sec::rows::<M>(&desired);

    // Steering onto a planned cycle replaces the secondary task: both shape the self-motion.
    let secondary = if params.steer.is_some() {
        SpatialSecondary::None
    } else {
        params.secondary
    };
    let (secondary_value, eta) = match secondary {
        SpatialSecondary::None => (0.0, None),
        SpatialSecondary::Manipulability => {
            let (w, g) = sec::manipulability(arm, kin, &j);
            (w, Some(g))
        }
        SpatialSecondary::Centring => {
            let (c, g) = sec::centring(q, &params.safety.q_min, &params.safety.q_max);
            (c, Some(-g))
        }
        SpatialSecondary::Obstacles if !params.spheres.is_empty() => {
            let mut points: Points<N> = [Default::default(); crate::basics::MAX_JOINTS + 1];
            arm.capsule_points(kin, qd, &mut points);
            let (h, g) = sec::potential(arm, &points, &params.spheres, params.weight);
            (h, Some(-g))
        }
        SpatialSecondary::Obstacles => (0.0, Some(VecN::<N>::zeros())),
        SpatialSecondary::Custom(index) => custom_eta(index, params, kin, t, q, qd),
    };
    let diff = qd - qd_delayed;
    let feedback = params.feedback_active(t);
    if feedback {
        flag |= flags::FEEDBACK_ACTIVE;
    }
    let terms = NullTerms {
        eta,
        alpha: params.alpha,
        diff,
        mu: feedback.then_some(params.mu),
        projection: params.projection,
    };
    let mut qdd = resolve(&j, &jpinv, &task_acc, &terms);
    if let Some(s) = &params.steer {
        qdd += s.pull(t, q, qd, &j, &jpinv, &qdd, &params.safety);
    }
    if params.null_damping != 0.0 {
        qdd -= (qd - jpinv * (j * qd)) * params.null_damping;
    }
    if params.pause {
        qdd = crate::safety::pause_brake(qd, &params.safety.qdd_max);
    }
    let demand = (0..N)
        .map(|i| qdd[i].abs() / params.safety.qdd_max[i])
        .fold(0.0, f64::max);
    if params.safety.enabled && qdd.iter().all(|v| v.is_finite()) {
        let f = crate::safety::capsules::filter(
            &params.safety,
            arm,
            &params.spheres,
            kin,
            q,
            qd,
            &j,
            &jpinv,
            &qdd,
        );
        qdd = f.qdd;
        flag |= f.flags;
    }
    let (clearance, in_zone) = if params.spheres.is_empty() {
        (f64::INFINITY, false)
    } else {
        sec::clearance(arm, &arm.capsule_positions(kin)[..N + 1], &params.spheres)
    };
    if in_zone {
        flag |= flags::IN_SAFETY_ZONE;
    }
    let tracking_error = ep.norm();
    if tracking_error.is_nan() || tracking_error > params.track_loss {
        flag |= flags::TRACK_LOST;
    }
    if !qdd.iter().all(|v| v.is_finite()) {
        qdd = VecN::<N>::zeros();
        flag |= flags::NONFINITE;
    }
    ControlOutput {
        qdd,
        p: kin.p,
        p_desired: target.p,
        tracking_error,
        orientation_error: eo.norm(),
        sigma_min: smin,
        damping: lambda,
        secondary_value,
        period_residual: diff.norm(),
        null_residual: (diff - jpinv * (j * diff)).norm(),
        clearance,
        joint_margin: params.safety.joint_margin(q),
        demand,
        base_rate: 0.0,
        flags: flag,
    }
}
