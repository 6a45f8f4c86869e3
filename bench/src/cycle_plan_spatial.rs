//! The spatial planner's time on the Panda (issue 25's target: ≤ 1 s), each layout planned in
//! turn, round after round, so a noisy moment hits them alike: the whole plan the daemon makes
//! (the path's check, the relaxations from each start, the steered law's run for a period).

use anyhow::Result;
use control::config::spatial::SpatialConfig;
use control::config::spatial::SphereEntry;
use control::model::{builtin, Chain};
use control::plan::spatial::plan_setup;
use control::plan::{PlanOutcome, PlanSettings};
use control::sim::spatial::SpatialSimulation;
use control::steer::SpatialSteer;
use std::time::Instant;

/// Spheres as (x, y, z, radius), m.
type Spheres = &'static [[f64; 4]];

/// The layouts: a label, the spheres, and the moment of the edit (s): 0 plans the start from
/// its posture; later, the arm has followed the start's steered cycle until then, and the plan
/// starts from that cycle, as the daemon's does after an edit.
const LAYOUTS: [(&str, Spheres, f64); 6] = [
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
];

/// A planning job: the set-up with the spheres, the task time, the posture and the cycle
/// followed then.
type Job = (
    control::config::spatial::SpatialSetup<7>,
    f64,
    nalgebra::SVector<f64, 7>,
    Option<control::steer::CycleTable<{ control::MAX_JOINTS }>>,
);

fn job(chain: &Chain, spheres: &[[f64; 4]], at: f64) -> Result<Job> {
    let mut cfg = SpatialConfig::preset("panda").expect("the panda preset");
    cfg.safety.plan = control::safety::policy::PlanMode::On;
    let (start, _) = control::plan::setup_planned::<7>(&cfg, chain)?;
    let mut sim = SpatialSimulation::<7, 3>::spatial(
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
    cfg.obstacles = spheres.iter().copied().map(SphereEntry::of).collect();
    let set = cfg.setup::<7>(chain)?;
    let following = (at > 0.0)
        .then(|| start.params.steer.map(|s: SpatialSteer| s.cycle))
        .flatten();
    Ok((set, sim.time(), sim.state().q, following))
}

pub fn section(quick: bool) -> Result<String> {
    let rounds = if quick { 3 } else { 7 };
    let chain = Chain::from_urdf(builtin("panda")?, None, None)?;
    let jobs: Vec<Job> = LAYOUTS
        .iter()
        .map(|(_, s, at)| job(&chain, s, *at))
        .collect::<Result<_>>()?;
    let s = PlanSettings::default();
    let mut times = vec![Vec::new(); LAYOUTS.len()];
    let mut outcomes = vec![None; LAYOUTS.len()];
    for order in crate::plan::interleave(&(0..LAYOUTS.len()).collect::<Vec<_>>(), rounds) {
        for i in order {
            let (set, t0, q, following) = &jobs[i];
            let t = Instant::now();
            let planned = plan_setup(set, *t0, Some(*q), following.as_ref(), &s);
            times[i].push(t.elapsed().as_secs_f64() * 1e3);
            outcomes[i] = Some((planned.outcome, planned.limits_only));
        }
    }
    let mut text = format!(
        "\n### Planning a clean cycle (Panda)\n\n`control::plan::spatial` on {} phases, the \
         Panda's study set-up, {rounds} rounds, interleaved (target ≤ 1 s): the whole plan the \
         daemon makes, from the arm's posture (at 6.1 s: from the cycle it follows then) and \
         the starts spread over the joint box, each strict, then within the physical limits:\n\n\
         | layout | outcome | smallest clearance | fastest joint | median | max |\n\
         |---|---|---|---|---|---|\n",
        s.phases
    );
    for (i, (label, _, _)) in LAYOUTS.iter().enumerate() {
        let (median, max) = crate::cycle_plan::median_max(&times[i]);
        let (found, clearance, rate) = match &outcomes[i] {
            Some((PlanOutcome::Found(c), loose)) => (
                if *loose {
                    "cycle (limits only)"
                } else {
                    "cycle"
                },
                crate::cycle_plan::clearance_cell(c),
                format!("{:.2} rad/s", c.max_rate),
            ),
            _ => ("blocked", "–".into(), "–".into()),
        };
        text.push_str(&format!(
            "| {label} | {found} | {clearance} | {rate} | {median:.1} ms | {max:.1} ms |\n"
        ));
    }
    Ok(text)
}
