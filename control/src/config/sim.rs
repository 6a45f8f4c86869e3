//! `[sim]`: one section for every arm's file, the offline run's step, length and start.
//!
//! A planar file that leaves `transient` out gets the planar default (20 s) and one without
//! `q0` the paper's start; a robot's file needs its `q0` (a robot has no start of its own) and
//! has no base attitude `phi0` (the planar floating base's).

use crate::basics::ConfigError;
use serde::{Deserialize, Serialize};

/// The longest run a file may ask for (s): four months of simulated time, far beyond any
/// study, short of a run that would never end.
pub const MAX_DURATION: f64 = 1e7;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimSection {
    /// Integration step (s).
    pub dt: f64,
    /// Simulated time (s).
    pub duration: f64,
    /// Statistics skip this initial transient (s).
    pub transient: f64,
    /// Initial joint angles (rad): one per joint on a robot; on the planar arm default the
    /// paper's (0, π/2, π/2), cut or padded with zeros.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub q0: Option<Vec<f64>>,
    /// Initial joint rates (rad/s); default zero.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub qd0: Option<Vec<f64>>,
    /// Initial base attitude φ (rad), the planar floating base only.
    #[serde(skip_serializing_if = "super::is_zero")]
    pub phi0: f64,
}

/// A robot's defaults (its `q0` must be given).
impl Default for SimSection {
    fn default() -> Self {
        Self {
            dt: 1e-3,
            duration: 300.0,
            transient: 0.0,
            q0: None,
            qd0: None,
            phi0: 0.0,
        }
    }
}

impl SimSection {
    /// The planar arm's defaults: statistics after a 20 s transient.
    pub fn planar() -> Self {
        Self {
            transient: 20.0,
            ..Self::default()
        }
    }

    /// Gives the keys a planar file's `[sim]` (`given`, None if it has none) leaves out their
    /// planar defaults, so an older planar file means what it meant.
    pub fn fill_planar_defaults(&mut self, given: Option<&toml::Table>) {
        if !given.is_some_and(|t| t.contains_key("transient")) {
            self.transient = Self::planar().transient;
        }
    }

    /// The start angles as given (empty when the file gives none).
    pub fn start(&self) -> &[f64] {
        self.q0.as_deref().unwrap_or(&[])
    }

    /// A robot's rules: a start of its own, no base attitude.
    pub fn check_robot(&self) -> Result<(), ConfigError> {
        if self.q0.is_none() {
            return Err(crate::basics::invalid(
                "sim.q0",
                "none",
                "one start angle per joint (rad): a robot has no start of its own",
            ));
        }
        if self.phi0 != 0.0 {
            return Err(crate::basics::invalid(
                "sim.phi0",
                self.phi0,
                "0: a robot's base is fixed (phi0 is the planar floating base's attitude)",
            ));
        }
        Ok(())
    }
}

/// The largest |q| (rad) or |q̇| (rad/s) a start may give. Far beyond it an angle's step in one
/// period is lost to rounding (at 1e300 rad, q + q̇·dt == q: the joint could never move), and no
/// arm turns a joint ten thousand radians a second.
pub const MAX_START: f64 = 1e4;

/// `sim.q0` or `sim.qd0`, of either arm's file: every entry within ±[`MAX_START`].
pub(crate) fn check_start_size(field: &str, v: &[f64]) -> Result<(), ConfigError> {
    if v.iter().all(|x| x.abs() <= MAX_START) {
        return Ok(());
    }
    Err(crate::basics::invalid(
        field,
        v,
        "entries within ±10000 (rad, rad/s): beyond, a step's change is lost to rounding",
    ))
}
