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

mod arm;
pub mod detour;
pub mod planar;
pub mod refine;
mod setup;
pub mod spatial;
pub mod trap;

use crate::steer::{Blocked, Cycle, CycleTable, SteerError};

/// A set-up the planner cannot plan for, or a cycle the loop cannot hold.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PlanError {
    #[error(
        "the planner handles the fixed-base 3-link arm (this one has {links} links, {base:?} base)"
    )]
    PlanarArm {
        links: usize,
        base: crate::config::ModelKind,
    },
    #[error("the planner handles 2 to 12 joints (this arm has {0})")]
    Joints(usize),
    #[error(transparent)]
    Config(#[from] crate::basics::ConfigError),
    #[error(transparent)]
    Steer(#[from] SteerError),
}
pub use arm::{has_planner, plan_arm, plan_arm_with, plan_asked, planned_law, steering_of};
pub use setup::{law_params_planned, setup_planned};

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
    /// safety filter's barrier (s² + k1·s + k0, a double root at −20/s by default) brakes a
    /// faster approach, and a cycle that approaches faster is braked off its path. Judged on
    /// each posture's nearest obstacle, between consecutive phases.
    pub approach: f64,
    /// The share of each joint's rate limit a spatial cycle may use (the planar grid has its
    /// own bound, `max_rate`): the rest is the filter's room to act without braking the cycle.
    pub rate_share: f64,
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
            rate_share: 1.0,
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
            rate_share: 0.6,
        }
    }
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
}

/// Plans for a planar config from task time `t0` near posture `q_now`: with the default
/// settings first, then with the physical limits alone, so that `Blocked` means what it says
/// (no clean cycle within the filter's own limits) and not that a margin was too greedy. A
/// cycle counts only if, refined, the filter has nothing to do on it: one it would brake takes
/// the arm off its path each time round, which is a trap, so it is `Blocked` with the row that
/// brakes it.
pub fn plan_config(
    cfg: &crate::config::Config,
    t0: f64,
    q_now: Option<[f64; 3]>,
) -> Result<Planned, PlanError> {
    plan_config_with(cfg, t0, q_now, &PlanSettings::default())
}

/// [`plan_config`] with settings of one's own for the first try (`chaosctl plan --margin`).
pub fn plan_config_with(
    cfg: &crate::config::Config,
    t0: f64,
    q_now: Option<[f64; 3]>,
    settings: &PlanSettings,
) -> Result<Planned, PlanError> {
    // The cycle is one of the periodic loop: the path's start-up ramp is not part of it.
    let periodic;
    let cfg = if cfg.planar().is_some_and(|p| p.task.ramp > 0.0) {
        let mut c = cfg.clone();
        *c.task_ramp_mut() = 0.0;
        periodic = c;
        &periodic
    } else {
        cfg
    };
    let problem = planar::PlanarProblem::from_config(cfg, t0, q_now)?;
    let mut strict = refined(&problem, cfg, planar::plan(&problem, settings));
    // A cycle the refinement could not clear of the filter: a finer grid gives another.
    if let Err(Braked(_)) = strict {
        let finer = PlanSettings {
            angles: 180,
            ..*settings
        };
        if let Ok(c) = refined(&problem, cfg, planar::plan(&problem, &finer)) {
            strict = Ok(c);
        }
    }
    let (outcome, limits_only) = match strict {
        Ok(c) => (PlanOutcome::Found(c), false),
        Err(why) => {
            let rate = problem.qd_max.into_iter().fold(f64::INFINITY, f64::min);
            let loose = planar::plan(&problem, &PlanSettings::limits_only(rate));
            let outcome = match (refined(&problem, cfg, loose), why) {
                (Ok(c), _) => PlanOutcome::Found(c),
                // The strict plan's braking says more than the loose plan's.
                (Err(_), b @ Braked(_)) => PlanOutcome::Blocked(b.into_blocked()),
                // No cycle even within the physical limits says it all.
                (Err(Unusable::NoCycle(b)), _) => PlanOutcome::Blocked(b),
                // The settings' own bound failed first, then the filter's braking.
                (Err(Braked(loose)), Unusable::NoCycle(strict)) => {
                    PlanOutcome::Blocked(both(strict, loose))
                }
            };
            (outcome, true)
        }
    };
    let outcome = match outcome {
        PlanOutcome::Found(c) => with_detour(&problem, c),
        b => b,
    };
    Ok(Planned {
        outcome,
        limits_only,
    })
}

/// A cycle the arm cannot reach with its hand on the path gets a joint-space detour, or, when
/// there is none, becomes `Blocked` with both reasons.
fn with_detour(problem: &planar::PlanarProblem, mut c: Cycle) -> PlanOutcome {
    let (Some(why), Some(q_now)) = (c.unreachable.clone(), problem.q_now) else {
        return PlanOutcome::Found(c);
    };
    let way = CycleTable::new(&c)
        .map_err(detour::DetourError::from)
        .and_then(|t| detour::plan(problem, &t, q_now, problem.t0));
    match way {
        Ok(d) => {
            c.detour = Some(Box::new(d));
            PlanOutcome::Found(c)
        }
        Err(e) => PlanOutcome::Blocked(Blocked {
            reason: format!("{}, and {e}", why.reason),
            ..why
        }),
    }
}

/// Why neither plan gave a usable cycle: the first try's settings (the user's own bounds, which
/// failed first), and then the filter, which would brake the cycle the physical limits alone
/// allow. The obstacle, link and clearance are the braking's.
fn both(strict: Blocked, loose: Blocked) -> Blocked {
    Blocked {
        reason: format!(
            "{}; within the physical limits alone: {}",
            strict.reason, loose.reason
        ),
        ..loose
    }
}

/// Why a plan gave no usable cycle: none on the grid, or one the filter would brake.
enum Unusable {
    NoCycle(Blocked),
    Braked(Blocked),
}
use Unusable::Braked;

impl Unusable {
    fn into_blocked(self) -> Blocked {
        match self {
            Unusable::NoCycle(b) | Unusable::Braked(b) => b,
        }
    }
}

/// Where the config's arm is at task time `at` (s), simulated from its start without steering:
/// the posture a planner asked at that moment starts from. Returns the step's time and the
/// posture.
///
/// # Panics
/// On a robot's config: the planar arm's only, as [`crate::config::Config::n`] is.
pub fn posture_at(cfg: &crate::config::Config, at: f64) -> (f64, [f64; 3]) {
    let mut sim = crate::sim::Simulation::new(
        cfg.model::<3>(),
        cfg.law_params(),
        cfg.sim.dt,
        cfg.initial_state::<3>(),
        cfg.feedback.capacity(),
    );
    while sim.time() < at {
        sim.step();
    }
    let q = sim.state().q;
    (sim.time(), [q[0], q[1], q[2]])
}

/// A found cycle refined against the config's own filter; usable only if the filter has
/// nothing to do on it.
fn refined(
    problem: &planar::PlanarProblem,
    cfg: &crate::config::Config,
    o: PlanOutcome,
) -> Result<Cycle, Unusable> {
    match o {
        PlanOutcome::Found(c) => {
            let safety = cfg.law_params().core.safety;
            let r = refine::refine(problem, &safety, &c, &refine::RefineSettings::default());
            if r.worst.value >= 0.0 {
                Ok(r.cycle)
            } else {
                Err(Braked(braked(problem, &r, &safety)))
            }
        }
        PlanOutcome::Blocked(b) => Err(Unusable::NoCycle(b)),
    }
}

/// Why a refined cycle is no way out: the filter's row that brakes it, in words.
fn braked(
    problem: &planar::PlanarProblem,
    r: &refine::Refined,
    safety: &crate::safety::SafetyParams,
) -> Blocked {
    let w = r.worst;
    let at = w.obstacle_link(problem.obstacles.len());
    let what = match at {
        Some((o, l)) => format!(
            "link {} closes in on obstacle {} faster than the filter's barrier (k0 = {}, k1 = \
             {}) lets it",
            l + 1,
            o + 1,
            safety.k0,
            safety.k1
        ),
        None => "a joint's rate or acceleration limit binds".into(),
    };
    Blocked {
        reason: format!(
            "a cycle round the obstacles exists, but the safety filter would brake it off the \
             path: at task time {:.3} s {what} (short by {:.1}); a faster barrier (safety.k0, \
             safety.k1), a slower task or another obstacle layout would let it through",
            w.t, -w.value
        ),
        best_clearance: r.cycle.min_clearance,
        obstacle: at.map(|a| a.0),
        link: at.map(|a| a.1),
        task_time: w.t,
    }
}

impl planar::PlanarProblem {
    /// The problem a planar config poses: its arm, circle, obstacles, the filter's clearance
    /// and joint limits, starting at task time `t0` near posture `q_now`. Only the fixed-base
    /// 3-link arm has its self-motion on a circle the planner grids; other arms are refused.
    pub fn from_config(
        cfg: &crate::config::Config,
        t0: f64,
        q_now: Option<[f64; 3]>,
    ) -> Result<Self, PlanError> {
        let Some(planar) = cfg.planar() else {
            return Err(PlanError::Config(crate::basics::ConfigError::Spatial(
                "the config given to the planar planner".into(),
            )));
        };
        let arm = &planar.arm;
        if cfg.n() != 3 || arm.model != crate::config::ModelKind::Fixed {
            return Err(PlanError::PlanarArm {
                links: cfg.n(),
                base: arm.model,
            });
        }
        let p = cfg.law_params();
        Ok(Self {
            links: [arm.links[0], arm.links[1], arm.links[2]],
            task: p.task,
            obstacles: p.obstacles,
            clearance: p.core.safety.clearance,
            q_min: [
                p.core.safety.q_min[0],
                p.core.safety.q_min[1],
                p.core.safety.q_min[2],
            ],
            q_max: [
                p.core.safety.q_max[0],
                p.core.safety.q_max[1],
                p.core.safety.q_max[2],
            ],
            qd_max: [
                p.core.safety.qd_max[0],
                p.core.safety.qd_max[1],
                p.core.safety.qd_max[2],
            ],
            t0,
            q_now,
        })
    }
}
