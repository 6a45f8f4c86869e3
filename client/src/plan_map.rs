//! `chaosctl plan --map PREFIX`: where one more obstacle leaves the arm a clean cycle, over a
//! grid of centres, one panel per radius: the book's picture of when chaosd tracks round an
//! obstacle, when the arm must first take a joint-space detour because it is on the obstacle's
//! wrong side, and when it says `Blocked`.

use crate::analysis::parallel::{jobs, run_all};
use crate::plot::{Figure, Grid, Panel, PALETTE};
use anyhow::{bail, Context, Result};
use control::config::ObstacleConfig;
use control::plan::planar::{plan, PlanarProblem};
use control::plan::{detour, PlanOutcome, PlanSettings};
use control::steer::CycleTable;
use control::Config;
use plotters::style::RGBColor;
use std::path::Path;
use std::time::Instant;

/// What one obstacle position leaves the arm.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// A clean cycle the arm reaches from its posture with its hand on the path.
    Reachable = 0,
    /// Clean cycles exist, but the arm reaches them only by a joint-space detour.
    Detour = 1,
    /// Clean cycles exist, but the arm reaches none, by a detour either: `Blocked`.
    Elsewhere = 2,
    /// No clean cycle at all: `Blocked`.
    None = 3,
}

const NAMES: [&str; 4] = [
    "reached tracking",
    "reached by a detour",
    "unreachable ones only (Blocked)",
    "no clean cycle (Blocked)",
];

/// The verdicts' colours, in `NAMES`' order.
const CATEGORIES: [(&str, RGBColor); 4] = [
    (NAMES[0], PALETTE[2]),
    (NAMES[1], PALETTE[0]),
    (NAMES[2], PALETTE[3]),
    (NAMES[3], PALETTE[1]),
];

/// A map's grid of centres: the two in-plane coordinates and their labels.
pub struct MapAxes {
    pub xs: Vec<f64>,
    pub ys: Vec<f64>,
    pub labels: (String, String),
}

/// Draws one panel per title (each `xs` × `ys` cells of `cells`, in order), colouring each
/// cell by its category: `PREFIX.png` and `.svg`.
pub fn save_map(
    prefix: &Path,
    axes: &MapAxes,
    titles: Vec<String>,
    cells: &[usize],
    categories: &[(&str, RGBColor)],
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
                    .map(|(n, c)| (n.to_string(), *c))
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

/// Checks the map's radii and cells per side.
pub fn check_spec(radii: &[f64], n: usize) -> Result<()> {
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

/// Writes a map's CSV text to `PREFIX.csv`, creating its directory.
pub fn save_csv(prefix: &Path, csv: &str) -> Result<std::path::PathBuf> {
    let path = crate::plot::with_ext(prefix, "csv");
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    std::fs::write(&path, csv).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

/// Where the arm is at task time `at` (s), without the new obstacle: simulated from the
/// config's start, as the daemon would have run it until the obstacle is added.
pub fn posture_at(cfg: &Config, at: f64) -> [f64; 3] {
    control::plan::posture_at(cfg, at).1
}

/// The verdict for `cfg` with one more disc at (x, y) of radius r, added at task time `at`
/// with the arm at `q`.
pub fn verdict(
    cfg: &Config,
    s: &PlanSettings,
    (at, q): (f64, [f64; 3]),
    (x, y, r): (f64, f64, f64),
) -> Result<Verdict> {
    let mut c = cfg.clone();
    c.control.obstacles.push(ObstacleConfig::disc(x, y, r));
    let p = PlanarProblem::from_config(&c, at, Some(q))
        .map_err(|e| anyhow::anyhow!("chaosctl plan --map: {e}"))?;
    let cycle = match plan(&p, s) {
        PlanOutcome::Found(c) if c.unreachable.is_none() => return Ok(Verdict::Reachable),
        PlanOutcome::Found(c) => c,
        PlanOutcome::Blocked(_) => return Ok(Verdict::None),
    };
    let table = CycleTable::new(&cycle).map_err(|e| anyhow::anyhow!(e))?;
    Ok(match detour::plan(&p, &table, q, at) {
        Ok(_) => Verdict::Detour,
        Err(_) => Verdict::Elsewhere,
    })
}

/// The grid of centres round the task and the arm's base: `n` × `n`.
fn centres(cfg: &Config, n: usize) -> (Vec<f64>, Vec<f64>) {
    let (c, r) = (cfg.task.center, cfg.task.radius);
    let span = |lo: f64, hi: f64| -> Vec<f64> {
        (0..n)
            .map(|k| lo + (hi - lo) * k as f64 / (n - 1) as f64)
            .collect()
    };
    (
        span(c[0].min(0.0) - r - 0.5, c[0].max(0.0) + r + 0.5),
        span(c[1].min(0.0) - r - 0.5, c[1].max(0.0) + r + 0.5),
    )
}

/// Maps every centre for every radius, writes `PREFIX.csv`, `.png` and `.svg`, and returns a
/// one-line summary.
/// What to map: the radii, centres per side, the moment the obstacle is added (s) and the
/// threads.
pub struct MapSpec<'a> {
    pub radii: &'a [f64],
    pub cells: usize,
    pub at: f64,
    pub threads: Option<usize>,
}

pub fn run(cfg: &Config, s: &PlanSettings, spec: &MapSpec, prefix: &Path) -> Result<String> {
    let (radii, n) = (spec.radii, spec.cells);
    if !(spec.at.is_finite() && (0.0..=600.0).contains(&spec.at)) {
        bail!("--map-at {}: must be a time in [0, 600] s", spec.at);
    }
    check_spec(radii, n)?;
    let (xs, ys) = centres(cfg, n);
    let mut cells = Vec::with_capacity(radii.len() * n * n);
    for &r in radii {
        for &y in &ys {
            cells.extend(xs.iter().map(|&x| (x, y, r)));
        }
    }
    let started = Instant::now();
    let arm = (spec.at, posture_at(cfg, spec.at));
    let own = PlanarProblem::from_config(cfg, arm.0, Some(arm.1))
        .map_err(|e| anyhow::anyhow!("chaosctl plan --map: {e}"))?;
    if let PlanOutcome::Blocked(b) = plan(&own, s) {
        bail!(
            "--map: the config's own obstacles leave no clean cycle already ({}); map with \
             fewer of them",
            b.reason
        );
    }
    let verdicts = run_all(&cells, jobs(spec.threads), "plan map", |&cell| {
        verdict(cfg, s, arm, cell)
    })?
    .into_iter()
    .collect::<Result<Vec<_>>>()?;
    let took = started.elapsed().as_secs_f64();
    let mut csv = String::from("x,y,radius,verdict\n");
    for (&(x, y, r), v) in cells.iter().zip(&verdicts) {
        csv.push_str(&format!("{x},{y},{r},{}\n", NAMES[*v as usize]));
    }
    let path = save_csv(prefix, &csv)?;
    let panels = radii
        .iter()
        .map(|r| {
            format!(
                "one more obstacle, radius {r} m, centre (x, y), added at t = {} s",
                spec.at
            )
        })
        .collect();
    let cells: Vec<usize> = verdicts.iter().map(|v| *v as usize).collect();
    let axes = MapAxes {
        xs,
        ys,
        labels: ("x (m)".into(), "y (m)".into()),
    };
    let files = save_map(prefix, &axes, panels, &cells, &CATEGORIES)?;
    let share = |v: Verdict| {
        100.0 * verdicts.iter().filter(|x| **x == v).count() as f64 / verdicts.len() as f64
    };
    Ok(format!(
        "{} obstacle positions in {took:.1} s: reached tracking {:.0} %, by a detour {:.0} %, \
         clean cycles out of reach {:.0} %, none {:.0} %; wrote {}",
        verdicts.len(),
        share(Verdict::Reachable),
        share(Verdict::Detour),
        share(Verdict::Elsewhere),
        share(Verdict::None),
        wrote(&path, &files)
    ))
}

/// The files a map wrote, for its summary line.
pub fn wrote(csv: &Path, figures: &[std::path::PathBuf]) -> String {
    std::iter::once(csv)
        .chain(figures.iter().map(|f| f.as_path()))
        .map(|f| f.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_verdicts_are_told_apart() {
        let cfg = Config::default();
        let s = PlanSettings::default();
        let start = (3.0, posture_at(&cfg, 3.0));
        // Far from the arm: nothing changes.
        let far = (-2.5, -2.5, 0.2);
        assert_eq!(verdict(&cfg, &s, start, far).unwrap(), Verdict::Reachable);
        // On the hand's path: no way round.
        let on_path = (1.5, 2.0, 0.2);
        assert_eq!(verdict(&cfg, &s, start, on_path).unwrap(), Verdict::None);
        // The user's trap: added at 5 s the arm is on its wrong side and takes a detour; at
        // 3 s it is not.
        let trap = (0.9, 1.1, 0.15);
        let at = |t: f64| verdict(&cfg, &s, (t, posture_at(&cfg, t)), trap).unwrap();
        assert_eq!(at(5.0), Verdict::Detour);
        assert_eq!(at(3.0), Verdict::Reachable);
    }
}
