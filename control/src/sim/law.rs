//! What a closed loop needs of its law, whichever arm it drives, so that one [`super::Simulation`],
//! one Lyapunov trajectory and one monitored run serve the planar arm and every URDF chain.
//!
//! A law here is an arm model with its parameter block: the planar closed form with
//! [`LawParams`] ([`PlanarLaw`]), a URDF chain with [`SpatialParams`] for a task of `M` rows
//! ([`SpatialLaw`]), or the daemon's [`crate::tick_law::TickLaw`], which holds either. The
//! simulation steps all of them with the same integrator, delay line and adaptation, so a
//! number that differs between two arms differs because of the arm, never because of the loop.

use super::{ArmState, StatsSetup};
use crate::arm::spatial::{SpatialArm, SpatialKinematics};
use crate::arm::{ArmModel, Kinematics, VecN};
use crate::law::pipeline::{Command, Full, Output};
use crate::law::spatial::SpatialParams;
pub use crate::law::LoopFeedback;
use crate::law::{self, LawCore, LawParams, ParamBlock};
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

/// The paper's planar arm (fixed or floating base) under [`crate::law::evaluate`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarLaw<const N: usize> {
    pub model: ArmModel<N>,
    pub params: LawParams,
}

impl<const N: usize> ClosedLoopLaw<N> for PlanarLaw<N> {
    type Scratch = Kinematics<N>;

    #[inline]
    fn run<O: Output<N>>(
        &self,
        t: f64,
        x: &ArmState<N>,
        delayed: &VecN<N>,
        kin: &mut Kinematics<N>,
        out: O,
    ) -> O::Value {
        let (m, p) = (&self.model, &self.params);
        law::run(p, m, t, (x.phi, &x.q, &x.qd), delayed, kin, out)
    }
    fn core(&self) -> &LawCore {
        &self.params.core
    }
    fn core_mut(&mut self) -> &mut LawCore {
        &mut self.params.core
    }
    fn is_floating(&self) -> bool {
        self.model.is_floating()
    }
    fn stats_setup(&self) -> StatsSetup {
        StatsSetup::planar(&self.params)
    }
    fn set_steering(&mut self, steering: Option<Steering>) {
        self.params.steer = match steering {
            Some(Steering::Planar(s)) => Some(s),
            _ => None,
        };
    }
    fn steering(&self) -> Option<Steering> {
        self.params.steer.map(Steering::Planar)
    }
    fn set_block(&mut self, block: ParamBlock) -> bool {
        match block {
            ParamBlock::Planar(p) => self.params = p,
            ParamBlock::Spatial(_) => return false,
        }
        true
    }
}

/// A URDF chain under [`crate::law::spatial::evaluate`] for a task of `M` rows (3: position, 6:
/// pose); `M` is static so that the task's size costs nothing per step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialLaw<const N: usize, const M: usize> {
    pub arm: SpatialArm<N>,
    pub params: SpatialParams,
}

impl<const N: usize, const M: usize> ClosedLoopLaw<N> for SpatialLaw<N, M> {
    type Scratch = SpatialKinematics<N>;

    #[inline]
    fn run<O: Output<N>>(
        &self,
        t: f64,
        x: &ArmState<N>,
        delayed: &VecN<N>,
        kin: &mut SpatialKinematics<N>,
        out: O,
    ) -> O::Value {
        let (arm, p) = (&self.arm, &self.params);
        law::spatial::run::<N, M, O>(p, arm, t, (&x.q, &x.qd), delayed, kin, out)
    }
    fn core(&self) -> &LawCore {
        &self.params.core
    }
    fn core_mut(&mut self) -> &mut LawCore {
        &mut self.params.core
    }
    fn stats_setup(&self) -> StatsSetup {
        StatsSetup::spatial(&self.params)
    }
    fn set_steering(&mut self, steering: Option<Steering>) {
        self.params.steer = match steering {
            Some(Steering::Spatial(s)) => Some(s),
            _ => None,
        };
    }
    fn steering(&self) -> Option<Steering> {
        self.params.steer.map(Steering::Spatial)
    }
    fn set_block(&mut self, block: ParamBlock) -> bool {
        match block {
            ParamBlock::Spatial(p) if p.task.kind.rows() == M => self.params = p,
            _ => return false,
        }
        true
    }
}
