//! `chaosctl sweep` on a spatial robot: for each μ and start, λ_max (Benettin, the planar norm) and
//! what the run did (final period residual, joint drift per period, speed, margin to the limits),
//! in parallel; writes PREFIX.csv and a two-panel figure (λ_max and log₁₀ residual against μ, a
//! line per start).

use crate::plot::{Chart, Figure, Panel, Rule, Series, Style, DARK, PALETTE};
use crate::spatial::{lyapunov, run_summary};
use anyhow::{Context, Result};
use control::config::spatial::SpatialConfig;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// One (μ, start) of the sweep; a shard file carries exactly this per grid point.
#[derive(Serialize, Deserialize, Clone, Debug)]
pub struct SpatialRow {
    pub mu: f64,
    /// Which start (0-based, in `--start` order; 0 alone without `--start`) and its posture.
    pub start: usize,
    pub q0: Vec<f64>,
    pub lambda_max: Option<f64>,
    pub stderr: Option<f64>,
    pub residual_final: Option<f64>,
    pub drift_per_period: Option<f64>,
    pub max_joint_speed: Option<f64>,
    pub min_joint_margin: Option<f64>,
    /// The Poincaré class of the section from the window's start (the planar arm's rule).
    pub motion: Option<String>,
    pub error: Option<String>,
}

/// How each μ is run: the length, λ_max's window, the partner's offset and the blocks of the
/// standard error.
#[derive(Clone, Copy, Debug)]
pub struct Spec {
    pub duration: f64,
    pub window: [f64; 2],
    pub d0: f64,
    pub blocks: usize,
}

impl Spec {
    /// The window defaults to the last two thirds of the run.
    pub fn new(duration: f64, window: Option<[f64; 2]>, d0: f64, blocks: usize) -> Self {
        Self {
            duration,
            window: window.unwrap_or([duration / 3.0, duration]),
            d0,
            blocks,
        }
    }
}

/// Fails early, once, on a set-up that cannot run.
pub fn check(cfg: &SpatialConfig) -> Result<()> {
    crate::spatial::run_summary(&{
        let mut c = cfg.clone();
        c.sim.duration = c.sim.dt;
        c
    })?;
    Ok(())
}

/// Runs one μ from start number `start` (`cfg` starts there).
pub fn row(cfg: &SpatialConfig, start: usize, mu: f64, spec: &Spec) -> SpatialRow {
    let (duration, window) = (spec.duration, spec.window);
    let mut c = cfg.clone();
    c.feedback.mu = mu;
    c.sim.duration = duration;
    let mut r = SpatialRow {
        mu,
        start,
        q0: c.sim.start().to_vec(),
        lambda_max: None,
        stderr: None,
        residual_final: None,
        drift_per_period: None,
        max_joint_speed: None,
        min_joint_margin: None,
        motion: None,
        error: None,
    };
    match lyapunov(&c, duration, Some(window), spec.d0, None, spec.blocks) {
        Ok((l, _)) => (r.lambda_max, r.stderr) = (Some(l.lambda_max), Some(l.stderr)),
        Err(e) => r.error = Some(format!("{e:#}")),
    }
    match crate::spatial::section(&c, duration, window[0], &Default::default()) {
        Ok((_, class)) => r.motion = Some(class.motion.label()),
        Err(e) => r.error = Some(format!("{e:#}")),
    }
    match run_summary(&c) {
        Ok(s) => {
            r.residual_final = s.period_residual_final;
            r.drift_per_period = s.drift_per_period;
            r.max_joint_speed = Some(s.max_joint_speed);
            r.min_joint_margin = s.min_joint_margin;
        }
        Err(e) => r.error = Some(format!("{e:#}")),
    }
    r
}

/// Writes PREFIX.csv and the figure.
pub fn write(prefix: &Path, rows: &[SpatialRow], cfg: &SpatialConfig, spec: &Spec) -> Result<()> {
    write_csv(&crate::plot::with_ext(prefix, "csv"), rows)?;
    plot(prefix, rows, cfg, spec.window)
}

fn cell(v: Option<f64>) -> String {
    v.map(|x| format!("{x:.6e}")).unwrap_or_default()
}

fn write_csv(path: &Path, rows: &[SpatialRow]) -> Result<()> {
    let mut w = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?,
    );
    writeln!(
        w,
        "mu,start,q0,lambda_max,stderr,motion,residual_final,drift_per_period,max_joint_speed,min_joint_margin,error"
    )?;
    for r in rows {
        let q0: Vec<String> = r.q0.iter().map(f64::to_string).collect();
        writeln!(
            w,
            "{},{},{},{},{},{},{},{},{},{},{}",
            r.mu,
            r.start + 1,
            q0.join(";"),
            cell(r.lambda_max),
            cell(r.stderr),
            r.motion.as_deref().unwrap_or(""),
            cell(r.residual_final),
            cell(r.drift_per_period),
            cell(r.max_joint_speed),
            cell(r.min_joint_margin),
            r.error.as_deref().unwrap_or("").replace(',', ";")
        )?;
    }
    w.flush()?;
    Ok(())
}

fn plot(prefix: &Path, rows: &[SpatialRow], cfg: &SpatialConfig, window: [f64; 2]) -> Result<()> {
    let starts = rows.iter().map(|r| r.start + 1).max().unwrap_or(1);
    let label = |what: &str, s: usize| {
        if starts == 1 {
            what.to_string()
        } else {
            format!("{what}, start {}", s + 1)
        }
    };
    let (mut lambda, mut residual) = (Vec::new(), Vec::new());
    for s in 0..starts {
        let of: Vec<&SpatialRow> = rows.iter().filter(|r| r.start == s).collect();
        let ok: Vec<&&SpatialRow> = of.iter().filter(|r| r.lambda_max.is_some()).collect();
        let color = PALETTE[(2 * s) % PALETTE.len()];
        lambda.push(
            Series::new(
                Some(label("λ_max ± stderr", s)),
                color,
                Style::LineMarkers { width: 2, size: 3 },
                ok.iter()
                    .map(|r| (r.mu, r.lambda_max.unwrap_or(f64::NAN)))
                    .collect(),
            )
            .yerr(ok.iter().map(|r| r.stderr.unwrap_or(0.0)).collect()),
        );
        residual.push(Series::new(
            Some(label("log₁₀ final residual |q̇(t) − q̇(t − T)|", s)),
            PALETTE[(2 * s + 1) % PALETTE.len()],
            Style::LineMarkers { width: 2, size: 3 },
            of.iter()
                .filter_map(|r| {
                    r.residual_final
                        .filter(|v| *v > 0.0)
                        .map(|v| (r.mu, v.log10()))
                })
                .collect(),
        ));
    }
    let zero = Rule {
        value: 0.0,
        vertical: false,
        color: DARK,
        label: None,
    };
    let title = cfg.describe();
    Figure {
        title: Some(title),
        panels: vec![
            Panel::Chart(Chart {
                title: format!("λ_max over {:.0}–{:.0} s", window[0], window[1]),
                x_label: "Pyragas gain μ (1/s)".into(),
                y_label: "λ_max (1/s)".into(),
                series: lambda,
                rules: vec![zero],
                legend: true,
                ..Default::default()
            }),
            Panel::Chart(Chart {
                title: "period residual over the last 10 periods".into(),
                x_label: "Pyragas gain μ (1/s)".into(),
                y_label: "log₁₀ residual (rad/s)".into(),
                series: residual,
                legend: true,
                ..Default::default()
            }),
        ],
        cols: 2,
        panel_size: (640, 460),
    }
    .save(prefix)?;
    Ok(())
}

/// The rows as a table.
pub fn print(rows: &[SpatialRow]) {
    let several = rows.iter().any(|r| r.start > 0);
    let start = |r: Option<&SpatialRow>| match (several, r) {
        (false, _) => String::new(),
        (true, None) => "start  ".into(),
        (true, Some(r)) => format!("{:>5}  ", r.start + 1),
    };
    println!(
        "{}      μ   λ_max (1/s)       Poincaré class       residual  drift/period  max speed  min margin",
        start(None)
    );
    let f = |v: Option<f64>| v.map(|x| format!("{x:.2e}")).unwrap_or_else(|| "—".into());
    for r in rows {
        let lam = match (r.lambda_max, r.stderr) {
            (Some(l), Some(s)) => format!("{l:+.4} ± {s:.4}"),
            _ => "—".into(),
        };
        println!(
            "{}{:7.3}  {lam:>16}  {:<18}  {:>11}  {:>12}  {:>9}  {:>10}{}",
            start(Some(r)),
            r.mu,
            r.motion.as_deref().unwrap_or("—"),
            f(r.residual_final),
            f(r.drift_per_period),
            f(r.max_joint_speed),
            f(r.min_joint_margin),
            r.error
                .as_deref()
                .map(|e| format!("  ({e})"))
                .unwrap_or_default()
        );
    }
}
