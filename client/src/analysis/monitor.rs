//! `chaosctl monitor`: does the daemon's chaos monitor agree with the offline analysis, and does
//! `mu = "auto"` find a working gain on its own?
//!
//! Every (start, μ) of a sweep runs twice: once with a Benettin pair for the offline λ_max (the
//! reference the book trusts), once in the plain simulation with the daemon's own monitor
//! ([`control::monitor`]) watching, fed what the daemon's reporter feeds it. Then each start runs
//! with `mu = "auto"`, and again with a task edit and an obstacle edit half-way, as a live
//! `chaosctl set` would make them; as in the daemon, auto takes its gain from the model at the
//! start and after the edit ([`control::tune`]). The report is a confusion table (offline
//! verdict × monitor verdict) with the monitor's detection delay, and auto-μ against the best
//! fixed μ the analysis finds for the same start and against the smallest fixed μ of the sweep
//! that stabilises it (time to periodic, final μ, control effort ∫|Pyragas term|²).

use super::monitor_cells::{AutoCell, BestFixed, EditKind, FixedCell, Offline};
use super::parallel::{jobs, run_all};
use super::{ClassifyArgs, LyapunovArgs, ScanModelArgs, StartArgs};
use crate::subject::Subject;
use anyhow::{Context, Result};
use clap::Args;
use control::adapt::AutoMu;
use control::monitor::run::{Edit, Watched};
use control::monitor::{MonitorSettings, Verdict};
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
    /// γ of the auto runs (default: the config's, else the model's for the gain it chooses).
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
    Fixed(usize, Subject),
    Auto(usize, Subject, EditKind, Vec<Edit>),
    /// The start at the best fixed gain of the analysis (the auto set-up, μ fixed there).
    Best(usize, Subject),
}

enum Done {
    Fixed(FixedCell),
    Auto(AutoCell),
    Best(BestFixed),
}

pub fn run(args: MonitorCmd) -> Result<()> {
    crate::plot::make_room(&args.output)?;
    let base = Subject::load(&args.model.setup, None)?;
    let mus = args.model.mus(default_mus(&base))?;
    let starts = base.starts(&args.starts, args.model.setup.q0.is_some())?;
    let spec = args
        .lyapunov
        .spec(base.period(), base.dt(), args.classify.config()?)?;
    let settings = settings(&args)?;
    let tau = base.tau_and_t_on().0;
    let auto = auto_settings(&args, &base, tau)?;
    let duration = spec.duration;
    let mut work = Vec::new();
    for (i, s) in starts.iter().enumerate() {
        for &mu in &mus {
            let mut c = s.clone();
            c.set_mu(mu);
            c.feedback_mut().auto = None;
            c.check()
                .with_context(|| format!("μ = {mu}, start {}", i + 1))?;
            work.push(Job::Fixed(i, c));
        }
        // `mu = "auto"` as in a file: from 0 until the model's gain is in (at once here).
        let mut c = s.clone();
        c.set_mu(0.0);
        c.feedback_mut().auto = Some(auto);
        c.check().with_context(|| format!("start {}", i + 1))?;
        work.push(Job::Best(i, c.clone()));
        for edit in EditKind::ALL {
            match edits(&c, edit, duration) {
                Ok(Some(e)) => work.push(Job::Auto(i, c.clone(), edit, e)),
                Ok(None) => {}
                Err(e) => eprintln!("monitor: start {}: no {edit:?} edit run: {e:#}", i + 1),
            }
        }
    }
    let t0 = std::time::Instant::now();
    let done = run_all(&work, jobs(args.jobs), "monitor", |j| match j {
        Job::Fixed(i, c) => fixed(*i, c, &spec, settings).map(Done::Fixed),
        Job::Auto(i, c, kind, e) => {
            let w = c.watch(2.0 * duration, settings, e)?;
            Ok(Done::Auto(auto_cell(*i, *kind, e.first().map(|e| e.t), w)))
        }
        Job::Best(i, c) => best_fixed(*i, c, 2.0 * duration, settings).map(Done::Best),
    })?;
    let (mut fixed_cells, mut auto_cells, mut best) = (Vec::new(), Vec::new(), Vec::new());
    for d in done {
        match d? {
            Done::Fixed(f) => fixed_cells.push(f),
            Done::Auto(a) => auto_cells.push(a),
            Done::Best(b) => best.push(b),
        }
    }
    let report = super::monitor_report::Report::new(
        tau,
        starts.iter().map(Subject::q0).collect(),
        fixed_cells,
        auto_cells,
        best,
        auto,
        settings,
        duration,
        t0.elapsed().as_secs_f64(),
    );
    report.write(&args.output, args.json)
}

/// The μ range a sweep covers unless `--mu` says: the paper's planar arm is captured below
/// μ = 0.5 and quasi-periodic above; a robot's gains are larger (docs/panda-study.md).
fn default_mus(s: &Subject) -> &'static str {
    if s.dims() == 2 {
        "0:0.5:0.05"
    } else {
        "0:3:0.5"
    }
}

/// The edits of an auto run of `c` that makes `kind` half-way through a run of `2 × duration`
/// s, as a live `chaosctl set` (or `obstacle`) would: none for [`EditKind::None`], and no run
/// at all (None) for an obstacle edit without obstacles. An edit the set-up refuses (a radius
/// out of reach) is an error.
fn edits(c: &Subject, kind: EditKind, duration: f64) -> Result<Option<Vec<Edit>>> {
    let system = c.system();
    let at = duration;
    let edit = match kind {
        EditKind::None => return Ok(Some(Vec::new())),
        EditKind::Obstacle if system.obstacle_rows().is_empty() => return Ok(None),
        EditKind::Radius => Edit::of(system, at, |s| {
            *s.task_circle_mut().0 *= 1.1;
            Ok(())
        }),
        EditKind::Period => Edit::of(system, at, |s| {
            let period = s.task_circle_mut().1;
            *period *= 1.1;
            let tau = *period;
            s.feedback_section_mut().tau = Some(tau);
            Ok(())
        }),
        EditKind::Obstacle => Edit::of(system, at, |s| {
            let mut o = s.obstacle_rows().remove(0);
            s.remove_obstacle(0);
            o.center[0] += 0.05;
            s.add_obstacle(&o.center, o.radius, o.margin)
        }),
    };
    Ok(Some(vec![edit?]))
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

fn auto_settings(args: &MonitorCmd, base: &Subject, tau: f64) -> Result<AutoMu> {
    let mut a = base.feedback().auto.unwrap_or_default();
    if let Some(g) = args.gamma {
        (a.gamma, a.gamma_given) = (g, true);
    }
    a.max_mu = args.max_mu.unwrap_or(a.max_mu);
    a.check(tau)?;
    Ok(a)
}

/// `c` (μ = "auto") at the gain the model chooses for it from its start, fixed, for `duration` s.
fn best_fixed(
    start: usize,
    c: &Subject,
    duration: f64,
    settings: MonitorSettings,
) -> Result<BestFixed> {
    let system = c.system();
    let spec = control::tune::TuneSpec::of(system);
    let mu = control::tune::choose_gain(system, None, &spec)
        .map(|g| g.mu)
        .map_err(|e| e.to_string());
    let Ok(m) = mu else {
        return Ok(BestFixed {
            start,
            mu,
            verdict: Verdict::Unknown,
            periodic_at: None,
            effort: 0.0,
        });
    };
    let mut fixed = c.clone();
    fixed.set_mu(m);
    fixed.feedback_mut().auto = None;
    let w = fixed.watch(duration, settings, &[])?;
    Ok(BestFixed {
        start,
        mu,
        verdict: w.last.verdict,
        periodic_at: w.settled_at,
        effort: w.effort,
    })
}

/// A fixed-μ run of `c`: the offline λ_max (a run that yields none is labelled failed) and the
/// monitor's verdict on the same loop.
fn fixed(
    start: usize,
    c: &Subject,
    spec: &control::analysis::RunSpec,
    s: MonitorSettings,
) -> Result<FixedCell> {
    let offline = c
        .analyse(spec)
        .ok()
        .and_then(|a| a.lyapunov)
        .map(|l| (l.lambda_max, l.stderr));
    let w = c.watch(spec.duration, s, &[])?;
    let tau = c.tau_and_t_on().0;
    Ok(fixed_cell(start, c.mu(), tau, offline, &w))
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
        first_verdict: w
            .edges
            .iter()
            .find(|e| e.to != Verdict::Unknown)
            .map(|e| (e.to, e.t)),
        model: w.model,
        trace: w.trace,
    }
}
