//! `chaosctl plan --map PREFIX`: where one more obstacle leaves the arm a clean cycle, over a
//! grid of centres, one panel per radius: the book's picture of when chaosd tracks round an
//! obstacle, when the arm must first take a joint-space detour because it is on the obstacle's
//! wrong side, and when it says `Blocked`.
//!
//! One map for every arm: the grid, the parallel runs, the CSV, the figure and the summary are
//! written once; an arm brings its slice of centres and its planner's verdict on one more
//! obstacle ([`MapArm`]). The planar arm's grid is its plane round the task and the base; a
//! robot's is one slice of space (a 3-D grid of plans, each up to a second when there is no
//! cycle, is too slow to draw and too hard to read): the plane parallel to the path's,
//! `--map-offset` metres from it towards the base, where the links sweep between the shoulder
//! and the hand.

use crate::analysis::parallel::{jobs, run_all};
use crate::plot::{Figure, Grid, Panel, PALETTE};
use anyhow::{bail, Context, Result};
use control::config::spatial::SphereEntry;
use control::config::ObstacleConfig;
use control::plan::planar::{plan, PlanarProblem};
use control::plan::{detour, PlanOutcome, PlanSettings};
use control::steer::CycleTable;
use control::system::SpatialSystem;
use control::task::{Path as TaskPath, Vec3};
use control::{with_dof, Config, System};
use plotters::style::RGBColor;
use std::path::Path;
use std::time::Instant;

/// What to map: the radii, centres per side, the moment the obstacle is added (s), a robot's
/// slice offset from the path's plane (m, towards the base) and the threads.
pub struct MapSpec<'a> {
    pub radii: &'a [f64],
    pub cells: usize,
    pub at: f64,
    pub offset: f64,
    pub threads: Option<usize>,
}

/// A verdict's colour, its name in the legend and the CSV, and its name in the summary.
type Category = (&'static str, RGBColor, &'static str);

/// An arm's side of the map.
trait MapArm: Sync {
    /// The verdicts, in the order [`Self::verdict`] numbers them.
    const CATEGORIES: &'static [Category];
    /// What one more obstacle is: "obstacle" (a disc) or "sphere".
    const NOUN: &'static str;
    /// The CSV's coordinate columns.
    const HEADER: &'static str;
    /// The grid's two coordinates and their labels.
    fn axes(&self, spec: &MapSpec) -> MapAxes;
    /// The centre of the cell at grid coordinates (a, b).
    fn centre(&self, a: f64, b: f64) -> Vec3;
    /// The planner's verdict with one more obstacle (centre, radius): a category's index.
    fn verdict(&self, c: Vec3, r: f64) -> Result<usize>;
    /// One CSV row's coordinates: "x,y" or "x,y,z".
    fn coords(&self, c: Vec3) -> String;
    /// A panel's title for radius `r`.
    fn title(&self, r: f64, spec: &MapSpec) -> String;
}

/// A map's grid of centres: the two in-plane coordinates and their labels.
pub struct MapAxes {
    pub xs: Vec<f64>,
    pub ys: Vec<f64>,
    pub labels: (String, String),
}

/// The planar arm: discs round the task and the base, planned by the grid search, with the
/// detour the daemon takes when the arm is on an obstacle's wrong side.
struct PlanarMap<'a> {
    cfg: &'a Config,
    settings: &'a PlanSettings,
    /// The moment the disc is added and the arm's posture then.
    at: (f64, [f64; 3]),
}

/// The planar verdicts: reached tracking, by a detour, clean cycles the arm reaches by
/// neither (Blocked), none at all (Blocked).
const PLANAR: [Category; 4] = [
    ("reached tracking", PALETTE[2], "reached tracking"),
    ("reached by a detour", PALETTE[0], "by a detour"),
    (
        "unreachable ones only (Blocked)",
        PALETTE[3],
        "clean cycles out of reach",
    ),
    ("no clean cycle (Blocked)", PALETTE[1], "none"),
];

impl MapArm for PlanarMap<'_> {
    const CATEGORIES: &'static [Category] = &PLANAR;
    const NOUN: &'static str = "obstacle";
    const HEADER: &'static str = "x,y";

    fn axes(&self, spec: &MapSpec) -> MapAxes {
        let task = &self.cfg.planar_part().task;
        let (c, r) = (task.center, task.radius);
        let n = spec.cells;
        MapAxes {
            xs: spaced(c[0].min(0.0) - r - 0.5, c[0].max(0.0) + r + 0.5, n),
            ys: spaced(c[1].min(0.0) - r - 0.5, c[1].max(0.0) + r + 0.5, n),
            labels: ("x (m)".into(), "y (m)".into()),
        }
    }

    fn centre(&self, a: f64, b: f64) -> Vec3 {
        Vec3::new(a, b, 0.0)
    }

    fn verdict(&self, c: Vec3, r: f64) -> Result<usize> {
        let mut cfg = self.cfg.clone();
        cfg.planar_mut()
            .expect("the planar map holds the planar arm")
            .obstacles
            .push(ObstacleConfig::disc(c.x, c.y, r));
        let (at, q) = self.at;
        let p = PlanarProblem::from_config(&cfg, at, Some(q))
            .map_err(|e| anyhow::anyhow!("chaosctl plan --map: {e}"))?;
        let cycle = match plan(&p, self.settings) {
            PlanOutcome::Found(c) if c.unreachable.is_none() => return Ok(0),
            PlanOutcome::Found(c) => c,
            PlanOutcome::Blocked(_) => return Ok(3),
        };
        let table = CycleTable::new(&cycle).map_err(|e| anyhow::anyhow!(e))?;
        Ok(match detour::plan(&p, &table, q, at) {
            Ok(_) => 1,
            Err(_) => 2,
        })
    }

    fn coords(&self, c: Vec3) -> String {
        format!("{},{}", c.x, c.y)
    }

    fn title(&self, r: f64, spec: &MapSpec) -> String {
        format!(
            "one more obstacle, radius {r} m, centre (x, y), added at t = {} s",
            spec.at
        )
    }
}

/// A robot: spheres on one slice parallel to the path's plane, planned as the daemon plans.
struct SpatialMap<'a> {
    sys: &'a SpatialSystem,
    settings: &'a PlanSettings,
    /// The moment the sphere is added and the arm's posture then.
    at: (f64, Vec<f64>),
    path: TaskPath,
    /// The slice's centre: the path's, moved towards the base.
    origin: Vec3,
}

/// The spatial verdicts: a clean cycle, the hand's path through the sphere (no cycle can
/// exist), or a clear path but no clean cycle found (or one the filter would brake).
const SPATIAL: [Category; 3] = [
    ("clean cycle (steered)", PALETTE[2], "clean cycle"),
    ("on the path (Blocked)", PALETTE[1], "on the path"),
    ("no clean cycle (Blocked)", PALETTE[3], "no clean cycle"),
];

impl MapArm for SpatialMap<'_> {
    const CATEGORIES: &'static [Category] = &SPATIAL;
    const NOUN: &'static str = "sphere";
    const HEADER: &'static str = "x,y,z";

    fn axes(&self, spec: &MapSpec) -> MapAxes {
        let (path, n) = (&self.path, spec.cells);
        let half = path.radius + 0.35;
        // Upwards from the floor the base stands on (z = 0), where u climbs.
        let floor = if path.u.z > 0.1 {
            (-self.origin.z / path.u.z).max(-half)
        } else {
            -half
        };
        MapAxes {
            xs: spaced(-half, half, n),
            ys: spaced(floor, half, n),
            labels: (
                "along v, the path's horizontal axis (m from its centre)".into(),
                "along u, the path's upward axis (m)".into(),
            ),
        }
    }

    fn centre(&self, a: f64, b: f64) -> Vec3 {
        self.origin + self.path.v * a + self.path.u * b
    }

    fn verdict(&self, c: Vec3, r: f64) -> Result<usize> {
        let mut with = self.sys.clone();
        with.own_mut()
            .obstacles
            .push(SphereEntry::of([c.x, c.y, c.z, r]));
        let (at, q) = (self.at.0, &self.at.1);
        let planned =
            control::plan::spatial::plan_system_with(&with, at, Some(q), None, self.settings)
                .map_err(|e| anyhow::anyhow!("chaosctl plan --map: {e}"))?;
        Ok(match planned.outcome {
            PlanOutcome::Found(_) => 0,
            PlanOutcome::Blocked(b) if b.reason.starts_with("the path runs through") => 1,
            PlanOutcome::Blocked(_) => 2,
        })
    }

    fn coords(&self, c: Vec3) -> String {
        format!("{},{},{}", c.x, c.y, c.z)
    }

    fn title(&self, r: f64, spec: &MapSpec) -> String {
        format!(
            "one more sphere, radius {r} m, {} m from the path's plane, added at t = {} s",
            spec.offset, spec.at
        )
    }
}

fn spaced(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| lo + (hi - lo) * k as f64 / (n - 1) as f64)
        .collect()
}

/// The map of either arm's set-up: the planar arm's plane, or a robot's slice
/// ([`MapSpec::offset`]); the two planners behind [`control::plan::plan_arm`] draw it.
pub fn of(system: &System, s: &PlanSettings, spec: &MapSpec, prefix: &Path) -> Result<String> {
    match system {
        System::Planar(cfg) => planar(cfg, s, spec, prefix),
        System::Spatial(sys) => spatial(sys, s, spec, prefix),
    }
}

/// The planar arm's map of `cfg`.
fn planar(cfg: &Config, s: &PlanSettings, spec: &MapSpec, prefix: &Path) -> Result<String> {
    check_spec(spec)?;
    let arm = PlanarMap {
        cfg,
        settings: s,
        at: (spec.at, control::plan::posture_at(cfg, spec.at).1),
    };
    let own = PlanarProblem::from_config(cfg, arm.at.0, Some(arm.at.1))
        .map_err(|e| anyhow::anyhow!("chaosctl plan --map: {e}"))?;
    if let PlanOutcome::Blocked(b) = plan(&own, s) {
        refuse_own(&b.reason)?;
    }
    map(&arm, spec, prefix)
}

/// A robot's map of `sys`, on the slice `spec.offset` from the path's plane.
fn spatial(sys: &SpatialSystem, s: &PlanSettings, spec: &MapSpec, prefix: &Path) -> Result<String> {
    check_spec(spec)?;
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
        refuse_own(&b.reason)?;
    }
    // Towards the base: the normal's sign that points from the path's centre to the origin.
    let normal = path.u.cross(&path.v);
    let toward_base = match normal.dot(&path.center) > 0.0 {
        true => -normal,
        false => normal,
    };
    let arm = SpatialMap {
        sys,
        settings: s,
        at: (spec.at, q),
        origin: path.center + toward_base * spec.offset,
        path,
    };
    map(&arm, spec, prefix)
}

/// A config whose own obstacles leave no clean cycle: every cell would say the same.
fn refuse_own(reason: &str) -> Result<()> {
    bail!(
        "--map: the config's own obstacles leave no clean cycle already ({reason}); map with \
         fewer of them"
    )
}

/// The path, and the robot's joint angles at task time `at` of the config's own run (without
/// steering, as from its start).
fn path_and_posture(sys: &SpatialSystem, at: f64) -> Result<(TaskPath, Vec<f64>)> {
    let (cfg, chain) = (&sys.config, &sys.chain);
    with_dof!(chain.dof(), N => {
        let s = cfg.setup::<N>(chain)?;
        let path = s.params.task.path;
        let mut q: Vec<f64> = s.q0.iter().copied().collect();
        if at > 0.0 {
            let mut sim = s.simulation();
            control::sim::run(&mut sim, at, 0.0, |_, x, _| q = x.q.iter().copied().collect());
        }
        Ok((path, q))
    })
}

/// Checks the map's radii, cells per side and moment.
fn check_spec(spec: &MapSpec) -> Result<()> {
    let (radii, n) = (spec.radii, spec.cells);
    if !(spec.at.is_finite() && (0.0..=600.0).contains(&spec.at)) {
        bail!("--map-at {}: must be a time in [0, 600] s", spec.at);
    }
    if !(3..=200).contains(&n) {
        bail!("--map-cells {n}: must be between 3 and 200");
    }
    if radii.is_empty()
        || radii
            .iter()
            .any(|r| !(r.is_finite() && *r > 0.0 && *r <= 2.0))
    {
        bail!("--map-radii {radii:?}: one or more radii in (0, 2] m");
    }
    Ok(())
}

/// Maps every centre for every radius, writes `PREFIX.csv`, `.png` and `.svg`, and returns a
/// one-line summary.
fn map<A: MapArm>(arm: &A, spec: &MapSpec, prefix: &Path) -> Result<String> {
    let axes = arm.axes(spec);
    let mut cells = Vec::new();
    for &r in spec.radii {
        for &b in &axes.ys {
            cells.extend(axes.xs.iter().map(|&a| (arm.centre(a, b), r)));
        }
    }
    let started = Instant::now();
    let verdicts = run_all(&cells, jobs(spec.threads), "plan map", |&(c, r)| {
        arm.verdict(c, r)
    })?
    .into_iter()
    .collect::<Result<Vec<_>>>()?;
    let took = started.elapsed().as_secs_f64();
    let mut csv = format!("{},radius,verdict\n", A::HEADER);
    for ((c, r), v) in cells.iter().zip(&verdicts) {
        let name = A::CATEGORIES[*v].0;
        csv.push_str(&format!("{},{r},{name}\n", arm.coords(*c)));
    }
    let csv_path = save_csv(prefix, &csv)?;
    let titles = spec.radii.iter().map(|r| arm.title(*r, spec)).collect();
    let files = save_map(prefix, &axes, titles, &verdicts, A::CATEGORIES)?;
    let shares = A::CATEGORIES
        .iter()
        .enumerate()
        .map(|(k, (_, _, short))| {
            let n = verdicts.iter().filter(|v| **v == k).count();
            format!("{short} {:.0} %", 100.0 * n as f64 / verdicts.len() as f64)
        })
        .collect::<Vec<_>>()
        .join(", ");
    Ok(format!(
        "{} {} positions in {took:.1} s: {shares}; wrote {}",
        verdicts.len(),
        A::NOUN,
        wrote(&csv_path, &files)
    ))
}

/// Draws one panel per title (each `xs` × `ys` cells of `cells`, in order), colouring each
/// cell by its category: `PREFIX.png` and `.svg`.
fn save_map(
    prefix: &Path,
    axes: &MapAxes,
    titles: Vec<String>,
    cells: &[usize],
    categories: &[Category],
) -> Result<Vec<std::path::PathBuf>> {
    let per = axes.xs.len() * axes.ys.len();
    let cols = titles.len().min(3);
    let panels = titles
        .into_iter()
        .enumerate()
        .map(|(k, title)| {
            Panel::Grid(Grid {
                title,
                x_label: axes.labels.0.clone(),
                y_label: axes.labels.1.clone(),
                xs: axes.xs.clone(),
                ys: axes.ys.clone(),
                cells: cells[k * per..(k + 1) * per].to_vec(),
                categories: categories
                    .iter()
                    .map(|(n, c, _)| (n.to_string(), *c))
                    .collect(),
            })
        })
        .collect();
    Figure {
        title: Some("Where does the arm keep a clean periodic cycle?".into()),
        panels,
        cols,
        panel_size: (820, 560),
    }
    .save(prefix)
}

/// Writes a map's CSV text to `PREFIX.csv`, creating its directory.
fn save_csv(prefix: &Path, csv: &str) -> Result<std::path::PathBuf> {
    let path = crate::plot::with_ext(prefix, "csv");
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    std::fs::write(&path, csv).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

/// The files a map wrote, for its summary line.
fn wrote(csv: &Path, figures: &[std::path::PathBuf]) -> String {
    std::iter::once(csv)
        .chain(figures.iter().map(|f| f.as_path()))
        .map(|f| f.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    const REACHABLE: usize = 0;
    const DETOUR: usize = 1;
    const NONE: usize = 3;

    #[test]
    fn the_planar_verdicts_are_told_apart() {
        let cfg = Config::default();
        let s = PlanSettings::default();
        let arm = |t: f64| PlanarMap {
            cfg: &cfg,
            settings: &s,
            at: (t, control::plan::posture_at(&cfg, t).1),
        };
        let at =
            |t: f64, (x, y, r): (f64, f64, f64)| arm(t).verdict(Vec3::new(x, y, 0.0), r).unwrap();
        // Far from the arm: nothing changes.
        assert_eq!(at(3.0, (-2.5, -2.5, 0.2)), REACHABLE);
        // On the hand's path: no way round.
        assert_eq!(at(3.0, (1.5, 2.0, 0.2)), NONE);
        // The user's trap: added at 5 s the arm is on its wrong side and takes a detour; at
        // 3 s it is not.
        let trap = (0.9, 1.1, 0.15);
        assert_eq!(at(5.0, trap), DETOUR);
        assert_eq!(at(3.0, trap), REACHABLE);
    }

    /// The paper's recipe, the set-up of the book's plan map (docs/analysis.md).
    fn panda() -> SpatialSystem {
        let config = control::Config::robot_preset("panda-paper").unwrap();
        let chain = rt::robot::load(&config.spatial_part().robot.description, None, None).unwrap();
        SpatialSystem { config, chain }
    }

    #[test]
    fn the_spatial_verdicts_are_told_apart() {
        let sys = panda();
        let (path, q) = path_and_posture(&sys, 0.0).unwrap();
        let s = PlanSettings::default();
        let arm = SpatialMap {
            sys: &sys,
            settings: &s,
            at: (0.0, q),
            origin: path.center,
            path,
        };
        let at = |c: Vec3, r: f64| SPATIAL[arm.verdict(c, r).unwrap()].2;
        // Far behind the base: nothing changes.
        assert_eq!(at(Vec3::new(-0.6, 0.6, 0.3), 0.05), "clean cycle");
        // On the path, where the hand starts.
        let start = arm.path.center + arm.path.u * arm.path.radius;
        assert_eq!(at(start, 0.03), "on the path");
        // The study's sphere whose cycle the filter brakes: the path is clear, no cycle is.
        assert_eq!(at(Vec3::new(0.15, -0.15, 0.45), 0.08), "no clean cycle");
    }

    #[test]
    fn the_robot_moves_on_by_the_moment_the_sphere_is_added() {
        let sys = panda();
        let (_, q0) = path_and_posture(&sys, 0.0).unwrap();
        let (_, q1) = path_and_posture(&sys, 0.5).unwrap();
        assert_eq!(q0, sys.config.sim.start());
        assert!(q0.iter().zip(&q1).any(|(a, b)| (a - b).abs() > 1e-3));
    }
}
