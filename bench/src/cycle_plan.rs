//! The cycle planner's time on the planar arm's layouts (issue 25's target: ≤ 50 ms), each
//! layout planned in turn, round after round, so a noisy moment hits them alike. Two times per
//! layout: the grid search alone, and the whole plan the daemon makes (the search, the
//! refinement against the filter, a detour when the arm cannot reach the cycle tracking).

use anyhow::Result;
use control::plan::planar::{plan, PlanarProblem};
use control::plan::{plan_config, PlanOutcome, PlanSettings};
use control::Config;
use std::time::Instant;

/// Discs as (x, y, radius), m.
type Discs = &'static [(f64, f64, f64)];

/// The layouts: a label, the obstacles, and the task time the arm's posture is taken at (the
/// default set-up's run, obstacle-free until then).
const LAYOUTS: [(&str, Discs, f64); 7] = [
    ("no obstacle", &[], 0.0),
    (
        "the filter's trap (0.9, 1.1) r 0.15",
        &[(0.9, 1.1, 0.15)],
        0.0,
    ),
    (
        "the paper's obstacle (0, 1.6) r 0.25",
        &[(0.0, 1.6, 0.25)],
        0.0,
    ),
    ("one on the path (1.5, 2.0) r 0.2", &[(1.5, 2.0, 0.2)], 0.0),
    ("the trap added at 5 s (a detour)", &[(0.9, 1.1, 0.15)], 5.0),
    (
        "two discs (−0.033, 1.838) r 0.237, (0.506, 2.727) r 0.136",
        &[(-0.033, 1.838, 0.237), (0.506, 2.727, 0.136)],
        0.0,
    ),
    (
        "two discs (1.624, 2.319) r 0.082, (0.136, 0.989) r 0.083: the filter brakes the cycle",
        &[(1.624, 2.319, 0.082), (0.136, 0.989, 0.083)],
        0.0,
    ),
];

/// A layout's config, task time and the arm's posture then.
fn setup(obstacles: &[(f64, f64, f64)], at: f64) -> (Config, f64, [f64; 3]) {
    let mut cfg = Config::default();
    let (t, q) = control::plan::posture_at(&cfg, at);
    cfg.control.obstacles = obstacles
        .iter()
        .map(|&(x, y, r)| control::config::ObstacleConfig::disc(x, y, r))
        .collect();
    (cfg, t, q)
}

pub fn median_max(t: &[f64]) -> (f64, f64) {
    let mut t = t.to_vec();
    t.sort_by(f64::total_cmp);
    (t[t.len() / 2], t[t.len() - 1])
}

pub fn section(quick: bool) -> Result<String> {
    let rounds = if quick { 3 } else { 11 };
    let setups: Vec<_> = LAYOUTS.iter().map(|(_, o, at)| setup(o, *at)).collect();
    let problems = setups
        .iter()
        .map(|(c, t, q)| PlanarProblem::from_config(c, *t, Some(*q)))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| anyhow::anyhow!(e))?;
    let s = PlanSettings::default();
    let (mut grid, mut whole) = (
        vec![Vec::new(); LAYOUTS.len()],
        vec![Vec::new(); LAYOUTS.len()],
    );
    let mut outcomes = vec![None; LAYOUTS.len()];
    for order in crate::plan::interleave(&(0..LAYOUTS.len()).collect::<Vec<_>>(), rounds) {
        for i in order {
            let t = Instant::now();
            std::hint::black_box(plan(&problems[i], &s));
            grid[i].push(t.elapsed().as_secs_f64() * 1e3);
            let (cfg, t0, q) = &setups[i];
            let t = Instant::now();
            let planned = plan_config(cfg, *t0, Some(*q)).map_err(|e| anyhow::anyhow!(e))?;
            whole[i].push(t.elapsed().as_secs_f64() * 1e3);
            outcomes[i] = Some(planned.outcome);
        }
    }
    let mut text = format!(
        "\n### Planning a clean cycle (planar arm)\n\n`control::plan` on {} phases × {} \
         postures, {rounds} rounds, interleaved (target ≤ 50 ms). \"grid\" is the search alone; \
         \"whole\" is what the daemon runs: the search, the refinement against the filter, and a \
         detour when the arm cannot reach the cycle with its hand on the path:\n\n\
         | layout | outcome | smallest clearance | filter margin | grid median | grid max | \
         whole median | whole max |\n|---|---|---|---|---|---|---|---|\n",
        s.phases,
        2 * s.angles
    );
    for (i, (label, _, _)) in LAYOUTS.iter().enumerate() {
        let (gm, gx) = median_max(&grid[i]);
        let (wm, wx) = median_max(&whole[i]);
        let (found, clearance, margin) = match &outcomes[i] {
            Some(PlanOutcome::Found(c)) => (
                if c.detour.is_some() {
                    "cycle, by a detour"
                } else {
                    "cycle"
                },
                clearance_cell(c),
                format!("{:.1}", c.filter_margin),
            ),
            _ => ("blocked", "–".into(), "–".into()),
        };
        text.push_str(&format!(
            "| {label} | {found} | {clearance} | {margin} | {gm:.1} ms | {gx:.1} ms | {wm:.1} ms \
             | {wx:.1} ms |\n"
        ));
    }
    Ok(text)
}

/// A table cell for a cycle's smallest clearance: "0.050 m", or "–" without obstacles.
pub fn clearance_cell(c: &control::steer::Cycle) -> String {
    if c.min_clearance.is_finite() {
        format!("{:.3} m", c.min_clearance)
    } else {
        "–".into()
    }
}
