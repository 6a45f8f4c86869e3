//! What the daemon does when the arm is blocked, and when it calls the arm trapped.
//!
//! Both settings live in the `[safety]` table of every arm, planar or spatial: a trap (tracking
//! lost, or the filter outside the null space, for `trap_time`) is detected whether or not a
//! planner exists for the arm, and `Blocked` is then said either way.

use crate::basics::invalid;
use crate::basics::ConfigError;
use crate::basics::LiveError;
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
    pub fn parse(key: &str, v: Option<&str>) -> Result<Self, LiveError> {
        match v {
            Some("hold") => Ok(WhenBlocked::Hold),
            Some("best-effort") => Ok(WhenBlocked::BestEffort),
            other => Err(LiveError::not_one_of(key, other, "hold or best-effort")),
        }
    }
}

/// Whether the self-motion is steered onto a planned clean cycle (`safety.plan`).
///
/// The filter alone is local: it keeps clearance now and can hold the arm off its path for
/// good. Steering is the safety layer's way round, so it is on wherever the filter has an
/// obstacle to keep clear of (`auto`, the default). Without obstacles nothing can trap the
/// arm and the self-motion is the paper's, chaotic until the feedback holds it; `true` steers
/// always, `false` never (the daemon then steers only after a trap).
///
/// ```
/// use control::safety::policy::PlanMode;
/// assert!(PlanMode::Auto.steers(true) && !PlanMode::Auto.steers(false));
/// assert_eq!(PlanMode::parse("safety.plan", Some("auto")), Ok(PlanMode::Auto));
/// assert!(PlanMode::parse("safety.plan", Some("maybe")).is_err());
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PlanMode {
    /// Steer while the filter is on and there is at least one obstacle.
    #[default]
    Auto,
    /// Steer whenever the filter is on.
    On,
    /// Never steer before a trap.
    Off,
}

impl PlanMode {
    /// Whether this mode steers an arm whose filter is on, with or without obstacles.
    pub fn steers(self, any_obstacle: bool) -> bool {
        match self {
            PlanMode::Auto => any_obstacle,
            PlanMode::On => true,
            PlanMode::Off => false,
        }
    }

    /// Parses `auto`, `on` or `off` (the `set` request's value; `true`/`false` too).
    pub fn parse(key: &str, v: Option<&str>) -> Result<Self, LiveError> {
        match v {
            Some("auto") => Ok(PlanMode::Auto),
            Some("on" | "true" | "1") => Ok(PlanMode::On),
            Some("off" | "false" | "0") => Ok(PlanMode::Off),
            other => Err(LiveError::not_one_of(key, other, "auto, on or off")),
        }
    }
}

impl From<bool> for PlanMode {
    fn from(on: bool) -> Self {
        if on {
            PlanMode::On
        } else {
            PlanMode::Off
        }
    }
}

/// In a config file: `true`, `false` or `"auto"` (and `"on"`/`"off"`).
impl Serialize for PlanMode {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            PlanMode::Auto => s.serialize_str("auto"),
            PlanMode::On => s.serialize_bool(true),
            PlanMode::Off => s.serialize_bool(false),
        }
    }
}

impl<'de> Deserialize<'de> for PlanMode {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Bool(bool),
            Text(String),
        }
        let expected = "safety.plan must be true, false or \"auto\"";
        match Raw::deserialize(d).map_err(|_| serde::de::Error::custom(expected))? {
            Raw::Bool(b) => Ok(b.into()),
            Raw::Text(t) => Self::parse("safety.plan", Some(&t))
                .map_err(|_| serde::de::Error::custom(format!("{expected}, not {t:?}"))),
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
