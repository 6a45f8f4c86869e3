//! The method on a spatial arm from URDF (SCIENCE.md §8): tasks of 3 or 6 rows, the law, the
//! secondary tasks, the safety filter and the closed loop.
//!
//! The planar arm keeps its closed-form kinematics ([`crate::arm`]) because the paper's numbers
//! are pinned to them; a spatial arm runs on [`crate::model::Model`]. Both hand their task
//! Jacobian and task acceleration to [`crate::resolve`], so the law proper exists once.

pub mod arm;
pub mod commanded;
pub mod config;
pub mod custom;
pub mod law;
pub mod safety;
pub mod secondary;
pub mod sim;
pub mod task;

pub use arm::{SpatialArm, SpatialKinematics};
pub use law::{SpatialParams, SpatialSecondary};
pub use secondary::{Sphere, SphereSet};
pub use sim::{SpatialSimulation, SpatialSummary};
pub use task::{Path, Shape, SpatialTask, Target, TaskKind, Vec3};

/// Calls `$body` with `const M: usize` bound to the task's row count (3 or 6).
#[macro_export]
macro_rules! with_task_rows {
    ($kind:expr, |$m:ident| $body:expr) => {
        match $kind {
            $crate::spatial::TaskKind::Position => {
                const $m: usize = 3;
                $body
            }
            $crate::spatial::TaskKind::Pose => {
                const $m: usize = 6;
                $body
            }
        }
    };
}
