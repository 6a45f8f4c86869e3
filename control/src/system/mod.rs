//! What a daemon and a plant run: the paper's planar arm or a URDF chain, from one config file.
//!
//! Both processes read the same file and must agree on the arm. Every file is one [`Config`];
//! a robot's also needs its chain loaded, which this enum carries beside it. This enum is the
//! one place outside the config that tells the arms apart, so the daemon's loop, its handshake and the plant ask it
//! for what they need (the joint count, the law, the start, the arm's identity) and never parse
//! a file twice. The robot description itself is read by the caller (`rt::robot`): this crate
//! does no I/O, so [`System::parse`] takes the chain resolver as an argument.

use crate::arm::VecN;
use crate::basics::ConfigError;
use crate::command::CommandMode;
use crate::config::spatial::is_spatial;
use crate::config::{Config, FeedbackSection, LawSection, Robot};
use crate::model::Chain;
use crate::safety::SafetySection;
use crate::sim::{ArmState, ClosedLoopLaw};
use crate::tick_law::{ParamBlock, TickLaw};

mod drawing;
mod obstacles;
mod robot;
mod run;
pub use drawing::{Drawing, Posed};
pub use obstacles::ObstacleRow;

/// A robot's set-up: its config (always [`crate::config::Robot::Spatial`]) and the chain its
/// `[robot]` names.
#[derive(Clone, Debug, PartialEq)]
pub struct SpatialSystem {
    pub config: Config,
    pub chain: Chain,
}

/// A whole set-up, planar or spatial.
// Built once at start-up and on a live change, never on the loop: size does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq)]
pub enum System {
    Planar(Config),
    Spatial(Box<SpatialSystem>),
}

/// Loads the chain a `[robot]` table names: `(description, base, tip)`.
pub type Resolve<'a> =
    &'a dyn Fn(&str, Option<&str>, Option<&str>) -> Result<Chain, crate::model::RobotError>;

/// A [`Resolve`] that knows the robots built into this crate and nothing else (it reads no
/// file): for tests and benchmarks that must not depend on the disk.
///
/// ```
/// let s = control::System::preset("panda", &control::system::builtin_robot).unwrap();
/// assert_eq!(s.n(), 7);
/// ```
pub fn builtin_robot(
    description: &str,
    base: Option<&str>,
    tip: Option<&str>,
) -> Result<Chain, crate::model::RobotError> {
    let model = |error| crate::model::RobotError::Model {
        origin: format!("built-in robot {description:?}"),
        error,
    };
    let text = crate::model::builtin(description).map_err(model)?;
    Chain::from_urdf(text, base, tip).map_err(model)
}

/// Who the arm is, for the handshake: a name a person reads and a fingerprint of every number.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Identity {
    /// `panda (panda_link0 → panda_link8)`.
    pub name: String,
    /// FNV-1a of the chain's numbers, the tool point and the link radii.
    pub fingerprint: u64,
}

impl System {
    /// Parses a file's text and validates it: the paper's planar arm when `[robot]` names
    /// `"planar"` (or the file has the older planar form, without `[robot]`), else a chain.
    pub fn parse(text: &str, resolve: Resolve) -> Result<Self, ConfigError> {
        if !is_spatial(text) {
            return Ok(System::Planar(Config::parse(text)?));
        }
        let s = Self::read(text, resolve)?;
        s.validate()?;
        Ok(s)
    }

    /// [`Self::parse`] without the validation, for a caller that changes the set-up first (a
    /// command's flags) and validates what it runs. The chain a `[robot]` names is loaded here.
    pub fn read(text: &str, resolve: Resolve) -> Result<Self, ConfigError> {
        Self::with_chain(Config::read_any(text)?, resolve)
    }

    /// A built-in set-up, validated: the planar presets and the spatial ones (`panda`, …).
    pub fn preset(name: &str, resolve: Resolve) -> Result<Self, ConfigError> {
        let s = Self::named(name, resolve)?;
        s.validate()?;
        Ok(s)
    }

    /// [`Self::preset`] without the validation (see [`Self::read`]).
    pub fn named(name: &str, resolve: Resolve) -> Result<Self, ConfigError> {
        match Config::robot_preset(name) {
            Some(c) => Self::with_chain(c, resolve),
            None => Ok(System::Planar(Config::preset(name)?)),
        }
    }

    /// Loads the chain of a robot's config and checks the config against it.
    pub fn spatial(config: Config, resolve: Resolve) -> Result<Self, ConfigError> {
        let s = Self::with_chain(config, resolve)?;
        s.validate()?;
        Ok(s)
    }

    /// A robot's config with the chain its `[robot]` names, not yet checked against it; the
    /// planar arm's as it is.
    fn with_chain(config: Config, resolve: Resolve) -> Result<Self, ConfigError> {
        let Some(robot) = config.spatial() else {
            return Ok(System::Planar(config));
        };
        let r = &robot.robot;
        let chain = resolve(&r.description, r.base.as_deref(), r.tip.as_deref()).map_err(|e| {
            ConfigError::Invalid {
                field: "robot.description".into(),
                value: format!("{:?}", r.description),
                expected: e.to_string(),
            }
        })?;
        Ok(System::Spatial(Box::new(SpatialSystem { config, chain })))
    }

    /// The joint count.
    pub fn n(&self) -> usize {
        match self {
            System::Planar(c) => c.n(),
            System::Spatial(s) => s.chain.dof(),
        }
    }

    pub fn planar(&self) -> Option<&Config> {
        match self {
            System::Planar(c) => Some(c),
            System::Spatial(_) => None,
        }
    }

    /// The whole config, on every arm.
    pub fn config(&self) -> &Config {
        match self {
            System::Planar(c) => c,
            System::Spatial(s) => &s.config,
        }
    }

    pub fn config_mut(&mut self) -> &mut Config {
        match self {
            System::Planar(c) => c,
            System::Spatial(s) => &mut s.config,
        }
    }

    /// Validates the whole set-up (for a spatial one, against its chain).
    pub fn validate(&self) -> Result<(), ConfigError> {
        match self {
            System::Planar(c) => c.validate(),
            System::Spatial(s) => {
                let n = s.chain.dof();
                if !(crate::basics::MIN_JOINTS..=crate::basics::MAX_JOINTS).contains(&n) {
                    return Err(ConfigError::Invalid {
                        field: "robot.description".into(),
                        value: format!("{:?}", s.own().robot.description),
                        expected: format!(
                            "a chain of {} to {} joints (this one has {n})",
                            crate::basics::MIN_JOINTS,
                            crate::basics::MAX_JOINTS
                        ),
                    });
                }
                crate::with_dof!(n, N => s.config.setup::<N>(&s.chain).map(|_| ()))
            }
        }
    }

    /// The sampled-loop rules at the daemon's step `dt` (`step` names where dt comes from), and
    /// τ ≥ dt (the delay line is filled once per tick).
    pub fn check_step(&self, dt: f64, step: &str) -> Result<(), ConfigError> {
        match self {
            System::Planar(c) => crate::config::stability::check(c, dt, step)?,
            System::Spatial(s) => s.config.check_step(&s.chain, dt, step)?,
        }
        let tau = self.feedback().tau;
        if tau < dt {
            return Err(ConfigError::Invalid {
                field: "feedback.tau".into(),
                value: format!("{tau}"),
                expected: format!("must be at least one control period ({dt} s at {step})"),
            });
        }
        Ok(())
    }

    /// Refuses a start whose first seconds of motion need more than a joint's effort limit
    /// (`control::config::rehearsal`), in the interfaces where the arm's own motors carry the
    /// motion (position, velocity, torque). Acceleration mode is the ideal arm's interface (the
    /// kinematic plant integrates q̈ whatever it costs) and the planar arm has no dynamics:
    /// both pass.
    pub fn check_motion_effort(&self) -> Result<(), ConfigError> {
        match self {
            System::Spatial(s) if s.own().command.mode != CommandMode::Acceleration => {
                crate::with_dof!(s.chain.dof(), N => s.config.check_motion_effort::<N>(&s.chain))
            }
            _ => Ok(()),
        }
    }

    /// The law a control tick runs; `N` must be [`System::n`]. The set-up was validated.
    pub fn tick_law<const N: usize>(&self) -> TickLaw<N> {
        match self {
            System::Planar(c) => c.tick_law::<N>(),
            System::Spatial(s) => {
                let set = s
                    .config
                    .setup::<N>(&s.chain)
                    .expect("a validated spatial set-up builds");
                TickLaw::Spatial {
                    arm: set.arm,
                    params: set.params,
                }
            }
        }
    }

    /// The state a simulated plant starts from; `N` must be [`System::n`].
    pub fn initial_state<const N: usize>(&self) -> ArmState<N> {
        match self {
            System::Planar(c) => c.initial_state(),
            System::Spatial(s) => {
                let q = s.config.sim.start();
                let qd = s.config.sim.qd0.clone().unwrap_or_else(|| vec![0.0; N]);
                ArmState {
                    q: VecN::<N>::from_fn(|i, _| q.get(i).copied().unwrap_or(0.0)),
                    qd: VecN::<N>::from_fn(|i, _| qd.get(i).copied().unwrap_or(0.0)),
                    phi: 0.0,
                }
            }
        }
    }

    /// The arm's smallest clearance to the set-up's obstacles at posture `q` and base attitude
    /// `phi` (the planar floating base's; 0 for every other arm) (m; negative: a link inside
    /// one; ∞ without obstacles), by the law's own geometry: the law evaluated once at rest
    /// there. Not for the loop (it builds the law).
    pub fn clearance_at(&self, phi: f64, q: &[f64]) -> f64 {
        crate::with_dof!(self.n(), N => {
            let law = self.tick_law::<N>();
            let mut x = self.initial_state::<N>();
            x.phi = phi;
            x.q = VecN::<N>::from_fn(|i, _| q.get(i).copied().unwrap_or(0.0));
            x.qd = VecN::<N>::zeros();
            let mut scratch = crate::tick_law::LawScratch::<N>::default();
            law.evaluate(0.0, &x, &VecN::<N>::zeros(), &mut scratch).clearance
        })
    }

    /// The feedback settings every arm has.
    pub fn feedback(&self) -> Feedback {
        let (f, period) = (self.feedback_section(), self.period());
        Feedback {
            mu: f.mu,
            auto: f.auto,
            tau: f.tau_for(period),
            t_on: f.t_on,
            max_tau: f.capacity(),
        }
    }

    /// Sets μ (a gain, or "auto" with its default tuning unless already adapting) and t_on,
    /// and switches the feedback on (the demo's schedule).
    pub fn schedule_feedback(&mut self, mu: crate::adapt::MuSetting, t_on: f64) {
        let f = self.feedback_section_mut();
        f.mu = mu.start();
        if mu.is_auto() {
            f.auto.get_or_insert_with(Default::default);
        } else {
            f.auto = None;
        }
        f.t_on = t_on;
        f.enabled = true;
    }

    /// This set-up with a gain from the model ([`crate::tune`]) for `mu = "auto"`: μ starts at
    /// `mu` and the speed-gradient law is anchored on it ([`crate::adapt::AutoMu::anchor`]),
    /// with the model's adaptation gain `gamma` unless the user gave one
    /// ([`crate::adapt::model_gamma`]). None when μ is not "auto" (a fixed gain is the user's,
    /// not the model's).
    ///
    /// ```
    /// use control::{adapt::MuSetting, System};
    /// let mut s = System::preset("paper", &control::system::builtin_robot).unwrap();
    /// assert!(s.with_model_gain(0.2, 1e-3).is_none());
    /// s.schedule_feedback(MuSetting::Auto, 0.0);
    /// let g = s.with_model_gain(0.2, 1e-3).unwrap();
    /// let a = g.feedback().auto.unwrap();
    /// assert_eq!((g.feedback().mu, a.anchor, a.gamma), (0.2, Some(0.2), 1e-3));
    /// // A γ the user set stays theirs.
    /// let f = s.feedback_section_mut();
    /// control::adapt::set_live("gamma", Some("2e-4"), &mut f.mu, &mut f.auto).unwrap();
    /// assert_eq!(s.with_model_gain(0.2, 1e-3).unwrap().feedback().auto.unwrap().gamma, 2e-4);
    /// ```
    pub fn with_model_gain(&self, mu: f64, gamma: f64) -> Option<System> {
        let mut s = self.clone();
        let f = s.feedback_section_mut();
        let auto = f.auto.as_mut()?;
        auto.anchor = Some(mu);
        if !auto.gamma_given {
            auto.gamma = gamma;
        }
        f.mu = mu;
        Some(s)
    }

    /// The file's `[feedback]`, one section for every arm.
    pub fn feedback_section(&self) -> &FeedbackSection {
        &self.config().feedback
    }

    pub fn feedback_section_mut(&mut self) -> &mut FeedbackSection {
        &mut self.config_mut().feedback
    }

    /// The file's `[sim]`, one section for every arm.
    pub fn sim_section(&self) -> &crate::config::SimSection {
        &self.config().sim
    }

    pub fn sim_section_mut(&mut self) -> &mut crate::config::SimSection {
        &mut self.config_mut().sim
    }

    /// The file's `[law]`, one section for every arm.
    pub fn law_section(&self) -> &LawSection {
        &self.config().law
    }

    pub fn law_section_mut(&mut self) -> &mut LawSection {
        &mut self.config_mut().law
    }

    /// The file's `[safety]`, one section for every arm.
    pub fn safety_section(&self) -> &SafetySection {
        &self.config().safety
    }

    pub fn safety_section_mut(&mut self) -> &mut SafetySection {
        &mut self.config_mut().safety
    }

    /// The task circle's radius and period T (m, s), to change in place.
    pub fn task_circle_mut(&mut self) -> (&mut f64, &mut f64) {
        self.config_mut().task_circle_mut()
    }

    /// How long the path takes to come up to full speed from rest (s; 0: at full speed from
    /// t = 0), to change in place.
    pub fn task_ramp_mut(&mut self) -> &mut f64 {
        self.config_mut().task_ramp_mut()
    }

    /// Moves the task's centre: [`Self::obstacle_dims`] numbers (x, y on the planar arm; x, y,
    /// z in a robot's base frame).
    pub fn set_task_center(&mut self, c: &[f64]) -> Result<(), ConfigError> {
        let wrong = |d: usize| crate::basics::invalid("task.center", c, &format!("{d} numbers"));
        match &mut self.config_mut().robot {
            Robot::Planar(p) => p.task.center = c.try_into().map_err(|_| wrong(2))?,
            Robot::Spatial(s) => s.task.center = Some(c.try_into().map_err(|_| wrong(3))?),
        }
        Ok(())
    }

    /// The task as text: two set-ups with the same key follow the same path.
    pub fn task_key(&self) -> String {
        self.config().task_key()
    }

    /// The task's period T (s).
    pub fn period(&self) -> f64 {
        self.config().period()
    }

    pub fn command_mode(&self) -> crate::command::CommandMode {
        match self {
            System::Planar(_) => crate::command::CommandMode::Acceleration,
            System::Spatial(s) => s.own().command.mode,
        }
    }

    /// Whether commands pass the limiter (the planar arm has no limits to enforce).
    pub fn limiter_on(&self) -> bool {
        match self {
            System::Planar(_) => false,
            System::Spatial(s) => s.own().command.limiter,
        }
    }

    /// The motion generator and limiter at the daemon's period `dt` (`N` = [`System::n`]). The
    /// planar arm has no maker's limits: its q̈ passes through untouched, as it always has.
    pub fn generator<const N: usize>(
        &self,
        dt: f64,
    ) -> Result<crate::command::MotionGenerator<N>, ConfigError> {
        match self {
            System::Planar(_) => Ok(crate::command::MotionGenerator::passthrough(dt)),
            System::Spatial(s) => s.config.generator::<N>(&s.chain, dt),
        }
    }

    /// Each joint's effort limit (N·m or N) as the command stream obeys it: the description's,
    /// tightened by the maker's table and `[command.limits]`; ∞ for the planar arm (it has
    /// none) and past [`System::n`].
    pub fn effort_limits(&self) -> [f64; crate::basics::MAX_JOINTS] {
        let mut out = [f64::INFINITY; crate::basics::MAX_JOINTS];
        crate::with_dof!(self.n(), N => {
            if let Ok(l) = self.device_limits::<N>() {
                out[..N].copy_from_slice(&l.tau);
            }
        });
        out
    }

    /// The running law's parameters as a block for [`TickLaw::set`]. The set-up was validated.
    pub fn param_block(&self) -> ParamBlock {
        match self {
            System::Planar(c) => ParamBlock::Planar(c.law_params()),
            System::Spatial(s) => ParamBlock::Spatial(crate::with_dof!(s.chain.dof(), N => {
                s.config.setup::<N>(&s.chain).expect("a validated spatial set-up builds").params
            })),
        }
    }

    /// What a report says about the arm's safety settings.
    pub fn safety(&self) -> SafetySummary {
        let c = self.config();
        SafetySummary {
            enabled: c.safety.enabled,
            clearance: c.safety.clearance,
            track_loss: c.law.track_loss,
            obstacles: c.obstacle_count(),
            trap_time: c.safety.trap_time,
            when_blocked: c.safety.when_blocked,
            task_period: c.period(),
        }
    }

    /// One line naming the arm: `3-link planar arm, fixed base` or `panda (panda_link0 →
    /// panda_link8), 7 joints, position task`.
    pub fn describe_arm(&self) -> String {
        match self {
            System::Planar(c) => format!(
                "{}-link planar arm, {} base",
                c.n(),
                if c.planar_part().arm.model == crate::config::ModelKind::Floating {
                    "floating"
                } else {
                    "fixed"
                }
            ),
            System::Spatial(s) => format!(
                "{} ({} → {}), {} joints, {} task",
                s.chain.robot,
                s.chain.base,
                s.chain.tip,
                s.chain.dof(),
                s.own().task.kind
            ),
        }
    }

    /// The `[daemon]` and `[plant]` tables the file carries for the processes.
    pub fn tables(&self) -> (&Option<toml::Table>, &Option<toml::Table>) {
        let c = self.config();
        (&c.daemon, &c.plant)
    }

    pub fn tables_mut(&mut self) -> (&mut Option<toml::Table>, &mut Option<toml::Table>) {
        let c = self.config_mut();
        (&mut c.daemon, &mut c.plant)
    }

    /// The file again, tables included.
    pub fn to_toml(&self) -> String {
        self.config().to_toml()
    }

    /// The file's `[task]`, to print or serialise as the file has it.
    pub fn task(&self) -> TaskRef<'_> {
        match &self.config().robot {
            Robot::Planar(p) => TaskRef::Planar(&p.task),
            Robot::Spatial(s) => TaskRef::Spatial(&s.task),
        }
    }

    /// A robot's kinematic chain; the planar arm has its closed form instead.
    pub fn chain(&self) -> Option<&Chain> {
        match self {
            System::Planar(_) => None,
            System::Spatial(s) => Some(&s.chain),
        }
    }

    /// A spatial arm's identity (a planar arm's is its link lengths, in the handshake itself).
    pub fn identity(&self) -> Option<Identity> {
        match self {
            System::Planar(_) => None,
            System::Spatial(s) => Some(s.identity()),
        }
    }
}

/// Either arm's `[task]` section ([`System::task`]); serialises as the section itself.
#[derive(Debug, serde::Serialize)]
#[serde(untagged)]
pub enum TaskRef<'a> {
    Planar(&'a crate::config::TaskConfig),
    Spatial(&'a crate::config::TaskSection),
}

impl SpatialSystem {
    /// The robot's own sections (`[robot]`, `[task]`, `[[obstacles]]`, `[command]`).
    pub fn own(&self) -> &crate::config::SpatialRobot {
        self.config.spatial_part()
    }

    pub fn own_mut(&mut self) -> &mut crate::config::SpatialRobot {
        self.config
            .spatial_mut()
            .expect("a robot's set-up holds a robot's config")
    }

    /// Who the arm is: the chain's name and a fingerprint of its numbers.
    pub fn identity(&self) -> Identity {
        let c = &self.chain;
        let r = &self.config.spatial_part().robot;
        // Debug prints every float exactly (shortest round-trip form), so equal text is equal
        // numbers; the description string is left out, so a copy of the URDF elsewhere agrees.
        let text = format!("{:?}|{:?}|{:?}", c, r.tool, r.link_radii);
        Identity {
            name: format!("{} ({} → {})", c.robot, c.base, c.tip),
            fingerprint: fnv1a(text.as_bytes()),
        }
    }
}

/// The safety settings of [`System::safety`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SafetySummary {
    pub enabled: bool,
    /// Required clearance (m).
    pub clearance: f64,
    /// Tracking error (m) above which tracking counts as lost.
    pub track_loss: f64,
    pub obstacles: usize,
    /// How long a trap lasts before the daemon acts (s), and what it does when blocked.
    pub trap_time: f64,
    pub when_blocked: crate::safety::policy::WhenBlocked,
    /// The task's period (s): a trap that recurs is counted in periods of it.
    pub task_period: f64,
}

/// The feedback settings of [`System::feedback`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Feedback {
    pub mu: f64,
    /// `mu = "auto"`: the adaptation's settings.
    pub auto: Option<crate::adapt::AutoMu>,
    pub tau: f64,
    pub t_on: f64,
    pub max_tau: f64,
}

/// 64-bit FNV-1a: a stable hash (std's `DefaultHasher` may change between Rust releases, and
/// two builds must agree).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    use super::builtin_robot as builtin;

    #[test]
    fn tells_planar_from_spatial_and_names_the_arm() {
        let p = System::preset("demo", &builtin).unwrap();
        assert_eq!((p.n(), p.identity()), (3, None));
        let s = System::preset("panda", &builtin).unwrap();
        assert_eq!(s.n(), 7);
        let id = s.identity().unwrap();
        assert_eq!(id.name, "panda (panda_link0 → panda_link8)");
        let again = System::parse(&s.to_toml(), &builtin).unwrap();
        assert_eq!(again.identity().unwrap(), id);
        let short = System::parse(
            &s.to_toml()
                .replace("[robot]\n", "[robot]\ntip = \"panda_link7\"\n"),
            &builtin,
        )
        .unwrap();
        assert_ne!(short.identity().unwrap().fingerprint, id.fingerprint);
        let e = System::parse(&s.to_toml().replace("\"panda\"", "\"ur99\""), &builtin);
        assert!(e.unwrap_err().to_string().contains("robot.description"));
    }

    #[test]
    fn the_control_step_is_checked_for_either_arm() {
        let s = System::preset("panda", &builtin).unwrap();
        assert!(s.check_step(0.001, "daemon.rate_hz = 1000").is_ok());
        let e = s.check_step(0.05, "daemon.rate_hz = 20").unwrap_err();
        assert!(e.to_string().contains("daemon.rate_hz = 20"), "{e}");
    }
}
