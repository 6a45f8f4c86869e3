//! `[law]`: one section for every arm's file, the resolved-acceleration law's gains, its
//! secondary task and the pseudo-inverse's damping.
//!
//! Most keys mean the same on every arm. A few belong to one arm's law and are refused by name
//! on the other: the planar disc potential's two weights `w1`/`w2` (a robot's sphere potential
//! has one, `obstacle_weight`), and a robot's null-space shaping (`null_damping`, `null_speed`)
//! and pseudo-inverse `metric`. Where the two forms' older files had different defaults
//! (`alpha`, `secondary`), a key a planar file leaves out gets the planar default
//! ([`LawSection::fill_planar_defaults`]).

use super::{ObstacleConfig, SecondaryKind};
use crate::basics::{invalid, ConfigError};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LawSection {
    /// Position gain K_p (eq. 1's text: 40; eq. 11 swaps K_p and K_v, see the `paper-eq11` preset).
    pub kp: f64,
    /// Velocity gain K_v.
    pub kv: f64,
    /// Null-space gain α.
    pub alpha: f64,
    /// A built-in secondary task by name, or one the program registered.
    pub secondary: SecondaryKind,
    /// The planar arm's older form only: `[[control.obstacles]]` (the shared form's discs are
    /// the top-level `[[obstacles]]`, [`super::planar_file`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub obstacles: Vec<ObstacleConfig>,
    /// The planar disc potential's weights (eqs. 7-10); None: 2.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub w1: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub w2: Option<f64>,
    /// A robot's sphere potential's weight W; None: 2.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub obstacle_weight: Option<f64>,
    /// A robot's null-space joint damping k_d ≥ 0 (0: the paper's law).
    #[serde(skip_serializing_if = "super::is_zero")]
    pub null_damping: f64,
    /// The largest self-motion speed (rad/s) a robot's secondary task may ask for; 0: no cap
    /// ([`crate::law::spatial::pull_scale`]). Needs `null_damping` > 0.
    #[serde(skip_serializing_if = "super::is_zero")]
    pub null_speed: f64,
    /// A robot's joint-space metric of the pseudo-inverse: "identity", "speed" (each joint's
    /// motion measured against its speed limit) or "auto" (speed where the limits differ by more
    /// than [`crate::law::metric::AUTO_SPEED_RATIO`]×). See [`crate::law::metric`].
    #[serde(skip_serializing_if = "is_auto")]
    pub metric: String,
    /// σ_min below which damped least squares starts.
    pub damping_threshold: f64,
    /// Damping λ at σ_min = 0.
    pub damping_max: f64,
    /// Tracking error (m) above which tracking counts as lost.
    pub track_loss: f64,
}

/// The default weight of either arm's obstacle potential.
pub const DEFAULT_WEIGHT: f64 = 2.0;

fn is_auto(m: &str) -> bool {
    m == "auto"
}

/// A robot's defaults: no secondary task until one is chosen.
impl Default for LawSection {
    fn default() -> Self {
        Self {
            kp: 40.0,
            kv: 15.0,
            alpha: 0.0,
            secondary: SecondaryKind::None,
            obstacles: Vec::new(),
            w1: None,
            w2: None,
            obstacle_weight: None,
            null_damping: 0.0,
            null_speed: 0.0,
            metric: "auto".into(),
            damping_threshold: 0.05,
            damping_max: 0.05,
            track_loss: 0.05,
        }
    }
}

impl LawSection {
    /// The planar arm's defaults: the manipulability task at α = 1 (the paper's).
    pub fn planar() -> Self {
        Self {
            alpha: 1.0,
            secondary: SecondaryKind::Manipulability,
            ..Self::default()
        }
    }

    /// Gives the keys a planar file's `[law]` (or older `[control]`, `given`) leaves out their
    /// planar defaults.
    pub fn fill_planar_defaults(&mut self, given: Option<&toml::Table>) {
        let has = |k: &str| given.is_some_and(|t| t.contains_key(k));
        let planar = Self::planar();
        if !has("alpha") {
            self.alpha = planar.alpha;
        }
        if !has("secondary") {
            self.secondary = planar.secondary;
        }
    }

    /// Refuses a robot's keys on the planar arm.
    pub fn check_planar(&self) -> Result<(), ConfigError> {
        let why = "a robot's key: the planar arm's law has no null-space shaping or metric, and its disc potential takes law.w1 and law.w2";
        let robot_keys = [
            ("obstacle_weight", self.obstacle_weight.is_some()),
            ("null_damping", self.null_damping != 0.0),
            ("null_speed", self.null_speed != 0.0),
            ("metric", !is_auto(&self.metric)),
        ];
        match robot_keys.into_iter().find(|(_, set)| *set) {
            Some((key, _)) => Err(invalid(&format!("law.{key}"), key, why)),
            None => Ok(()),
        }
    }

    /// Refuses the planar arm's keys in a robot's file.
    pub fn check_robot(&self) -> Result<(), ConfigError> {
        for (key, v) in [("w1", self.w1), ("w2", self.w2)] {
            if let Some(v) = v {
                return Err(invalid(
                    &format!("law.{key}"),
                    v,
                    "the planar disc potential's weight: a robot's sphere potential has one, law.obstacle_weight",
                ));
            }
        }
        if !self.obstacles.is_empty() {
            return Err(invalid(
                "law.obstacles",
                format!("{} entries", self.obstacles.len()),
                "the obstacles are a top-level [[obstacles]] list",
            ));
        }
        Ok(())
    }

    /// The planar disc potential's weights (w1, w2).
    pub fn disc_weights(&self) -> (f64, f64) {
        (
            self.w1.unwrap_or(DEFAULT_WEIGHT),
            self.w2.unwrap_or(DEFAULT_WEIGHT),
        )
    }
}
