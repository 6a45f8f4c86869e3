//! The continuous law in a sampled-data loop: how a command is held between two ticks.
//!
//! The paper's law is continuous in time; the daemon evaluates it once per period and the plant
//! applies the result until the next command. Holding q̈ constant (a zero-order hold) is a
//! first-order error, and this arm's self-motion is fast (|q̇| up to ~20 rad/s): at 1 kHz a
//! zero-order hold tracks the circle only to millimetres and does not reproduce the continuous
//! system's orbits. A first-order hold fixes that: the daemon evaluates the law at the state's
//! time and again one period later, on the state predicted with the first result, and sends q̈
//! with its rate q⃛; the plant ramps q̈ = q̈₀ + q⃛·s over the period. At 1 kHz this tracks to
//! ~1e-5 m and follows the continuous system's orbits (`tests/sampled_data.rs`).

use crate::arm::{ArmModel, VecN};
use crate::resolve::ControlOutput;
use crate::sim::{plant_derivative, rk4_step, ArmState, ClosedLoopLaw};
use crate::tick_law::{LawScratch, TickLaw};

/// A command for one hold interval.
#[derive(Clone, Copy, Debug)]
pub struct HeldCommand<const N: usize> {
    /// q̈ at the start of the interval.
    pub qdd: VecN<N>,
    /// dq̈/dt over the interval (zero for a zero-order hold).
    pub qddd: VecN<N>,
    /// The law's output at the start (tracking error, flags, ...).
    pub output: ControlOutput<N>,
}

/// Evaluates the law at (t, x) and, for a first-order hold, at t + h on the predicted state.
/// `delayed(t)` returns q̇(t − τ)'s source signal at time t (the delay line, read by the caller).
#[allow(clippy::too_many_arguments)]
pub fn command<const N: usize>(
    law: &TickLaw<N>,
    t: f64,
    x: &ArmState<N>,
    h: f64,
    first_order: bool,
    mut delayed: impl FnMut(f64) -> VecN<N>,
    scratch: &mut LawScratch<N>,
) -> HeldCommand<N> {
    let tau = law.tau();
    let d0 = delayed(t - tau);
    let out = law.evaluate(t, x, &d0, scratch);
    let mut qddd = VecN::<N>::zeros();
    if first_order && h > 0.0 {
        let u = out.qdd;
        let predicted = ArmState {
            q: x.q + x.qd * h + u * (0.5 * h * h),
            qd: x.qd + u * h,
            phi: x.phi + out.base_rate * h,
        };
        let d1 = delayed(t + h - tau);
        let (next, _) = law.acceleration(t + h, &predicted, &d1, scratch);
        qddd = (next - u) / h;
        if !qddd.iter().all(|v| v.is_finite()) {
            qddd = VecN::<N>::zeros();
        }
    }
    HeldCommand {
        qdd: out.qdd,
        qddd,
        output: out,
    }
}

/// Integrates the kinematic plant over `dt` under q̈(s) = qdd + qddd·(offset + s), with the ramp
/// time clamped to `max_ramp` (a late command is not extrapolated without bound), in `substeps`
/// RK4 steps.
#[allow(clippy::too_many_arguments)]
pub fn integrate<const N: usize>(
    model: &ArmModel<N>,
    x: &ArmState<N>,
    qdd: &VecN<N>,
    qddd: &VecN<N>,
    offset: f64,
    max_ramp: f64,
    dt: f64,
    substeps: u32,
) -> ArmState<N> {
    let h = dt / substeps.max(1) as f64;
    let mut x = *x;
    for i in 0..substeps.max(1) {
        let s0 = offset + i as f64 * h;
        x = rk4_step(&x, h, |c, y| {
            let ramp = (s0 + c * h).clamp(0.0, max_ramp);
            let a = qdd + qddd * ramp;
            let rate = match model {
                ArmModel::Fixed(_) => 0.0,
                ArmModel::Floating(f) => f.base_rate(&y.q, &y.qd),
            };
            plant_derivative(y, &a, rate)
        });
    }
    x
}
