//! `[feedback]`: one section for every arm's file, the Pyragas term's gain, delay and switch.
//!
//! The planar arm and a URDF robot read, print, validate and change it (the daemon's live `set`
//! and `dfc`) through this one type. The two forms' defaults differ where their older files
//! differ, and a file means what it meant: a planar file that leaves a key out gets the planar
//! default ([`FeedbackSection::fill_planar_defaults`]: τ = 1 s, t_on = 5 s, a 2 s delay line),
//! a robot's file the robot's (τ = the task's period, t_on = 0, a [`MAX_TAU`] delay line).

use super::ProjectionKind;
use crate::adapt::{AutoMu, MuSetting};
use crate::basics::{invalid, range, ConfigError};
use serde::{Deserialize, Serialize};

/// The longest delay τ (s) any set-up may ask for, and a robot's delay line when its file
/// gives no `feedback.max_tau`.
pub const MAX_TAU: f64 = 60.0;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "FeedbackToml", into = "FeedbackToml")]
pub struct FeedbackSection {
    /// The switch (`chaosctl dfc on|off`); μ = 0 also leaves the law as the paper's.
    pub enabled: bool,
    /// Pyragas gain μ (≥ 0; chaosd uses the stabilising sign −μ[q̇(t) − q̇(t−τ)]); with `auto`,
    /// the gain the adaptation starts from (0).
    pub mu: f64,
    /// `mu = "auto"`: the speed-gradient law adapts μ ([`crate::adapt`]).
    pub auto: Option<AutoMu>,
    /// `mu = "auto"`: steer the arm onto the cycle the model's gain is for, and hand it to the
    /// feedback once on it ([`crate::target`]); false: the feedback catches the arm alone.
    pub target: bool,
    /// Delay τ (s); None: the task's period ([`Self::tau_for`]).
    pub tau: Option<f64>,
    /// Switch-on time t_on (s).
    pub t_on: f64,
    /// Capacity of the delay line (s): the largest τ a running daemon accepts; None:
    /// [`MAX_TAU`] ([`Self::capacity`]).
    pub max_tau: Option<f64>,
    /// Where the delayed term acts: "full" (every joint, the paper's form) or "null-space"
    /// (projected by I − J⁺J onto the self-motion, so tracking is never disturbed).
    pub projection: ProjectionKind,
}

/// `[feedback]` as written: `mu` is a number or `"auto"`, and `gamma`/`max_mu` tune "auto".
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct FeedbackToml {
    enabled: bool,
    mu: MuSetting,
    #[serde(skip_serializing_if = "Option::is_none")]
    gamma: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    max_mu: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    target: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    tau: Option<f64>,
    t_on: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    max_tau: Option<f64>,
    projection: ProjectionKind,
}

impl Default for FeedbackToml {
    fn default() -> Self {
        FeedbackSection::default().into()
    }
}

impl TryFrom<FeedbackToml> for FeedbackSection {
    type Error = ConfigError;
    fn try_from(f: FeedbackToml) -> Result<Self, ConfigError> {
        if f.target.is_some() && !f.mu.is_auto() {
            return Err(ConfigError::AutoTuningWithoutAuto);
        }
        Ok(Self {
            enabled: f.enabled,
            mu: f.mu.start(),
            auto: crate::adapt::auto_from_toml(f.mu, f.gamma, f.max_mu)?,
            target: f.target.unwrap_or(true),
            tau: f.tau,
            t_on: f.t_on,
            max_tau: f.max_tau,
            projection: f.projection,
        })
    }
}

impl From<FeedbackSection> for FeedbackToml {
    fn from(f: FeedbackSection) -> Self {
        Self {
            enabled: f.enabled,
            mu: match f.auto {
                Some(_) => MuSetting::Auto,
                None => MuSetting::Fixed(f.mu),
            },
            gamma: f.auto.filter(|a| a.gamma_given).map(|a| a.gamma),
            max_mu: f.auto.map(|a| a.max_mu),
            target: f.auto.map(|_| f.target).filter(|t| !t),
            tau: f.tau,
            t_on: f.t_on,
            max_tau: f.max_tau,
            projection: f.projection,
        }
    }
}

/// A robot's defaults: off until a gain is set, τ the task's period, on from the start.
impl Default for FeedbackSection {
    fn default() -> Self {
        Self {
            enabled: true,
            mu: 0.0,
            auto: None,
            target: true,
            tau: None,
            t_on: 0.0,
            max_tau: None,
            projection: ProjectionKind::Full,
        }
    }
}

impl FeedbackSection {
    /// The planar arm's defaults: τ = 1 s (the paper's period), on from t = 5 s, a 2 s line.
    pub fn planar() -> Self {
        Self {
            tau: Some(1.0),
            t_on: 5.0,
            max_tau: Some(2.0),
            ..Self::default()
        }
    }

    /// Gives the keys a planar file's `[feedback]` (`given`, None if the file has none) leaves
    /// out their planar defaults, so an older planar file means what it meant.
    ///
    /// ```
    /// use control::config::FeedbackSection;
    /// let given: toml::Table = "mu = 0.2\nt_on = 8.0".parse().unwrap();
    /// let mut f: FeedbackSection = toml::Value::Table(given.clone()).try_into().unwrap();
    /// f.fill_planar_defaults(Some(&given));
    /// assert_eq!((f.tau, f.t_on, f.max_tau), (Some(1.0), 8.0, Some(2.0)));
    /// ```
    pub fn fill_planar_defaults(&mut self, given: Option<&toml::Table>) {
        let has = |k: &str| given.is_some_and(|t| t.contains_key(k));
        let planar = Self::planar();
        if !has("tau") {
            self.tau = planar.tau;
        }
        if !has("t_on") {
            self.t_on = planar.t_on;
        }
        if !has("max_tau") {
            self.max_tau = planar.max_tau;
        }
    }

    /// τ (s) on a task of this `period`.
    pub fn tau_for(&self, period: f64) -> f64 {
        self.tau.unwrap_or(period)
    }

    /// The delay line's capacity (s).
    pub fn capacity(&self) -> f64 {
        self.max_tau.unwrap_or(MAX_TAU)
    }

    /// The section's own rules at integration step `dt` on a task of `period` (s).
    pub fn validate(&self, dt: f64, period: f64) -> Result<(), ConfigError> {
        range("feedback.mu", self.mu, 0.0, 100.0)?;
        let tau = self.tau_for(period);
        if let Some(a) = &self.auto {
            a.check(tau)?;
        }
        let capacity = self.capacity();
        range("feedback.max_tau", capacity, dt, MAX_TAU)?;
        if !(tau.is_finite() && tau >= dt && tau <= capacity) {
            return Err(invalid(
                "feedback.tau",
                tau,
                &format!(
                    "must be between sim.dt = {dt} s and feedback.max_tau = {capacity} s (the delay line holds τ/dt samples)"
                ),
            ));
        }
        range("feedback.t_on", self.t_on, 0.0, 1e9)
    }
}
