//! Targeting: the arm steered onto the model's cycle, then handed to the delayed feedback.
//!
//! Delayed feedback makes a cycle stable, but only an arm that comes near it is caught, and a
//! chaotic self-motion comes near when it happens to: on the planar arm that took 30–250 s at
//! every gain that stabilises it (docs/monitor.md), while the gain itself was right. The
//! daemon knows the cycle it chose the gain for ([`crate::tune`] finds it by Newton's method),
//! so it need not wait: it steers the self-motion onto it with the planner's pull
//! ([`crate::steer`]: a critically damped joint pull with the cycle's acceleration fed forward,
//! projected onto the self-motion, so the hand's tracking is untouched), and once the steered
//! arm repeats itself to [`RELEASE_RESIDUAL`] for a whole period it takes the pull away. The
//! Pyragas term vanishes on the cycle and the chosen gain makes it stable, so the arm stays.
//!
//! The pull follows a table of 64 postures ([`crate::steer::CycleTable`]), and a chaotic arm's
//! cycle is too sharp for that: a spline through the cycle's own postures misses its
//! acceleration by 118 rad/s² on the planar arm, and the steered arm settles 6 mm-rad off the
//! cycle (more with a softer pull), from where the feedback takes 20 periods more. So the table
//! is corrected off the loop ([`CORRECTIONS`] times): the steered law is run from the cycle,
//! and each posture is moved by how far the steered arm missed it there. Three corrections
//! bring the steered arm within 5e-6 rad of the cycle.
//!
//! This allocates and simulates a few periods per correction: the daemon runs it on the gain
//! search's thread, never on the loop, and the offline monitor calls the same function.

use crate::analysis::PeriodicOrbit;
use crate::basics::wrap_angle;
use crate::sim::{ClosedLoopLaw, Simulation};
use crate::steer::{Cycle, SpatialSteer, Steer, SteerError, Steering, MAX_PHASES};
use crate::system::System;
use crate::with_dof;

/// The pull's natural frequency in cycles per task period, critically damped: the planar
/// arm's cycle (1 s) sweeps at up to 10 rad/s, and a pull of one cycle a period lagged it by
/// 0.1 rad; the Panda's (2 s) is slower, and a pull twice as fast as its own made the filter
/// brake it.
pub const TARGET_CYCLES: f64 = 4.0;

/// The period residual |q̇(t) − q̇(t − T)| (rad/s) the steered arm must stay below for a whole
/// period before the pull is taken away: a twentieth of the monitor's `periodic` threshold, so
/// the feedback takes over an arm already on its cycle.
pub const RELEASE_RESIDUAL: f64 = 1e-3;

/// Periods of steering after which the pull is taken away whether or not the arm settled (an
/// arm the filter or a plant that is not the model keeps off the cycle).
pub const MAX_STEER_PERIODS: f64 = 10.0;

/// How often an arm knocked off its cycle after the model's gain came (the monitor calls it
/// chaotic again) is steered back before the next edit: a plant the steering cannot hold on
/// the cycle is left to the feedback after that.
pub const MAX_RETARGETS: u32 = 3;

/// How often the table is corrected against the steered law (see the module docs).
pub const CORRECTIONS: usize = 3;

/// The largest miss (rad) of a steered law that can be corrected: beyond it the pull cannot
/// follow the cycle at all (the steered arm went elsewhere).
const MAX_MISS: f64 = 0.1;

/// Periods the steered law runs from the cycle before its miss is measured.
const SETTLE_PERIODS: usize = 4;

/// Why there is no steering onto the model's cycle.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TargetError {
    #[error(
        "the cycle's period {period} s is shorter than {MAX_PHASES} of the simulation's steps"
    )]
    TooShort { period: f64 },
    #[error("the model's cycle cannot be steered onto: {0}")]
    Table(#[from] SteerError),
    #[error("the steered law left the cycle by {miss} rad (it cannot follow it)")]
    Unfollowed { miss: f64 },
}

/// The steering onto the model's cycle, and how well the steered law follows it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Target {
    pub steering: Steering,
    /// The steered law's largest miss of the cycle's postures (rad), after the corrections.
    pub miss: f64,
}

/// The steering onto `orbit` (the cycle the model's gain makes stable, its point at t = kT)
/// for the set-up `system`.
///
/// ```
/// use control::tune::{choose_gain, TuneSpec};
/// let mut system = control::System::preset("paper", &control::system::builtin_robot).unwrap();
/// system.schedule_feedback(control::adapt::MuSetting::Auto, 0.0);
/// let choice = choose_gain(&system, None, &TuneSpec::of(&system)).unwrap();
/// let t = control::target::target(&system, &choice.orbit).unwrap();
/// assert!(t.miss < 1e-4, "{}", t.miss);
/// ```
pub fn target(system: &System, orbit: &PeriodicOrbit) -> Result<Target, TargetError> {
    // The cycle as the loop runs it later: no start ramp, and no feedback (it vanishes there).
    let mut steady = system.clone();
    *steady.task_ramp_mut() = 0.0;
    steady.schedule_feedback(crate::adapt::MuSetting::Fixed(0.0), 0.0);
    let period = system.period();
    // A step that divides the period into the table's phases.
    let per_phase = (period / (MAX_PHASES as f64 * system.sim_section().dt)).round();
    if per_phase < 1.0 {
        return Err(TargetError::TooShort { period });
    }
    let dt = period / (MAX_PHASES as f64 * per_phase);
    let per_phase = per_phase as usize;
    with_dof!(system.n(), N => {
        let start = orbit.state::<N>();
        let postures = |law, periods: usize| {
            let mut sim = Simulation::of(law, dt, start, period);
            let mut out = Vec::with_capacity(MAX_PHASES);
            for k in 0..(periods + 1) * MAX_PHASES * per_phase {
                if k >= periods * MAX_PHASES * per_phase && k % per_phase == 0 {
                    out.push(sim.state().q.as_slice().to_vec());
                }
                sim.step();
            }
            out
        };
        let cycle = postures(steady.tick_law::<N>(), 0);
        let mut rows = cycle.clone();
        let mut steering = steering_of(system, &rows, period)?;
        let mut miss = f64::INFINITY;
        for correction in 0..=CORRECTIONS {
            let mut law = steady.tick_law::<N>();
            law.set_steering(Some(steering));
            let got = postures(law, SETTLE_PERIODS);
            miss = 0.0;
            for (row, (want, got)) in rows.iter_mut().zip(cycle.iter().zip(&got)) {
                for (r, (w, g)) in row.iter_mut().zip(want.iter().zip(got)) {
                    let d = wrap_angle(w - g);
                    miss = f64::max(miss, d.abs());
                    *r += d;
                }
            }
            if miss.is_nan() || miss > MAX_MISS {
                return Err(TargetError::Unfollowed { miss });
            }
            if correction < CORRECTIONS {
                steering = steering_of(system, &rows, period)?;
            }
        }
        Ok(Target { steering, miss })
    })
}

/// Whether `system` is steered onto the model's cycle: `mu = "auto"` with `feedback.target`
/// (the default), and no planner that steers it onto a clean cycle of its own (`safety.plan`:
/// with obstacles the planner has the arm).
pub fn target_wanted(system: &System) -> bool {
    let f = system.feedback_section();
    f.auto.is_some() && f.target && f.enabled && !crate::plan::plan_asked(system).0
}

/// The pull onto the cycle through `rows` (one posture per phase from t = 0).
fn steering_of(system: &System, rows: &[Vec<f64>], period: f64) -> Result<Steering, SteerError> {
    let c = Cycle::through(0.0, period, rows.to_vec());
    match system {
        System::Planar(_) => Steer::of(&c, TARGET_CYCLES / period).map(Steering::Planar),
        System::Spatial(_) => SpatialSteer::of(&c, TARGET_CYCLES / period).map(Steering::Spatial),
    }
}

/// Whether the steered arm may be handed to the feedback: it watches the period residual.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Release {
    /// When the steering began (s).
    pub since: f64,
    period: f64,
    /// Since when the residual has stayed below [`RELEASE_RESIDUAL`].
    calm_from: Option<f64>,
}

/// Why the pull was taken away.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Released {
    /// The steered arm repeated itself for a whole period: on the cycle.
    OnTheCycle,
    /// [`MAX_STEER_PERIODS`] went by without that.
    TimedOut,
}

impl Release {
    /// A watch for a steering that began at `t`, for a cycle of `period` s.
    pub fn new(t: f64, period: f64) -> Self {
        Self {
            since: t,
            period,
            calm_from: None,
        }
    }

    /// One step of the steered arm at time `t` with period residual `residual` (rad/s), the
    /// delayed feedback on or not yet (`feedback`): Some once the pull should go. It stays
    /// while the feedback is off (before `feedback.t_on`): nothing would hold the arm on its
    /// cycle then.
    ///
    /// ```
    /// use control::target::{Release, Released};
    /// let mut r = Release::new(10.0, 1.0);
    /// assert_eq!(r.observe(10.5, 1e-4, true), None);
    /// assert_eq!(r.observe(11.2, 5e-3, true), None); // not yet calm a whole period
    /// assert_eq!(r.observe(11.3, 1e-4, true), None);
    /// assert_eq!(r.observe(12.3, 1e-4, false), None); // the feedback is not on yet
    /// assert_eq!(r.observe(12.4, 1e-4, true), None);
    /// assert_eq!(r.observe(13.4, 1e-4, true), Some(Released::OnTheCycle));
    /// assert_eq!(Release::new(0.0, 1.0).observe(10.0, 1.0, true), Some(Released::TimedOut));
    /// ```
    pub fn observe(&mut self, t: f64, residual: f64, feedback: bool) -> Option<Released> {
        if residual < RELEASE_RESIDUAL && feedback {
            let from = *self.calm_from.get_or_insert(t);
            if t - from >= self.period {
                return Some(Released::OnTheCycle);
            }
        } else {
            self.calm_from = None;
        }
        let timed_out = feedback && t - self.since >= MAX_STEER_PERIODS * self.period;
        timed_out.then_some(Released::TimedOut)
    }
}
