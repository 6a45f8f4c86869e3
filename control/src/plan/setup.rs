//! A configuration's law with its planned steering: the planner run at set-up, from the start
//! posture, for the daemon, the plant and the offline tools alike.
//!
//! It sits with the planner rather than in the configuration, so that a config stays a schema
//! that builds the lower layers' parameters and never runs the layer above it.

use super::{PlanOutcome, PlanSettings};
use crate::basics::ConfigError;
use crate::config::spatial::{SpatialConfig, SpatialSetup};
use crate::config::Config;
use crate::law::LawParams;
use crate::model::Chain;
use crate::steer::{Blocked, SpatialSteer, Steer};

/// [`Config::law_params`] with the steering onto a planned clean cycle when `safety.plan` asks
/// for it (the filter on, the fixed-base 3-link arm), planned from the start posture; and
/// why there is none, when the planner found none (the law then runs without it).
pub fn law_params_planned(cfg: &Config) -> (LawParams, Option<Blocked>) {
    let mut p = cfg.law_params();
    if !cfg.steers_onto_plan() {
        return (p, None);
    }
    let q0 = cfg.initial_state::<3>().q;
    let Ok(planned) = super::plan_config(cfg, 0.0, Some([q0[0], q0[1], q0[2]])) else {
        return (p, None);
    };
    match planned.outcome {
        PlanOutcome::Found(c) => {
            p.steer = Steer::of(&c, cfg.safety.plan_hz).ok();
            (p, None)
        }
        PlanOutcome::Blocked(b) => (p, Some(b)),
    }
}

/// [`SpatialConfig::setup`] with the steering onto a planned clean cycle when `safety.plan` asks for
/// it (the filter on), planned from the start posture; and why there is none, when the
/// planner found none (the law then runs without it).
pub fn setup_planned<const N: usize>(
    cfg: &SpatialConfig,
    chain: &Chain,
) -> Result<(SpatialSetup<N>, Option<Blocked>), ConfigError> {
    let mut set = cfg.setup::<N>(chain)?;
    if !cfg.steers_onto_plan() {
        return Ok((set, None));
    }
    let planned =
        super::spatial::plan_setup(&set, 0.0, Some(set.q0), None, &PlanSettings::default());
    match planned.outcome {
        PlanOutcome::Found(c) => {
            set.params.steer = SpatialSteer::of(&c, cfg.safety.plan_hz).ok();
            Ok((set, None))
        }
        PlanOutcome::Blocked(b) => Ok((set, Some(b))),
    }
}
