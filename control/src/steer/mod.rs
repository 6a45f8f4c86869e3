//! Planned cycles as the law reads them: the cycle, the steering onto it and its detour.
//!
//! The planner ([`crate::plan`]) finds a clean cycle; the law ([`crate::law`]) pulls the
//! self-motion onto it every tick. What passes between them is plain data, `Copy` where the
//! loop holds it, so it sits below the law and the planner both and ties neither to the other.

pub mod detour;
mod error;
pub mod spatial;
pub mod table;

pub use detour::DetourTable;
pub use error::SteerError;
pub use spatial::SpatialSteer;
pub use table::{CycleTable, Sample, MAX_PHASES};

/// Why no clean cycle exists, in words and numbers.
#[derive(Clone, Debug, PartialEq)]
pub struct Blocked {
    pub reason: String,
    /// The largest clearance any posture reaches at the hardest phase (m; negative: contact).
    pub best_clearance: f64,
    /// The obstacle and the link (0-based) that set it, if an obstacle did.
    pub obstacle: Option<usize>,
    pub link: Option<usize>,
    /// The task time of the hardest phase (s).
    pub task_time: f64,
}

/// A planned cycle: the posture at `phases` evenly spaced task times from `t0`, joint angles
/// continuous along the cycle (it closes up to whole turns of no joint).
#[derive(Clone, Debug, PartialEq)]
pub struct Cycle {
    /// The task time of the first posture (s).
    pub t0: f64,
    pub period: f64,
    pub q: Vec<Vec<f64>>,
    /// The smallest distance from any link to any obstacle's surface along the cycle (m).
    pub min_clearance: f64,
    /// The fastest joint rate along the cycle (rad/s).
    pub max_rate: f64,
    /// How far the safety filter's rows stay above their bounds along the cycle, as the loop's
    /// spline runs it ([`crate::plan::refine`]; m/s² for an obstacle): negative, the filter will brake the
    /// cycle there and the arm leaves its path for a moment. +∞ until refined.
    pub filter_margin: f64,
    /// Why the arm cannot reach this cycle with its hand on the path, if it cannot (None: it
    /// can, or its posture was not given).
    pub unreachable: Option<Blocked>,
    /// The arm's posture was off the planner's grid (its hand off the path, or a link inside a
    /// margin): a start's transient, not an obstacle in the way.
    pub arm_off_path: bool,
    /// The joint-space way onto the cycle for an arm that cannot reach it tracking
    /// ([`crate::plan::detour`]; set by [`crate::plan::plan_config`]).
    pub detour: Option<Box<DetourTable>>,
}

impl Cycle {
    /// A cycle through `q` (one posture per phase from task time `t0`) that no planner
    /// checked: no obstacle clearance, margin, detour or reachability to report.
    ///
    /// ```
    /// let c = control::steer::Cycle::through(0.0, 2.0, vec![vec![0.1; 7]; 8]);
    /// assert!(c.detour.is_none() && c.min_clearance.is_infinite());
    /// ```
    pub fn through(t0: f64, period: f64, q: Vec<Vec<f64>>) -> Self {
        Self {
            t0,
            period,
            q,
            min_clearance: f64::INFINITY,
            max_rate: 0.0,
            filter_margin: f64::INFINITY,
            unreachable: None,
            arm_off_path: false,
            detour: None,
        }
    }
}

/// Steering onto a planned cycle: a joint PD towards it, projected onto the self-motion, so
/// tracking is untouched; the Pyragas term then holds the cycle (its period is τ).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Steer {
    pub cycle: CycleTable,
    /// A joint-space detour onto the cycle first, tracking paused while it runs.
    pub detour: Option<DetourTable>,
    /// Gains of the pull (1/s², 1/s).
    pub kp: f64,
    pub kd: f64,
}

/// A planned cycle to steer onto, for the arm the law drives: what the planner thread hands
/// the loop.
// Not boxed: it crosses to the loop by value, and the loop frees nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Steering {
    Planar(Steer),
    Spatial(SpatialSteer),
}

/// The natural frequency (Hz) of the joint-space pull along a detour, critically damped.
pub const DETOUR_HZ: f64 = 4.0;

impl Steer {
    /// A pull with natural frequency `hz`, critically damped.
    pub fn new(cycle: CycleTable, hz: f64) -> Self {
        let w = std::f64::consts::TAU * hz;
        Self {
            cycle,
            detour: None,
            kp: w * w,
            kd: 2.0 * w,
        }
    }

    /// The steering onto planned cycle `c`, with its detour if it has one.
    pub fn of(c: &Cycle, hz: f64) -> Result<Self, SteerError> {
        Ok(Self {
            detour: c.detour.as_deref().copied(),
            ..Self::new(CycleTable::new(c)?, hz)
        })
    }
}
