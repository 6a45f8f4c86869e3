//! What a closed loop needs of its law, whichever arm it drives, so that one [`super::Simulation`],
//! one Lyapunov trajectory and one monitored run serve the planar arm and every URDF chain.
//!
//! The law every simulation steps is the daemon's own [`crate::tick_law::TickLaw`], which holds
//! either arm (the paper's planar closed form, or a URDF chain for a task of 3 or 6 rows); a
//! user's own law (`examples/`) implements this trait too. One integrator, one delay line and
//! one adaptation for all of them, so a number that differs between two arms differs because
//! of the arm, never because of the loop, and an offline run is the daemon's law to the bit.

use super::{ArmState, StatsSetup};
use crate::arm::VecN;
use crate::law::pipeline::{Command, Full, Output};
pub use crate::law::LoopFeedback;
use crate::law::{LawCore, ParamBlock};
use crate::resolve::ControlOutput;
use crate::steer::Steering;

/// A control law a closed loop can step: its evaluation and the few numbers the loop reads.
pub trait ClosedLoopLaw<const N: usize>: Clone {
    /// The law's scratch (kinematics), kept by the simulation so that a step never allocates.
    type Scratch: Clone + Default + std::fmt::Debug;

    /// The law at time `t` on state `x`, with the delayed velocity q̇(t − τ): what `out` asks
    /// for ([`Output`]), the whole output or the command alone.
    fn run<O: Output<N>>(
        &self,
        t: f64,
        x: &ArmState<N>,
        delayed: &VecN<N>,
        scratch: &mut Self::Scratch,
        out: O,
    ) -> O::Value;

    /// [`Self::run`]'s whole output.
    #[inline]
    fn evaluate(
        &self,
        t: f64,
        x: &ArmState<N>,
        delayed: &VecN<N>,
        scratch: &mut Self::Scratch,
    ) -> ControlOutput<N> {
        self.run(t, x, delayed, scratch, Full)
    }

    /// [`Self::evaluate`]'s (q̈, φ̇) alone, bit for bit: what an integrator's inner stages need,
    /// without the diagnostics nobody reads there.
    #[inline]
    fn acceleration(
        &self,
        t: f64,
        x: &ArmState<N>,
        delayed: &VecN<N>,
        scratch: &mut Self::Scratch,
    ) -> (VecN<N>, f64) {
        self.run(t, x, delayed, scratch, Command)
    }

    /// The gains, feedback and limits every arm's law has.
    fn core(&self) -> &LawCore;
    fn core_mut(&mut self) -> &mut LawCore;

    /// The gains the loop reads: μ now, τ, where the feedback acts, and whether the delayed
    /// history is part of the state (feedback on with μ ≠ 0).
    fn loop_feedback(&self) -> LoopFeedback {
        self.core().loop_feedback()
    }

    /// Adapts μ after a step whose output was `out` (`feedback.mu = "auto"`), `dt` after the last.
    #[inline]
    fn adapt(&mut self, out: &ControlOutput<N>, dt: f64) {
        self.core_mut().adapt(out, dt)
    }

    /// Whether the base turns (the planar floating base): φ is then part of the state.
    fn is_floating(&self) -> bool {
        false
    }

    /// What a run's statistics need of this law.
    fn stats_setup(&self) -> StatsSetup;

    /// Steers the self-motion onto a planned cycle, or stops (None). A cycle planned for
    /// another kind of arm stops the steering.
    fn set_steering(&mut self, steering: Option<Steering>);
    /// The planned cycle the law steers onto, if any (what a trap watch follows).
    fn steering(&self) -> Option<Steering>;

    /// Replaces the whole parameter block; false (and unchanged) when the block is for
    /// another kind of arm or task.
    fn set_block(&mut self, block: ParamBlock) -> bool;

    /// A live change, as the daemon makes it: the new block in, an adapting gain going on from
    /// where it stood ([`LawCore::carry_adapted_mu`]), the planned cycle kept. False (and
    /// unchanged) for a block of another kind of arm or task.
    fn take_block(&mut self, block: ParamBlock) -> bool {
        let (mu, steering) = (self.core().mu, self.steering());
        let anchor = self.core().auto_mu.and_then(|a| a.anchor);
        if !self.set_block(block) {
            return false;
        }
        self.core_mut().carry_adapted_mu(mu, anchor);
        self.set_steering(steering);
        true
    }
}
