//! `chaosctl plan --preset panda --map PREFIX`: the planar map's question for a spatial arm.
//!
//! A sphere has three coordinates, and a 3-D grid of plans (each up to a second when there is
//! no cycle) is too slow to draw and too hard to read. So the map takes one slice: the plane
//! parallel to the path's, `--map-offset` metres from it towards the arm's base, where the
//! links sweep between the shoulder and the hand. Each cell is a sphere centred there; the
//! planner the daemon runs ([`control::plan::spatial::plan_system_with`]) says whether a clean
//! cycle remains.

use crate::analysis::parallel::{jobs, run_all};
use crate::plan_map::{check_spec, save_csv, save_map, wrote, MapAxes};
use crate::plot::PALETTE;
use anyhow::{bail, Result};
use control::config::spatial::SpatialSetup;
use control::config::spatial::SphereEntry;
use control::plan::{PlanOutcome, PlanSettings};
use control::sim::spatial::run as simulate;
use control::system::SpatialSystem;
use control::task::Path as TaskPath;
use control::task::Vec3;
use control::{with_dof, with_task_rows};
use plotters::style::RGBColor;
use std::path::Path;
use std::time::Instant;

/// What one sphere leaves the arm.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// A clean cycle: the daemon steers onto it.
    Clean = 0,
    /// The hand's path runs through the sphere: no cycle can exist.
    OnPath = 1,
    /// The path is clear, but the planner found no clean cycle (or the filter would brake
    /// the one it found): `Blocked`.
    NoCycle = 2,
}

const CATEGORIES: [(&str, RGBColor); 3] = [
    ("clean cycle (steered)", PALETTE[2]),
    ("on the path (Blocked)", PALETTE[1]),
    ("no clean cycle (Blocked)", PALETTE[3]),
];

/// The spatial map's extent: the radii, centres per side, the moment the sphere is added, the
/// slice's distance from the path's plane (m, towards the base) and the threads.
pub struct SpatialMapSpec<'a> {
    pub radii: &'a [f64],
    pub cells: usize,
    pub at: f64,
    pub offset: f64,
    pub threads: Option<usize>,
}

/// The verdict for `sys` with one more sphere `(centre, r)` added at task time `at` with the
/// arm at `q`.
pub fn verdict(
    sys: &SpatialSystem,
    s: &PlanSettings,
    (at, q): (f64, &[f64]),
    (c, r): (Vec3, f64),
) -> Result<Verdict> {
    let mut with = sys.clone();
    with.config
        .obstacles
        .push(SphereEntry::of([c.x, c.y, c.z, r]));
    let planned = control::plan::spatial::plan_system_with(&with, at, Some(q), None, s)
        .map_err(|e| anyhow::anyhow!("chaosctl plan --map: {e}"))?;
    Ok(match planned.outcome {
        PlanOutcome::Found(_) => Verdict::Clean,
        PlanOutcome::Blocked(b) if b.reason.starts_with("the path runs through") => Verdict::OnPath,
        PlanOutcome::Blocked(_) => Verdict::NoCycle,
    })
}

/// The path, and the arm's joint angles at task time `at` of the config's own run (without
/// steering, as from its start).
fn path_and_posture(sys: &SpatialSystem, at: f64) -> Result<(TaskPath, Vec<f64>)> {
    let (cfg, chain) = (&sys.config, &sys.chain);
    let kind = cfg.task_kind()?;
    with_dof!(chain.dof(), N => {
        let s: SpatialSetup<N> = cfg.setup::<N>(chain)?;
        let path = s.params.task.path;
        let mut q: Vec<f64> = s.q0.iter().copied().collect();
        if at > 0.0 {
            with_task_rows!(kind, |M| {
                let mut sim =
                    s.simulation::<M>();
                simulate(&mut sim, at, 0.0, |_, x, _| q = x.q.iter().copied().collect());
            });
        }
        Ok((path, q))
    })
}

/// Maps every centre of the slice for every radius, writes `PREFIX.csv`, `.png` and `.svg`,
/// and returns a one-line summary.
pub fn run(
    sys: &SpatialSystem,
    s: &PlanSettings,
    spec: &SpatialMapSpec,
    prefix: &Path,
) -> Result<String> {
    check_spec(spec.radii, spec.cells)?;
    if !(spec.at.is_finite() && (0.0..=600.0).contains(&spec.at)) {
        bail!("--map-at {}: must be a time in [0, 600] s", spec.at);
    }
    if !(spec.offset.is_finite() && spec.offset.abs() <= 2.0) {
        bail!(
            "--map-offset {}: must be a distance in [-2, 2] m",
            spec.offset
        );
    }
    let (path, q) = path_and_posture(sys, spec.at)?;
    let planned = control::plan::spatial::plan_system_with(sys, spec.at, Some(&q), None, s)
        .map_err(|e| anyhow::anyhow!("chaosctl plan --map: {e}"))?;
    if let PlanOutcome::Blocked(b) = planned.outcome {
        bail!(
            "--map: the config's own obstacles leave no clean cycle already ({}); map with \
             fewer of them",
            b.reason
        );
    }
    // Towards the base: the normal's sign that points from the path's centre to the origin.
    let normal = path.u.cross(&path.v);
    let toward_base = if normal.dot(&path.center) > 0.0 {
        -normal
    } else {
        normal
    };
    let centre = path.center + toward_base * spec.offset;
    let half = path.radius + 0.35;
    // Upwards from the floor the base stands on (z = 0), where u climbs.
    let floor = if path.u.z > 0.1 {
        (-centre.z / path.u.z).max(-half)
    } else {
        -half
    };
    let spaced = |lo: f64, hi: f64| -> Vec<f64> {
        (0..spec.cells)
            .map(|k| lo + (hi - lo) * k as f64 / (spec.cells - 1) as f64)
            .collect()
    };
    let (across, up) = (spaced(-half, half), spaced(floor, half));
    let mut cells = Vec::new();
    for &r in spec.radii {
        for &b in &up {
            cells.extend(
                across
                    .iter()
                    .map(|&a| (centre + path.v * a + path.u * b, r)),
            );
        }
    }
    let started = Instant::now();
    let verdicts = run_all(&cells, jobs(spec.threads), "plan map", |&cell| {
        verdict(sys, s, (spec.at, &q), cell)
    })?
    .into_iter()
    .collect::<Result<Vec<_>>>()?;
    let took = started.elapsed().as_secs_f64();
    let mut csv = String::from("x,y,z,radius,verdict\n");
    for ((c, r), v) in cells.iter().zip(&verdicts) {
        let name = CATEGORIES[*v as usize].0;
        csv.push_str(&format!("{},{},{},{r},{name}\n", c.x, c.y, c.z));
    }
    let csv_path = save_csv(prefix, &csv)?;
    let titles = spec
        .radii
        .iter()
        .map(|r| {
            format!(
                "one more sphere, radius {r} m, {} m from the path's plane, added at t = {} s",
                spec.offset, spec.at
            )
        })
        .collect();
    let axes = MapAxes {
        xs: across,
        ys: up,
        labels: (
            "along v, the path's horizontal axis (m from its centre)".into(),
            "along u, the path's upward axis (m)".into(),
        ),
    };
    let codes: Vec<usize> = verdicts.iter().map(|v| *v as usize).collect();
    let files = save_map(prefix, &axes, titles, &codes, &CATEGORIES)?;
    let share = |v: Verdict| {
        100.0 * verdicts.iter().filter(|x| **x == v).count() as f64 / verdicts.len() as f64
    };
    Ok(format!(
        "{} sphere positions in {took:.1} s: clean cycle {:.0} %, on the path {:.0} %, \
         no clean cycle {:.0} %; wrote {}",
        verdicts.len(),
        share(Verdict::Clean),
        share(Verdict::OnPath),
        share(Verdict::NoCycle),
        wrote(&csv_path, &files)
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper's recipe, the set-up of the book's plan map (docs/analysis.md).
    fn panda() -> SpatialSystem {
        let config = control::config::spatial::SpatialConfig::preset("panda-paper").unwrap();
        let chain = rt::robot::load(&config.robot.description, None, None).unwrap();
        SpatialSystem { config, chain }
    }

    #[test]
    fn the_verdicts_are_told_apart() {
        let sys = panda();
        let (path, q) = path_and_posture(&sys, 0.0).unwrap();
        let s = PlanSettings::default();
        let at = |c: Vec3, r: f64| verdict(&sys, &s, (0.0, &q), (c, r)).unwrap();
        // Far behind the base: nothing changes.
        assert_eq!(at(Vec3::new(-0.6, 0.6, 0.3), 0.05), Verdict::Clean);
        // On the path, where the hand starts.
        assert_eq!(
            at(path.center + path.u * path.radius, 0.03),
            Verdict::OnPath
        );
        // The study's sphere whose cycle the filter brakes: the path is clear, no cycle is.
        assert_eq!(at(Vec3::new(0.15, -0.15, 0.45), 0.08), Verdict::NoCycle);
    }

    #[test]
    fn the_arm_moves_on_by_the_moment_the_sphere_is_added() {
        let sys = panda();
        let (_, q0) = path_and_posture(&sys, 0.0).unwrap();
        let (_, q1) = path_and_posture(&sys, 0.5).unwrap();
        assert_eq!(q0, sys.config.sim.start());
        assert!(q0.iter().zip(&q1).any(|(a, b)| (a - b).abs() > 1e-3));
    }
}
