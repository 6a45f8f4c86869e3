//! `chaosctl arm-figure`: the arm itself, drawn at several instants of one period late in a run,
//! with the task's path, the obstacles and the clearance the safety filter keeps, filter off and
//! on side by side.
//!
//! Numbers say how much contact there was; this picture says what it looks like: with the paper's
//! potential alone the links sweep through the obstacle, with the filter they bend round it while
//! the end effector stays on its path.

use crate::plot::{Chart, Figure, Panel, Series, Style, DARK, GREY, PALETTE};
use crate::setup::ModelArgs;
use crate::simulate::run_subject;
use crate::subject::Subject;
use anyhow::{bail, Result};
use clap::Args;
use control::{with_dof, Config, Kinematics, VecN};
use plotters::style::RGBColor;
use std::f64::consts::TAU;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ArmFigureCmd {
    /// Model flags as for `simulate`; without --config/--preset the preset is `paper-obstacle`.
    /// Without --safety both panels are drawn (filter off, on); --safety on|off draws only one.
    #[command(flatten)]
    pub model: ModelArgs,
    #[command(flatten)]
    pub obstacles: super::obstacles::ObstacleArgs,
    /// Start of the drawn window (s); the run lasts until its end.
    #[arg(long, default_value_t = 380.0)]
    pub from: f64,
    /// Length of the window (s; default: one task period T).
    #[arg(long)]
    pub span: Option<f64>,
    /// Arms drawn per panel, evenly spread over the window (at most 8).
    #[arg(long, default_value_t = 8)]
    pub frames: usize,
    /// Output prefix: writes PREFIX.png and PREFIX.svg.
    #[arg(long, default_value = "arm")]
    pub output: PathBuf,
}

/// The drawn window of one run.
struct Window {
    safety: bool,
    /// (t, joint positions base … end effector) of each drawn arm.
    frames: Vec<(f64, Vec<(f64, f64)>)>,
    /// The end effector over the whole window.
    path: Vec<(f64, f64)>,
    /// Minimum clearance (m) and time in contact (s) over the window.
    min_clearance: f64,
    contact: f64,
    rms: f64,
}

/// Base, joints and end effector at (q, φ).
fn arm_points(cfg: &Config, q: &[f64], phi: f64) -> Vec<(f64, f64)> {
    with_dof!(cfg.n(), N => {
        let mut kin = Kinematics::<N>::default();
        let q = VecN::<N>::from_column_slice(q);
        cfg.model::<N>().kinematics(phi, &q, &VecN::<N>::zeros(), &mut kin);
        kin.points.iter().chain(std::iter::once(&kin.p)).map(|p| (p.x, p.y)).collect()
    })
}

/// Smallest distance (m) from any link to any obstacle's surface.
fn clearance(cfg: &Config, pts: &[(f64, f64)]) -> f64 {
    let mut min = f64::INFINITY;
    for o in &cfg.control.obstacles {
        for w in pts.windows(2) {
            let (a, b) = (w[0], w[1]);
            let d = (b.0 - a.0, b.1 - a.1);
            let l2 = d.0 * d.0 + d.1 * d.1;
            let t = if l2 > 0.0 {
                (((o.center[0] - a.0) * d.0 + (o.center[1] - a.1) * d.1) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let (x, y) = (a.0 + t * d.0 - o.center[0], a.1 + t * d.1 - o.center[1]);
            min = min.min((x * x + y * y).sqrt() - o.radius);
        }
    }
    min
}

fn simulate_window(cfg: &Config, from: f64, span: f64, frames: usize) -> Result<Window> {
    let dt = cfg.sim.dt;
    let first = (from / dt).round() as u64;
    let frame_steps: Vec<u64> = (0..frames)
        .map(|i| first + (i as f64 * span / frames as f64 / dt).round() as u64)
        .collect();
    let mut w = Window {
        safety: cfg.safety.enabled,
        frames: Vec::new(),
        path: Vec::new(),
        min_clearance: f64::INFINITY,
        contact: 0.0,
        rms: 0.0,
    };
    let (mut sq, mut count) = (0.0, 0u64);
    let path = cfg.law_params().task;
    run_subject(&Subject::Planar(cfg.clone()), |k, t, q, _qd, phi| {
        if k < first {
            return Ok(());
        }
        let pts = arm_points(cfg, q, phi);
        let c = clearance(cfg, &pts);
        w.min_clearance = w.min_clearance.min(c);
        if c < 0.0 {
            w.contact += dt;
        }
        let p = pts[pts.len() - 1];
        let pd = path.at_xy(t).0;
        sq += (p.0 - pd.x).powi(2) + (p.1 - pd.y).powi(2);
        count += 1;
        if k % 5 == 0 {
            w.path.push(p);
        }
        if frame_steps.contains(&k) {
            w.frames.push((t, pts));
        }
        Ok(())
    })?;
    w.rms = (sq / count.max(1) as f64).sqrt();
    Ok(w)
}

/// One round of the task's path once it is up to speed.
fn task_path(cfg: &Config) -> Vec<(f64, f64)> {
    let path = cfg.law_params().task;
    (0..=180)
        .map(|i| {
            let p = path.at_xy(path.ramp + path.period * i as f64 / 180.0).0;
            (p.x, p.y)
        })
        .collect()
}

fn circle(c: [f64; 2], r: f64) -> Vec<(f64, f64)> {
    (0..=180)
        .map(|i| {
            let a = TAU * i as f64 / 180.0;
            (c[0] + r * a.cos(), c[1] + r * a.sin())
        })
        .collect()
}

pub fn run(args: ArmFigureCmd) -> Result<()> {
    let mut model = args.model.clone();
    if model.setup.config.is_none() && model.setup.preset.is_none() {
        model.setup.preset = Some("paper-obstacle".into());
    }
    if let Some(cfg) = crate::spatial::load(&model.setup, model.mu)? {
        crate::spatial_figure::draw(&cfg, args.from, args.span, args.frames, &args.output)?;
        println!("wrote {}.png and .svg", args.output.display());
        return Ok(());
    }
    let mut base = model.load()?;
    args.obstacles.apply(&mut base)?;
    let span = args.span.unwrap_or(base.task.period);
    if !(args.from.is_finite() && args.from >= 0.0) {
        bail!("--from {}: must be a finite time ≥ 0 s", args.from);
    }
    if !(span.is_finite() && span > 0.0 && span <= 100.0) {
        bail!("--span {span}: must be between 0 and 100 s");
    }
    if !(1..=PALETTE.len()).contains(&args.frames) {
        bail!(
            "--frames {}: must be between 1 and {}",
            args.frames,
            PALETTE.len()
        );
    }
    let filters = match args.model.setup.safety {
        Some(on) => vec![on],
        None => vec![false, true],
    };
    let mut cfgs = Vec::new();
    for on in filters {
        let mut c = base.clone();
        c.safety.enabled = on;
        c.sim.duration = args.from + span;
        c.sim.transient = 0.0;
        c.validate()?;
        super::check_config(&c)?;
        cfgs.push(c);
    }
    let windows = super::parallel::run_all(&cfgs, cfgs.len(), "arm-figure", |c| {
        simulate_window(c, args.from, span, args.frames).map_err(|e| format!("{e:#}"))
    })?
    .into_iter()
    .collect::<Result<Vec<_>, String>>()
    .map_err(anyhow::Error::msg)?;
    let files = draw(&args, &base, span, &windows)?;
    for w in &windows {
        println!(
            "filter {}: t = {}…{} s, min clearance {:+.4} m, {:.3} s in contact, RMS tracking {:.2e} m",
            if w.safety { "on " } else { "off" },
            args.from,
            args.from + span,
            w.min_clearance,
            w.contact,
            w.rms
        );
    }
    super::print_written(&files);
    Ok(())
}

/// The x and y ranges that hold every drawn point with equal metres per pixel in a
/// `plot_px`-sized plot area, plus room on the right for the legend.
fn ranges(points: &[(f64, f64)], plot_px: (f64, f64), legend: f64) -> ((f64, f64), (f64, f64)) {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for p in points {
        x0 = x0.min(p.0);
        x1 = x1.max(p.0);
        y0 = y0.min(p.1);
        y1 = y1.max(p.1);
    }
    let pad = 0.15;
    let (x0, x1, y0, y1) = (x0 - pad, x1 + pad + legend, y0 - pad, y1 + pad);
    let per_px = ((x1 - x0) / plot_px.0).max((y1 - y0) / plot_px.1);
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let (hw, hh) = (0.5 * per_px * plot_px.0, 0.5 * per_px * plot_px.1);
    ((cx - hw, cx + hw), (cy - hh, cy + hh))
}

fn draw(args: &ArmFigureCmd, cfg: &Config, span: f64, windows: &[Window]) -> Result<Vec<PathBuf>> {
    // The plot area of a 760 × 760 panel: minus the label areas (64, 44), margins and caption.
    let panel = (760u32, 760u32);
    let plot_px = (
        panel.0 as f64 - 64.0 - 20.0,
        panel.1 as f64 - 44.0 - 20.0 - 27.0,
    );
    let ring = RGBColor(214, 39, 40);
    let mut all: Vec<(f64, f64)> = windows
        .iter()
        .flat_map(|w| w.frames.iter().flat_map(|f| f.1.iter().copied()))
        .collect();
    all.extend(task_path(cfg));
    for o in &cfg.control.obstacles {
        all.extend(circle(o.center, o.radius + cfg.safety.clearance));
    }
    let (xr, yr) = ranges(&all, plot_px, 1.3);
    let panels = windows
        .iter()
        .map(|w| {
            let mut series = vec![Series::new(
                Some("task path".into()),
                GREY,
                Style::Line(1),
                task_path(cfg),
            )];
            for (i, o) in cfg.control.obstacles.iter().enumerate() {
                let first = i == 0;
                series.push(
                    Series::new(
                        first.then(|| "obstacle".into()),
                        DARK,
                        Style::Fill,
                        circle(o.center, o.radius),
                    )
                    .alpha(0.35),
                );
                series.push(Series::new(
                    first.then(|| format!("required clearance {} m", cfg.safety.clearance)),
                    ring,
                    Style::Line(1),
                    circle(o.center, o.radius + cfg.safety.clearance),
                ));
            }
            series.push(
                Series::new(
                    Some("end effector".into()),
                    DARK,
                    Style::Line(1),
                    w.path.clone(),
                )
                .alpha(0.6),
            );
            for (i, (t, pts)) in w.frames.iter().enumerate() {
                series.push(Series::new(
                    Some(format!("t = {t:.3} s")),
                    PALETTE[i % PALETTE.len()],
                    Style::LineMarkers { width: 2, size: 3 },
                    pts.clone(),
                ));
            }
            series.push(Series::new(
                None,
                DARK,
                Style::Markers {
                    size: 5,
                    filled: true,
                },
                vec![w.frames.first().map(|f| f.1[0]).unwrap_or((0.0, 0.0))],
            ));
            let title = format!(
                "filter {}: min clearance {:+.3} m, {:.2} s in contact",
                if w.safety {
                    "on"
                } else {
                    "off (paper's potential)"
                },
                w.min_clearance,
                w.contact
            );
            Panel::Chart(Chart {
                title,
                x_label: "x (m)".into(),
                y_label: "y (m)".into(),
                series,
                x_range: Some(xr),
                y_range: Some(yr),
                legend: true,
                ..Default::default()
            })
        })
        .collect::<Vec<_>>();
    Figure {
        title: Some(format!(
            "The arm at {} instants of t = {}…{} s (μ = {}, obstacles {}); base at the black dot",
            args.frames,
            args.from,
            args.from + span,
            cfg.feedback.mu,
            cfg.control
                .obstacles
                .iter()
                .map(|o| format!("({}, {}) r {}", o.center[0], o.center[1], o.radius))
                .collect::<Vec<_>>()
                .join(", ")
        )),
        cols: panels.len(),
        panels,
        panel_size: panel,
    }
    .save(&args.output)
}
