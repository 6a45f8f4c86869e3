//! Secondary tasks written by users. The built-in tasks (manipulability, centring, obstacles)
//! cover the paper; a real cell needs its own: stay near a ready posture, keep the elbow up, look
//! away from a camera. A program registers its tasks by name once, before any config is read;
//! a config then names one in `law.secondary` like a built-in, and the law calls it on every
//! tick. The registry is frozen at registration, so the loop reads it with one atomic load: no
//! lock, and the task itself must not allocate (it writes η into a buffer the law owns).
//!
//! ```
//! use control::secondary::custom::{self, NullTask, NullTaskInput};
//!
//! /// η = −k (q − q_ref): pulls the self-motion towards a preferred posture.
//! struct Posture { q_ref: [f64; 7], k: f64 }
//!
//! impl NullTask for Posture {
//!     fn eta(&self, x: &NullTaskInput, eta: &mut [f64]) -> f64 {
//!         let mut cost = 0.0;
//!         for i in 0..x.q.len() {
//!             let e = x.q[i] - self.q_ref[i];
//!             eta[i] = -self.k * e;
//!             cost += 0.5 * self.k * e * e;
//!         }
//!         cost
//!     }
//! }
//!
//! static READY: Posture = Posture { q_ref: [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785], k: 1.0 };
//! custom::register(&[("ready-posture", &READY)]).unwrap();
//! assert!(custom::lookup("ready-posture").is_some());
//! ```

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::OnceLock;

/// What a task sees on each tick; every slice has one entry per joint unless said otherwise.
pub struct NullTaskInput<'a> {
    /// Controller time (s).
    pub t: f64,
    pub q: &'a [f64],
    pub qd: &'a [f64],
    /// The tool point (m) in the base frame.
    pub tip: [f64; 3],
    /// The tool point's Jacobian, 6 × n, column-major: rows 0-2 linear, 3-5 angular.
    pub jacobian: &'a [f64],
    /// The configured joint limits (rad).
    pub q_min: &'a [f64],
    pub q_max: &'a [f64],
}

/// A secondary task: the law adds α(I − J⁺J)η, so η moves the posture without disturbing the
/// hand. `Sync` because the loop runs on its own thread; it is called once per tick.
pub trait NullTask: Sync {
    /// Writes η (one entry per joint, `eta` arrives zeroed) and returns the task's value, which
    /// the daemon reports as the secondary value (a cost or a measure, as the task defines it).
    fn eta(&self, input: &NullTaskInput, eta: &mut [f64]) -> f64;
}

/// A registered task: its name in `law.secondary`, and the code.
pub type Entry = (&'static str, &'static dyn NullTask);

static REGISTRY: OnceLock<Vec<Entry>> = OnceLock::new();

/// Set by programs that read configs but never evaluate the law (the plant, a bridge).
static OUTSIDE: AtomicBool = AtomicBool::new(false);

/// The index an unregistered name gets in a program [`outside_the_controller`]: η = 0.
const ELSEWHERE: u8 = u8::MAX;

/// The most tasks one program registers (the index travels in a `u8`).
pub const MAX_TASKS: usize = 64;

/// Why a registration was refused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RegisterError {
    /// Tasks were registered already: the registry is frozen after its first use.
    AlreadyRegistered,
    /// Two tasks of one name, or a built-in's name.
    BadName(String),
    TooMany(usize),
}

impl std::fmt::Display for RegisterError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::AlreadyRegistered => {
                write!(
                    f,
                    "custom secondary tasks are registered once, before any config is read"
                )
            }
            Self::BadName(n) => write!(
                f,
                "custom secondary task {n:?}: empty, a built-in's name or registered twice"
            ),
            Self::TooMany(n) => write!(f, "{n} custom secondary tasks: at most {MAX_TASKS}"),
        }
    }
}

impl std::error::Error for RegisterError {}

/// The built-in tasks' names, which a custom task may not take.
pub const BUILT_IN: [&str; 4] = ["none", "manipulability", "centring", "obstacles"];

/// Registers this program's tasks, once. Call it at the start of `main`, before any config is
/// read (a config naming a task that is not registered is refused).
pub fn register(tasks: &[Entry]) -> Result<(), RegisterError> {
    if tasks.len() > MAX_TASKS {
        return Err(RegisterError::TooMany(tasks.len()));
    }
    for (i, (name, _)) in tasks.iter().enumerate() {
        let taken = BUILT_IN.contains(name) || tasks[..i].iter().any(|(n, _)| n == name);
        if name.is_empty() || taken {
            return Err(RegisterError::BadName(name.to_string()));
        }
    }
    REGISTRY
        .set(tasks.to_vec())
        .map_err(|_| RegisterError::AlreadyRegistered)
}

fn registry() -> &'static [Entry] {
    REGISTRY.get().map_or(&[], |v| v.as_slice())
}

/// Says that this program reads configs but never evaluates the law (a plant, a bridge): a
/// `law.secondary` it has no task for is then accepted, for the controller's program to check.
pub fn outside_the_controller() {
    OUTSIDE.store(true, Ordering::Relaxed);
}

/// The index of the task registered under `name` (in a program outside the controller, any
/// name that could be a task's).
pub fn lookup(name: &str) -> Option<u8> {
    let found = registry().iter().position(|(n, _)| *n == name);
    match found {
        Some(i) => Some(i as u8),
        None if OUTSIDE.load(Ordering::Relaxed) && !name.is_empty() => Some(ELSEWHERE),
        None => None,
    }
}

/// The registered names, for an error message.
pub fn names() -> Vec<&'static str> {
    registry().iter().map(|(n, _)| *n).collect()
}

/// Runs task `index`: its value, η written into `eta`. An index with no task (impossible once a
/// config was accepted) leaves η zero.
pub fn call(index: u8, input: &NullTaskInput, eta: &mut [f64]) -> f64 {
    match registry().get(index as usize) {
        Some((_, task)) => task.eta(input, eta),
        None => 0.0,
    }
}
