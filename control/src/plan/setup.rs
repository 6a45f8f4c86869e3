//! A configuration's law with its planned steering: the planner run at set-up, from the start
//! posture, for the daemon, the plant and the offline tools alike.
//!
//! It sits with the planner rather than in the configuration, so that a config stays a schema
//! that builds the lower layers' parameters and never runs the layer above it. The rule is
//! written once, for a whole [`System`] ([`super::planned_law`]); the two functions here hand
//! its steering to callers that hold one arm's parameter block.

use crate::basics::ConfigError;
use crate::config::spatial::SpatialSetup;
use crate::config::Config;
use crate::law::LawParams;
use crate::model::Chain;
use crate::steer::{Blocked, Steering};
use crate::system::{SpatialSystem, System};

/// [`Config::law_params`] with the steering onto a planned clean cycle when `safety.plan` asks
/// for it (the filter on, the fixed-base 3-link arm), planned from the start posture; and
/// why there is none, when the planner found none (the law then runs without it).
///
/// # Panics
/// On a robot's config ([`setup_planned`] is a robot's), as [`Config::law_params`] does.
pub fn law_params_planned(cfg: &Config) -> (LawParams, Option<Blocked>) {
    let mut p = cfg.law_params();
    let (steering, blocked) = planned_steering(&System::Planar(cfg.clone()));
    if let Some(Steering::Planar(s)) = steering {
        p.steer = Some(s);
    }
    (p, blocked)
}

/// [`Config::setup`] with the steering onto a planned clean cycle when `safety.plan` asks for
/// it (the filter on), planned from the start posture; and why there is none, when the
/// planner found none (the law then runs without it).
pub fn setup_planned<const N: usize>(
    cfg: &Config,
    chain: &Chain,
) -> Result<(SpatialSetup<N>, Option<Blocked>), ConfigError> {
    let mut set = cfg.setup::<N>(chain)?;
    let system = System::Spatial(Box::new(SpatialSystem {
        config: cfg.clone(),
        chain: chain.clone(),
    }));
    let (steering, blocked) = planned_steering(&system);
    if let Some(Steering::Spatial(s)) = steering {
        set.params.steer = Some(s);
    }
    Ok((set, blocked))
}

/// The steering [`super::planned_law`] gives `system`'s law, and why there is none.
fn planned_steering(system: &System) -> (Option<Steering>, Option<Blocked>) {
    use crate::sim::ClosedLoopLaw;
    crate::with_dof!(system.n(), N => {
        let (law, blocked) = super::planned_law::<N>(system);
        (law.steering(), blocked)
    })
}
