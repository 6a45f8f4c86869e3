//! The resolved-acceleration control law of docs/science.md, "The control law" (eqs. 1, 11, 13).
//!
//! q̈ = J⁺(p̈_d + K_v(ṗ_d − Jq̇) + K_p(p_d − p) − J̇q̇) + α(I − J⁺J)η − μ[q̇(t) − q̇(t−τ)]
//!
//! [`LawParams`] is a small `Copy` block with no dimension parameter: the daemon swaps a whole
//! validated block at a tick boundary, and the offline tools share exactly the same code. The
//! evaluation is a few hundred flops on the stack; it never allocates and never produces NaN from
//! finite inputs (damped least squares near singularities, a non-finite guard at the end).
//!
//! The safety filter ([`crate::safety`]) runs last, on the whole command: it is part of the
//! evaluation so that the offline simulation, the analysis and the daemon all get the same
//! filtered command, and a disabled filter costs one branch.

pub mod spatial;

use crate::arm::{ArmModel, Jac, Kinematics, VecN};
use crate::basics::{flags, wrap_angle};
use crate::resolve::{damped_pinv, resolve, ControlOutput, NullTerms, Projection};
use crate::safety::{self, SafetyParams};
use crate::secondary::{self, ObstacleSet, PotentialWeights};
use crate::task::Circle;
use nalgebra::Vector3;

type Vec3 = Vector3<f64>;

/// Which secondary task drives the null space.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Secondary {
    None,
    /// η = +∇w, w = √det(JJᵀ) (eq. 1).
    #[default]
    Manipulability,
    /// η = −∇h, the obstacle potential (eqs. 7-10).
    Obstacles,
}

/// Every tunable of the control law.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LawParams {
    pub task: Circle,
    /// Position-error gain K_p.
    pub kp: f64,
    /// Velocity-error gain K_v.
    pub kv: f64,
    /// Null-space gain α.
    pub alpha: f64,
    pub secondary: Secondary,
    pub obstacles: ObstacleSet,
    pub weights: PotentialWeights,
    /// Damped least squares starts when σ_min(J) falls below this.
    pub damping_threshold: f64,
    /// λ at σ_min = 0.
    pub damping_max: f64,
    /// Pyragas gain μ ≥ 0.
    pub mu: f64,
    /// Pyragas delay τ (s).
    pub tau: f64,
    /// Feedback is active for t ≥ t_on.
    pub t_on: f64,
    /// Master switch for the delayed feedback (the daemon's `dfc on|off`).
    pub feedback: bool,
    /// Where the delayed term acts.
    pub projection: Projection,
    /// The safety filter applied to the result ([`crate::safety`]).
    pub safety: SafetyParams,
    /// Tracking error (m) above which tracking counts as lost.
    pub track_loss: f64,
    /// A planned clean cycle to steer the self-motion onto ([`crate::plan`]); planar 3-link
    /// arm only. None: the law as the paper has it.
    pub steer: Option<crate::steer::Steer>,
    /// Tracking paused (the daemon's blocked hold): the arm brakes to rest, the filter keeping
    /// clearance as ever ([`crate::safety::pause_brake`]).
    pub pause: bool,
    /// `feedback.mu = "auto"`: the caller adapts `mu` after each step ([`crate::adapt`]).
    pub auto_mu: Option<crate::adapt::AutoMu>,
}

impl LawParams {
    /// Whether the delayed term applies at time t.
    #[inline]
    pub fn feedback_active(&self, t: f64) -> bool {
        self.feedback && (self.mu != 0.0 || self.auto_mu.is_some()) && t >= self.t_on
    }
}

/// The pull towards the planned cycle at `t`, in the null space: (I − J⁺J)(q̈* + K_p(q* − q) +
/// K_d(q̇* − q̇)). The cycle's own acceleration is fed forward, so an arm on the cycle stays on
/// it instead of lagging behind. Only the first three joints have a plan.
#[inline]
fn steering<const N: usize>(
    s: &crate::steer::Steer,
    t: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
    j: &Jac<N>,
    jpinv: &nalgebra::SMatrix<f64, N, 2>,
) -> VecN<N> {
    let r = s.cycle.sample(t);
    let mut v = VecN::<N>::zeros();
    for i in 0..N.min(3) {
        let e = wrap_angle(r.q[i] - q[i]);
        v[i] = r.qdd[i] + s.kp * e + s.kd * (r.qd[i] - qd[i]);
    }
    v - jpinv * (j * v)
}

/// The joint-space pull along a running detour: q̈_ref + K_p(q_ref − q) + K_d(q̇_ref − q̇), in
/// the full joint space (the hand leaves its path on purpose), for the first three joints.
#[inline]
fn detour_pull<const N: usize>(
    s: &crate::steer::Steer,
    d: &crate::steer::DetourTable,
    t: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
) -> VecN<N> {
    let w = std::f64::consts::TAU * crate::steer::DETOUR_HZ;
    let (kp, kd) = (w * w, 2.0 * w);
    let r = d.sample(t, &s.cycle);
    let mut v = VecN::<N>::zeros();
    for i in 0..N.min(3) {
        let e = wrap_angle(r.q[i] - q[i]);
        v[i] = r.qdd[i] + kp * e + kd * (r.qd[i] - qd[i]);
    }
    v
}

/// Evaluates the law at time `t` for state (φ, q, q̇) with delayed velocity q̇(t − τ).
///
/// `kin` is scratch; on return it holds the kinematics at the state.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn evaluate<const N: usize>(
    params: &LawParams,
    model: &ArmModel<N>,
    t: f64,
    phi: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
    qd_delayed: &VecN<N>,
    kin: &mut Kinematics<N>,
) -> ControlOutput<N> {
    model.kinematics(phi, q, qd, kin);
    let target = params.task.at(t);
    let j: &Jac<N> = &kin.j;
    let mut flag = 0u32;

    let (jpinv, smin, lambda) = damped_pinv(j, params.damping_threshold, params.damping_max);
    if lambda > 0.0 {
        flag |= flags::SINGULAR;
    }
    let err = target.p - kin.p;
    let task_acc = target.a + (target.v - j * qd) * params.kv + err * params.kp - kin.jdot_qd;
    let mut secondary_value = 0.0;
    // Steering onto a planned cycle replaces the secondary task: both shape the self-motion.
    let secondary = if params.steer.is_some() {
        Secondary::None
    } else {
        params.secondary
    };
    let eta = match secondary {
        Secondary::None => None,
        Secondary::Manipulability => {
            let (w, g) = model.manipulability(q, kin);
            secondary_value = w;
            Some(g)
        }
        Secondary::Obstacles => {
            let (h, g) = secondary::potential(kin, &params.obstacles, params.weights);
            secondary_value = h;
            Some(-g)
        }
    };
    let diff = qd - qd_delayed;
    // A detour's motion is not the cycle's: the delayed feedback waits a delay past it.
    // By reference: the table is kilobytes, and this runs every tick.
    let detour = params
        .steer
        .as_ref()
        .and_then(|s| s.detour.as_ref().map(|d| (s, d)));
    let after_detour = detour.is_some_and(|(_, d)| t < d.t_arrive + params.tau);
    let feedback = params.feedback_active(t) && !after_detour;
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
    let mut qdd = match detour.filter(|(_, d)| d.running(t)) {
        Some((s, d)) => {
            flag |= flags::DETOUR;
            detour_pull(s, d, t, q, qd)
        }
        None => {
            let mut qdd = resolve(j, &jpinv, &task_acc, &terms);
            if let Some(s) = &params.steer {
                qdd += steering(s, t, q, qd, j, &jpinv);
            }
            qdd
        }
    };
    if params.pause {
        qdd = safety::pause_brake(qd, &params.safety.qdd_max);
    }
    let demand = (0..N)
        .map(|i| qdd[i].abs() / params.safety.qdd_max[i])
        .fold(0.0, f64::max);
    if params.safety.enabled && qdd.iter().all(|v| v.is_finite()) {
        let f = safety::filter(
            &params.safety,
            model,
            &params.obstacles,
            kin,
            phi,
            q,
            qd,
            &jpinv,
            &qdd,
        );
        qdd = f.qdd;
        flag |= f.flags;
    }

    let (clearance, in_zone) = if params.obstacles.is_empty() {
        (f64::INFINITY, false)
    } else {
        secondary::clearance(kin, &params.obstacles)
    };
    if in_zone {
        flag |= flags::IN_SAFETY_ZONE;
    }
    let tracking_error = err.norm();
    if tracking_error.is_nan() || tracking_error > params.track_loss {
        flag |= flags::TRACK_LOST;
    }
    let from_base = (target.p - kin.points[0]).norm();
    if from_base > model.reach() || from_base < model.inner_reach() {
        flag |= flags::OUT_OF_REACH;
    }
    if !qdd.iter().all(|v| v.is_finite()) {
        qdd = VecN::<N>::zeros();
        flag |= flags::NONFINITE;
    }
    ControlOutput {
        qdd,
        p: Vec3::new(kin.p.x, kin.p.y, 0.0),
        p_desired: Vec3::new(target.p.x, target.p.y, 0.0),
        tracking_error,
        orientation_error: 0.0,
        sigma_min: smin,
        damping: lambda,
        secondary_value,
        period_residual: diff.norm(),
        null_residual: (diff - jpinv * (j * diff)).norm(),
        clearance,
        joint_margin: params.safety.joint_margin(q),
        demand,
        base_rate: kin.base_rate,
        flags: flag,
    }
}
