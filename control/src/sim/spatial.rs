//! The deterministic closed loop on a spatial arm: the kinematic plant (q̈ is commanded) under the
//! spatial law, with the conventions of docs/science.md, "Time, integration and determinism" (RK4, the law at every stage, q̇(s − τ)
//! from the delay line, time = step · dt).
//!
//! The loop itself is the one [`Simulation`]; what is spatial here is the summary of a run and the
//! stroboscopic map the orbit search iterates.

use crate::arm::spatial::SpatialArm;
use crate::arm::spatial::VecN;
use crate::basics::flags;
use crate::delay::DelayLine;
use crate::law::spatial::SpatialParams;
use crate::resolve::ControlOutput;
use crate::sim::{ArmState, Simulation, SpatialLaw};
use crate::steer::SpatialSteer;

/// A spatial closed loop for a task of `M` rows: the one [`Simulation`] on a [`SpatialLaw`].
pub type SpatialSimulation<const N: usize, const M: usize> = Simulation<N, SpatialLaw<N, M>>;

impl<const N: usize, const M: usize> Simulation<N, SpatialLaw<N, M>> {
    /// `arm` under `params` from rest-or-moving (`q0`, `qd0`); `max_tau` fixes the delay-line
    /// capacity. Panics if `M` is not the task's row count: the caller picks `M` from
    /// `params.task.kind` (see [`crate::with_task_rows`]).
    pub fn spatial(
        arm: SpatialArm<N>,
        params: SpatialParams,
        dt: f64,
        q0: VecN<N>,
        qd0: VecN<N>,
        max_tau: f64,
    ) -> Self {
        assert_eq!(M, params.task.kind.rows(), "task rows and M disagree");
        let initial = ArmState {
            q: q0,
            qd: qd0,
            phi: 0.0,
        };
        Simulation::of(SpatialLaw { arm, params }, dt, initial, max_tau)
    }
}

/// What a spatial run did, in docs/science.md's units (m, rad, s).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SpatialSummary {
    pub duration: f64,
    pub rms_tracking_error: f64,
    pub max_tracking_error: f64,
    pub max_orientation_error: f64,
    /// Mean |q̇(t) − q̇(t − T)| over the 10 periods before feedback (or the first 10 after the
    /// transient without feedback), and over the last 10 periods.
    pub period_residual_before: Option<f64>,
    pub period_residual_final: Option<f64>,
    /// |q(kT) − q((k−1)T)| at the last two stroboscopic samples: the joint drift per period.
    pub drift_per_period: Option<f64>,
    pub max_joint_speed: f64,
    /// max over the run of max_i |q̇_i| / q̇_max,i (above 1: a rate limit was exceeded).
    pub max_speed_ratio: f64,
    pub min_joint_margin: Option<f64>,
    pub min_clearance: Option<f64>,
    pub singular_fraction: f64,
    pub track_lost_fraction: f64,
    pub safety_active_time: f64,
    pub safety_left_null_space_steps: u64,
    pub safety_infeasible_steps: u64,
    pub nonfinite_steps: u64,
    /// Whether the state stayed finite to the end.
    pub finite: bool,
}

impl super::StatsSetup {
    /// A spatial law's: its path's period, its feedback, its spheres and its filter.
    pub fn spatial(p: &SpatialParams) -> Self {
        Self {
            period: p.task.path.period,
            t_on: p.t_on,
            feedback_used: p.feedback && p.mu != 0.0,
            required_clearance: p.safety.clearance,
            has_obstacles: !p.spheres.is_empty(),
            safety_enabled: p.safety.enabled,
        }
    }
}

/// Runs `sim` for `duration` s, calling `each(t, state, output)` every step, and summarises.
pub fn run<const N: usize, const M: usize>(
    sim: &mut SpatialSimulation<N, M>,
    duration: f64,
    transient: f64,
    mut each: impl FnMut(f64, &ArmState<N>, &ControlOutput<N>),
) -> SpatialSummary {
    run_steering(sim, duration, transient, |t, x, o| {
        each(t, x, o);
        None
    })
}

/// [`run`], where `each` may hand the law a steering (a cycle planned after a trap, as the
/// daemon does): it takes effect from the next step.
pub fn run_steering<const N: usize, const M: usize>(
    sim: &mut SpatialSimulation<N, M>,
    duration: f64,
    transient: f64,
    mut each: impl FnMut(f64, &ArmState<N>, &ControlOutput<N>) -> Option<SpatialSteer>,
) -> SpatialSummary {
    let dt = sim.dt();
    let p = sim.law.params;
    let period = p.task.path.period;
    let steps = (duration / dt).round() as u64;
    let per = (period / dt).round().max(1.0) as u64;
    let mut hist = DelayLine::<N>::new(period / dt, sim.state().qd);
    let mut s = SpatialSummary {
        duration,
        min_joint_margin: None,
        finite: true,
        ..Default::default()
    };
    let (mut sq, mut n_after) = (0.0, 0u64);
    let (mut before, mut after) = ((0.0, 0u64), (0.0, 0u64));
    let (mut singular, mut lost, mut active) = (0u64, 0u64, 0u64);
    let feedback = p.feedback && p.mu != 0.0;
    let before_end = if feedback {
        p.t_on
    } else {
        transient + 10.0 * period
    };
    let mut strobe = [None, None];
    let (mut margin, mut clear) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..steps {
        let k = sim.step_index();
        let t = sim.time();
        let x = *sim.state();
        let out = sim.step();
        if let Some(steer) = each(t, &x, &out) {
            sim.law.params.steer = Some(steer);
        }
        hist.push(x.qd);
        let resid = (x.qd - hist.sample(k as f64 - period / dt)).norm();
        if t >= period && t < before_end && t >= before_end - 10.0 * period {
            before.0 += resid;
            before.1 += 1;
        }
        if t >= duration - 10.0 * period {
            after.0 += resid;
            after.1 += 1;
        }
        if k.is_multiple_of(per) {
            strobe = [strobe[1], Some(x.q)];
        }
        if t >= transient {
            sq += out.tracking_error * out.tracking_error;
            n_after += 1;
            s.max_tracking_error = s.max_tracking_error.max(out.tracking_error);
            s.max_orientation_error = s.max_orientation_error.max(out.orientation_error);
        }
        s.max_joint_speed = s.max_joint_speed.max(x.qd.amax());
        let ratio = (0..N)
            .map(|i| x.qd[i].abs() / p.safety.qd_max[i])
            .fold(0.0, f64::max);
        s.max_speed_ratio = s.max_speed_ratio.max(ratio);
        margin = margin.min(out.joint_margin);
        clear = clear.min(out.clearance);
        singular += u64::from(out.flags & flags::SINGULAR != 0);
        lost += u64::from(out.flags & flags::TRACK_LOST != 0);
        active += u64::from(out.flags & flags::SAFETY_ACTIVE != 0);
        s.safety_left_null_space_steps += u64::from(out.flags & flags::SAFETY_LEFT_NULL_SPACE != 0);
        s.safety_infeasible_steps += u64::from(out.flags & flags::SAFETY_INFEASIBLE != 0);
        s.nonfinite_steps += u64::from(out.flags & flags::NONFINITE != 0);
        if !sim.state().is_finite() {
            s.finite = false;
            break;
        }
    }
    let mean = |(sum, n): (f64, u64)| (n > 0).then(|| sum / n as f64);
    s.rms_tracking_error = if n_after > 0 {
        (sq / n_after as f64).sqrt()
    } else {
        0.0
    };
    s.period_residual_before = mean(before);
    s.period_residual_final = mean(after);
    if let [Some(a), Some(b)] = strobe {
        s.drift_per_period = Some((b - a).norm());
    }
    s.min_joint_margin = margin.is_finite().then_some(margin);
    s.min_clearance = clear.is_finite().then_some(clear);
    let n = steps.max(1) as f64;
    s.singular_fraction = singular as f64 / n;
    s.track_lost_fraction = lost as f64 / n;
    s.safety_active_time = active as f64 * dt;
    s
}

/// The stroboscopic map of the loop without feedback: `steps` steps (one task period) from t = 0
/// and state `x`. On a period-T orbit the Pyragas term vanishes, so the orbits the feedback can
/// stabilise are this map's fixed points (`control::analysis::newton_orbit`).
pub fn stroboscopic_map<const N: usize, const M: usize>(
    arm: &SpatialArm<N>,
    params: &SpatialParams,
    dt: f64,
    steps: u64,
    x: &ArmState<N>,
) -> ArmState<N> {
    let mut p = *params;
    p.feedback = false;
    let mut sim = SpatialSimulation::<N, M>::spatial(*arm, p, dt, x.q, x.qd, p.tau);
    for _ in 0..steps {
        sim.step();
    }
    *sim.state()
}
