//! Planning a clean periodic posture cycle, so safety never traps the arm silently.
//!
//! The safety filter is local: it keeps every link clear now, but cannot know that the
//! self-motion should have gone round an obstacle the other way, and it can hold the arm off
//! its path for good. A redundant arm has room to go round while its hand keeps tracking; the
//! planner looks for that room over the whole period at once: a posture cycle q*(t), t ∈ [0, T),
//! that puts the hand on the path, keeps every clearance and joint limit with a margin and moves
//! the joints at bounded rates. When there is none it says why, so the daemon can say `Blocked`
//! instead of running on with the arm at rest off its path.
//!
//! The planner allocates and takes milliseconds: it runs off the loop, and hands its cycle over
//! whole.

pub mod planar;
mod policy;

pub use policy::{check_trap_time, WhenBlocked, DEFAULT_TRAP_TIME};

/// How finely the planner searches, and with what margins.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanSettings {
    /// Phases over one period.
    pub phases: usize,
    /// Values of the self-motion coordinate (per elbow branch, over a full turn).
    pub angles: usize,
    /// Clearance kept beyond the safety filter's (m).
    pub margin: f64,
    /// Distance kept from every joint limit (rad).
    pub joint_margin: f64,
    /// The fastest any joint of the cycle may move (rad/s), the task's own motion included.
    pub max_rate: f64,
    /// Closing starts tried for the cheapest cycle (the nearest the arm's posture first).
    pub candidates: usize,
    /// How fast the arm may close in on an obstacle, per metre of clearance left (1/s): the
    /// safety filter's barrier (s² + k1·s + k0, a double root at −10/s by default) brakes a
    /// faster approach, and a cycle that approaches faster is braked off its path. Judged on
    /// each posture's nearest obstacle, between consecutive phases.
    pub approach: f64,
}

impl PlanSettings {
    /// The physical limits alone: the filter's clearance and joint limits without extra
    /// margin, the safety rate limit, no approach bound. When no cycle exists under these,
    /// none exists at all (on the grid): the arm is blocked, whatever the steering's settings.
    pub fn limits_only(max_rate: f64) -> Self {
        Self {
            margin: 0.0,
            joint_margin: 0.0,
            max_rate,
            approach: f64::INFINITY,
            ..Self::default()
        }
    }
}

impl Default for PlanSettings {
    fn default() -> Self {
        Self {
            phases: 64,
            angles: 120,
            margin: 0.02,
            joint_margin: 0.05,
            max_rate: 8.0,
            candidates: 6,
            approach: 10.0,
        }
    }
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
}

/// The most phases a cycle handed to the loop may have.
pub const MAX_PHASES: usize = 64;

/// A planar cycle in a fixed-size, `Copy` table: what the control law steers towards. Built
/// off the loop from a [`Cycle`]; read on the loop without allocating.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CycleTable {
    pub t0: f64,
    pub period: f64,
    n: usize,
    q: [[f64; 3]; MAX_PHASES],
}

impl CycleTable {
    /// The table of a 3-joint cycle of at most [`MAX_PHASES`] phases.
    pub fn new(c: &Cycle) -> Result<Self, String> {
        if c.q.is_empty() || c.q.len() > MAX_PHASES || c.q.iter().any(|q| q.len() != 3) {
            return Err(format!(
                "a cycle of 1 to {MAX_PHASES} phases of 3 joints (this one has {} phases)",
                c.q.len()
            ));
        }
        let rows: Vec<[f64; 3]> = c.q.iter().map(|p| [p[0], p[1], p[2]]).collect();
        Self::from_rows(c.t0, c.period, &rows)
    }

    /// The table of `rows` postures (as [`Self::rows`] gives them back: a recording's copy).
    pub fn from_rows(t0: f64, period: f64, rows: &[[f64; 3]]) -> Result<Self, String> {
        if rows.is_empty() || rows.len() > MAX_PHASES {
            return Err(format!(
                "a cycle of 1 to {MAX_PHASES} phases (this one has {})",
                rows.len()
            ));
        }
        let mut q = [[0.0; 3]; MAX_PHASES];
        q[..rows.len()].copy_from_slice(rows);
        Ok(Self {
            t0,
            period,
            n: rows.len(),
            q,
        })
    }

    /// The postures, one per phase.
    pub fn rows(&self) -> &[[f64; 3]] {
        &self.q[..self.n]
    }

    /// The planned posture and rate at task time `t` (linear between phases, periodic).
    #[inline]
    pub fn at(&self, t: f64) -> ([f64; 3], [f64; 3]) {
        let dt = self.period / self.n as f64;
        let x = (t - self.t0).rem_euclid(self.period) / dt;
        let k = (x.floor() as usize).min(self.n - 1);
        let f = x - k as f64;
        let (a, b) = (self.q[k], self.q[(k + 1) % self.n]);
        let mut q = [0.0; 3];
        let mut qd = [0.0; 3];
        for i in 0..3 {
            let d = crate::analysis::closed_loop::wrap_angle(b[i] - a[i]);
            q[i] = a[i] + d * f;
            qd[i] = d / dt;
        }
        (q, qd)
    }
}

/// Steering onto a planned cycle: a joint PD towards it, projected onto the self-motion, so
/// tracking is untouched; the Pyragas term then holds the cycle (its period is τ).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Steer {
    pub cycle: CycleTable,
    /// Gains of the pull (1/s², 1/s).
    pub kp: f64,
    pub kd: f64,
}

impl Steer {
    /// A pull with natural frequency `hz`, critically damped.
    pub fn new(cycle: CycleTable, hz: f64) -> Self {
        let w = std::f64::consts::TAU * hz;
        Self {
            cycle,
            kp: w * w,
            kd: 2.0 * w,
        }
    }
}

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

/// What the planner found.
#[derive(Clone, Debug, PartialEq)]
pub enum PlanOutcome {
    Found(Cycle),
    Blocked(Blocked),
}

/// A config's plan: the cycle to steer onto, or why there is none, and the planning time.
#[derive(Clone, Debug, PartialEq)]
pub struct Planned {
    pub outcome: PlanOutcome,
    /// Whether only the physical limits admit the cycle ([`PlanSettings::limits_only`]): the
    /// default settings' margins and approach bound found none.
    pub limits_only: bool,
    pub took: std::time::Duration,
}

/// Plans for a planar config from task time `t0` near posture `q_now`: with the default
/// settings first, then with the physical limits alone, so that `Blocked` means what it says
/// (no clean cycle within the filter's own limits) and not that a margin was too greedy.
pub fn plan_config(
    cfg: &crate::Config,
    t0: f64,
    q_now: Option<[f64; 3]>,
) -> Result<Planned, String> {
    let started = std::time::Instant::now();
    let problem = planar::PlanarProblem::from_config(cfg, t0, q_now)?;
    let strict = planar::plan(&problem, &PlanSettings::default());
    let (outcome, limits_only) = match strict {
        PlanOutcome::Found(c) => (PlanOutcome::Found(c), false),
        PlanOutcome::Blocked(_) => {
            let rate = problem.qd_max.into_iter().fold(f64::INFINITY, f64::min);
            (
                planar::plan(&problem, &PlanSettings::limits_only(rate)),
                true,
            )
        }
    };
    Ok(Planned {
        outcome,
        limits_only,
        took: started.elapsed(),
    })
}

impl planar::PlanarProblem {
    /// The problem a planar config poses: its arm, circle, obstacles, the filter's clearance
    /// and joint limits, starting at task time `t0` near posture `q_now`. Only the fixed-base
    /// 3-link arm has its self-motion on a circle the planner grids; other arms are refused.
    pub fn from_config(
        cfg: &crate::Config,
        t0: f64,
        q_now: Option<[f64; 3]>,
    ) -> Result<Self, String> {
        if cfg.n() != 3 || cfg.arm.model != crate::config::ModelKind::Fixed {
            return Err(format!(
                "the planner handles the fixed-base 3-link arm (this one has {} links, {:?} base)",
                cfg.n(),
                cfg.arm.model
            ));
        }
        let p = cfg.law_params();
        Ok(Self {
            links: [cfg.arm.links[0], cfg.arm.links[1], cfg.arm.links[2]],
            task: p.task,
            obstacles: p.obstacles,
            clearance: p.safety.clearance,
            q_min: [p.safety.q_min[0], p.safety.q_min[1], p.safety.q_min[2]],
            q_max: [p.safety.q_max[0], p.safety.q_max[1], p.safety.q_max[2]],
            qd_max: [p.safety.qd_max[0], p.safety.qd_max[1], p.safety.qd_max[2]],
            t0,
            q_now,
        })
    }
}
