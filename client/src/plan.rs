//! `chaosctl plan`: whether a clean periodic posture cycle exists for a set-up, and what it is,
//! before any arm moves: the same planner the daemon runs when obstacles change.

use crate::setup::{parse_list, FloatList, SetupArgs};
use anyhow::{bail, Context, Result};
use clap::Args;
use control::config::obstacles::OBSTACLE_MARGIN;
use control::plan::{plan_arm_with, PlanOutcome, PlanSettings, Planned};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct PlanCmd {
    #[command(flatten)]
    pub setup: SetupArgs,
    /// One more obstacle besides the config's, X,Y,RADIUS (m; a spatial robot's sphere:
    /// X,Y,Z,RADIUS); repeat for more.
    #[arg(long = "obstacle", value_parser = parse_list, allow_hyphen_values = true)]
    pub obstacles: Vec<FloatList>,
    /// Clearance the cycle keeps beyond the safety filter's (m).
    #[arg(long, default_value_t = PlanSettings::default().margin)]
    pub margin: f64,
    /// The fastest any joint of the cycle may move (rad/s).
    #[arg(long = "max-rate", default_value_t = PlanSettings::default().max_rate)]
    pub max_rate: f64,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
    /// Write the cycle's postures as CSV (t, q1 … qn).
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Map where one more obstacle leaves a clean cycle, over a grid of centres round the
    /// task, one panel per radius: writes PREFIX.csv, .png and .svg. A spatial robot's map is
    /// one slice: the plane parallel to the path's, --map-offset from it.
    #[arg(long, value_name = "PREFIX")]
    pub map: Option<PathBuf>,
    /// The radii the map tries (m) [default: 0.1,0.2,0.3; a spatial robot's: 0.06,0.1].
    #[arg(long = "map-radii", value_parser = parse_list)]
    pub map_radii: Option<FloatList>,
    /// Centres per side of the map's grid [default: 25; a spatial robot's: 13].
    #[arg(long = "map-cells")]
    pub map_cells: Option<usize>,
    /// A spatial robot's map: the slice's distance from the path's plane, towards the base (m).
    #[arg(long = "map-offset", default_value_t = 0.1, allow_hyphen_values = true)]
    pub map_offset: f64,
    /// The moment the map's obstacle is added (s): the arm is where the config's run (without
    /// it) has brought it by then.
    #[arg(long = "map-at", default_value_t = 0.0)]
    pub map_at: f64,
    /// Threads for the map (default: every core).
    #[arg(long)]
    pub jobs: Option<usize>,
}

pub fn run(a: &PlanCmd) -> Result<()> {
    let mut system = a.setup.load(None)?;
    let dims = system.obstacle_dims();
    for (i, o) in a.obstacles.iter().enumerate() {
        if o.0.len() != dims + 1 {
            let form = match dims {
                2 => "X,Y,RADIUS (three numbers)",
                _ => "X,Y,Z,RADIUS (four numbers)",
            };
            bail!("--obstacle {:?}: expected {form}", o.0);
        }
        let r = o.0[dims];
        system
            .add_obstacle(&o.0[..dims], r, OBSTACLE_MARGIN)
            .with_context(|| format!("--obstacle #{}", i + 1))?;
    }
    // Checks the file against the arm (the obstacles too) before planning.
    system.validate()?;
    let settings = settings(a)?;
    if let Some(prefix) = &a.map {
        let (radii, cells) = match dims {
            2 => (vec![0.1, 0.2, 0.3], 25),
            _ => (vec![0.06, 0.1], 13),
        };
        let spec = crate::plan_map::MapSpec {
            radii: &a.map_radii.as_ref().map_or(radii, |r| r.0.clone()),
            cells: a.map_cells.unwrap_or(cells),
            at: a.map_at,
            offset: a.map_offset,
            threads: a.jobs,
        };
        println!(
            "{}",
            crate::plan_map::of(&system, &settings, &spec, prefix)?
        );
        return Ok(());
    }
    let q0 = system.start_coords(false);
    // What the daemon does: the search, the refinement against the filter, a detour when the
    // arm cannot reach the cycle tracking.
    let started = std::time::Instant::now();
    let planned = plan_arm_with(&system, 0.0, Some(&q0), None, &settings)
        .map_err(|e| anyhow::anyhow!("chaosctl plan: {e}"))?;
    report(a, &settings, &planned, started.elapsed(), dims == 3)
}

/// The settings `--margin` and `--max-rate` ask for, checked.
fn settings(a: &PlanCmd) -> Result<PlanSettings> {
    let settings = PlanSettings {
        margin: a.margin,
        max_rate: a.max_rate,
        ..PlanSettings::default()
    };
    if !(settings.margin.is_finite() && settings.margin >= 0.0) {
        bail!("--margin {}: must be a distance ≥ 0 (m)", settings.margin);
    }
    if !(settings.max_rate.is_finite() && settings.max_rate > 0.0) {
        bail!(
            "--max-rate {}: must be a rate > 0 (rad/s)",
            settings.max_rate
        );
    }
    Ok(settings)
}

/// Prints a plan that took `took` (and writes `--csv`): words, or JSON with `--json`.
/// `spatial`: the planner searched from starts (a robot's), not over a grid (the planar arm's).
fn report(
    a: &PlanCmd,
    s: &PlanSettings,
    planned: &Planned,
    took: std::time::Duration,
    spatial: bool,
) -> Result<()> {
    let (outcome, ms) = (&planned.outcome, took.as_secs_f64() * 1e3);
    let loose = planned.limits_only;
    if let (Some(path), PlanOutcome::Found(c)) = (&a.csv, outcome) {
        let dt = c.period / c.q.len() as f64;
        let n = c.q.first().map_or(0, Vec::len);
        let names: Vec<String> = (1..=n).map(|i| format!("q{i}")).collect();
        let mut text = format!("t,{}\n", names.join(","));
        for (k, q) in c.q.iter().enumerate() {
            let row: Vec<String> = q.iter().map(f64::to_string).collect();
            text.push_str(&format!("{},{}\n", c.t0 + k as f64 * dt, row.join(",")));
        }
        std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))?;
    }
    if a.json {
        println!("{}", json(outcome, s, ms, loose, spatial));
    } else {
        println!("{}", words(outcome, s, ms, loose, spatial));
    }
    Ok(())
}

/// `limits_only`: no cycle met the settings (`--margin`, `--max-rate`), and the outcome is the
/// plan within the filter's physical limits alone, as the daemon falls back to.
fn json(
    o: &PlanOutcome,
    s: &PlanSettings,
    ms: f64,
    limits_only: bool,
    spatial: bool,
) -> serde_json::Value {
    let grid = if spatial {
        serde_json::json!({ "phases": s.phases, "starts": s.candidates + 2 })
    } else {
        serde_json::json!({ "phases": s.phases, "postures_per_phase": 2 * s.angles })
    };
    let mut v = match o {
        PlanOutcome::Found(c) => serde_json::json!({
            "exists": true, "min_clearance_m": finite(c.min_clearance),
            "max_rate_rad_s": c.max_rate, "filter_margin": finite(c.filter_margin),
            "filter_acts": c.filter_margin < 0.0, "planning_ms": ms, "grid": grid,
            "detour": c.detour.as_ref().map(|d| serde_json::json!({
                "seconds": d.t_arrive - d.t_start, "why": c.unreachable.as_ref().map(|b| &b.reason),
            })),
            "blocked": null,
        }),
        PlanOutcome::Blocked(b) => serde_json::json!({
            "exists": false, "min_clearance_m": null, "max_rate_rad_s": null,
            "filter_margin": null, "filter_acts": null, "planning_ms": ms, "grid": grid,
            "detour": null,
            "blocked": {
                "reason": b.reason, "best_clearance_m": finite(b.best_clearance),
                "obstacle": b.obstacle.map(|i| i + 1), "link": b.link.map(|i| i + 1),
                "task_time_s": b.task_time,
            },
        }),
    };
    v["limits_only"] = limits_only.into();
    v
}

/// What the safety filter will do on the cycle, from its rows' smallest margin. A spatial
/// cycle whose rows the filter acts on was run through the steered law: the filter keeps it in
/// the null space, so the hand stays on its path.
fn filter_words(margin: f64, spatial: bool) -> String {
    if margin >= 0.0 {
        format!("the filter never acts on it (rows {margin:.1} above their bounds)")
    } else if spatial {
        format!(
            "the filter acts on it (rows {:.1} below their bounds) within the null space, the \
             hand on its path",
            -margin
        )
    } else {
        format!(
            "but the filter will brake it where its rows fall {:.1} below their bounds (the \
             arm leaves its path there for a moment)",
            -margin
        )
    }
}

/// JSON has no infinity: no obstacle, no clearance to report.
fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

fn words(o: &PlanOutcome, s: &PlanSettings, ms: f64, limits_only: bool, spatial: bool) -> String {
    let grid = if spatial {
        format!("{} phases, optimised in the null space", s.phases)
    } else {
        format!("{} phases × {} postures", s.phases, 2 * s.angles)
    };
    match o {
        PlanOutcome::Found(c) => {
            let exists = if limits_only {
                format!(
                    "no cycle keeps a margin of {} m at joint rates within {} rad/s; within the \
                     filter's physical limits alone a clean cycle exists",
                    s.margin, s.max_rate
                )
            } else {
                "a clean cycle exists".into()
            };
            format!(
                "{exists}: smallest clearance {}, fastest joint {:.2} rad/s, {} (planned \
             in {ms:.1} ms on {grid})",
                if c.min_clearance.is_finite() {
                    format!("{:.3} m", c.min_clearance)
                } else {
                    "n/a (no obstacle)".into()
                },
                c.max_rate,
                filter_words(c.filter_margin, spatial)
            ) + &c.detour.as_ref().map_or(String::new(), |d| {
                format!(
                    "; the arm reaches it by a joint-space detour of {:.2} s, tracking paused",
                    d.t_arrive - d.t_start
                )
            })
        }
        PlanOutcome::Blocked(b) => format!(
            "no clean cycle: {} (planned in {ms:.1} ms on {grid})",
            b.reason
        ),
    }
}
