//! The file forms as their own types, read and written only at the text boundary: the planar
//! arm's older form (`[arm]`, `[control]`, `[[control.obstacles]]`) and a robot's file.
//! (The planar arm's shared form has its own, [`super::planar_file`].)
//!
//! Why separate types: the in-memory [`Config`] is laid out for the program (the arm's own
//! part in [`Robot`], every shared section once), while files and recordings written before keep
//! their layout and their exact serde messages ("unknown field `kpp`, expected one of …"). The
//! text meets these types, the program meets [`Config`], and the conversions below are the one
//! place the layouts meet. A sharded grid's fingerprint is these types' `Debug` text, so older
//! shards keep matching.

use super::command::CommandSection;
use super::{
    ArmConfig, Config, FeedbackSection, LawSection, PlanarRobot, Robot, RobotSection, SimSection,
    SpatialRobot, SphereEntry, TaskConfig, TaskSection,
};
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
    /// `[[control.obstacles]]` become the planar arm's obstacles.
    fn from(f: older::Config) -> Self {
        let mut law = f.control;
        let obstacles = std::mem::take(&mut law.obstacles);
        Config {
            robot: Robot::Planar(PlanarRobot {
                arm: f.arm,
                task: f.task,
                obstacles,
            }),
            law,
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
    ///
    /// # Panics
    /// On a robot's config (it has no older form).
    fn from(c: &Config) -> Self {
        let p = c.planar_part();
        let mut control = c.law.clone();
        control.obstacles = p.obstacles.clone();
        older::Config {
            arm: p.arm.clone(),
            task: p.task.clone(),
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
///
/// # Panics
/// On a robot's config (it has no older form), as [`older_debug`] does.
pub fn older_text(c: &Config) -> String {
    toml::to_string(&older::Config::from(c)).unwrap_or_default()
}

/// The `Debug` text of `c` in the older layout: a planar shard grid's fingerprint, kept as it
/// was so that shards written before still match. The planar arm's only (see [`older_text`]).
pub fn older_debug(c: &Config) -> String {
    format!("{:?}", older::Config::from(c))
}

/// A robot's file, field for field (the struct keeps the name it had: serde's messages and the
/// `Debug` text of a fingerprint name it).
pub(crate) mod robot {
    use super::*;

    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct SpatialConfig {
        pub robot: RobotSection,
        pub task: TaskSection,
        #[serde(default)]
        pub law: LawSection,
        #[serde(default)]
        pub feedback: FeedbackSection,
        #[serde(default)]
        pub safety: SafetySection,
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        pub obstacles: Vec<SphereEntry>,
        #[serde(default)]
        pub command: CommandSection,
        pub sim: SimSection,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        pub daemon: Option<toml::Table>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        pub plant: Option<toml::Table>,
    }
}

impl From<robot::SpatialConfig> for Config {
    fn from(f: robot::SpatialConfig) -> Self {
        Config {
            robot: Robot::Spatial(Box::new(SpatialRobot {
                robot: f.robot,
                task: f.task,
                obstacles: f.obstacles,
                command: f.command,
            })),
            law: f.law,
            feedback: f.feedback,
            sim: f.sim,
            safety: f.safety,
            daemon: f.daemon,
            plant: f.plant,
        }
    }
}

impl From<&Config> for robot::SpatialConfig {
    /// # Panics
    /// On the planar arm's config (its files have their own forms).
    fn from(c: &Config) -> Self {
        let r = c.spatial_part();
        robot::SpatialConfig {
            robot: r.robot.clone(),
            task: r.task.clone(),
            law: c.law.clone(),
            feedback: c.feedback.clone(),
            safety: c.safety.clone(),
            obstacles: r.obstacles.clone(),
            command: r.command.clone(),
            sim: c.sim.clone(),
            daemon: c.daemon.clone(),
            plant: c.plant.clone(),
        }
    }
}

/// Reads a robot's file (no validation: that needs its chain).
pub(crate) fn read_robot(text: &str) -> Result<Config, ConfigError> {
    toml::from_str::<robot::SpatialConfig>(text)
        .map(Config::from)
        .map_err(|e| super::parse_error(text, &e))
}

/// A robot's config as its file.
pub(crate) fn robot_text(c: &Config) -> String {
    toml::to_string(&robot::SpatialConfig::from(c)).expect("a config serialises")
}

/// The `Debug` text of a robot's config in its file's layout, for a fingerprint.
///
/// # Panics
/// On the planar arm's config ([`older_debug`] is its fingerprint).
pub fn robot_debug(c: &Config) -> String {
    format!("{:?}", robot::SpatialConfig::from(c))
}

impl Config {
    /// Parses a robot's file (no validation: that needs its chain, [`crate::System`]).
    pub fn from_robot_toml(text: &str) -> Result<Self, ConfigError> {
        if text.len() > crate::basics::MAX_CONFIG_BYTES {
            return Err(ConfigError::Parse(format!(
                "the config is {} bytes; at most {} are accepted",
                text.len(),
                crate::basics::MAX_CONFIG_BYTES
            )));
        }
        super::file::read_robot(text)
    }

    /// The file again in the form `chaosctl config` prints: the shared form for the planar arm
    /// ([`super::planar_file`]), a robot's file for a chain.
    pub fn to_toml(&self) -> String {
        match &self.robot {
            Robot::Planar(_) => super::planar_file::write(self),
            Robot::Spatial(_) => robot_text(self),
        }
    }
}
