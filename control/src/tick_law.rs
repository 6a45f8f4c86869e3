//! The law a control tick runs, whichever arm it drives: the paper's planar arm (closed-form
//! kinematics, [`crate::law`]) or a URDF chain ([`crate::law::spatial`]).
//!
//! The daemon's controller, the sampled-data hold and the benchmarks hold a [`TickLaw`] and never
//! ask which it is: both evaluate to the same [`ControlOutput`], read q̇(t − τ) from the same delay
//! line and obey the same [`SafetyParams`] (the runaway guard's limits). One `match` per
//! evaluation is the whole cost of the choice; the scratch for both lives side by side so a
//! switch never allocates. Gains, feedback, limits and pause are every arm's [`LawCore`]: read
//! and changed through [`TickLaw::core`], with no per-arm code.

use crate::arm::spatial::SpatialArm;
use crate::arm::spatial::SpatialKinematics;
use crate::arm::{ArmModel, Kinematics, VecN};
use crate::law::pipeline::Output;
use crate::law::spatial as spatial_law;
use crate::law::spatial::SpatialParams;
pub use crate::law::ParamBlock;
use crate::law::{self, LawCore, LawParams};
use crate::resolve::ControlOutput;
use crate::safety::SafetyParams;
use crate::sim::{ArmState, Simulation};
use crate::task::pose::TaskKind;

/// The arm model and the parameters of its law, as one `Copy` block.
// The spatial variant is the larger by far (a URDF model, spheres); boxing it would put the
// tick's law behind a pointer and lose `Copy`, which the swap at a tick boundary relies on.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TickLaw<const N: usize> {
    Planar {
        model: ArmModel<N>,
        params: LawParams,
    },
    Spatial {
        arm: SpatialArm<N>,
        params: SpatialParams,
    },
}

/// Kinematics scratch for either law.
#[derive(Clone, Copy, Debug, Default)]
pub struct LawScratch<const N: usize> {
    pub planar: Kinematics<N>,
    pub spatial: SpatialKinematics<N>,
}

impl<const N: usize> TickLaw<N> {
    /// φ̇ for the state (the planar floating base turns; every other arm has a fixed base).
    #[inline]
    pub fn base_rate(&self, x: &ArmState<N>) -> f64 {
        match self {
            TickLaw::Planar {
                model: ArmModel::Floating(f),
                ..
            } => f.base_rate(&x.q, &x.qd),
            _ => 0.0,
        }
    }

    /// The gains, feedback and limits every arm's law has: the one place that asks which arm
    /// the law drives for them.
    pub fn core(&self) -> &LawCore {
        match self {
            TickLaw::Planar { params, .. } => &params.core,
            TickLaw::Spatial { params, .. } => &params.core,
        }
    }

    pub fn core_mut(&mut self) -> &mut LawCore {
        match self {
            TickLaw::Planar { params, .. } => &mut params.core,
            TickLaw::Spatial { params, .. } => &mut params.core,
        }
    }

    pub fn safety(&self) -> &SafetyParams {
        &self.core().safety
    }

    /// (μ, τ, t_on, feedback switch).
    pub fn feedback(&self) -> (f64, f64, f64, bool) {
        let c = self.core();
        (c.mu, c.tau, c.t_on, c.feedback)
    }

    /// Adapts μ after a law run whose output was `out`, `dt` after the last one (`feedback.mu =
    /// "auto"`; a fixed gain is left as it is). One multiply-add: it runs on the tick. Not while
    /// tracking is paused: the braking arm's residual says nothing about the gain.
    #[inline]
    pub fn adapt(&mut self, out: &ControlOutput<N>, dt: f64) {
        self.core_mut().adapt(out, dt)
    }

    /// The gain and its adaptation's state: all that [`Self::adapt`] changes, for a caller that
    /// runs a tick and undoes it ([`Self::set_gain`]).
    pub fn gain(&self) -> (f64, Option<crate::adapt::AutoMu>) {
        (self.core().mu, self.core().auto_mu)
    }

    /// Puts the gain back where [`Self::gain`] found it.
    pub fn set_gain(&mut self, (mu, auto_mu): (f64, Option<crate::adapt::AutoMu>)) {
        let c = self.core_mut();
        (c.mu, c.auto_mu) = (mu, auto_mu);
    }

    pub fn tau(&self) -> f64 {
        self.feedback().1
    }

    /// Swaps in a parameter block of the same kind of arm; false (and unchanged) otherwise.
    pub fn set(&mut self, block: ParamBlock) -> bool {
        match (self, block) {
            (TickLaw::Planar { params, .. }, ParamBlock::Planar(p)) => *params = p,
            (TickLaw::Spatial { params, .. }, ParamBlock::Spatial(p)) => *params = p,
            _ => return false,
        }
        true
    }

    /// Steers the self-motion onto a planned cycle, or stops. A cycle planned for the other
    /// kind of arm stops the steering.
    pub fn set_steer(&mut self, steer: Option<crate::steer::Steering>) {
        use crate::steer::Steering;
        match self {
            TickLaw::Planar { params, .. } => {
                params.steer = steer.and_then(|s| match s {
                    Steering::Planar(p) => Some(p),
                    Steering::Spatial(_) => None,
                })
            }
            TickLaw::Spatial { params, .. } => {
                params.steer = steer.and_then(|s| match s {
                    Steering::Spatial(p) => Some(p),
                    Steering::Planar(_) => None,
                })
            }
        }
    }

    /// Pauses tracking (the arm brakes to rest under the filter), or resumes it.
    pub fn set_pause(&mut self, pause: bool) {
        self.core_mut().pause = pause
    }

    /// Where a spatial arm's tool point is at `q` (None for the planar arm, whose law always
    /// runs on the measured state).
    pub fn tool_position(&self, q: &VecN<N>) -> Option<crate::task::Vec3> {
        match self {
            TickLaw::Planar { .. } => None,
            TickLaw::Spatial { arm, .. } => Some(arm.tool_position(q)),
        }
    }

    /// The planar law's parameters (None for a spatial arm).
    pub fn planar_params(&self) -> Option<&LawParams> {
        match self {
            TickLaw::Planar { params, .. } => Some(params),
            TickLaw::Spatial { .. } => None,
        }
    }
}

impl<const N: usize> Simulation<N, TickLaw<N>> {
    /// The planar arm `model` under `params` from `initial`. `max_tau` fixes the delay-line
    /// capacity; `params.tau` may later change up to it.
    pub fn new(
        model: ArmModel<N>,
        params: LawParams,
        dt: f64,
        initial: ArmState<N>,
        max_tau: f64,
    ) -> Self {
        Self::of(TickLaw::Planar { model, params }, dt, initial, max_tau)
    }

    /// The URDF chain `arm` under `params` from (`q0`, `qd0`); `max_tau` fixes the delay-line
    /// capacity.
    pub fn spatial(
        arm: SpatialArm<N>,
        params: SpatialParams,
        dt: f64,
        q0: VecN<N>,
        qd0: VecN<N>,
        max_tau: f64,
    ) -> Self {
        let initial = ArmState {
            q: q0,
            qd: qd0,
            phi: 0.0,
        };
        Self::of(TickLaw::Spatial { arm, params }, dt, initial, max_tau)
    }
}

/// The daemon's law in the one closed loop: a simulation of a [`crate::system::System`] runs what
/// the daemon runs, whichever arm it holds.
impl<const N: usize> crate::sim::ClosedLoopLaw<N> for TickLaw<N> {
    type Scratch = LawScratch<N>;

    /// The one place a tick asks which arm it drives.
    #[inline]
    fn run<O: Output<N>>(
        &self,
        t: f64,
        x: &ArmState<N>,
        delayed: &VecN<N>,
        scratch: &mut LawScratch<N>,
        out: O,
    ) -> O::Value {
        match self {
            TickLaw::Planar { model, params } => {
                let state = (x.phi, &x.q, &x.qd);
                law::run(params, model, t, state, delayed, &mut scratch.planar, out)
            }
            TickLaw::Spatial { arm, params } => {
                let (k, state) = (&mut scratch.spatial, (&x.q, &x.qd));
                match params.task.kind {
                    TaskKind::Position => {
                        spatial_law::run::<N, 3, O>(params, arm, t, state, delayed, k, out)
                    }
                    TaskKind::Pose => {
                        spatial_law::run::<N, 6, O>(params, arm, t, state, delayed, k, out)
                    }
                }
            }
        }
    }
    fn core(&self) -> &LawCore {
        TickLaw::core(self)
    }
    fn core_mut(&mut self) -> &mut LawCore {
        TickLaw::core_mut(self)
    }
    fn is_floating(&self) -> bool {
        matches!(self, TickLaw::Planar { model, .. } if model.is_floating())
    }
    fn set_steering(&mut self, steering: Option<crate::steer::Steering>) {
        self.set_steer(steering)
    }
    fn steering(&self) -> Option<crate::steer::Steering> {
        use crate::steer::Steering;
        match self {
            TickLaw::Planar { params, .. } => params.steer.map(Steering::Planar),
            TickLaw::Spatial { params, .. } => params.steer.map(Steering::Spatial),
        }
    }
    fn stats_setup(&self) -> crate::sim::StatsSetup {
        match self {
            TickLaw::Planar { params, .. } => crate::sim::StatsSetup::planar(params),
            TickLaw::Spatial { params, .. } => crate::sim::StatsSetup::spatial(params),
        }
    }
    fn set_block(&mut self, block: ParamBlock) -> bool {
        self.set(block)
    }
}
