//! The cycle planner's time on each arm's layouts (issue 25's targets: ≤ 50 ms on the planar
//! arm, ≤ 1 s on the Panda), through the one entry the daemon and `chaosctl simulate` plan by
//! (`control::plan::plan_arm`): the whole plan, each layout planned in turn, round after round,
//! so a noisy moment hits them alike. What differs between the arms is their layouts and how
//! the arm got to the moment of the edit ([`Arm::job`]); the timing and the table are one.

use anyhow::Result;
use control::config::spatial::SphereEntry;
use control::config::{Config, ObstacleConfig};
use control::plan::{plan_arm, PlanOutcome, Planned};
use control::steer::Steering;
use control::System;
use std::time::Instant;

/// Obstacles as (x, y, z, radius), m; the planar arm's discs lie in z = 0.
type Balls = &'static [[f64; 4]];

/// A layout: a label, the obstacles, and the moment of the edit (s). At 0 the plan starts from
/// the start's posture; later, the arm has run until then and the plan starts from where it is.
type Layout = (&'static str, Balls, f64);

/// One arm's part of the section.
pub struct Arm {
    title: &'static str,
    /// What the plan does on this arm and its target, for the paragraph above the table.
    what: &'static str,
    rounds: [usize; 2],
    layouts: &'static [Layout],
    /// The set-up with the layout's obstacles at its moment of the edit.
    job: fn(Balls, f64) -> Result<Job>,
}

/// A planning job: the set-up, the task time, the posture then and the cycle followed then.
pub struct Job {
    system: System,
    t0: f64,
    q: Vec<f64>,
    following: Option<Steering>,
}

pub const PLANAR: Arm = Arm {
    title: "planar arm",
    what: "(target ≤ 50 ms): the grid search over phases and postures, the refinement against \
           the filter, and a detour when the arm cannot reach the cycle with its hand on the \
           path; a layout added at 5 s plans from the posture the obstacle-free run has then",
    rounds: [3, 11],
    layouts: &[
        ("no obstacle", &[], 0.0),
        (
            "the filter's trap (0.9, 1.1) r 0.15",
            &[[0.9, 1.1, 0.0, 0.15]],
            0.0,
        ),
        (
            "the paper's obstacle (0, 1.6) r 0.25",
            &[[0.0, 1.6, 0.0, 0.25]],
            0.0,
        ),
        (
            "one on the path (1.5, 2.0) r 0.2",
            &[[1.5, 2.0, 0.0, 0.2]],
            0.0,
        ),
        (
            "the trap added at 5 s (a detour)",
            &[[0.9, 1.1, 0.0, 0.15]],
            5.0,
        ),
        (
            "two discs (−0.033, 1.838) r 0.237, (0.506, 2.727) r 0.136",
            &[[-0.033, 1.838, 0.0, 0.237], [0.506, 2.727, 0.0, 0.136]],
            0.0,
        ),
        (
            "two discs (1.624, 2.319) r 0.082, (0.136, 0.989) r 0.083: the filter brakes the cycle",
            &[[1.624, 2.319, 0.0, 0.082], [0.136, 0.989, 0.0, 0.083]],
            0.0,
        ),
    ],
    job: planar_job,
};

pub const PANDA: Arm = Arm {
    title: "Panda",
    what: "on its study set-up (target ≤ 1 s): from the arm's posture (at 6.1 s: from the \
           cycle it follows then) and the starts spread over the joint box, each strict, then \
           within the physical limits",
    rounds: [3, 7],
    layouts: &[
        ("no sphere", &[], 0.0),
        (
            "between arm and circle (0.089, −0.196, 0.575) r 0.058",
            &[[0.089, -0.196, 0.575, 0.058]],
            0.0,
        ),
        (
            "two: (0.145, −0.233, 0.675) r 0.072, (0.385, −0.315, 0.452) r 0.083",
            &[[0.145, -0.233, 0.675, 0.072], [0.385, -0.315, 0.452, 0.083]],
            0.0,
        ),
        (
            "beside the path (0.15, −0.15, 0.45) r 0.08: the filter brakes the hand",
            &[[0.15, -0.15, 0.45, 0.08]],
            0.0,
        ),
        (
            "one on the path (0.307, 0, 0.487) r 0.05",
            &[[0.307, 0.0, 0.487, 0.05]],
            0.0,
        ),
        (
            "between arm and circle, added at 6.1 s",
            &[[0.089, -0.196, 0.575, 0.058]],
            6.1,
        ),
    ],
    job: panda_job,
};

/// The default planar set-up, obstacle-free until `at`, then with the discs.
fn planar_job(discs: Balls, at: f64) -> Result<Job> {
    let mut cfg = Config::default();
    let (t0, q) = control::plan::posture_at(&cfg, at);
    cfg.planar_mut().expect("the planar arm").obstacles = discs
        .iter()
        .map(|b| ObstacleConfig::disc(b[0], b[1], b[3]))
        .collect();
    Ok(Job {
        system: System::Planar(cfg),
        t0,
        q: q.to_vec(),
        following: None,
    })
}

/// The Panda's study set-up with planning on, following its start's steered cycle until `at`,
/// then with the spheres.
fn panda_job(spheres: Balls, at: f64) -> Result<Job> {
    let resolve = &control::system::builtin_robot;
    let mut cfg = Config::robot_preset("panda").expect("the panda preset");
    cfg.safety.plan = control::safety::policy::PlanMode::On;
    let chain = resolve("panda", None, None)?;
    let (start, _) = control::plan::setup_planned::<7>(&cfg, &chain)?;
    let mut sim = control::sim::Simulation::spatial(
        start.arm,
        start.params,
        start.dt,
        start.q0,
        start.qd0,
        start.params.core.tau,
    );
    while sim.time() < at {
        sim.step();
    }
    cfg.spatial_mut().expect("a robot").obstacles =
        spheres.iter().copied().map(SphereEntry::of).collect();
    let following = start.params.steer.filter(|_| at > 0.0);
    Ok(Job {
        system: System::spatial(cfg, resolve)?,
        t0: sim.time(),
        q: sim.state().q.as_slice().to_vec(),
        following: following.map(Steering::Spatial),
    })
}

/// The table of `arm`'s layouts.
pub fn section(arm: &Arm, quick: bool) -> Result<String> {
    let rounds = arm.rounds[usize::from(!quick)];
    let n = arm.layouts.len();
    let jobs: Vec<Job> = arm
        .layouts
        .iter()
        .map(|(_, balls, at)| (arm.job)(balls, *at))
        .collect::<Result<_>>()?;
    let mut times = vec![Vec::new(); n];
    let mut planned: Vec<Option<Planned>> = vec![None; n];
    for order in crate::plan::interleave(&(0..n).collect::<Vec<_>>(), rounds) {
        for i in order {
            let j = &jobs[i];
            let t = Instant::now();
            let p = plan_arm(&j.system, j.t0, Some(&j.q), j.following.as_ref())
                .map_err(|e| anyhow::anyhow!(e))?;
            times[i].push(t.elapsed().as_secs_f64() * 1e3);
            planned[i] = Some(p);
        }
    }
    let mut text = format!(
        "\n### Planning a clean cycle ({})\n\n`control::plan::plan_arm` on {} phases, {rounds} \
         rounds, interleaved: the whole plan the daemon makes {}:\n\n\
         | layout | outcome | smallest clearance | filter margin | fastest joint | median | max |\n\
         |---|---|---|---|---|---|---|\n",
        arm.title,
        control::plan::PlanSettings::default().phases,
        arm.what
    );
    for (i, (label, _, _)) in arm.layouts.iter().enumerate() {
        let (median, max) = median_max(&times[i]);
        text.push_str(&format!(
            "| {label} | {} | {median:.1} ms | {max:.1} ms |\n",
            outcome_cells(planned[i].as_ref())
        ));
    }
    Ok(text)
}

/// The outcome, smallest clearance, filter margin and fastest joint of a plan.
fn outcome_cells(p: Option<&Planned>) -> String {
    let Some(Planned {
        outcome: PlanOutcome::Found(c),
        limits_only,
    }) = p
    else {
        return "blocked | – | – | –".into();
    };
    let found = match (c.detour.is_some(), limits_only) {
        (true, _) => "cycle, by a detour",
        (false, true) => "cycle (limits only)",
        (false, false) => "cycle",
    };
    let clearance = if c.min_clearance.is_finite() {
        format!("{:.3} m", c.min_clearance)
    } else {
        "–".into()
    };
    let margin = if c.filter_margin.is_finite() {
        format!("{:.1}", c.filter_margin)
    } else {
        "–".into()
    };
    format!("{found} | {clearance} | {margin} | {:.2} rad/s", c.max_rate)
}

fn median_max(t: &[f64]) -> (f64, f64) {
    let mut t = t.to_vec();
    t.sort_by(f64::total_cmp);
    (t[t.len() / 2], t[t.len() - 1])
}
