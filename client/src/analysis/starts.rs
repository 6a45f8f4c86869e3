//! `chaosctl starts`: from how many starts does the set-up become periodic inside every limit?
//!
//! A method that works from one start is a demonstration; the question a user of a real arm asks
//! is how many of the postures it may be switched on in lead to the cycle without breaking a
//! joint's position, speed, acceleration or jerk limit on the way. This is the basin study of
//! docs/panda-study.md as one command: starts drawn at random (a fixed, seeded draw, the same on
//! every machine) near the set-up's start or anywhere in the joint box, each run once as
//! `chaosctl simulate` runs it, and judged by the first rule it breaks. The draw of start k
//! depends on the seed and k only, so a larger `--count` adds starts and keeps the earlier ones,
//! and a shard (`--shard I/N`, merged by `chaosctl merge`) holds exactly the unsharded rows.

use super::parallel::jobs;
use super::shard::{self, Loaded, Shard};
use crate::setup::ModelArgs;
use crate::subject::Subject;
use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use control::command::CommandMode;
use control::rigid_body::RigidBodyConfig;
use control::Summary;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct StartsCmd {
    #[command(flatten)]
    pub model: ModelArgs,
    /// Where the starts are drawn: near (each joint within ±--spread of the set-up's start) or
    /// box (anywhere in the joint box, --margin of each range in from its limits).
    #[arg(long, value_enum, default_value_t = Draw::Near)]
    pub draw: Draw,
    /// How many starts.
    #[arg(long, default_value_t = 100)]
    pub count: usize,
    /// The draw's seed: the same seed, the same starts on every machine.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// `--draw near`: each joint within ± this of the set-up's start (rad).
    #[arg(long, default_value_t = 0.5, allow_hyphen_values = true)]
    pub spread: f64,
    /// `--draw box`: the fraction of each joint's range left out at either end.
    #[arg(long, default_value_t = 0.1)]
    pub margin: f64,
    /// Each start's joint rates within ± this (rad/s) [default: 0.1 near, 0.2 in the box].
    #[arg(long, allow_hyphen_values = true)]
    pub rates: Option<f64>,
    /// A residual check T:TOL: the mean period residual over the 10 periods before T s is at
    /// most TOL rad/s. Repeat it; each run lasts the latest T.
    #[arg(long = "check", value_parser = parse_check, default_values = ["60:1e-3", "120:1e-6"])]
    pub checks: Vec<Check>,
    /// The tracking check T:TOL: from T s on the tool stays within TOL m of its path. A start
    /// on a cycle the law cannot track on (a damped pseudo-inverse near a singular posture)
    /// fails it, however periodic [default: 10:5e-3, or from half a shorter run].
    #[arg(long, value_parser = parse_check)]
    pub tracking: Option<Check>,
    /// An acceleration peak inside the first this many seconds is named apart ("acceleration
    /// at the start": the hand at rest on a moving path), not as the self-motion's.
    #[arg(long, default_value_t = 0.1)]
    pub start_window: f64,
    /// What the starts run against: law (the law's own model, as `simulate` runs it) or
    /// rigid-body (the command interface of the file's `[command]` and the dynamic arm of its
    /// `[plant.rigid_body]`: friction, payload, mass scale, sensor noise; at `daemon.rate_hz`
    /// with `plant.substeps`), judged on the arm's own motion (its true state, not the
    /// sensors' reading of it). Robots only.
    #[arg(long, value_enum, default_value_t = Against::Law)]
    pub plant: Against,
    /// With --plant rigid-body: the command interface, acceleration, position, velocity or
    /// torque [default: the file's `command.mode`].
    #[arg(long, value_parser = parse_mode)]
    pub mode: Option<CommandMode>,
    /// Worker threads (default: every core).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Output prefix: writes PREFIX.csv, one row per start.
    #[arg(long, default_value = "starts")]
    pub output: PathBuf,
    /// Print the verdicts as JSON instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Run only shard I of N (0 ≤ I < N; start k goes to shard k mod N) and write
    /// PREFIX.shard-I-of-N.json; `chaosctl merge` makes the table from all N.
    #[arg(long, value_parser = shard::parse_shard, value_name = "I/N")]
    pub shard: Option<Shard>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Draw {
    Near,
    Box,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Against {
    Law,
    RigidBody,
}

fn parse_mode(s: &str) -> Result<CommandMode, String> {
    CommandMode::parse(s).map_err(|e| e.to_string())
}

/// `--check T:TOL`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Check {
    pub at: f64,
    pub tol: f64,
}

fn parse_check(s: &str) -> Result<Check, String> {
    let bad = || format!("{s:?}: expected T:TOL with T > 0 s and TOL > 0 rad/s, e.g. 60:1e-3");
    let (t, tol) = s.split_once(':').ok_or_else(bad)?;
    let num = |x: &str| {
        x.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v > 0.0)
    };
    match (num(t), num(tol)) {
        (Some(at), Some(tol)) => Ok(Check { at, tol }),
        _ => Err(bad()),
    }
}

/// One start's run, as far as the verdict needs it; a shard file carries exactly this.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StartEnd {
    /// The mean period residual over the 10 periods before each check's time (rad/s).
    pub residuals: Vec<Option<f64>>,
    /// Peaks over the whole run, against the limits (1 = at the limit).
    pub speed: f64,
    pub accel: f64,
    /// The acceleration peak of the first `--start-window` seconds alone.
    pub accel_start: f64,
    pub jerk: f64,
    /// The largest tracking error from the tracking check's time on (m).
    pub tracking: f64,
    /// The smallest distance to a position limit (rad; ≤ 0: at or past it).
    pub margin: Option<f64>,
    /// The fraction of the run's time the safety filter changed the command.
    pub filter_active: f64,
    pub finite: bool,
}

/// Every start of the study: its coordinates, and its set-up (or why it was refused).
struct Plan {
    base: Subject,
    starts: Vec<(Vec<f64>, Vec<f64>)>,
    cells: Vec<Result<Subject, String>>,
    duration: f64,
    tracking: Check,
    plant: Option<Plant>,
}

/// `--plant rigid-body`: the dynamic arm, the period and the substeps the live pair would use.
#[derive(Clone, Debug)]
struct Plant {
    config: RigidBodyConfig,
    dt: f64,
    substeps: u32,
}

fn plan(args: &StartsCmd) -> Result<Plan> {
    check_args(args)?;
    let mut base = Subject::load(&args.model.setup, args.model.mu)?;
    let duration = args.checks.iter().map(|c| c.at).fold(0.0, f64::max);
    let tracking = args.tracking.unwrap_or(Check {
        at: (duration / 2.0).min(10.0),
        tol: 5e-3,
    });
    if tracking.at >= duration {
        bail!(
            "--tracking {}:{}: the check's time must come before the run ends at {duration} s",
            tracking.at,
            tracking.tol
        );
    }
    base.set_duration(Some(duration), Some(tracking.at))?;
    let plant = plant(args, &mut base)?;
    let boxes = joint_box(&base, args)?;
    let rates = args.rates.unwrap_or(match args.draw {
        Draw::Near => 0.1,
        Draw::Box => 0.2,
    });
    let starts: Vec<_> = (0..args.count)
        .map(|k| draw(args.seed, k as u64, &boxes, rates))
        .collect();
    let cells = starts
        .iter()
        .map(|(q, qd)| {
            base.with_start_coords(false, q.clone())
                .and_then(|s| s.with_start_coords(true, qd.clone()))
                .map_err(|e| format!("{e:#}"))
        })
        .collect();
    Ok(Plan {
        base,
        starts,
        cells,
        duration,
        tracking,
        plant,
    })
}

/// The dynamic arm of `--plant rigid-body` from the file's `[daemon]` and `[plant]` tables, read
/// and checked as the live processes read them, then by one tick of the loop (the interface, its
/// limits and the plant's physics), with `--mode` set on the robot.
fn plant(args: &StartsCmd, base: &mut Subject) -> Result<Option<Plant>> {
    if args.plant == Against::Law {
        if args.mode.is_some() {
            bail!("--mode is the command interface of --plant rigid-body; the law's own model takes accelerations");
        }
        return Ok(None);
    }
    let Some(robot) = base.system_mut().robot_mut() else {
        bail!("--plant rigid-body: the paper's planar arm has no mass model; use a robot (e.g. --preset panda)");
    };
    if let Some(mode) = args.mode {
        robot.own_mut().command.mode = mode;
    }
    // The two tables as the live daemon and plant read and check them.
    let daemon = daemon::config::DaemonSetup::from_system(base.system().clone())?.daemon;
    let plant = plant::PlantConfig::from_table(base.system().tables().1.as_ref())?;
    let p = Plant {
        config: plant.rigid_body,
        dt: 1.0 / daemon.rate_hz,
        substeps: plant.substeps,
    };
    control::with_dof!(base.n(), N => {
        control::commanded::run_at::<N>(base.system(), &p.config, p.dt, p.substeps, p.dt, 0.0, &[])?;
    });
    Ok(Some(p))
}

fn check_args(args: &StartsCmd) -> Result<()> {
    if args.count == 0 || args.count > 1_000_000 {
        bail!("--count {}: from 1 to 1000000 starts", args.count);
    }
    let positive = |v: f64| v.is_finite() && v >= 0.0;
    if !positive(args.spread) || !(0.0..0.5).contains(&args.margin) {
        bail!("--spread must be ≥ 0 rad and --margin in [0, 0.5)");
    }
    if args.rates.is_some_and(|r| !positive(r)) {
        bail!("--rates must be a finite number ≥ 0 (rad/s)");
    }
    if !(args.start_window > 0.0 && args.start_window.is_finite()) {
        bail!("--start-window must be a finite number of seconds > 0");
    }
    Ok(())
}

/// Each joint's (low, high) to draw its angle from.
fn joint_box(base: &Subject, args: &StartsCmd) -> Result<Vec<(f64, f64)>> {
    let block = base.system().param_block();
    let limits = block.safety();
    let start = base.q0();
    (0..base.n())
        .map(|j| match args.draw {
            Draw::Near => Ok((start[j] - args.spread, start[j] + args.spread)),
            Draw::Box => {
                let (lo, hi) = (limits.q_min[j], limits.q_max[j]);
                if !(lo.is_finite() && hi.is_finite()) {
                    bail!(
                        "--draw box: joint {} has no position limits to draw between; use --draw near",
                        j + 1
                    );
                }
                let m = args.margin * (hi - lo);
                Ok((lo + m, hi - m))
            }
        })
        .collect()
}

/// Start `k` of the draw `seed`: its own generator, so that it does not depend on the count.
fn draw(seed: u64, k: u64, boxes: &[(f64, f64)], rates: f64) -> (Vec<f64>, Vec<f64>) {
    let mut u = control::basics::rng::uniform(control::basics::rng::mix(seed, k));
    let q = boxes
        .iter()
        .map(|&(lo, hi)| lo + (hi - lo) * (u() + 1.0) / 2.0)
        .collect();
    let qd = boxes.iter().map(|_| rates * u()).collect();
    (q, qd)
}

/// Runs one start to the latest check, with the summaries at the start window and each check.
fn run_start(
    cell: &Result<Subject, String>,
    args: &StartsCmd,
    plant: Option<&Plant>,
) -> Result<StartEnd, String> {
    let subject = cell.as_ref().map_err(Clone::clone)?;
    let mut ends = vec![args.start_window];
    ends.extend(args.checks.iter().map(|c| c.at));
    let Some(p) = plant else {
        let (report, at) = crate::simulate::run_subject_at(subject, &ends, |_| Ok(()))
            .map_err(|e| format!("{e:#}"))?;
        return Ok(start_end(&report.summary, &at));
    };
    let (duration, transient) = subject.duration();
    ends.push(duration);
    let system = subject.system();
    let (_, mut at) = control::with_dof!(subject.n(), N => {
        control::commanded::run_at::<N>(system, &p.config, p.dt, p.substeps, duration, transient, &ends)
    })
    .map_err(|e| e.to_string())?;
    let whole = at.pop().expect("the run's own end");
    Ok(start_end(&whole, &at))
}

fn start_end(whole: &Summary, at: &[Summary]) -> StartEnd {
    StartEnd {
        residuals: at[1..].iter().map(|s| s.period_residual_final).collect(),
        speed: whole.max_speed_ratio,
        accel: whole.max_accel_ratio,
        accel_start: at[0].max_accel_ratio,
        jerk: whole.max_jerk_ratio,
        tracking: whole.max_tracking_error,
        margin: whole.min_joint_margin,
        filter_active: whole.safety_active_time / whole.duration,
        finite: whole.finite,
    }
}

/// The first rule a start broke, or "periodic".
pub fn verdict(end: &StartEnd, tracking: Check, checks: &[Check]) -> String {
    let over = |v: f64| v > 1.0;
    if !end.finite {
        return "diverged".into();
    }
    if end.margin.is_some_and(|m| m <= 0.0) {
        return "position".into();
    }
    if over(end.speed) {
        return "speed".into();
    }
    if over(end.accel) {
        return match end.accel == end.accel_start {
            true => "acceleration at the start".into(),
            false => "acceleration".into(),
        };
    }
    if over(end.jerk) {
        return "jerk".into();
    }
    if end.tracking.is_nan() || end.tracking > tracking.tol {
        return "tracking".into();
    }
    for (c, r) in checks.iter().zip(&end.residuals) {
        if r.is_none_or(|r| r > c.tol) {
            return format!("slow at {} s", c.at);
        }
    }
    "periodic".into()
}

/// The grid a shard file names: the draw, the run and every start's whole set-up.
fn grid(args: &StartsCmd, plan: &Plan) -> shard::Grid {
    let head = format!(
        "{:?} {} {} {:?} {:?} {:?} {}",
        args.draw, args.seed, args.start_window, args.checks, args.tracking, plan.plant, plan.base
    );
    let parts = std::iter::once(head).chain(plan.cells.iter().map(|c| match c {
        Ok(s) => format!("{s}"),
        Err(e) => e.clone(),
    }));
    let labels = (0..plan.starts.len())
        .map(|k| format!("start {k}"))
        .collect();
    shard::Grid::new("starts", parts, labels)
}

pub fn run(args: StartsCmd) -> Result<()> {
    let plan = plan(&args)?;
    let threads = jobs(args.jobs);
    let work = |c: &Result<Subject, String>| run_start(c, &args, plan.plant.as_ref());
    let grid = || grid(&args, &plan);
    let (items, out) = (&plan.cells, &args.output);
    let Some(ends) = shard::run_or_shard("starts", args.shard, grid, items, out, threads, work)?
    else {
        return Ok(());
    };
    finish(&args, &plan, &ends)
}

/// `chaosctl merge` of starts shards: the same CSV and table as the unsharded run.
pub fn merge(args: StartsCmd, files: Vec<Loaded>) -> Result<()> {
    let plan = plan(&args)?;
    let ends: Vec<Result<StartEnd, String>> = shard::collect(&grid(&args, &plan), files)?;
    finish(&args, &plan, &ends)
}

/// What the study found, as `--json` prints it.
#[derive(Serialize)]
struct Found<'a> {
    robot: String,
    draw: Draw,
    seed: u64,
    duration: f64,
    /// The tracking check: within `tracking_tol` m of the path from `tracking_from` s on.
    tracking_from: f64,
    tracking_tol: f64,
    /// Starts run (the refused ones left out) and how many became periodic inside every limit.
    run: usize,
    periodic: usize,
    /// Starts on which the safety filter changed the command on more than 1 % of the run.
    filter_over_1_percent: usize,
    failures: Vec<(String, usize)>,
    starts: Vec<Row<'a>>,
}

#[derive(Serialize)]
struct Row<'a> {
    start: usize,
    q0: &'a [f64],
    qd0: &'a [f64],
    verdict: String,
    #[serde(flatten)]
    end: Option<&'a StartEnd>,
    refused: Option<&'a str>,
}

fn finish(args: &StartsCmd, plan: &Plan, ends: &[Result<StartEnd, String>]) -> Result<()> {
    let rows: Vec<Row> = plan
        .starts
        .iter()
        .zip(ends)
        .enumerate()
        .map(|(k, ((q0, qd0), end))| Row {
            start: k,
            q0,
            qd0,
            verdict: match end {
                Ok(e) => verdict(e, plan.tracking, &args.checks),
                Err(_) => "refused".into(),
            },
            end: end.as_ref().ok(),
            refused: end.as_ref().err().map(String::as_str),
        })
        .collect();
    let found = tally(args, plan, rows);
    write_csv(args, &found)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&found)?);
        return Ok(());
    }
    print_table(&found);
    super::print_written(&[crate::plot::with_ext(&args.output, "csv")]);
    Ok(())
}

fn tally<'a>(args: &StartsCmd, plan: &Plan, starts: Vec<Row<'a>>) -> Found<'a> {
    let ran = || starts.iter().filter(|r| r.end.is_some());
    let mut failures: Vec<(String, usize)> = Vec::new();
    for r in ran().filter(|r| r.verdict != "periodic") {
        match failures.iter_mut().find(|(v, _)| *v == r.verdict) {
            Some((_, n)) => *n += 1,
            None => failures.push((r.verdict.clone(), 1)),
        }
    }
    failures.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    Found {
        robot: plan.base.name(),
        draw: args.draw,
        seed: args.seed,
        duration: plan.duration,
        tracking_from: plan.tracking.at,
        tracking_tol: plan.tracking.tol,
        run: ran().count(),
        periodic: ran().filter(|r| r.verdict == "periodic").count(),
        filter_over_1_percent: ran()
            .filter(|r| r.end.is_some_and(|e| e.filter_active > 0.01))
            .count(),
        failures,
        starts,
    }
}

fn print_table(f: &Found) {
    let refused = f.starts.len() - f.run;
    println!(
        "{}: {} starts ({}, seed {}), {} s each{}",
        f.robot,
        f.starts.len(),
        match f.draw {
            Draw::Near => "near the set-up's start",
            Draw::Box => "across the joint box",
        },
        f.seed,
        f.duration,
        match refused {
            0 => String::new(),
            n => format!(
                "; {n} refused by the set-up's check (first: {})",
                first_refusal(f)
            ),
        }
    );
    println!(
        "periodic inside every limit, tracking within {} m from {} s: {} of {}",
        f.tracking_tol, f.tracking_from, f.periodic, f.run
    );
    for (v, n) in &f.failures {
        println!("  {v}: {n}");
    }
    if f.starts
        .iter()
        .any(|r| r.end.is_some_and(|e| e.filter_active > 0.0))
    {
        println!(
            "the safety filter changed the command on more than 1 % of the run on {} of {}",
            f.filter_over_1_percent, f.run
        );
    }
}

fn first_refusal(f: &Found) -> String {
    f.starts
        .iter()
        .find_map(|r| r.refused.map(|e| format!("start {}: {e}", r.start)))
        .unwrap_or_default()
}

fn write_csv(args: &StartsCmd, f: &Found) -> Result<()> {
    let path = crate::plot::with_ext(&args.output, "csv");
    crate::plot::make_room(&args.output)?;
    let mut out = std::io::BufWriter::new(
        std::fs::File::create(&path).with_context(|| format!("cannot write {}", path.display()))?,
    );
    let n = f.starts.first().map_or(0, |r| r.q0.len());
    let mut head: Vec<String> = vec!["start".into(), "verdict".into()];
    head.extend((1..=n).map(|j| format!("q{j}")));
    head.extend((1..=n).map(|j| format!("qd{j}")));
    head.extend(args.checks.iter().map(|c| format!("residual_{}s", c.at)));
    head.extend(
        [
            "speed_ratio",
            "accel_ratio",
            "accel_ratio_start",
            "jerk_ratio",
            "tracking_max",
            "min_joint_margin",
            "filter_active",
        ]
        .map(String::from),
    );
    writeln!(out, "{}", head.join(","))?;
    // Debug prints a float exactly and in exponent form where it is small (1e-14, not 0.0000…).
    let num = |v: f64| format!("{v:?}");
    let opt = |v: Option<f64>| v.map_or(String::new(), num);
    for r in &f.starts {
        let mut cells = vec![r.start.to_string(), r.verdict.clone()];
        cells.extend(r.q0.iter().chain(r.qd0).map(|&v| num(v)));
        match r.end {
            Some(e) => {
                cells.extend(e.residuals.iter().map(|&v| opt(v)));
                cells.extend([e.speed, e.accel, e.accel_start, e.jerk, e.tracking].map(num));
                cells.extend([opt(e.margin), num(e.filter_active)]);
            }
            None => cells.extend(std::iter::repeat_n(String::new(), args.checks.len() + 7)),
        }
        writeln!(out, "{}", cells.join(","))?;
    }
    out.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn end() -> StartEnd {
        StartEnd {
            residuals: vec![Some(5e-4), Some(5e-7)],
            speed: 0.5,
            accel: 0.6,
            accel_start: 0.2,
            jerk: 0.3,
            tracking: 1e-4,
            margin: Some(0.1),
            filter_active: 0.0,
            finite: true,
        }
    }

    const CHECKS: [Check; 2] = [
        Check {
            at: 60.0,
            tol: 1e-3,
        },
        Check {
            at: 120.0,
            tol: 1e-6,
        },
    ];
    const TRACKING: Check = Check {
        at: 10.0,
        tol: 5e-3,
    };

    #[test]
    fn the_verdict_names_the_first_rule_broken() {
        assert_eq!(verdict(&end(), TRACKING, &CHECKS), "periodic");
        let with = |f: fn(&mut StartEnd)| {
            let mut e = end();
            f(&mut e);
            verdict(&e, TRACKING, &CHECKS)
        };
        assert_eq!(with(|e| e.residuals[1] = Some(2e-6)), "slow at 120 s");
        assert_eq!(with(|e| e.residuals[0] = None), "slow at 60 s");
        assert_eq!(with(|e| e.tracking = 0.04), "tracking");
        assert_eq!(with(|e| e.tracking = f64::NAN), "tracking");
        assert_eq!(with(|e| (e.jerk, e.tracking) = (1.01, 0.04)), "jerk");
        assert_eq!(with(|e| e.accel = 1.2), "acceleration");
        assert_eq!(
            with(|e| (e.accel, e.accel_start) = (1.2, 1.2)),
            "acceleration at the start"
        );
        assert_eq!(with(|e| (e.speed, e.jerk) = (1.5, 2.0)), "speed");
        assert_eq!(with(|e| (e.margin, e.speed) = (Some(0.0), 2.0)), "position");
        assert_eq!(
            with(|e| (e.finite, e.margin) = (false, Some(-1.0))),
            "diverged"
        );
        // At a limit is inside it; a set-up without position limits has no position rule.
        assert_eq!(with(|e| (e.speed, e.margin) = (1.0, None)), "periodic");
    }

    #[test]
    fn a_start_is_drawn_from_its_seed_and_index_alone() {
        let boxes = [(-1.0, 1.0), (0.0, 2.0)];
        let a = draw(7, 3, &boxes, 0.1);
        assert_eq!(a, draw(7, 3, &boxes, 0.1));
        assert_ne!(a, draw(7, 4, &boxes, 0.1));
        assert_ne!(a, draw(8, 3, &boxes, 0.1));
        for k in 0..200 {
            let (q, qd) = draw(1, k, &boxes, 0.1);
            assert!(q.iter().zip(&boxes).all(|(v, (lo, hi))| v >= lo && v < hi));
            assert!(qd.iter().all(|v| v.abs() <= 0.1));
        }
    }

    #[test]
    fn checks_parse_and_reject() {
        assert_eq!(
            parse_check("60:1e-3"),
            Ok(Check {
                at: 60.0,
                tol: 1e-3
            })
        );
        for bad in ["60", "0:1e-3", "60:-1", "x:1", "60:nan", ""] {
            assert!(parse_check(bad).is_err(), "{bad}");
        }
    }
}
