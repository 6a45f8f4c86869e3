//! The cycle planner's time on the planar arm's layouts (issue 25's target: ≤ 50 ms), each
//! layout planned in turn, round after round, so a noisy moment hits them alike.

use anyhow::Result;
use control::plan::planar::{plan, PlanarProblem};
use control::plan::{PlanOutcome, PlanSettings};
use std::time::Instant;

/// Discs as (x, y, radius), m.
type Discs = &'static [(f64, f64, f64)];

/// The layouts: a label and the obstacles.
const LAYOUTS: [(&str, Discs); 4] = [
    ("no obstacle", &[]),
    ("the filter's trap (0.9, 1.1) r 0.15", &[(0.9, 1.1, 0.15)]),
    ("the paper's obstacle (0, 1.6) r 0.25", &[(0.0, 1.6, 0.25)]),
    ("one on the path (1.5, 2.0) r 0.2", &[(1.5, 2.0, 0.2)]),
];

fn problem(obstacles: &[(f64, f64, f64)]) -> Result<PlanarProblem> {
    let mut cfg = control::Config::preset("demo")?;
    cfg.control.obstacles = obstacles
        .iter()
        .map(|&(x, y, r)| control::config::ObstacleConfig::disc(x, y, r))
        .collect();
    let q0 = cfg.initial_state::<3>().q;
    PlanarProblem::from_config(&cfg, 0.0, Some([q0[0], q0[1], q0[2]]))
        .map_err(|e| anyhow::anyhow!(e))
}

pub fn section(quick: bool) -> Result<String> {
    let rounds = if quick { 3 } else { 11 };
    let problems = LAYOUTS
        .iter()
        .map(|(_, o)| problem(o))
        .collect::<Result<Vec<_>>>()?;
    let s = PlanSettings::default();
    let mut times = vec![Vec::new(); LAYOUTS.len()];
    let mut outcomes = vec![None; LAYOUTS.len()];
    for order in crate::plan::interleave(&(0..LAYOUTS.len()).collect::<Vec<_>>(), rounds) {
        for i in order {
            let t = Instant::now();
            let o = plan(&problems[i], &s);
            times[i].push(t.elapsed().as_secs_f64() * 1e3);
            outcomes[i] = Some(o);
        }
    }
    let mut text = format!(
        "\n### Planning a clean cycle (planar arm)\n\n`control::plan::planar` on {} phases × {} \
         postures, {rounds} rounds, interleaved (target ≤ 50 ms):\n\n\
         | layout | clean cycle | smallest clearance | median | max |\n|---|---|---|---|---|\n",
        s.phases,
        2 * s.angles
    );
    for (i, (label, _)) in LAYOUTS.iter().enumerate() {
        let mut t = times[i].clone();
        t.sort_by(f64::total_cmp);
        let (found, clearance) = match &outcomes[i] {
            Some(PlanOutcome::Found(c)) if c.min_clearance.is_finite() => {
                ("yes", format!("{:.3} m", c.min_clearance))
            }
            Some(PlanOutcome::Found(_)) => ("yes", "–".into()),
            _ => ("no (blocked)", "–".into()),
        };
        text.push_str(&format!(
            "| {label} | {found} | {clearance} | {:.1} ms | {:.1} ms |\n",
            t[t.len() / 2],
            t[t.len() - 1]
        ));
    }
    Ok(text)
}
