//! `chaosctl lyapunov`: λ_max of one closed-loop run by Benettin's method, with its standard error,
//! on any arm (one [`Subject::analyse`] run with a partner: the section and the run's summary
//! come with it).

use super::{fmt_list, verdict, ClassifyArgs, LyapunovArgs};
use crate::setup::ModelArgs;
use crate::subject::Subject;
use anyhow::{Context, Result};
use clap::Args;
use control::analysis::{Classification, Growth, RunAnalysis, RunSpec};
use control::Summary;
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct LyapunovCmd {
    #[command(flatten)]
    pub model: ModelArgs,
    #[command(flatten)]
    pub lyapunov: LyapunovArgs,
    #[command(flatten)]
    pub classify: ClassifyArgs,
    /// Write the log growth of every renormalisation interval as CSV (t0,t1,log_growth).
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

/// What `lyapunov --json` prints.
#[derive(Serialize)]
pub struct LyapunovReport {
    pub lambda_max: f64,
    pub stderr: f64,
    pub window: [f64; 2],
    pub intervals: usize,
    pub blocks: Vec<f64>,
    pub d0: f64,
    pub renorm: f64,
    pub mu: f64,
    pub tau: f64,
    pub t_on: f64,
    pub q0: Vec<f64>,
    pub qd0: Vec<f64>,
    /// Whether the delay history was part of the perturbed and renormalised state (μ ≠ 0).
    pub history_in_norm: bool,
    pub verdict: &'static str,
    pub section: Classification,
    pub run: Summary,
}

pub fn run(args: LyapunovCmd) -> Result<()> {
    let subject = Subject::load(&args.model.setup, args.model.mu)?;
    subject.check()?;
    let spec = args
        .lyapunov
        .spec(subject.period(), subject.dt(), args.classify.config()?)?;
    let run = subject.analyse(&spec)?;
    let report = build_report(&subject, &spec, &run)?;
    if let Some(path) = &args.csv {
        write_growth(path, &run.growth)?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    print_report(&report);
    if let Some(p) = &args.csv {
        println!("  growth per interval  {}", p.display());
    }
    Ok(())
}

fn build_report(s: &Subject, spec: &RunSpec, run: &RunAnalysis) -> Result<LyapunovReport> {
    let l = spec.lyapunov.context("no Lyapunov spec")?;
    let e = run
        .lyapunov
        .as_ref()
        .context("the run produced no exponent")?;
    let (tau, t_on) = s.tau_and_t_on();
    Ok(LyapunovReport {
        lambda_max: e.lambda_max,
        stderr: e.stderr,
        window: e.window,
        intervals: e.intervals,
        blocks: e.blocks.clone(),
        d0: l.d0,
        renorm: l.renorm,
        mu: s.mu(),
        tau,
        t_on,
        q0: s.q0(),
        qd0: s.start_coords(true),
        history_in_norm: s.feedback().enabled && s.mu() != 0.0,
        verdict: verdict(e),
        section: run.classification.clone(),
        run: run.summary.clone(),
    })
}

fn write_growth(path: &PathBuf, growth: &[Growth]) -> Result<()> {
    let file =
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = std::io::BufWriter::new(file);
    writeln!(w, "t0,t1,log_growth")?;
    for g in growth {
        writeln!(w, "{:.6},{:.6},{:.9e}", g.t0, g.t1, g.log_growth)?;
    }
    w.flush()?;
    Ok(())
}

fn print_report(r: &LyapunovReport) {
    println!(
        "chaosd Lyapunov exponent: μ = {}, τ = {} s, t_on = {} s, q0 = ({}), q̇0 = ({})",
        r.mu,
        r.tau,
        r.t_on,
        fmt_list(&r.q0),
        fmt_list(&r.qd0)
    );
    println!(
        "  λ_max            {:+.4} ± {:.4} 1/s (standard error from {} blocks)",
        r.lambda_max,
        r.stderr,
        r.blocks.len()
    );
    println!(
        "  window           {:.0}..{:.0} s: {} renormalisations every {} s, d0 = {:e}{}",
        r.window[0],
        r.window[1],
        r.intervals,
        r.renorm,
        r.d0,
        if r.history_in_norm {
            ", delay history perturbed and renormalised"
        } else {
            ""
        }
    );
    println!(
        "  blocks           [{}] 1/s (drift here means the window is too short)",
        r.blocks
            .iter()
            .map(|b| format!("{b:+.3}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!("  verdict          {}", r.verdict);
    let s = &r.section;
    let k =
        s.k.map(|k| format!(", 0-1 test K = {k:.2}"))
            .unwrap_or_default();
    let ret = s
        .returns
        .first()
        .map(|r| format!(", |x_k − x_(k−1)| ≤ {r:.2e}"))
        .unwrap_or_default();
    println!("  Poincaré section {}{k}{ret}", s.motion.label());
    println!(
        "  tracking         RMS {:.3e} m after the transient{}",
        r.run.rms_tracking_error,
        r.run
            .min_clearance
            .map(|c| format!(
                "; obstacle clearance min {c:+.3} m, {:.1} s in a safety zone",
                r.run.time_in_safety_zone
            ))
            .unwrap_or_default()
    );
}
