//! The planar arm's older file form (`[arm]`, `[control]`, `[[control.obstacles]]`) as its own
//! type, read and written only at the text boundary.
//!
//! Why a separate type: the in-memory [`Config`] is laid out for the program (the obstacles at
//! the top level, the law's section named `law`), while files and recordings written before keep
//! the older layout and its exact serde messages ("unknown field `kpp`, expected one of …").
//! A copy of the older derive keeps both: the text meets this type, the program meets
//! [`Config`], and the conversions below are the one place the two layouts meet. A sharded grid's
//! fingerprint is this type's `Debug` text, so older shards keep matching.

use super::{ArmConfig, Config, FeedbackSection, LawSection, SimSection, TaskConfig};
use crate::basics::{excerpt, ConfigError};
use crate::safety::SafetySection;
use serde::{Deserialize, Serialize};

/// The older form, field for field as files wrote it (the struct keeps the name `Config`: serde's
/// messages and the `Debug` text name it).
pub(crate) mod older {
    use super::*;

    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct Config {
        pub arm: ArmConfig,
        pub task: TaskConfig,
        pub control: LawSection,
        pub feedback: FeedbackSection,
        pub sim: SimSection,
        pub safety: SafetySection,
        #[serde(skip_serializing_if = "Option::is_none")]
        pub daemon: Option<toml::Table>,
        #[serde(skip_serializing_if = "Option::is_none")]
        pub plant: Option<toml::Table>,
    }

    impl Default for Config {
        fn default() -> Self {
            Self::from(&super::Config::default())
        }
    }
}

impl From<older::Config> for Config {
    /// `[[control.obstacles]]` become the top-level obstacles.
    fn from(f: older::Config) -> Self {
        let mut law = f.control;
        let obstacles = std::mem::take(&mut law.obstacles);
        Config {
            arm: f.arm,
            task: f.task,
            law,
            obstacles,
            feedback: f.feedback,
            sim: f.sim,
            safety: f.safety,
            daemon: f.daemon,
            plant: f.plant,
        }
    }
}

impl From<&Config> for older::Config {
    /// The obstacles go back under `[control]`.
    fn from(c: &Config) -> Self {
        let mut control = c.law.clone();
        control.obstacles = c.obstacles.clone();
        older::Config {
            arm: c.arm.clone(),
            task: c.task.clone(),
            control,
            feedback: c.feedback.clone(),
            sim: c.sim.clone(),
            safety: c.safety.clone(),
            daemon: c.daemon.clone(),
            plant: c.plant.clone(),
        }
    }
}

/// Reads a file in the older form (no planar defaults filled yet: the caller does that).
pub(crate) fn read_older(text: &str) -> Result<Config, ConfigError> {
    toml::from_str::<older::Config>(text)
        .map(Config::from)
        .map_err(|e| ConfigError::Parse(excerpt(&e.to_string())))
}

/// `c` in the older form, as files written before the shared form have it (for tests of the
/// older form: `chaosctl config` prints the shared one).
///
/// ```
/// use control::config::{file::older_text, Config};
/// let c = Config::preset("paper-obstacle").unwrap();
/// let text = older_text(&c);
/// assert!(text.contains("[[control.obstacles]]"));
/// assert_eq!(Config::parse(&text).unwrap(), c);
/// ```
pub fn older_text(c: &Config) -> String {
    toml::to_string(&older::Config::from(c)).unwrap_or_default()
}

/// The `Debug` text of `c` in the older layout: a planar shard grid's fingerprint, kept as it
/// was so that shards written before still match.
pub fn older_debug(c: &Config) -> String {
    format!("{:?}", older::Config::from(c))
}
