//! `chaosctl obstacles`: does anything keep the links out of the obstacles? The paper's potential
//! against the safety filter, over starts × μ.
//!
//! docs/science.md, "Measuring chaos" asks chaosd to report clearance and time in contact "so users can see whether
//! avoidance works", and §7 adds a filter that is meant to guarantee it. This study runs every
//! (start, μ) cell twice, filter off and on, and reports per run what a user would ask first: was
//! a link ever inside an obstacle, for how long, how close did it come, did tracking survive, and
//! what did the self-motion become. A start that begins inside an obstacle (the basin grid has
//! some) is flagged, and its clearance is also measured from the moment it first got clear, so the
//! filter's push-out is visible instead of hidden.

use super::mujoco_judge::{MujocoJudge, Verdict};
use super::obstacle_cells::{self, Cell, Row, RunResult, Window};
use super::obstacles_judged as judged;
use super::parallel::{jobs, run_all};
use super::shard::{self, Grid, Loaded, Shard};
use super::{fmt_list, ClassifyArgs};
use crate::plot::{with_ext, Chart, Figure, Panel, Rule, Series, Style, DARK, GREY, PALETTE};
pub use crate::setup::ObstacleArgs;
use crate::setup::{parse_list, FloatList, SetupArgs};
use crate::subject::Subject;
use anyhow::{bail, Context, Result};
use clap::Args;
use control::config::SecondaryKind;
use control::Summary;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The basin grid's range of the first joint angle (rad): `basins`' default `q1=-1.5:1.5:0.125`.
const Q1_RANGE: (f64, f64) = (-1.5, 1.5);

#[derive(Args, Debug)]
pub struct ObstaclesCmd {
    /// Model flags as for `simulate`; without --config/--preset the preset is `paper-obstacle`.
    /// Without --safety every cell runs twice, filter off and on; --safety on|off runs only that.
    #[command(flatten)]
    pub setup: SetupArgs,
    #[command(flatten)]
    pub obstacles: ObstacleArgs,
    /// Pyragas gains μ, comma-separated.
    #[arg(long, value_parser = parse_list, default_value = "0,0.2,1.1,1.8", allow_hyphen_values = true)]
    pub mu: FloatList,
    /// Number of starts: q1 evenly over [−1.5, 1.5] rad (the basin grid; 25 gives its 0.125 rad
    /// step), the other coordinates from --q0/--qd0 (default: the paper's). 1: the --q0 start.
    #[arg(long, default_value_t = 25)]
    pub starts: usize,
    /// Simulated time per run (s).
    #[arg(long, default_value_t = 400.0)]
    pub duration: f64,
    /// The RMS tracking error is measured from this time on (s).
    #[arg(long = "rms-from", default_value_t = 20.0)]
    pub rms_from: f64,
    /// The Poincaré section is classified from this time on (s; default: a quarter of the run).
    #[arg(long = "section-from")]
    pub section_from: Option<f64>,
    #[command(flatten)]
    pub classify: ClassifyArgs,
    /// Worker threads (default: every core).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Output prefix: writes PREFIX.csv, PREFIX.png and PREFIX.svg.
    #[arg(long, default_value = "obstacles")]
    pub output: PathBuf,
    /// Run only shard I of N (0 ≤ I < N; grid point k goes to shard k mod N) and write
    /// PREFIX.shard-I-of-N.json; `chaosctl merge` makes the CSV, table and plot from all N.
    #[arg(long, value_parser = shard::parse_shard, value_name = "I/N")]
    pub shard: Option<Shard>,
    /// A robot's study only: MuJoCo judges every run a second time over this URDF's or MJCF's
    /// own collision geometry (its meshes), and the study names each run where the filter kept
    /// chaosd's capsules clear and MuJoCo saw a link touch; writes PREFIX-mujoco.csv. Needs
    /// chaosd-mujoco-judge (scripts/mujoco-setup; docs/mujoco.md).
    #[arg(long = "mujoco-judge", value_name = "MODEL")]
    pub mujoco_judge: Option<PathBuf>,
}

/// The validated study: one cell per run, in the order μ → filter → start.
struct Plan {
    cells: Vec<Cell>,
    window: Window,
    filters: Vec<bool>,
    mus: Vec<f64>,
    /// What the header and the figure say of the set-up: the obstacles, the filter's required
    /// clearance, and the start the others vary from.
    obstacles: Vec<String>,
    clearance: f64,
    q0: Vec<f64>,
    /// What keeps the arm off the obstacles with the filter off: the paper's potential, or
    /// nothing (another secondary task).
    off: String,
}

/// The study's base set-up, for either arm.
struct Base {
    arm: Subject,
    obstacles: Vec<String>,
    clearance: f64,
    q0: Vec<f64>,
    off: String,
}

/// What the law does about obstacles with the filter off, for secondary task `secondary`.
/// What keeps the arm off an obstacle when the filter is off: the paper's potential, or
/// nothing but the law's own secondary task.
pub fn without_filter(secondary: &SecondaryKind) -> String {
    match secondary {
        SecondaryKind::Obstacles => "the paper's potential".into(),
        other => format!("the law alone (secondary task {other})"),
    }
}

fn base(args: &ObstaclesCmd) -> Result<Base> {
    let mut setup = args.setup.clone();
    if setup.config.is_none() && setup.preset.is_none() {
        setup.preset = Some("paper-obstacle".into());
    }
    let mut arm = Subject::load(&setup, None)?;
    arm.set_obstacles(&args.obstacles)?;
    let rows = arm.system().obstacle_rows();
    if rows.is_empty() {
        let how = match arm.dims() {
            2 => "--obstacle X,Y,R (a disc; repeat for several), [[obstacles]] entries in the --config, or --preset paper-obstacle",
            _ => "--obstacle X,Y,Z,R (a sphere; repeat for several) or [[obstacles]] entries in the --config",
        };
        bail!("the configuration has no obstacles: give them with {how}");
    }
    // The set-up itself is checked once, before any start is (a bad obstacle is not a start's).
    arm.check()?;
    let obstacles = rows
        .iter()
        .map(|o| {
            let c: Vec<String> = o.center.iter().map(f64::to_string).collect();
            format!("({}) r {}", c.join(", "), o.radius)
        })
        .collect();
    Ok(Base {
        obstacles,
        off: without_filter(&arm.law().secondary),
        clearance: arm.system().safety_section().clearance,
        q0: arm.q0(),
        arm,
    })
}

/// The cell of `base` at gain `mu`, filter `on`, start `q0`.
fn cell(base: &Base, mu: f64, on: bool, q0: Vec<f64>) -> Result<Cell> {
    let mut arm = base.arm.clone();
    arm.set_mu(mu);
    arm.set_safety(on);
    let arm = arm
        .with_start(q0.clone())
        .with_context(|| format!("start with q1 = {}", q0[0]))?;
    Ok(Cell {
        mu,
        safety: on,
        q0,
        arm,
    })
}

fn plan(args: &ObstaclesCmd) -> Result<Plan> {
    let base = base(args)?;
    let d = args.duration;
    if !(d.is_finite() && d > 0.0) {
        bail!("--duration {d}: must be a finite number of seconds > 0");
    }
    if !(args.rms_from >= 0.0 && args.rms_from < d) {
        bail!(
            "--rms-from {}: must be in [0, --duration = {d})",
            args.rms_from
        );
    }
    let section_from = args.section_from.unwrap_or(d / 4.0);
    if !(section_from >= 0.0 && section_from < d) {
        bail!("--section-from {section_from}: must be in [0, --duration = {d})");
    }
    if args.starts == 0 || args.starts > 10_000 {
        bail!("--starts {}: must be between 1 and 10000", args.starts);
    }
    if args.mu.0.is_empty() {
        bail!("--mu: give at least one value");
    }
    let filters = match args.setup.safety {
        Some(on) => vec![on],
        None => vec![false, true],
    };
    let q0 = base.q0.clone();
    let q1s: Vec<f64> = if args.starts == 1 {
        vec![q0[0]]
    } else {
        (0..args.starts)
            .map(|i| {
                let f = i as f64 / (args.starts - 1) as f64;
                let v = Q1_RANGE.0 + f * (Q1_RANGE.1 - Q1_RANGE.0);
                (v * 1e9).round() / 1e9
            })
            .collect()
    };
    let mut cells = Vec::new();
    for &mu in &args.mu.0 {
        for &on in &filters {
            for &q1 in &q1s {
                let mut q = q0.clone();
                q[0] = q1;
                cells.push(cell(&base, mu, on, q)?);
            }
        }
    }
    Ok(Plan {
        cells,
        window: Window {
            duration: d,
            rms_from: args.rms_from,
            section_from,
            classify: args.classify.config()?,
        },
        filters,
        mus: args.mu.0.clone(),
        obstacles: base.obstacles,
        clearance: base.clearance,
        q0,
        off: base.off,
    })
}

fn grid(plan: &Plan) -> Grid {
    let w = &plan.window;
    let parts = [format!(
        "{} {} {} {:?}",
        w.duration, w.rms_from, w.section_from, w.classify
    )]
    .into_iter()
    .chain(plan.cells.iter().map(|c| c.to_string()));
    let labels = plan
        .cells
        .iter()
        .map(|c| {
            format!(
                "μ = {}, filter {}, q1 = {}",
                c.mu,
                if c.safety { "on" } else { "off" },
                c.q0[0]
            )
        })
        .collect();
    Grid::new("obstacles", parts, labels)
}

pub fn run(args: ObstaclesCmd) -> Result<()> {
    crate::plot::make_room(&args.output)?;
    let plan = plan(&args)?;
    let threads = jobs(args.jobs);
    if let Some(model) = &args.mujoco_judge {
        return run_judged(&args, &plan, model, threads);
    }
    let work = |c: &Cell| obstacle_cells::run(c, &plan.window);
    let started = Instant::now();
    let grid = || grid(&plan);
    let (items, out) = (&plan.cells, &args.output);
    let what = "obstacles";
    let Some(results) = shard::run_or_shard(what, args.shard, grid, items, out, threads, work)?
    else {
        return Ok(());
    };
    let verdicts = vec![None; results.len()];
    finish(
        &args,
        &plan,
        (results, verdicts),
        Some(started.elapsed().as_secs_f64()),
    )
}

/// The study with MuJoCo judging every robot run (not sharded: the verdicts are not in a
/// shard file).
fn run_judged(args: &ObstaclesCmd, plan: &Plan, model: &Path, threads: usize) -> Result<()> {
    if args.shard.is_some() {
        bail!("--mujoco-judge runs the whole study: it does not shard (drop --shard)");
    }
    if plan.cells.iter().any(|c| c.arm.system().planar().is_some()) {
        bail!("--mujoco-judge judges a robot's URDF: the paper's planar arm has no MuJoCo model");
    }
    let judge = MujocoJudge::new(model, "--mujoco-judge")?;
    let started = Instant::now();
    let work = |c: &Cell| obstacle_cells::run_judged(c, &plan.window, &judge);
    let (results, verdicts) = run_all(&plan.cells, threads, "obstacles", work)?
        .into_iter()
        .unzip();
    let wall = Some(started.elapsed().as_secs_f64());
    finish(args, plan, (results, verdicts), wall)?;
    Ok(())
}

/// `chaosctl merge` of obstacles shards: the same CSV, table and plot as the unsharded run.
pub fn merge(args: ObstaclesCmd, files: Vec<Loaded>) -> Result<()> {
    let plan = plan(&args)?;
    if args.mujoco_judge.is_some() {
        bail!("--mujoco-judge runs the whole study: shards carry no verdicts (run it unsharded)");
    }
    let results: Vec<RunResult> = shard::collect(&grid(&plan), files)?;
    let verdicts = vec![None; results.len()];
    finish(&args, &plan, (results, verdicts), None)
}

/// Writes the CSV and plot and prints the table; `wall` is the time of a local run.
fn finish(
    args: &ObstaclesCmd,
    plan: &Plan,
    (results, verdicts): (Vec<RunResult>, Vec<Option<Result<Verdict, String>>>),
    wall: Option<f64>,
) -> Result<()> {
    let rows: Vec<Row> = plan
        .cells
        .iter()
        .zip(results)
        .zip(verdicts)
        .map(|((c, r), verdict)| {
            let (summary, motion, k01, error) = match r {
                Ok((s, m, k)) => (Some(s), Some(m), k, None),
                Err(e) => (None, None, None, Some(e)),
            };
            Row {
                mu: c.mu,
                safety: c.safety,
                q0: c.q0.clone(),
                summary,
                motion,
                k01,
                error,
                verdict,
            }
        })
        .collect();
    let csv = with_ext(&args.output, "csv");
    write_csv(&csv, &rows)?;
    let mut files = plot(&args.output, plan, &rows)?;
    print_header(plan, rows.len(), wall);
    print_table(plan, &rows, plan.clearance);
    if let Some(model) = &args.mujoco_judge {
        let path = suffixed(&args.output, "-mujoco.csv");
        judged::write_csv(&path, &rows)?;
        judged::print(model, plan.clearance, &rows, &plan.mus, &plan.filters);
        files.push(path);
    }
    super::print_written(&[std::slice::from_ref(&csv), &files[..]].concat());
    Ok(())
}

/// PREFIX + `tail` (PREFIX-mujoco.csv beside PREFIX.csv).
fn suffixed(prefix: &Path, tail: &str) -> PathBuf {
    let mut s = prefix.as_os_str().to_owned();
    s.push(tail);
    PathBuf::from(s)
}

fn print_header(plan: &Plan, runs: usize, wall: Option<f64>) {
    let q0 = &plan.q0;
    let wall = wall.map_or_else(
        || "merged from shards".to_string(),
        |w| format!("in {w:.1} s wall"),
    );
    println!(
        "chaosd obstacles: {} obstacle(s) {}; required clearance {} m; {} runs of {} s ({} s simulated {wall})",
        plan.obstacles.len(),
        plan.obstacles.join(", "),
        plan.clearance,
        runs,
        plan.window.duration,
        runs as f64 * plan.window.duration,
    );
    println!(
        "  starts: q1 varied, others from ({}); RMS tracking from {} s; Poincaré section from {} s",
        fmt_list(&q0[1..]),
        plan.window.rms_from,
        plan.window.section_from
    );
    if !plan.off.starts_with("the paper's") {
        println!(
            "  filter off: {}: nothing but the filter keeps the links out of the obstacles",
            plan.off
        );
    }
}

/// Sorted finite values.
fn sorted(v: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut v: Vec<f64> = v.filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v
}

fn median(v: &[f64]) -> Option<f64> {
    match v.len() {
        0 => None,
        n if n % 2 == 1 => Some(v[n / 2]),
        n => Some(0.5 * (v[n / 2 - 1] + v[n / 2])),
    }
}

/// "worst / median" with `fmt`; `worst_is_max` picks the end of the sorted list.
fn worst_median(v: &[f64], worst_is_max: bool, fmt: impl Fn(f64) -> String) -> String {
    let worst = if worst_is_max { v.last() } else { v.first() };
    match (worst, median(v)) {
        (Some(w), Some(m)) => format!("{} / {}", fmt(*w), fmt(m)),
        _ => "–".into(),
    }
}

fn secs(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else {
        format!("{v:.3}")
    }
}

fn metres(v: f64) -> String {
    format!("{v:+.4}")
}

fn sci(v: f64) -> String {
    format!("{v:.1e}")
}

/// "12 irregular, 8 period-1, …" in order of frequency.
fn class_counts(rows: &[&Row]) -> String {
    let mut counts: Vec<(String, usize)> = Vec::new();
    for r in rows {
        let label = match (&r.motion, &r.error) {
            (Some(m), _) => m.label(),
            (None, _) => "failed".into(),
        };
        match counts.iter_mut().find(|(l, _)| *l == label) {
            Some(c) => c.1 += 1,
            None => counts.push((label, 1)),
        }
    }
    counts.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    counts
        .iter()
        .map(|(l, c)| format!("{c} {l}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The aggregated table, one line per μ × filter, as Markdown (pasted into docs/analysis.md as is).
fn print_table(plan: &Plan, rows: &[Row], clearance: f64) {
    println!(
        "| μ | filter | runs (start in contact) | contact (s) worst / median | contact after getting clear (s) worst | closer than {clearance} m (s) worst / median | min clearance after clear (m) worst / median | RMS tracking after {} s (m) worst / median | Poincaré class | left the null space (s) worst / median |",
        plan.window.rms_from
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for &mu in &plan.mus {
        for &on in &plan.filters {
            let group: Vec<&Row> = rows
                .iter()
                .filter(|r| r.mu == mu && r.safety == on)
                .collect();
            let ok: Vec<&Summary> = group.iter().filter_map(|r| r.summary.as_ref()).collect();
            let inside = ok
                .iter()
                .filter(|s| s.start_in_contact == Some(true))
                .count();
            let never_clear = ok.iter().filter(|s| s.first_clear.is_none()).count();
            let failed = group.len() - ok.len();
            let contact = sorted(ok.iter().filter_map(|s| s.time_in_contact));
            let contact_after = sorted(ok.iter().filter_map(|s| s.time_in_contact_after_clear));
            let close = sorted(ok.iter().filter_map(|s| s.time_inside_clearance));
            let after = sorted(ok.iter().filter_map(|s| s.min_clearance_after_clear));
            let rms = sorted(ok.iter().map(|s| s.rms_tracking_error));
            let left = sorted(ok.iter().map(|s| s.safety_left_null_space_time));
            let mut runs = format!("{} ({inside})", group.len());
            if never_clear > 0 {
                runs.push_str(&format!(", {never_clear} never clear"));
            }
            if failed > 0 {
                runs.push_str(&format!(", {failed} failed"));
            }
            println!(
                "| {mu} | {} | {runs} | {} | {} | {} | {} | {} | {} | {} |",
                if on { "on" } else { "off" },
                worst_median(&contact, true, secs),
                contact_after
                    .last()
                    .map(|v| secs(*v))
                    .unwrap_or_else(|| "–".into()),
                worst_median(&close, true, secs),
                worst_median(&after, false, metres),
                worst_median(&rms, true, sci),
                class_counts(&group),
                if on {
                    worst_median(&left, true, secs)
                } else {
                    "–".into()
                },
            );
        }
    }
    let contact_after: Vec<&Row> = rows
        .iter()
        .filter(|r| {
            r.safety
                && r.summary
                    .as_ref()
                    .and_then(|s| s.time_in_contact_after_clear)
                    .is_some_and(|t| t > 0.0)
        })
        .collect();
    println!(
        "  filter on: {} run(s) in contact after first getting clear; starts in contact are pushed out by t = {}",
        contact_after.len(),
        sorted(
            rows.iter()
                .filter(|r| r.safety)
                .filter_map(|r| r.summary.as_ref())
                .filter(|s| s.start_in_contact == Some(true))
                .filter_map(|s| s.first_clear)
        )
        .last()
        .map(|t| format!("{t:.3} s at the latest"))
        .unwrap_or_else(|| "– (none started inside)".into())
    );
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    let file =
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = std::io::BufWriter::new(file);
    writeln!(
        w,
        "mu,safety,q1,q0,start_in_contact,time_in_contact,time_inside_clearance,time_in_safety_zone,\
         min_clearance,first_clear,min_clearance_after_clear,time_in_contact_after_clear,\
         rms_tracking_error,max_tracking_error,track_lost_fraction,class,period,k01,\
         safety_active_time,left_null_space_time,infeasible_steps,min_joint_margin,error"
    )?;
    let o = |v: Option<f64>| v.map(|x| format!("{x:.6e}")).unwrap_or_default();
    for r in rows {
        let q0 =
            r.q0.iter()
                .map(|x| format!("{x}"))
                .collect::<Vec<_>>()
                .join(";");
        write!(
            w,
            "{},{},{},{q0},",
            r.mu,
            if r.safety { "on" } else { "off" },
            r.q0[0]
        )?;
        match &r.summary {
            Some(s) => write!(
                w,
                "{},{},{},{},{},{},{},{},{},{},{},",
                s.start_in_contact
                    .map(|b| b.to_string())
                    .unwrap_or_default(),
                o(s.time_in_contact),
                o(s.time_inside_clearance),
                o(Some(s.time_in_safety_zone)),
                o(s.min_clearance),
                o(s.first_clear),
                o(s.min_clearance_after_clear),
                o(s.time_in_contact_after_clear),
                o(Some(s.rms_tracking_error)),
                o(Some(s.max_tracking_error)),
                o(Some(s.track_lost_fraction)),
            )?,
            None => write!(w, ",,,,,,,,,,,")?,
        }
        let motion = r.motion.as_ref();
        write!(
            w,
            "{},{},{},",
            motion.map(|m| m.label()).unwrap_or_default(),
            motion
                .and_then(|m| m.period())
                .map(|p| p.to_string())
                .unwrap_or_default(),
            r.k01.map(|k| format!("{k:.4}")).unwrap_or_default()
        )?;
        match &r.summary {
            Some(s) => write!(
                w,
                "{},{},{},{},",
                o(Some(s.safety_active_time)),
                o(Some(s.safety_left_null_space_time)),
                s.safety_infeasible_steps,
                o(s.min_joint_margin)
            )?,
            None => write!(w, ",,,,")?,
        }
        writeln!(
            w,
            "{}",
            r.error.as_deref().unwrap_or_default().replace(',', ";")
        )?;
    }
    w.flush()?;
    Ok(())
}

/// Four panels over the start q1: time in contact, min clearance after getting clear, RMS
/// tracking (log10) and the time the filter left the null space; one colour per μ, filter off as
/// open circles, on as filled circles joined by a line.
fn plot(prefix: &Path, plan: &Plan, rows: &[Row]) -> Result<Vec<PathBuf>> {
    type Metric = fn(&Summary) -> Option<f64>;
    let metrics: [(&str, &str, Metric, bool); 4] = [
        (
            "time in contact (clearance < 0)",
            "time in contact (s)",
            |s| s.time_in_contact,
            false,
        ),
        (
            "minimum clearance after the start first got clear",
            "min clearance (m)",
            |s| s.min_clearance_after_clear,
            false,
        ),
        (
            "RMS tracking error after the transient",
            "log10 RMS error (m)",
            |s| Some(s.rms_tracking_error.max(1e-16).log10()),
            false,
        ),
        (
            "time the filter left the null space (tracking gave way)",
            "time (s)",
            |s| Some(s.safety_left_null_space_time),
            true,
        ),
    ];
    let clearance = plan.clearance;
    let panels = metrics
        .iter()
        .map(|(title, y_label, metric, only_on)| {
            let mut series = Vec::new();
            for (i, &mu) in plan.mus.iter().enumerate() {
                let color = PALETTE[i % PALETTE.len()];
                for &on in &plan.filters {
                    if *only_on && !on {
                        continue;
                    }
                    let points: Vec<(f64, f64)> = rows
                        .iter()
                        .filter(|r| r.mu == mu && r.safety == on)
                        .filter_map(|r| r.summary.as_ref().and_then(metric).map(|v| (r.q0[0], v)))
                        .collect();
                    let label = format!("μ = {mu}, filter {}", if on { "on" } else { "off" });
                    let style = if on {
                        Style::LineMarkers { width: 1, size: 3 }
                    } else {
                        Style::Markers {
                            size: 4,
                            filled: false,
                        }
                    };
                    series.push(Series::new(Some(label), color, style, points));
                }
            }
            let rules = if title.starts_with("minimum") {
                vec![
                    Rule {
                        value: clearance,
                        vertical: false,
                        color: DARK,
                        label: Some(format!("required clearance {clearance} m")),
                    },
                    Rule {
                        value: 0.0,
                        vertical: false,
                        color: GREY,
                        label: Some("contact".into()),
                    },
                ]
            } else {
                vec![]
            };
            // Head room above the data for the legend (drawn in the upper right).
            let ys = series
                .iter()
                .flat_map(|s| s.points.iter().map(|p| p.1))
                .chain(rules.iter().map(|r| r.value))
                .filter(|v| v.is_finite());
            let (lo, hi) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
            let y_range = (lo <= hi).then(|| {
                let span = (hi - lo).max(1e-3 * hi.abs().max(1.0));
                (lo - 0.05 * span, hi + 0.6 * span)
            });
            Panel::Chart(Chart {
                title: title.to_string(),
                x_label: "initial q1 (rad)".into(),
                y_label: y_label.to_string(),
                series,
                rules,
                y_range,
                legend: true,
                ..Default::default()
            })
        })
        .collect();
    Figure {
        title: Some(format!(
            "Obstacles {}: {} (filter off) vs the safety filter (on), {} s runs",
            plan.obstacles.join(", "),
            plan.off,
            plan.window.duration
        )),
        panels,
        cols: 2,
        panel_size: (800, 520),
    }
    .save(prefix)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn medians_and_worst() {
        assert_eq!(median(&[1.0, 2.0, 10.0]), Some(2.0));
        assert_eq!(median(&[1.0, 2.0, 3.0, 10.0]), Some(2.5));
        assert_eq!(median(&[]), None);
        let v = sorted([3.0, f64::NAN, 1.0, 2.0].into_iter());
        assert_eq!(v, vec![1.0, 2.0, 3.0]);
        assert_eq!(worst_median(&v, true, secs), "3.000 / 2.000");
        assert_eq!(worst_median(&v, false, secs), "1.000 / 2.000");
        assert_eq!(worst_median(&[], true, secs), "–");
    }
}
