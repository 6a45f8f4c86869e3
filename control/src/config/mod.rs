//! The configuration model: one TOML file describes the arm, task, controller, feedback and run.
//!
//! Parsing and validation are separate steps, as in ripgrep's low/high args: a file is parsed
//! into [`Config`] (unknown keys are errors, so typos cannot silently fall back to defaults), then
//! [`Config::validate`] checks every field and names the first bad one with its allowed range.
//! Nothing downstream re-checks; the runtime types built from a validated config are trusted.
//!
//! Every default is docs/science.md's; the `paper*` presets reproduce the paper's set-ups.

pub mod command;
pub mod feedback;
pub mod file;
pub mod law;
pub mod obstacles;
pub mod planar_file;
pub mod rehearsal;
pub mod robot;
pub mod sim;
pub mod spatial;
pub mod stability;

pub use feedback::{FeedbackSection, MAX_TAU};
pub use law::LawSection;
pub use obstacles::{ObstacleConfig, ObstacleEntry, SphereEntry};
pub use robot::{PlanarRobot, Robot, RobotSection, SpatialRobot, TaskSection};
pub use sim::SimSection;

use crate::arm::{ArmModel, FixedArm, FloatingArm, VecN};
use crate::basics::{
    excerpt, invalid, range, ConfigError, MAX_CONFIG_BYTES, MAX_JOINTS, MIN_JOINTS,
};
use crate::law::{LawCore, LawParams, Secondary};
use crate::resolve::Projection;
use crate::safety::SafetySection;
use crate::secondary::{ObstacleSet, PotentialWeights, MAX_OBSTACLES};
use crate::sim::ArmState;
use crate::task::{Path, Shape};
use serde::{Deserialize, Serialize};
use std::f64::consts::FRAC_PI_2;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum ModelKind {
    #[default]
    Fixed,
    Floating,
}

/// `control.secondary`: a built-in task by name, or a task the program registered
/// ([`crate::secondary::custom`]), named in the file as in a robot's `law.secondary`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum SecondaryKind {
    None,
    #[default]
    Manipulability,
    Centring,
    Obstacles,
    #[serde(untagged)]
    Custom(String),
}

impl SecondaryKind {
    /// The task it names; None for a name no program registered.
    pub fn task(&self) -> Option<Secondary> {
        Some(match self {
            SecondaryKind::None => Secondary::None,
            SecondaryKind::Manipulability => Secondary::Manipulability,
            SecondaryKind::Centring => Secondary::Centring,
            SecondaryKind::Obstacles => Secondary::Obstacles,
            SecondaryKind::Custom(name) => Secondary::parse(name)?,
        })
    }

    /// The name a file and a report give it.
    pub fn name(&self) -> &str {
        match self {
            SecondaryKind::None => "none",
            SecondaryKind::Manipulability => "manipulability",
            SecondaryKind::Centring => "centring",
            SecondaryKind::Obstacles => "obstacles",
            SecondaryKind::Custom(name) => name,
        }
    }
}

impl std::fmt::Display for SecondaryKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl From<&str> for SecondaryKind {
    /// A name as a file gives it (built-in or registered).
    fn from(name: &str) -> Self {
        use SecondaryKind::{Centring, Manipulability, None, Obstacles};
        [None, Manipulability, Centring, Obstacles]
            .into_iter()
            .find(|k| k.name() == name)
            .unwrap_or_else(|| SecondaryKind::Custom(name.to_string()))
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ArmConfig {
    pub model: ModelKind,
    /// Link lengths l_j (m); their number is the arm size n.
    pub links: Vec<f64>,
    /// Floating base only: base mass m₀ (kg). The paper's 1 kg puts the circle out of reach of
    /// the system's centre of mass; 200 kg is chaosd's default.
    pub base_mass: f64,
    /// Floating base only: base inertia I₀ (kg·m²).
    pub base_inertia: f64,
    /// Floating base only: distance l₀ from the base's centre of mass to joint 1 (m).
    pub base_offset: f64,
    /// Link masses (kg); default 1 kg each.
    pub link_masses: Option<Vec<f64>>,
    /// Link inertias (kg·m²); default 0.1·(n + 1 − j), which is the paper's (0.3, 0.2, 0.1).
    pub link_inertias: Option<Vec<f64>>,
}

impl Default for ArmConfig {
    fn default() -> Self {
        Self {
            model: ModelKind::Fixed,
            links: vec![1.0; 3],
            base_mass: 200.0,
            base_inertia: 200.0,
            base_offset: 1.0,
            link_masses: None,
            link_inertias: None,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TaskConfig {
    /// The path's shape, as on every arm (in the arm's plane: u = x, v = y).
    #[serde(skip_serializing_if = "Shape::is_circle")]
    pub path: Shape,
    pub center: [f64; 2],
    pub radius: f64,
    pub period: f64,
    /// Seconds over which the path speeds up from rest ([`crate::task::ramp`]); 0: full speed.
    #[serde(skip_serializing_if = "is_zero")]
    pub ramp: f64,
}

/// Keeps a key that is off out of a printed config.
pub(crate) fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// `task.ramp`, of either arm's file: a finite number of seconds ≥ 0.
pub(crate) fn check_ramp(seconds: f64) -> Result<(), ConfigError> {
    if seconds.is_finite() && (0.0..=1e4).contains(&seconds) {
        Ok(())
    } else {
        Err(invalid(
            "task.ramp",
            seconds,
            "seconds in [0, 10000] (0: no ramp)",
        ))
    }
}

impl Default for TaskConfig {
    fn default() -> Self {
        Self {
            path: Shape::Circle,
            center: [1.0, 2.0],
            radius: 0.5,
            period: 1.0,
            ramp: 0.0,
        }
    }
}

/// `feedback.projection`, one type for every arm's file: where the delayed term acts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ProjectionKind {
    #[default]
    Full,
    NullSpace,
}

impl ProjectionKind {
    /// The name a file, `chaosctl set projection NAME` and a report use.
    ///
    /// ```
    /// use control::config::ProjectionKind;
    /// for p in [ProjectionKind::Full, ProjectionKind::NullSpace] {
    ///     assert_eq!(ProjectionKind::parse(p.name()), Some(p));
    /// }
    /// assert_eq!(ProjectionKind::parse("sideways"), None);
    /// ```
    pub fn name(self) -> &'static str {
        match self {
            Self::Full => "full",
            Self::NullSpace => "null-space",
        }
    }

    pub fn parse(name: &str) -> Option<Self> {
        [Self::Full, Self::NullSpace]
            .into_iter()
            .find(|p| p.name() == name)
    }
}

impl std::fmt::Display for ProjectionKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl From<ProjectionKind> for Projection {
    fn from(p: ProjectionKind) -> Self {
        match p {
            ProjectionKind::Full => Projection::Full,
            ProjectionKind::NullSpace => Projection::NullSpace,
        }
    }
}

/// The whole set-up in memory, for every arm: what is the arm's own in [`Robot`], every shared
/// section once. Files are read and written through [`planar_file`] (the planar arm's shared
/// form), [`file`](mod@file) (its older form and a robot's file); `[daemon]` and `[plant]` are owned and
/// validated by those programs.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    pub robot: Robot,
    /// `[law]` (`[control]` in the planar arm's older form). Its `obstacles` stay empty: they
    /// are the robot part's.
    pub law: LawSection,
    pub feedback: FeedbackSection,
    pub sim: SimSection,
    /// The safety filter and the runaway guard (see `control::safety::config`).
    pub safety: SafetySection,
    pub daemon: Option<toml::Table>,
    pub plant: Option<toml::Table>,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            robot: Robot::Planar(PlanarRobot::default()),
            law: LawSection::planar(),
            feedback: FeedbackSection::planar(),
            sim: SimSection::planar(),
            safety: SafetySection::planar(),
            daemon: None,
            plant: None,
        }
    }
}

/// Names accepted by [`Config::preset`].
pub const PRESETS: &[&str] = &[
    "paper",
    "paper-eq11",
    "paper-obstacle",
    "paper-floating",
    "demo",
];

/// Start of the `demo` preset: a point of the paper arm's period-1 orbit (found by running
/// μ = 0.1 to convergence; `chaosctl orbits` finds it by Newton's method) with q̇₁ + 2 rad/s and
/// q̇₃ − 2 rad/s.
pub const DEMO_START: ([f64; 3], [f64; 3]) = (
    [1.550079628, -0.488376467, -0.934331288],
    [-2.361482957, 9.229261970, -6.001303515],
);

/// The obstacle of the `paper-obstacle` preset (the paper gives none; this one sits where the
/// uncontrolled self-motion sweeps the arm's middle links).
pub const PAPER_OBSTACLE: ([f64; 2], f64) = ([0.0, 1.6], 0.25);

impl Config {
    /// A named set-up. `paper`: fixed base, eq. 1 gains, manipulability, τ = T = 1 s, t_on = 5 s.
    pub fn preset(name: &str) -> Result<Self, ConfigError> {
        let mut c = Config::default();
        if name.starts_with("paper") {
            // A faithful reproduction: the paper has no filter.
            c.safety = SafetySection::paper();
        }
        match name {
            "paper" => {}
            "paper-eq11" => {
                c.law.kp = 15.0;
                c.law.kv = 40.0;
            }
            "paper-obstacle" => {
                c.law.secondary = SecondaryKind::Obstacles;
                c.planar_mut().expect("planar").obstacles = vec![ObstacleConfig {
                    center: PAPER_OBSTACLE.0,
                    radius: PAPER_OBSTACLE.1,
                    margin: 0.1,
                }];
            }
            "paper-floating" => {
                c.planar_mut().expect("planar").arm.model = ModelKind::Floating;
            }
            "demo" => {
                // The paper's arm kicked 2 rad/s off its period-1 orbit (the one small μ
                // stabilises): irregular without feedback, back on the orbit within ~15 s of μ = 0.2.
                c.sim.q0 = Some(DEMO_START.0.to_vec());
                c.sim.qd0 = Some(DEMO_START.1.to_vec());
                c.feedback.mu = 0.2;
                c.feedback.t_on = 8.0;
                c.sim.duration = 25.0;
            }
            s if spatial::SPATIAL_PRESETS.contains(&s) => {
                return Err(ConfigError::Spatial(format!("preset {s:?}")))
            }
            other => {
                return Err(ConfigError::UnknownPreset {
                    name: other.to_string(),
                    known: PRESETS
                        .iter()
                        .chain(spatial::SPATIAL_PRESETS)
                        .copied()
                        .collect::<Vec<_>>()
                        .join(", "),
                })
            }
        }
        Ok(c)
    }

    /// Parses TOML text (no validation; call [`Config::validate`]): the shared form
    /// (`[robot] description = "planar"`, [`planar_file`]) or the older one (`[arm]`,
    /// `[control]`).
    pub fn from_toml_str(text: &str) -> Result<Self, ConfigError> {
        if text.len() > MAX_CONFIG_BYTES {
            return Err(ConfigError::Parse(format!(
                "the config is {} bytes; at most {MAX_CONFIG_BYTES} are accepted",
                text.len()
            )));
        }
        let table = text.parse::<toml::Table>();
        let mut c = match &table {
            Ok(t) if planar_file::names_planar(t) => planar_file::read(text),
            Ok(t) if t.contains_key("robot") => {
                Err(ConfigError::Spatial("a config with a [robot] table".into()))
            }
            _ => file::read_older(text),
        }?;
        // Each shared section as the file gives it, for the planar form's own defaults.
        let given = table.ok();
        let section = |names: &[&str]| {
            let t = given.as_ref()?;
            names.iter().find_map(|n| t.get(*n)?.as_table())
        };
        c.feedback.fill_planar_defaults(section(&["feedback"]));
        c.sim.fill_planar_defaults(section(&["sim"]));
        c.law.fill_planar_defaults(section(&["law", "control"]));
        c.safety.fill_planar_defaults(section(&["safety"]));
        Ok(c)
    }

    /// Reads any arm's file (no validation): a robot's when its `[robot]` names a chain, else
    /// the planar arm's in either of its forms.
    ///
    /// ```
    /// use control::Config;
    /// let panda = Config::robot_preset("panda").unwrap();
    /// assert_eq!(Config::read_any(&panda.to_toml()).unwrap(), panda);
    /// let paper = Config::preset("paper").unwrap();
    /// assert_eq!(Config::read_any(&paper.to_toml()).unwrap(), paper);
    /// ```
    pub fn read_any(text: &str) -> Result<Self, ConfigError> {
        if spatial::is_spatial(text) {
            Self::from_robot_toml(text)
        } else {
            Self::from_toml_str(text)
        }
    }

    /// τ (s): the file's, or the task's period.
    pub fn tau(&self) -> f64 {
        self.feedback.tau_for(self.period())
    }

    /// Parses and validates; a refusal names the key as the text spells it (`law.kp` in the
    /// shared form, `control.kp` in the older one).
    pub fn parse(text: &str) -> Result<Self, ConfigError> {
        let c = Self::from_toml_str(text)?;
        c.validate().map_err(|e| {
            if is_older_form(text) {
                planar_file::in_legacy_terms(e)
            } else {
                e
            }
        })?;
        Ok(c)
    }

    /// The planar arm's size n.
    ///
    /// # Panics
    /// This and the methods below (to [`Self::initial_state`]) are the planar arm's (see
    /// [`Self::planar_part`]); a robot's set-up is asked through [`crate::System`].
    pub fn n(&self) -> usize {
        self.planar_part().arm.links.len()
    }

    pub fn link_masses(&self) -> Vec<f64> {
        self.planar_part()
            .arm
            .link_masses
            .clone()
            .unwrap_or_else(|| vec![1.0; self.n()])
    }

    pub fn link_inertias(&self) -> Vec<f64> {
        let n = self.n();
        self.planar_part()
            .arm
            .link_inertias
            .clone()
            .unwrap_or_else(|| (0..n).map(|j| 0.1 * (n - j) as f64).collect())
    }

    pub fn q0(&self) -> Vec<f64> {
        self.sim.q0.clone().unwrap_or_else(|| {
            let paper = [0.0, FRAC_PI_2, FRAC_PI_2];
            (0..self.n())
                .map(|i| paper.get(i).copied().unwrap_or(0.0))
                .collect()
        })
    }

    pub fn qd0(&self) -> Vec<f64> {
        self.sim.qd0.clone().unwrap_or_else(|| vec![0.0; self.n()])
    }

    /// Checks every field; the error names the first bad one and its allowed range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let Robot::Planar(p) = &self.robot else {
            return Err(ConfigError::Spatial(
                "a robot's config (validated against its chain by System)".into(),
            ));
        };
        let n = self.n();
        if !(MIN_JOINTS..=MAX_JOINTS).contains(&n) {
            return Err(invalid(
                "robot.links",
                &p.arm.links,
                &format!("must list {MIN_JOINTS} to {MAX_JOINTS} link lengths"),
            ));
        }
        for (i, l) in p.arm.links.iter().enumerate() {
            positive(&format!("robot.links[{i}]"), *l, 100.0)?;
        }
        positive("robot.base_mass", p.arm.base_mass, 1e9)?;
        positive("robot.base_inertia", p.arm.base_inertia, 1e9)?;
        range("robot.base_offset", p.arm.base_offset, 0.0, 100.0)?;
        for (name, v) in [
            ("robot.link_masses", &p.arm.link_masses),
            ("robot.link_inertias", &p.arm.link_inertias),
        ] {
            if let Some(v) = v {
                same_len(name, v, n)?;
                for (i, x) in v.iter().enumerate() {
                    positive(&format!("{name}[{i}]"), *x, 1e9)?;
                }
            }
        }
        finite_vec("task.center", &p.task.center)?;
        positive("task.radius", p.task.radius, 100.0)?;
        positive("task.period", p.task.period, 1e4)?;
        check_ramp(p.task.ramp)?;

        let c = &self.law;
        c.check_planar()?;
        if !c.obstacles.is_empty() {
            return Err(invalid(
                "law.obstacles",
                format!("{} entries", c.obstacles.len()),
                "the obstacles are a top-level [[obstacles]] list",
            ));
        }
        range("law.kp", c.kp, 0.0, 1e6)?;
        range("law.kv", c.kv, 0.0, 1e6)?;
        range("law.alpha", c.alpha, -1e3, 1e3)?;
        let (w1, w2) = c.disc_weights();
        range("law.w1", w1, 0.0, 1e6)?;
        range("law.w2", w2, 0.0, 1e6)?;
        positive("law.damping_threshold", c.damping_threshold, 10.0)?;
        positive("law.damping_max", c.damping_max, 10.0)?;
        positive("law.track_loss", c.track_loss, 100.0)?;
        if p.obstacles.len() > MAX_OBSTACLES {
            return Err(invalid(
                "obstacles",
                format!("{} obstacles", p.obstacles.len()),
                &format!("at most {MAX_OBSTACLES}"),
            ));
        }
        for (i, o) in p.obstacles.iter().enumerate() {
            o.validate(&format!("obstacles[{i}]"))?;
        }
        if let SecondaryKind::Custom(name) = &c.secondary {
            if Secondary::parse(name).is_none() {
                return Err(invalid("law.secondary", name, &Secondary::names()));
            }
        }
        let limits = self.safety.q_min.is_some() && self.safety.q_max.is_some();
        if c.secondary == SecondaryKind::Centring && !limits {
            return Err(invalid(
                "law.secondary",
                "centring",
                "centring pulls each joint to the middle of its range: give safety.q_min and safety.q_max",
            ));
        }
        if c.secondary == SecondaryKind::Obstacles && p.obstacles.is_empty() {
            return Err(invalid(
                "obstacles",
                "[]",
                "secondary = \"obstacles\" needs at least one [[obstacles]] entry",
            ));
        }

        let s = &self.sim;
        range("sim.dt", s.dt, 1e-5, 0.1)?;
        positive("sim.duration", s.duration, sim::MAX_DURATION)?;
        range("sim.transient", s.transient, 0.0, s.duration)?;
        self.feedback.validate(s.dt, p.task.period)?;
        for (name, v) in [("sim.q0", &s.q0), ("sim.qd0", &s.qd0)] {
            if let Some(v) = v {
                same_len(name, v, n)?;
                finite_vec(name, v)?;
                sim::check_start_size(name, v)?;
            }
        }
        range("sim.phi0", s.phi0, -1e6, 1e6)?;
        self.safety.validate(n)?;
        if self.safety.plan == crate::safety::policy::PlanMode::On && !self.has_planner() {
            return Err(invalid(
                "safety.plan",
                true,
                "the cycle planner handles the fixed-base 3-link arm only",
            ));
        }
        crate::config::stability::check(self, s.dt, &format!("sim.dt = {} s", s.dt))
    }

    /// The model and the law's parameters as the block a control tick runs.
    pub fn tick_law<const N: usize>(&self) -> crate::tick_law::TickLaw<N> {
        crate::tick_law::TickLaw::Planar {
            model: self.model::<N>(),
            params: self.law_params(),
        }
    }

    /// The control-law parameter block (the config must be valid).
    pub fn law_params(&self) -> LawParams {
        let (c, p) = (&self.law, self.planar_part());
        LawParams {
            // Validation refuses a name no program registered.
            core: self.law_core(
                c.secondary.task().unwrap_or(Secondary::None),
                self.safety.params(self.n()),
            ),
            task: Path::in_the_plane(p.task.path, p.task.center, p.task.radius, p.task.period)
                .with_ramp(p.task.ramp),
            obstacles: p
                .obstacles
                .iter()
                .map(ObstacleConfig::to_ball)
                .collect::<ObstacleSet>(),
            weights: {
                let (w1, w2) = c.disc_weights();
                PotentialWeights { w1, w2 }
            },
            steer: None,
        }
    }

    /// The part of the law's parameters every arm shares, from the shared sections: the
    /// secondary task and the limits come from the caller (a robot's from its chain).
    pub fn law_core(&self, secondary: Secondary, safety: crate::safety::SafetyParams) -> LawCore {
        let (c, f) = (&self.law, &self.feedback);
        LawCore {
            kp: c.kp,
            kv: c.kv,
            alpha: c.alpha,
            secondary,
            damping_threshold: c.damping_threshold,
            damping_max: c.damping_max,
            mu: f.mu,
            tau: self.tau(),
            t_on: f.t_on,
            feedback: f.enabled,
            projection: f.projection.into(),
            auto_mu: f.auto,
            safety,
            track_loss: c.track_loss,
            pause: false,
        }
    }

    /// Whether a cycle planner handles this arm: on the planar arm, the fixed-base 3-link one;
    /// every chain.
    pub fn has_planner(&self) -> bool {
        match &self.robot {
            Robot::Planar(p) => p.arm.links.len() == 3 && p.arm.model == ModelKind::Fixed,
            Robot::Spatial(_) => true,
        }
    }

    /// The arm model with N joints (N must equal `self.n()`).
    pub fn model<const N: usize>(&self) -> ArmModel<N> {
        assert_eq!(N, self.n(), "arm size mismatch");
        let arm = &self.planar_part().arm;
        let links = to_array(&arm.links);
        match arm.model {
            ModelKind::Fixed => ArmModel::Fixed(FixedArm::new(links)),
            ModelKind::Floating => ArmModel::Floating(FloatingArm {
                links,
                link_masses: to_array(&self.link_masses()),
                link_inertias: to_array(&self.link_inertias()),
                base_mass: arm.base_mass,
                base_inertia: arm.base_inertia,
                base_offset: arm.base_offset,
            }),
        }
    }

    pub fn initial_state<const N: usize>(&self) -> ArmState<N> {
        ArmState {
            q: VecN::<N>::from_column_slice(&self.q0()),
            qd: VecN::<N>::from_column_slice(&self.qd0()),
            phi: if self.planar_part().arm.model == ModelKind::Floating {
                self.sim.phi0
            } else {
                0.0
            },
        }
    }
}

/// A TOML parser's refusal with the line it points at, for every arm's file.
pub(crate) fn parse_error(text: &str, e: &toml::de::Error) -> ConfigError {
    let line = e
        .span()
        .map(|s| text.get(..s.start).unwrap_or(text).matches('\n').count() + 1);
    // The line itself names the key, which a refused value's message (an unknown shape, a
    // string where a number goes) does not.
    let at = line
        .map(|l| match text.lines().nth(l - 1).map(str::trim) {
            Some(src) if !src.is_empty() && src.chars().count() <= 60 => {
                format!("line {l} ({src}): ")
            }
            _ => format!("line {l}: "),
        })
        .unwrap_or_default();
    ConfigError::Parse(excerpt(&format!("{at}{}", e.message())))
}

/// Whether a planar file is written in the older form (no `[robot]` table).
fn is_older_form(text: &str) -> bool {
    text.parse::<toml::Table>()
        .map(|t| !t.contains_key("robot"))
        .unwrap_or(true)
}

fn to_array<const N: usize>(v: &[f64]) -> [f64; N] {
    let mut a = [0.0; N];
    a.copy_from_slice(v);
    a
}

fn positive(field: &str, v: f64, max: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 && v <= max {
        Ok(())
    } else {
        Err(invalid(
            field,
            v,
            &format!("must be a finite number > 0 and ≤ {max}"),
        ))
    }
}

fn finite_vec(field: &str, v: &[f64]) -> Result<(), ConfigError> {
    match v.iter().position(|x| !x.is_finite()) {
        None => Ok(()),
        Some(i) => Err(invalid(&format!("{field}[{i}]"), v[i], "must be finite")),
    }
}

fn same_len(field: &str, v: &[f64], n: usize) -> Result<(), ConfigError> {
    if v.len() == n {
        Ok(())
    } else {
        Err(invalid(
            field,
            v,
            &format!("must have {n} entries, one per link (robot.links has {n})"),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_validate() {
        for p in PRESETS {
            Config::preset(p).unwrap().validate().unwrap();
        }
        assert!(matches!(
            Config::preset("nope"),
            Err(ConfigError::UnknownPreset { .. })
        ));
    }

    #[test]
    fn round_trips_through_toml() {
        let c = Config::preset("paper-obstacle").unwrap();
        let back = Config::parse(&c.to_toml()).unwrap();
        assert_eq!(c, back);
    }

    #[test]
    fn errors_name_the_field() {
        let e = Config::parse("[control]\nkp = -3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("control.kp") && e.contains("-3"), "{e}");
        let e = Config::parse("[control]\nkpp = 3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("kpp"), "{e}");
        let e = Config::parse("[feedback]\ntau = 5.0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("feedback.tau") && e.contains("max_tau"), "{e}");
        let e = Config::parse("[sim]\nq0 = [1.0, 2.0]\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("sim.q0") && e.contains("3 entries"), "{e}");
        let e = Config::parse("[arm]\nlinks = [1.0]\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("arm.links"), "{e}");
        let e = Config::parse("[control]\nsecondary = \"obstacles\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("control.obstacles"), "{e}");
        let e = Config::parse("[task]\nradius = nan\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("task.radius"), "{e}");
        let e = Config::parse("this is not toml").unwrap_err().to_string();
        assert!(e.starts_with("cannot parse config"), "{e}");
    }

    #[test]
    fn huge_configs_and_values_give_short_errors() {
        let huge = format!("[task]\nradius = \"{}\"\n", "x".repeat(MAX_CONFIG_BYTES));
        let e = Config::parse(&huge).unwrap_err().to_string();
        assert!(e.len() < 200 && e.contains("at most"), "{}", e.len());
        let long = format!("[control]\nsecondary = \"{}\"\n", "y".repeat(100_000));
        let e = Config::parse(&long).unwrap_err().to_string();
        assert!(e.len() < 1024, "{} bytes", e.len());
        let links = format!("[arm]\nlinks = [{}]\n", vec!["1.0"; 5000].join(", "));
        let e = Config::parse(&links).unwrap_err().to_string();
        assert!(
            e.len() < 1024 && e.contains("arm.links"),
            "{} bytes",
            e.len()
        );
    }

    #[test]
    fn arms_of_up_to_twelve_links_fit_and_a_thirteen_link_one_does_not() {
        // A Panda's link lengths (m), with a circle it can reach.
        let seven = Config::parse(
            "[arm]\nlinks = [0.333, 0.316, 0.0825, 0.384, 0.088, 0.107, 0.1]\n\
             [task]\ncenter = [0.5, 0.6]\nradius = 0.2\n",
        )
        .unwrap();
        assert_eq!(seven.n(), 7);
        seven.validate().unwrap();
        assert_eq!(crate::with_dof!(seven.n(), N => N), 7);
        let twelve = Config::parse(
            "[arm]\nlinks = [0.2, 0.2, 0.2, 0.2, 0.2, 0.2, 0.2, 0.2, 0.2, 0.2, 0.2, 0.2]\n\
             [task]\ncenter = [0.5, 0.6]\nradius = 0.2\n",
        )
        .unwrap();
        assert_eq!(twelve.n(), MAX_JOINTS);
        twelve.validate().unwrap();
        assert_eq!(crate::with_dof!(twelve.n(), N => N), 12);
        let e = Config::parse("[arm]\nlinks = [1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("arm.links") && e.contains("must list 2 to 12 link lengths"),
            "{e}"
        );
    }

    #[test]
    fn default_inertias_are_the_papers() {
        let c = Config::default();
        assert_eq!(c.link_inertias(), vec![0.30000000000000004, 0.2, 0.1]);
        assert_eq!(c.q0(), vec![0.0, FRAC_PI_2, FRAC_PI_2]);
    }
}
