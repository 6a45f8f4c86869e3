//! A robot's set-up as the flags name it (`--preset panda` or a config file that has a
//! `[robot]` table), for [`crate::subject::Subject`], which runs every arm.
//!
//! The flags mean what they mean for the planar arm and are applied to the spatial file the same
//! way, so a command written for one arm takes the other.

use crate::setup::SetupArgs;
use anyhow::{bail, Context, Result};
use control::config::spatial::is_spatial;
use control::config::spatial::SpatialConfig;

/// The spatial set-up named by the flags, or None for a planar one.
pub fn load(setup: &SetupArgs, mu: Option<f64>) -> Result<Option<SpatialConfig>> {
    let mut cfg = match (&setup.config, &setup.preset) {
        (Some(path), _) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read config file {}", path.display()))?;
            if !is_spatial(&text) {
                return Ok(None);
            }
            SpatialConfig::from_toml(&text).with_context(|| format!("in {}", path.display()))?
        }
        (None, Some(p)) => match SpatialConfig::preset(p) {
            Some(c) => c,
            None => return Ok(None),
        },
        (None, None) => return Ok(None),
    };
    if setup.model.is_some() {
        bail!(
            "--model applies to the planar arm; a spatial robot is given by [robot] in its config"
        );
    }
    if let Some(v) = mu {
        cfg.feedback.mu = v;
    }
    if let Some(v) = setup.tau {
        cfg.feedback.tau = Some(v);
    }
    if let Some(v) = setup.t_on {
        cfg.feedback.t_on = v;
    }
    if let Some(v) = setup.dt {
        cfg.sim.dt = v;
    }
    if let Some(v) = &setup.q0 {
        cfg.sim.q0 = Some(v.0.clone());
    }
    if let Some(v) = &setup.qd0 {
        cfg.sim.qd0 = Some(v.0.clone());
    }
    if let Some(on) = setup.safety {
        cfg.safety.enabled = on;
    }
    if let Some(p) = setup.projection {
        cfg.feedback.projection = p;
    }
    Ok(Some(cfg))
}
