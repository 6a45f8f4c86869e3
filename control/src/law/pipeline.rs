//! The law's steps in their order, written once for every arm (docs/science.md, "The control
//! law"): the task's rows, the damped pseudo-inverse, the secondary task, the Pyragas term,
//! the pause, the safety filter, the flags and the output.
//!
//! What differs between the paper's planar arm and a URDF chain is behind [`ArmSide`]: how the
//! task's rows are built (closed form or a chain, a circle in the plane or a spatial path), the
//! secondary tasks' formulas, the steering onto a planned cycle, and the filter's geometry
//! (links against discs, capsules against spheres). A new kind of arm implements `ArmSide`; a
//! change to the law's order of steps is made here and holds for every arm. The planar numbers
//! are pinned to this order: each step computes what it computed before the two laws were one.

use crate::arm::VecN;
use crate::basics::flags;
use crate::resolve::{damped_pinv_deciding, resolve, ControlOutput, NullTerms, Projection};
use crate::safety::{pause_brake, Filtered, SafetyParams};
use nalgebra::{SMatrix, SVector, Vector3};

/// The task at one state: its M×N Jacobian, the acceleration it asks of the tool, and where the
/// tool is against where it should be.
pub struct TaskRows<const N: usize, const M: usize> {
    pub j: SMatrix<f64, M, N>,
    /// ẍ_d + K_v(ẋ_d − Jq̇) + K_p e − J̇q̇.
    pub acc: SVector<f64, M>,
    /// |p_d − p| (m) and, for a pose task, |log(R_d Rᵀ)| (rad).
    pub position_error: f64,
    pub orientation_error: f64,
    /// The tool point and its target in the base frame (z = 0 in the plane).
    pub p: Vector3<f64>,
    pub p_desired: Vector3<f64>,
}

/// The gains and switches every arm's law has, read once per evaluation.
#[derive(Clone, Copy)]
pub struct Gains<'a> {
    pub alpha: f64,
    pub damping_threshold: f64,
    pub damping_max: f64,
    pub mu: f64,
    /// The delayed feedback applies at this instant (`feedback_active(t)`).
    pub feedback_on: bool,
    pub projection: Projection,
    pub pause: bool,
    pub track_loss: f64,
    pub safety: &'a SafetyParams,
}

/// One arm's side of the law at one state: what the planar closed form and a URDF chain do
/// differently. The pipeline calls [`Self::task`] first; the other methods read the
/// kinematics it left behind, and [`Self::secondary`] before the others (it may keep scratch).
pub trait ArmSide<const N: usize, const M: usize> {
    fn gains(&self, t: f64) -> Gains<'_>;
    /// Computes the kinematics at (q, q̇) and returns the task's rows at `t`.
    fn task(&mut self, t: f64, q: &VecN<N>, qd: &VecN<N>) -> TaskRows<N, M>;
    /// The damped pseudo-inverse (J⁺, σ_min, λ) of the task's Jacobian; an arm with a closed
    /// form for its row count may give it (the planar arm's 2×2). Without `smin_wanted` σ_min
    /// may come back NaN where it only had to decide the damping
    /// ([`crate::resolve::damped_pinv_deciding`]); J⁺ and λ are the same.
    #[inline]
    fn pinv(
        &self,
        j: &SMatrix<f64, M, N>,
        threshold: f64,
        lambda_max: f64,
        smin_wanted: bool,
    ) -> (SMatrix<f64, N, M>, f64, f64) {
        damped_pinv_deciding(j, threshold, lambda_max, smin_wanted)
    }
    /// A planned cycle is being steered onto: it replaces the secondary task.
    fn steering(&self) -> bool;
    /// The secondary task's value and η (None: no secondary task).
    fn secondary(
        &mut self,
        t: f64,
        q: &VecN<N>,
        qd: &VecN<N>,
        j: &SMatrix<f64, M, N>,
    ) -> (f64, Option<VecN<N>>);
    /// Whether the delayed feedback waits at `t` even though it is on (a detour's motion is not
    /// the cycle's, so it waits a delay past it).
    fn feedback_held(&self, _t: f64) -> bool {
        false
    }
    /// A joint-space motion that replaces the resolved law at `t` (a running detour), with the
    /// flag it sets.
    fn takeover(&self, _t: f64, _q: &VecN<N>, _qd: &VecN<N>) -> Option<(VecN<N>, u32)> {
        None
    }
    /// What the arm adds to the resolved q̈: the pull onto a planned cycle, null-space damping.
    fn shape(
        &self,
        t: f64,
        q: &VecN<N>,
        qd: &VecN<N>,
        j: &SMatrix<f64, M, N>,
        jpinv: &SMatrix<f64, N, M>,
        qdd: &mut VecN<N>,
    );
    /// The safety filter on the command, with this arm's geometry.
    fn filter(
        &self,
        q: &VecN<N>,
        qd: &VecN<N>,
        j: &SMatrix<f64, M, N>,
        jpinv: &SMatrix<f64, N, M>,
        qdd: &VecN<N>,
    ) -> Filtered<N>;
    /// The clearance to the nearest obstacle (+∞ without any) and whether a link is in a
    /// safety zone.
    fn clearance(&self) -> (f64, bool);
    /// Flags only this arm can raise (the planar arm's out-of-reach target).
    fn task_flags(&self, _rows: &TaskRows<N, M>) -> u32 {
        0
    }
    /// φ̇ of a turning base (0 for a fixed base).
    fn base_rate(&self) -> f64 {
        0.0
    }
}

/// What a caller reads of one evaluation: the whole [`ControlOutput`] ([`Full`]) or the command
/// alone ([`Command`]). One [`run`] serves both, so the two can never compute different q̈.
pub trait Output<const N: usize>: Copy {
    type Value;
    /// Whether σ_min is wanted (only the full output reports it; [`ArmSide::pinv`]).
    const SMIN: bool;
    /// What the caller reads, from the command and the arm's kinematics at the state.
    fn finish<const M: usize>(
        self,
        arm: &mut impl ArmSide<N, M>,
        t: f64,
        q: &VecN<N>,
        c: Commanded<N, M>,
    ) -> Self::Value;
}

/// The whole output: q̈ with the diagnostics (clearance, residuals, joint margin, flags).
#[derive(Clone, Copy, Debug)]
pub struct Full;

/// The command alone, (q̈, φ̇), for the evaluations whose diagnostics nobody reads: an RK4 step's
/// inner stages and the first-order hold's second point. q̈ is [`Full`]'s bit for bit, as the
/// diagnostics never feed it; on the Panda with four spheres they are about a tenth of an
/// evaluation.
#[derive(Clone, Copy, Debug)]
pub struct Command;

impl<const N: usize> Output<N> for Full {
    type Value = ControlOutput<N>;
    const SMIN: bool = true;
    #[inline(always)]
    fn finish<const M: usize>(
        self,
        arm: &mut impl ArmSide<N, M>,
        t: f64,
        q: &VecN<N>,
        c: Commanded<N, M>,
    ) -> ControlOutput<N> {
        let g = arm.gains(t);
        let mut flag = c.flag;
        let (clearance, in_zone) = arm.clearance();
        if in_zone {
            flag |= flags::IN_SAFETY_ZONE;
        }
        let rows = &c.rows;
        let tracking_error = rows.position_error;
        if tracking_error.is_nan() || tracking_error > g.track_loss {
            flag |= flags::TRACK_LOST;
        }
        flag |= arm.task_flags(rows);
        let (j, diff) = (&rows.j, c.diff);
        ControlOutput {
            qdd: c.qdd,
            p: rows.p,
            p_desired: rows.p_desired,
            tracking_error,
            orientation_error: rows.orientation_error,
            sigma_min: c.smin,
            damping: c.lambda,
            secondary_value: c.secondary_value,
            period_residual: diff.norm(),
            null_residual: (diff - c.jpinv * (j * diff)).norm(),
            clearance,
            joint_margin: g.safety.joint_margin(q),
            demand: c.demand,
            base_rate: arm.base_rate(),
            flags: flag,
        }
    }
}

impl<const N: usize> Output<N> for Command {
    type Value = (VecN<N>, f64);
    const SMIN: bool = false;
    #[inline(always)]
    fn finish<const M: usize>(
        self,
        arm: &mut impl ArmSide<N, M>,
        _t: f64,
        _q: &VecN<N>,
        c: Commanded<N, M>,
    ) -> (VecN<N>, f64) {
        (c.qdd, arm.base_rate())
    }
}

/// Runs the law on `arm` at time `t` for state (q, q̇) with delayed velocity q̇(t − τ), and
/// returns what `out` asks for.
#[inline]
pub fn run<const N: usize, const M: usize, O: Output<N>>(
    arm: &mut impl ArmSide<N, M>,
    t: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
    qd_delayed: &VecN<N>,
    out: O,
) -> O::Value {
    let c = command(arm, t, q, qd, qd_delayed, O::SMIN);
    out.finish(arm, t, q, c)
}

/// What the law commands at one state and what it met on the way, before the diagnostics.
pub struct Commanded<const N: usize, const M: usize> {
    rows: TaskRows<N, M>,
    jpinv: SMatrix<f64, N, M>,
    smin: f64,
    lambda: f64,
    diff: VecN<N>,
    secondary_value: f64,
    qdd: VecN<N>,
    demand: f64,
    flag: u32,
}

/// The law's steps up to the finite, filtered q̈; σ_min is computed only if `smin_wanted`
/// (else it may be NaN, [`ArmSide::pinv`]).
#[inline(always)]
fn command<const N: usize, const M: usize>(
    arm: &mut impl ArmSide<N, M>,
    t: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
    qd_delayed: &VecN<N>,
    smin_wanted: bool,
) -> Commanded<N, M> {
    let rows = arm.task(t, q, qd);
    let j = &rows.j;
    let (secondary_value, eta) = if arm.steering() {
        (0.0, None)
    } else {
        arm.secondary(t, q, qd, j)
    };
    let g = arm.gains(t);
    let mut flag = 0u32;
    let (jpinv, smin, lambda) = arm.pinv(j, g.damping_threshold, g.damping_max, smin_wanted);
    if lambda > 0.0 {
        flag |= flags::SINGULAR;
    }
    let diff = qd - qd_delayed;
    let feedback = g.feedback_on && !arm.feedback_held(t);
    if feedback {
        flag |= flags::FEEDBACK_ACTIVE;
    }
    let terms = NullTerms {
        eta,
        alpha: g.alpha,
        diff,
        mu: feedback.then_some(g.mu),
        projection: g.projection,
    };
    let mut qdd = match arm.takeover(t, q, qd) {
        Some((qdd, f)) => {
            flag |= f;
            qdd
        }
        None => {
            let mut qdd = resolve(j, &jpinv, &rows.acc, &terms);
            arm.shape(t, q, qd, j, &jpinv, &mut qdd);
            qdd
        }
    };
    if g.pause {
        qdd = pause_brake(qd, &g.safety.qdd_max);
    }
    let demand = (0..N)
        .map(|i| qdd[i].abs() / g.safety.qdd_max[i])
        .fold(0.0, f64::max);
    if g.safety.enabled && qdd.iter().all(|v| v.is_finite()) {
        let f = arm.filter(q, qd, j, &jpinv, &qdd);
        qdd = f.qdd;
        flag |= f.flags;
    }
    if !qdd.iter().all(|v| v.is_finite()) {
        qdd = VecN::<N>::zeros();
        flag |= flags::NONFINITE;
    }
    Commanded {
        rows,
        jpinv,
        smin,
        lambda,
        diff,
        secondary_value,
        qdd,
        demand,
        flag,
    }
}
