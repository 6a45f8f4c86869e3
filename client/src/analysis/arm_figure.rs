//! `chaosctl arm-figure`: the arm itself, drawn at several instants of one period late in a run,
//! with the task's path, the obstacles and the clearance the safety filter keeps, and every
//! joint angle over the last periods beside it; with obstacles, filter off and on one above the
//! other.
//!
//! Numbers say how much contact there was; this picture says what it looks like: with the paper's
//! potential alone the links sweep through the obstacle, with the filter they bend round it while
//! the end effector stays on its path; the joint angles show the switch from chaotic to periodic
//! self-motion at a glance. One drawing for every arm: a planar arm is seen from above, an arm in
//! space from the side (x–z) and the front (y–z), at one scale per view so that windows compare.

use super::obstacles::ObstacleArgs;
use crate::plot::{Chart, Figure, Panel, Rule, Series, Style, DARK, GREY, PALETTE};
use crate::setup::ModelArgs;
use crate::simulate::run_subject;
use crate::subject::Subject;
use anyhow::{bail, Result};
use clap::Args;
use control::task::Vec3;
use plotters::style::RGBColor;
use std::f64::consts::TAU;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ArmFigureCmd {
    /// Model flags as for `simulate`; without --config/--preset the preset is `paper-obstacle`.
    /// Without --safety an arm with obstacles is drawn twice (filter off, on); --safety on|off
    /// draws only one.
    #[command(flatten)]
    pub model: ModelArgs,
    #[command(flatten)]
    pub obstacles: ObstacleArgs,
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
    /// (t, the arm as a polyline: base, joints, tool) of each drawn arm.
    frames: Vec<(f64, Vec<Vec3>)>,
    /// The tool over the whole window.
    path: Vec<Vec3>,
    /// (t, q) over the last [`JOINT_PERIODS`] periods up to the window's end, at most
    /// [`JOINT_POINTS`] of them.
    joints: Vec<(f64, Vec<f64>)>,
    /// Minimum clearance (m; +∞ without obstacles), time in contact (s) and RMS tracking
    /// error (m) over the window.
    min_clearance: f64,
    contact: f64,
    rms: f64,
}

/// Task periods of joint angles drawn: enough to tell a cycle from chaos (a whole 400 s run
/// is a solid band).
const JOINT_PERIODS: f64 = 10.0;

/// Joint samples drawn per joint: enough for the eye, few enough for a small SVG.
const JOINT_POINTS: u64 = 2000;

/// A projection: the horizontal and vertical coordinates drawn, and its name.
type View = (usize, usize, &'static str);

/// A planar arm is seen from above; an arm in space from the side and the front.
fn views(arm: &Subject) -> &'static [View] {
    match arm.dims() {
        2 => &[(0, 1, "")],
        _ => &[(0, 2, "side (x–z)"), (1, 2, "front (y–z)")],
    }
}

fn simulate_window(arm: &Subject, from: f64, span: f64, frames: usize) -> Result<Window> {
    let dt = arm.dt();
    let system = arm.system();
    let drawing = system.drawing();
    let first = (from / dt).round() as u64;
    let frame_steps: Vec<u64> = (0..frames)
        .map(|i| first + (i as f64 * span / frames as f64 / dt).round() as u64)
        .collect();
    let steps = (arm.duration().0 / dt).round() as u64;
    let joint_steps = ((JOINT_PERIODS * arm.period() / dt).round() as u64).min(steps);
    let joint_first = steps - joint_steps;
    let joint_every = joint_steps.div_ceil(JOINT_POINTS).max(1);
    let mut w = Window {
        safety: system.safety_section().enabled,
        frames: Vec::new(),
        path: Vec::new(),
        joints: Vec::new(),
        min_clearance: f64::INFINITY,
        contact: 0.0,
        rms: 0.0,
    };
    let (mut sq, mut count) = (0.0, 0u64);
    run_subject(arm, |v| {
        if v.k >= joint_first && (v.k - joint_first).is_multiple_of(joint_every) {
            w.joints.push((v.t, v.q.to_vec()));
        }
        // The window is [from, from + span): the final state, which the law never saw, is
        // not in it.
        let Some(law) = v.law.filter(|_| v.k >= first) else {
            return Ok(());
        };
        w.min_clearance = w.min_clearance.min(law.clearance);
        if law.clearance < 0.0 {
            w.contact += dt;
        }
        sq += law.tracking_error * law.tracking_error;
        count += 1;
        if v.k % 5 == 0 {
            w.path.push(law.p);
        }
        if frame_steps.contains(&v.k) {
            let points = drawing.posed(v.phi, v.q).points;
            w.frames
                .push((v.t, points.into_iter().map(Vec3::from).collect()));
        }
        Ok(())
    })?;
    w.rms = (sq / count.max(1) as f64).sqrt();
    Ok(w)
}

/// What every panel of one arm shares: its obstacles (centre, radius), the clearance the
/// filter keeps, one round of its path once up to speed.
struct Scene {
    obstacles: Vec<(Vec3, f64)>,
    clearance: f64,
    task_path: Vec<Vec3>,
    /// What keeps the arm off an obstacle without the filter.
    off: String,
}

impl Scene {
    fn of(arm: &Subject) -> Result<Scene> {
        let system = arm.system();
        let path = system.path()?;
        let obstacles = system.obstacle_rows().into_iter().map(|o| {
            let c = &o.center;
            (
                Vec3::new(c[0], c[1], c.get(2).copied().unwrap_or(0.0)),
                o.radius,
            )
        });
        Ok(Scene {
            obstacles: obstacles.collect(),
            clearance: system.safety_section().clearance,
            off: super::obstacles::without_filter(&arm.law().secondary),
            task_path: (0..=180)
                .map(|i| path.position(path.ramp + path.period * i as f64 / 180.0))
                .collect(),
        })
    }
}

/// The circle of radius `r` round `c`, in view `(h, v)` (a sphere's outline).
fn circle(c: &Vec3, r: f64, (h, v, _): View) -> Vec<(f64, f64)> {
    (0..=180)
        .map(|i| {
            let a = TAU * i as f64 / 180.0;
            (c[h] + r * a.cos(), c[v] + r * a.sin())
        })
        .collect()
}

fn project(points: &[Vec3], (h, v, _): View) -> Vec<(f64, f64)> {
    points.iter().map(|p| (p[h], p[v])).collect()
}

pub fn run(args: ArmFigureCmd) -> Result<()> {
    let mut model = args.model.clone();
    if model.setup.config.is_none() && model.setup.preset.is_none() {
        model.setup.preset = Some("paper-obstacle".into());
    }
    let mut base = Subject::load(&model.setup, model.mu)?;
    base.set_obstacles(&args.obstacles)?;
    let span = args.span.unwrap_or(base.period());
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
    let scene = Scene::of(&base)?;
    let filters = match (args.model.setup.safety, scene.obstacles.is_empty()) {
        (Some(on), _) => vec![on],
        (None, false) => vec![false, true],
        (None, true) => vec![base.system().safety_section().enabled],
    };
    let mut arms = Vec::new();
    for on in filters {
        let mut a = base.clone();
        a.set_safety(on);
        a.set_duration(Some(args.from + span), Some(0.0))?;
        a.check()?;
        arms.push(a);
    }
    let windows = super::parallel::run_all(&arms, arms.len(), "arm-figure", |a| {
        simulate_window(a, args.from, span, args.frames).map_err(|e| format!("{e:#}"))
    })?
    .into_iter()
    .collect::<Result<Vec<_>, String>>()
    .map_err(anyhow::Error::msg)?;
    let files = draw(&args, &base, &scene, span, &windows)?;
    for w in &windows {
        let obstacles = match w.min_clearance.is_finite() {
            true => format!(
                "min clearance {:+.4} m, {:.3} s in contact",
                w.min_clearance, w.contact
            ),
            false => "no obstacles".into(),
        };
        println!(
            "filter {}: t = {}…{} s, {obstacles}, RMS tracking {:.2e} m",
            if w.safety { "on " } else { "off" },
            args.from,
            args.from + span,
            w.rms
        );
    }
    super::print_written(&files);
    Ok(())
}

/// The side of a square panel and of its plot area (minus the label areas, margins and
/// caption) in pixels.
const PANEL: u32 = 640;
const PLOT_PX: (f64, f64) = (
    PANEL as f64 - 64.0 - 20.0,
    PANEL as f64 - 44.0 - 20.0 - 27.0,
);

/// The x and y ranges that hold every drawn point with equal metres per pixel in the plot
/// area, plus room on the right for the legend (a fraction of the drawing's width).
fn ranges(points: &[(f64, f64)]) -> ((f64, f64), (f64, f64)) {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for p in points {
        x0 = x0.min(p.0);
        x1 = x1.max(p.0);
        y0 = y0.min(p.1);
        y1 = y1.max(p.1);
    }
    let pad = 0.05 * (x1 - x0).max(y1 - y0).max(0.2);
    let legend = 0.5 * (x1 - x0).max(y1 - y0).max(0.2);
    let (x0, x1, y0, y1) = (x0 - pad, x1 + pad + legend, y0 - pad, y1 + pad);
    let per_px = ((x1 - x0) / PLOT_PX.0).max((y1 - y0) / PLOT_PX.1);
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let (hw, hh) = (0.5 * per_px * PLOT_PX.0, 0.5 * per_px * PLOT_PX.1);
    ((cx - hw, cx + hw), (cy - hh, cy + hh))
}

/// One view of one window: the path, the obstacles and their rings, the tool's path, the
/// drawn arms and the base.
fn view_chart(scene: &Scene, w: &Window, view: View, range: ((f64, f64), (f64, f64))) -> Chart {
    let ring = RGBColor(214, 39, 40);
    let mut series = vec![Series::new(
        Some("task path".into()),
        GREY,
        Style::Line(1),
        project(&scene.task_path, view),
    )];
    for (i, (c, r)) in scene.obstacles.iter().enumerate() {
        let first = i == 0;
        let disc = Series::new(
            first.then(|| "obstacle".into()),
            DARK,
            Style::Fill,
            circle(c, *r, view),
        );
        series.push(disc.alpha(0.35));
        series.push(Series::new(
            first.then(|| format!("required clearance {} m", scene.clearance)),
            ring,
            Style::Line(1),
            circle(c, r + scene.clearance, view),
        ));
    }
    let tool = Series::new(
        Some("end effector".into()),
        DARK,
        Style::Line(1),
        project(&w.path, view),
    );
    series.push(tool.alpha(0.6));
    for (i, (t, pts)) in w.frames.iter().enumerate() {
        series.push(Series::new(
            Some(format!("t = {t:.3} s")),
            PALETTE[i % PALETTE.len()],
            Style::LineMarkers { width: 2, size: 3 },
            project(pts, view),
        ));
    }
    let base = w.frames.first().map(|f| f.1[0]).unwrap_or_default();
    let dot = Style::Markers {
        size: 5,
        filled: true,
    };
    series.push(Series::new(None, DARK, dot, project(&[base], view)));
    let names = ["x (m)", "y (m)", "z (m)"];
    // The filter's name and what it kept, where there is an obstacle to keep off.
    let filter = match (w.min_clearance.is_finite(), w.safety) {
        (false, _) => String::new(),
        (true, on) => format!(
            "filter {}: min clearance {:+.3} m, {:.2} s in contact",
            if on {
                "on".into()
            } else {
                format!("off, {}", scene.off)
            },
            w.min_clearance,
            w.contact
        ),
    };
    let title = match (view.2, filter.is_empty()) {
        ("", true) => "the plane (x–y)".to_string(),
        ("", false) => filter,
        (name, true) => name.to_string(),
        (name, false) => format!("{name}, {filter}"),
    };
    Chart {
        title,
        x_label: names[view.0].into(),
        y_label: names[view.1].into(),
        series,
        x_range: Some(range.0),
        y_range: Some(range.1),
        legend: true,
        ..Default::default()
    }
}

/// Every joint angle over the last periods of the run, the moment the feedback comes on
/// marked when it is among them.
fn joints_chart(arm: &Subject, w: &Window) -> Chart {
    let t_on = arm.feedback().t_on;
    let n = w.joints.first().map_or(0, |j| j.1.len());
    let from = w.joints.first().map_or(0.0, |j| j.0);
    let rules = match t_on >= from {
        true => vec![Rule {
            value: t_on,
            vertical: true,
            color: DARK,
            label: Some("feedback on".into()),
        }],
        false => Vec::new(),
    };
    Chart {
        title: format!(
            "joint angles, the last {JOINT_PERIODS} periods (μ = {} from t = {t_on} s)",
            arm.mu()
        ),
        x_label: "t (s)".into(),
        y_label: "q (rad)".into(),
        series: (0..n)
            .map(|i| {
                Series::new(
                    Some(format!("q{}", i + 1)),
                    PALETTE[i % PALETTE.len()],
                    Style::Line(1),
                    w.joints.iter().map(|(t, q)| (*t, q[i])).collect(),
                )
            })
            .collect(),
        rules,
        legend: true,
        ..Default::default()
    }
}

fn draw(
    args: &ArmFigureCmd,
    arm: &Subject,
    scene: &Scene,
    span: f64,
    windows: &[Window],
) -> Result<Vec<PathBuf>> {
    let views = views(arm);
    let mut panels = Vec::new();
    let ranges: Vec<_> = views
        .iter()
        .map(|&view| {
            let mut all: Vec<(f64, f64)> = windows
                .iter()
                .flat_map(|w| w.frames.iter().flat_map(|f| project(&f.1, view)))
                .collect();
            all.extend(project(&scene.task_path, view));
            for (c, r) in &scene.obstacles {
                all.extend(circle(c, r + scene.clearance, view));
            }
            ranges(&all)
        })
        .collect();
    for w in windows {
        for (&view, &range) in views.iter().zip(&ranges) {
            panels.push(Panel::Chart(view_chart(scene, w, view, range)));
        }
        panels.push(Panel::Chart(joints_chart(arm, w)));
    }
    let obstacles = scene
        .obstacles
        .iter()
        .map(|(c, r)| match arm.dims() {
            2 => format!("({}, {}) r {r}", c.x, c.y),
            _ => format!("({}, {}, {}) r {r}", c.x, c.y, c.z),
        })
        .collect::<Vec<_>>();
    let obstacles = match obstacles.is_empty() {
        true => String::new(),
        false => format!(", obstacles {}", obstacles.join(", ")),
    };
    Figure {
        title: Some(format!(
            "{}: the arm at {} instants of t = {}…{} s (μ = {}{obstacles}); base at the black dot",
            arm.describe(),
            args.frames,
            args.from,
            args.from + span,
            arm.mu(),
        )),
        cols: views.len() + 1,
        panels,
        panel_size: (PANEL, PANEL),
    }
    .save(&args.output)
}
