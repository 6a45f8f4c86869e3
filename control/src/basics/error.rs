//! The refusal every layer gives a bad value: which field, what it was, what it must be.
//!
//! A URDF loader, a limiter and a config all refuse in the same words, so the error type and
//! its small helpers live below all of them.

/// A configuration that cannot be used, naming the offending field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot parse config: {0}")]
    Parse(String),
    #[error("invalid config: {field} = {value}: {expected}")]
    Invalid {
        field: String,
        value: String,
        expected: String,
    },
    #[error("unknown preset {name:?} (known presets: {known})")]
    UnknownPreset { name: String, known: String },
    /// `feedback.gamma`, `feedback.max_mu` or `feedback.target` beside a fixed μ: they would
    /// silently do nothing.
    #[error("feedback.gamma, feedback.max_mu and feedback.target tune mu = \"auto\"; with a fixed mu they do nothing: remove them")]
    AutoTuningWithoutAuto,
    /// A spatial robot's set-up given where only the planar arm runs yet.
    /// The robot's own physics cannot do what the set-up asks (found before the first command).
    #[error(transparent)]
    Physics(#[from] PhysicsError),
    #[error("{0} is a spatial robot's set-up; `chaosd`, `chaosd-plant` and `chaosctl config|simulate|lyapunov|sweep|poincare|orbits|basins|monitor|figures|obstacles|arm-figure|plan|replay` run spatial robots, but this command takes the planar arm only")]
    Spatial(String),
}

/// A robot whose physics cannot do what is asked of it, named by joint and number: found at
/// start-up so that it never surfaces later as a NaN or a runaway-guard FAULT.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PhysicsError {
    /// A movable joint that moves nothing: the mass matrix is singular.
    #[error("joint {index} ({joint:?}) moves no mass or inertia: link {link:?} and every link after it weigh nothing (a link without <inertial> has mass 0), so the mass matrix is singular and the arm's dynamics are undefined; give those links an <inertial>{remedy}")]
    Massless {
        /// 1-based, as every message numbers joints.
        index: usize,
        joint: String,
        link: String,
        /// What the user can do instead, where there is something (", or …").
        remedy: &'static str,
    },
    /// An effort limit below the gravity load at the start posture.
    #[error("joint {index} ({joint:?}) cannot hold the start posture: gravity there needs {load:.2} {unit} and its effort limit is {limit:.2} {unit}; start where the arm carries less (sim.q0){remedy}")]
    GravityBeyondEffort {
        index: usize,
        joint: String,
        load: f64,
        limit: f64,
        unit: &'static str,
        remedy: &'static str,
    },
    /// A motion from the start that needs more than a joint's effort limit, found by
    /// rehearsing the law offline (`control::config::rehearsal`).
    #[error("joint {index} ({joint:?}) cannot carry the motion from this start: the law, rehearsed offline over its first {span:.1} s, needs {load:.2} {unit} there at t = {t:.2} s and its effort limit is {limit:.2} {unit}; start where the arm carries less (sim.q0) or slow the path (task.period)")]
    MotionBeyondEffort {
        index: usize,
        joint: String,
        load: f64,
        limit: f64,
        unit: &'static str,
        /// When (s from the start) and over how long a rehearsal.
        t: f64,
        span: f64,
    },
}

/// Largest config text accepted: a config is a few hundred bytes; a huge file is a mistake, and
/// parsing it would cost memory in proportion.
pub const MAX_CONFIG_BYTES: usize = 1 << 20;
/// Longest excerpt of a bad value or a parser message quoted in an error.
pub const MAX_QUOTE: usize = 200;

/// At most [`MAX_QUOTE`] bytes of `s` (cut at a character boundary), marked when cut.
pub fn excerpt(s: &str) -> String {
    if s.len() <= MAX_QUOTE {
        return s.to_string();
    }
    let mut end = MAX_QUOTE;
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}… ({} bytes in all)", &s[..end], s.len())
}

/// A value given on a live `set` (`KEY VALUE`) or a command line that cannot be used: one line
/// naming the key. The daemon prints it as the request's answer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LiveError {
    #[error("{key}: missing value")]
    Missing { key: String },
    #[error("{key}: {value:?} is not a number")]
    NotANumber { key: String, value: String },
    #[error("{key}: {value} is not a finite number")]
    NotFinite { key: String, value: String },
    /// A word that is none of `expected` (given as `None` when the value was missing).
    #[error("{key}: {value:?} is not {expected}")]
    NotOneOf {
        key: String,
        value: Option<String>,
        expected: &'static str,
    },
    /// A gain that is neither a number ≥ 0 nor `auto`.
    #[error("{0} (give a number ≥ 0, or auto)")]
    NotAGain(Box<LiveError>),
    #[error("{value:?}: must be a number ≥ 0 or \"auto\"")]
    NotAGainWord { value: String },
    /// `gamma` or `max_mu` while μ is fixed.
    #[error("feedback.{key} tunes mu = \"auto\": set mu auto first (chaosctl set mu auto)")]
    NeedsAuto { key: String },
    #[error("unknown command mode {0:?} (expected \"acceleration\", \"velocity\", \"position\" or \"torque\")")]
    CommandMode(String),
}

/// For the daemon's answers, which are text.
impl From<LiveError> for String {
    fn from(e: LiveError) -> Self {
        e.to_string()
    }
}

impl LiveError {
    /// `value` is not one of the words in `expected` (e.g. `"hold or best-effort"`).
    pub fn not_one_of(key: &str, value: Option<&str>, expected: &'static str) -> Self {
        LiveError::NotOneOf {
            key: key.into(),
            value: value.map(String::from),
            expected,
        }
    }
}

/// A number given on a live `set` (`KEY VALUE`): the value, or a one-line error naming the key.
pub fn live_number(key: &str, v: Option<&str>) -> Result<f64, LiveError> {
    let v = v.ok_or_else(|| LiveError::Missing { key: key.into() })?;
    let x: f64 = v.parse().map_err(|_| LiveError::NotANumber {
        key: key.into(),
        value: v.into(),
    })?;
    if !x.is_finite() {
        return Err(LiveError::NotFinite {
            key: key.into(),
            value: v.into(),
        });
    }
    Ok(x)
}

/// The error for a field whose value is not what it should be (the value cut to an excerpt).
pub fn invalid(field: &str, value: impl std::fmt::Debug, expected: &str) -> ConfigError {
    ConfigError::Invalid {
        field: field.to_string(),
        value: excerpt(&format!("{value:?}")),
        expected: expected.to_string(),
    }
}

/// A finite number in [lo, hi], or the refusal naming `field`.
pub fn range(field: &str, v: f64, lo: f64, hi: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(invalid(
            field,
            v,
            &format!("must be a finite number in [{lo}, {hi}]"),
        ))
    }
}
