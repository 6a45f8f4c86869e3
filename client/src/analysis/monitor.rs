//! `chaosctl monitor`: does the daemon's chaos monitor agree with the offline analysis, and does
//! `mu = "auto"` find a working gain on its own?
//!
//! Every (start, μ) of a sweep runs twice: once with a Benettin pair for the offline λ_max (the
//! reference the book trusts), once in the plain simulation with the daemon's own monitor
//! ([`control::monitor`]) watching, fed what the daemon's reporter feeds it. Then each start runs
//! with `mu = "auto"`, and again with a task edit and an obstacle edit half-way, as a live
//! `chaosctl set` would make them. The report is a confusion table (offline verdict × monitor
//! verdict) with the monitor's detection delay, and auto-μ against the smallest fixed μ that
//! stabilises the same start (time to periodic, final μ, control effort ∫|Pyragas term|²).

use super::monitor_cells::{AutoCell, EditKind, FixedCell, Offline};
use super::parallel::{jobs, run_all};
use super::{ClassifyArgs, LyapunovArgs, ScanModelArgs, StartArgs};
use crate::subject::Subject;
use anyhow::{Context, Result};
use clap::Args;
use control::adapt::AutoMu;
use control::law::LawParams;
use control::monitor::run::{watch, Edit, Watched};
use control::monitor::{MonitorSettings, Verdict};
use control::Config;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct MonitorCmd {
    #[command(flatten)]
    pub model: ScanModelArgs,
    #[command(flatten)]
    pub starts: StartArgs,
    #[command(flatten)]
    pub lyapunov: LyapunovArgs,
    #[command(flatten)]
    pub classify: ClassifyArgs,
    /// γ of the auto runs (default: the config's, else chaosd's default).
    #[arg(long)]
    pub gamma: Option<f64>,
    /// max_mu of the auto runs (default: the config's, else chaosd's default).
    #[arg(long = "max-mu")]
    pub max_mu: Option<f64>,
    /// The monitor's periodic threshold (rad/s; default: the daemon's).
    #[arg(long = "periodic-residual")]
    pub periodic_residual: Option<f64>,
    /// Worker threads (default: every core).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Output prefix: writes PREFIX.json, PREFIX-cells.csv, PREFIX.png and PREFIX.svg.
    #[arg(long, default_value = "monitor")]
    pub output: PathBuf,
    /// Print the report as JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

enum Job {
    Fixed(usize, Config),
    Auto(usize, Config, EditKind),
}

enum Done {
    Fixed(FixedCell),
    Auto(AutoCell),
}

pub fn run(args: MonitorCmd) -> Result<()> {
    if let Some(cfg) = crate::spatial::load(&args.model.setup, None)? {
        return spatial(&args, &cfg);
    }
    let (base, mus) = args.model.load("0:0.5:0.05")?;
    let starts = args.starts.configs(&base, args.model.setup.q0.is_some())?;
    let spec = args
        .lyapunov
        .spec(base.task.period, base.sim.dt, args.classify.config()?)?;
    let settings = settings(&args)?;
    let auto = auto_settings(&args, &base)?;
    let mut work = Vec::new();
    for (i, s) in starts.iter().enumerate() {
        for &mu in &mus {
            let mut c = s.clone();
            c.feedback.mu = mu;
            c.feedback.auto = None;
            work.push(Job::Fixed(i, c));
        }
        let mut c = s.clone();
        c.feedback.auto = Some(auto);
        c.validate()?;
        for edit in [
            EditKind::None,
            EditKind::Radius,
            EditKind::Period,
            EditKind::Obstacle,
        ] {
            if edit != EditKind::Obstacle || !c.control.obstacles.is_empty() {
                work.push(Job::Auto(i, c.clone(), edit));
            }
        }
    }
    let duration = spec.duration;
    let t0 = std::time::Instant::now();
    let done = run_all(&work, jobs(args.jobs), "monitor", |j| match j {
        Job::Fixed(i, c) => Done::Fixed(fixed(*i, c, &spec, settings)),
        Job::Auto(i, c, e) => Done::Auto(auto_run(*i, c, *e, 2.0 * duration, settings)),
    })?;
    let (mut fixed_cells, mut auto_cells) = (Vec::new(), Vec::new());
    for d in done {
        match d {
            Done::Fixed(f) => fixed_cells.push(f),
            Done::Auto(a) => auto_cells.push(a),
        }
    }
    let report = super::monitor_report::Report::new(
        base.tau(),
        starts.iter().map(Config::q0).collect(),
        fixed_cells,
        auto_cells,
        auto,
        settings,
        duration,
        t0.elapsed().as_secs_f64(),
    );
    report.write(&args.output, args.json)
}

/// A spatial robot: each start (`--start`, else its config's), the μ sweep, and one auto run
/// per start (no edits: they act on the planar arm's parameter block).
fn spatial(args: &MonitorCmd, cfg: &control::config::spatial::SpatialConfig) -> Result<()> {
    let mus = match &args.model.mu {
        Some(r) => r.0.clone(),
        None => super::parse_range("0:3:0.5").map_err(anyhow::Error::msg)?,
    };
    let settings = settings(args)?;
    let tau = cfg.feedback.tau.unwrap_or(cfg.task.period);
    let mut auto = cfg.feedback.auto.unwrap_or_default();
    auto.gamma = args.gamma.unwrap_or(auto.gamma);
    auto.max_mu = args.max_mu.unwrap_or(auto.max_mu);
    auto.check(tau)?;
    let l = &args.lyapunov;
    let spec = l.spec(cfg.task.period, cfg.sim.dt, args.classify.config()?)?;
    let r = &cfg.robot;
    let chain = std::sync::Arc::new(rt::robot::load(
        &r.description,
        r.base.as_deref(),
        r.tip.as_deref(),
    )?);
    // Each start checked against the robot once, named by its number.
    let starts =
        Subject::Robot(Box::new(cfg.clone()), chain.clone()).starts(&args.starts, false)?;
    let q0s: Vec<Vec<f64>> = starts.iter().map(Subject::q0).collect();
    let mut work: Vec<(usize, Option<f64>)> = Vec::new();
    for i in 0..q0s.len() {
        work.extend(mus.iter().map(|&mu| (i, Some(mu))));
        work.push((i, None)); // the auto run
    }
    let t0 = std::time::Instant::now();
    let done = run_all(
        &work,
        jobs(args.jobs),
        "monitor",
        |&(i, mu)| -> Result<Done> {
            let mut c = cfg.clone();
            c.sim.q0 = Some(q0s[i].clone());
            c.feedback.auto = mu.is_none().then_some(auto);
            c.feedback.mu = mu.unwrap_or(0.0); // checked when the run sets the robot up
            let subject = Subject::Robot(Box::new(c), chain.clone());
            let Some(mu) = mu else {
                let w = subject.watch(2.0 * l.duration, settings)?;
                return Ok(Done::Auto(auto_cell(i, EditKind::None, None, w)));
            };
            let run = subject.analyse(&spec)?;
            let e = run.lyapunov.context("the run produced no exponent")?;
            let w = subject.watch(l.duration, settings)?;
            let offline = Some((e.lambda_max, e.stderr));
            Ok(Done::Fixed(fixed_cell(i, mu, tau, offline, &w)))
        },
    )?;
    let (mut fixed_cells, mut auto_cells) = (Vec::new(), Vec::new());
    for d in done {
        match d? {
            Done::Fixed(f) => fixed_cells.push(f),
            Done::Auto(a) => auto_cells.push(a),
        }
    }
    let report = super::monitor_report::Report::new(
        tau,
        q0s,
        fixed_cells,
        auto_cells,
        auto,
        settings,
        l.duration,
        t0.elapsed().as_secs_f64(),
    );
    report.write(&args.output, args.json)
}

fn settings(args: &MonitorCmd) -> Result<MonitorSettings> {
    let mut s = MonitorSettings::default();
    if let Some(r) = args.periodic_residual {
        if !(r > 0.0 && r <= 1.0) {
            anyhow::bail!("--periodic-residual {r}: must be a number in (0, 1] rad/s");
        }
        s.periodic_residual = r;
    }
    Ok(s)
}

fn auto_settings(args: &MonitorCmd, base: &Config) -> Result<AutoMu> {
    let mut a = base.feedback.auto.unwrap_or_default();
    a.gamma = args.gamma.unwrap_or(a.gamma);
    a.max_mu = args.max_mu.unwrap_or(a.max_mu);
    a.check(base.tau())?;
    Ok(a)
}

fn fixed(
    start: usize,
    c: &Config,
    spec: &control::analysis::RunSpec,
    s: MonitorSettings,
) -> FixedCell {
    let offline = Subject::Planar(c.clone())
        .analyse(spec)
        .ok()
        .and_then(|a| a.lyapunov)
        .map(|l| (l.lambda_max, l.stderr));
    let w = watch(c, spec.duration, s, &[]);
    fixed_cell(start, c.feedback.mu, c.tau(), offline, &w)
}

/// A fixed-μ cell from the offline (λ_max, standard error) and the watched run.
fn fixed_cell(
    start: usize,
    mu: f64,
    tau: f64,
    offline: Option<(f64, f64)>,
    w: &Watched,
) -> FixedCell {
    let label = match offline {
        Some((l, e)) if l - 2.0 * e > 0.0 => Offline::Chaotic,
        Some((l, e)) if l + 2.0 * e < 0.0 => Offline::Stable,
        Some(_) => Offline::Marginal,
        None => Offline::Failed,
    };
    FixedCell {
        start,
        mu,
        lambda_max: offline.map(|o| o.0),
        stderr: offline.map(|o| o.1),
        offline: label,
        verdict: w.last.verdict,
        first_verdict_periods: w.edges.first().map(|e| e.t / tau),
        first_verdict: w.edges.first().map_or(Verdict::Unknown, |e| e.to),
        settled_periods: settled(w, tau),
        effort: w.effort,
    }
}

/// Periods from the start until the final verdict was reached (None if it never was one).
fn settled(w: &Watched, tau: f64) -> Option<f64> {
    (w.last.verdict != Verdict::Unknown).then(|| w.last.since / tau)
}

fn auto_run(
    start: usize,
    c: &Config,
    edit: EditKind,
    duration: f64,
    s: MonitorSettings,
) -> AutoCell {
    let at = duration / 2.0;
    let radius = |p: &mut LawParams| p.task.radius *= 1.1;
    let period = |p: &mut LawParams| {
        p.task.period *= 1.1;
        p.core.tau = p.task.period;
    };
    let obstacle = |p: &mut LawParams| {
        if let Some(mut o) = p.obstacles.remove(0) {
            o.center.x += 0.05;
            let _ = p.obstacles.push(o);
        }
    };
    let apply: Option<&dyn Fn(&mut LawParams)> = match edit {
        EditKind::None => None,
        EditKind::Radius => Some(&radius),
        EditKind::Period => Some(&period),
        EditKind::Obstacle => Some(&obstacle),
    };
    let edits: Vec<Edit> = apply
        .map(|apply| Edit { t: at, apply })
        .into_iter()
        .collect();
    let w = watch(c, duration, s, &edits);
    auto_cell(start, edit, (edit != EditKind::None).then_some(at), w)
}

fn auto_cell(start: usize, edit: EditKind, edit_at: Option<f64>, w: Watched) -> AutoCell {
    let mu_at_edit = edit_at
        .and_then(|at| w.trace.iter().take_while(|p| p.t < at).last())
        .map(|p| p.mu);
    AutoCell {
        start,
        edit,
        edit_at,
        verdict: w.last.verdict,
        periodic_at: w.settled_at,
        mu_final: w.mu_final,
        mu_at_edit,
        effort: w.effort,
        trace: w.trace,
    }
}
