//! What the daemon does when the arm is blocked, and when it calls the arm trapped.
//!
//! Both settings live in the `[safety]` table of every arm, planar or spatial: a trap (tracking
//! lost, or the filter outside the null space, for `trap_time`) is detected whether or not a
//! planner exists for the arm, and `Blocked` is then said either way.

use crate::config::{invalid, ConfigError};
use serde::{Deserialize, Serialize};

/// How long (s) tracking may stay lost, or the filter act outside the null space, before the
/// daemon calls the arm trapped.
pub const DEFAULT_TRAP_TIME: f64 = 2.0;

/// What the daemon does while no clean cycle exists.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WhenBlocked {
    /// Hold the posture (the plant brings the joints to rest and keeps them there); tracking
    /// pauses until an edit leaves a clean cycle.
    #[default]
    Hold,
    /// Run on, the filter keeping clearance, with `blocked` raised in status and telemetry.
    BestEffort,
}

impl WhenBlocked {
    pub fn name(self) -> &'static str {
        match self {
            WhenBlocked::Hold => "hold",
            WhenBlocked::BestEffort => "best-effort",
        }
    }

    /// The wire code (`TelemetrySample::blocked`): 1 hold, 2 best-effort (0: not blocked).
    pub fn code(self) -> u32 {
        match self {
            WhenBlocked::Hold => 1,
            WhenBlocked::BestEffort => 2,
        }
    }

    /// Parses `hold` or `best-effort` (the `set` request's value).
    pub fn parse(key: &str, v: Option<&str>) -> Result<Self, String> {
        match v {
            Some("hold") => Ok(WhenBlocked::Hold),
            Some("best-effort") => Ok(WhenBlocked::BestEffort),
            other => Err(format!("{key}: {other:?} is not hold or best-effort")),
        }
    }
}

/// `safety.trap_time` must leave the arm time to get round (a transient: a trap shorter than
/// a tenth of a second is a filter doing its job) and still say it within a minute.
pub fn check_trap_time(v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && (0.1..=60.0).contains(&v) {
        Ok(())
    } else {
        Err(invalid(
            "safety.trap_time",
            v,
            "must be a number of seconds between 0.1 and 60",
        ))
    }
}
