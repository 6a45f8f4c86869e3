//! Planning for whichever arm a [`System`] holds: the daemon's planner thread and `chaosctl
//! simulate` both come through here, so an offline run answers a trap as the daemon does.

use super::spatial::plan_system_with;
use super::{PlanOutcome, PlanSettings, Planned};
use crate::steer::Blocked;
use crate::steer::SpatialSteer;
use crate::steer::{Cycle, Steer, Steering};
use crate::system::System;
use crate::tick_law::TickLaw;

/// Whether the set-up steers onto its planned cycle now (`safety.plan`: the filter on, an arm
/// with a planner and, for `auto`, an obstacle), and the pull's frequency (Hz).
pub fn plan_asked(system: &System) -> (bool, f64) {
    let c = system.config();
    (c.steers_onto_plan(), c.safety.plan_hz)
}

/// Whether the arm has a cycle planner: the fixed-base 3-link planar arm, or a URDF chain.
pub fn has_planner(system: &System) -> bool {
    system.config().has_planner()
}

/// A cycle for `system` from task time `t0`, near the posture `q_now` when given (else the
/// start's), and for a spatial arm bent from the cycle it `following` now.
pub fn plan_arm(
    system: &System,
    t0: f64,
    q_now: Option<&[f64]>,
    following: Option<&Steering>,
) -> Result<Planned, super::PlanError> {
    plan_arm_with(system, t0, q_now, following, &PlanSettings::default())
}

/// [`plan_arm`] with settings of one's own for the first try (`chaosctl plan --margin`): the
/// one entry point to both planners (a grid over the planar arm's self-motion, a search from
/// starts on a URDF chain).
pub fn plan_arm_with(
    system: &System,
    t0: f64,
    q_now: Option<&[f64]>,
    following: Option<&Steering>,
    settings: &PlanSettings,
) -> Result<Planned, super::PlanError> {
    match system {
        System::Planar(c) => {
            let q3 = q_now.filter(|q| q.len() >= 3).map(|q| [q[0], q[1], q[2]]);
            super::plan_config_with(c, t0, q3, settings)
        }
        System::Spatial(s) => {
            let following = match following {
                Some(Steering::Spatial(f)) => Some(&f.cycle),
                _ => None,
            };
            plan_system_with(s, t0, q_now, following, settings)
        }
    }
}

/// The law a run of `system` starts with: its [`TickLaw`], steered onto a clean cycle planned from
/// the start posture when `safety.plan` asks, and why there is none when the planner found
/// none (the law then runs unsteered, as the daemon's does). A planner that cannot run (an arm
/// without one) leaves the law unsteered and says nothing, as the daemon does.
pub fn planned_law<const N: usize>(system: &System) -> (TickLaw<N>, Option<Blocked>) {
    let mut law = system.tick_law::<N>();
    if !plan_asked(system).0 {
        return (law, None);
    }
    let q0 = system.start_coords(false);
    match plan_arm(system, 0.0, Some(&q0), None).map(|p| p.outcome) {
        Ok(PlanOutcome::Found(c)) => {
            law.set_steer(steering_of(system, &c).ok());
            (law, None)
        }
        Ok(PlanOutcome::Blocked(b)) => (law, Some(b)),
        Err(_) => (law, None),
    }
}

/// The steering onto planned cycle `c` for the arm `system` runs, at its `safety.plan_hz`.
pub fn steering_of(system: &System, c: &Cycle) -> Result<Steering, crate::steer::SteerError> {
    let hz = plan_asked(system).1;
    match system {
        System::Planar(_) => Steer::of(c, hz).map(Steering::Planar),
        System::Spatial(_) => SpatialSteer::of(c, hz).map(Steering::Spatial),
    }
}
