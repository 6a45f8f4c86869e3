//! The deterministic closed loop on a spatial arm: the kinematic plant (q̈ is commanded) under the
//! spatial law, with the conventions of docs/science.md, "Time, integration and determinism" (RK4, the law at every stage, q̇(s − τ)
//! from the delay line, time = step · dt).
//!
//! The loop itself is the one [`Simulation`] and a run the one [`run`]; what is spatial here is
//! the constructor (the orbit search's period map is every arm's,
//! [`crate::analysis::stroboscopic_map`]).

use crate::arm::spatial::SpatialArm;
use crate::arm::spatial::VecN;
use crate::law::spatial::SpatialParams;
use crate::sim::{ArmState, Simulation, SpatialLaw};

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

impl super::StatsSetup {
    /// A spatial law's: its path's period, its feedback, its spheres and its filter.
    pub fn spatial(p: &SpatialParams) -> Self {
        Self::of(&p.core, p.task.path.period, !p.spheres.is_empty())
    }
}

pub use super::{run, run_steering};
