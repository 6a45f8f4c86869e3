//! `chaosctl arm-figure` on a spatial robot: the arm drawn in two orthogonal projections (side:
//! x–z, front: y–z) at several instants of a window late in the run, with the tool's path and the
//! obstacles, and every joint angle over the whole run beneath, so that the switch from chaotic
//! to periodic self-motion is visible at a glance.

use crate::plot::{Chart, Figure, Panel, Rule, Series, Style, DARK, GREY, PALETTE};
use anyhow::{bail, Result};
use control::arm::spatial::SpatialKinematics;
use control::config::spatial::SpatialConfig;
use control::config::spatial::SpatialSetup;
use control::sim::spatial::run;
use control::{with_dof, with_task_rows};
use std::f64::consts::TAU;
use std::path::Path;

/// What the run leaves to draw: arms (base, joint origins, tool) at the drawn instants, the tool's
/// path over the window, and (t, q) every 10 ms.
struct Drawn {
    frames: Vec<(f64, Vec<[f64; 3]>)>,
    path: Vec<[f64; 3]>,
    joints: Vec<(f64, Vec<f64>)>,
}

fn simulate(cfg: &SpatialConfig, from: f64, span: f64, frames: usize) -> Result<Drawn> {
    let chain = rt::robot::load(
        &cfg.robot.description,
        cfg.robot.base.as_deref(),
        cfg.robot.tip.as_deref(),
    )?;
    let kind = cfg.task_kind()?;
    let mut d = Drawn {
        frames: Vec::new(),
        path: Vec::new(),
        joints: Vec::new(),
    };
    with_dof!(chain.dof(), N => {
        let s: SpatialSetup<N> = cfg.setup::<N>(&chain)?;
        with_task_rows!(kind, |M| {
            let mut sim = s.simulation::<M>();
            let stride = ((0.01 / s.dt).round() as u64).max(1);
            let every = (span / frames as f64 / s.dt).round().max(1.0) as u64;
            let start = (from / s.dt).round() as u64;
            let mut k = 0u64;
            let mut kin = SpatialKinematics::<N>::default();
            run(&mut sim, from + span, 0.0, |t, x, out| {
                if k.is_multiple_of(stride) {
                    d.joints.push((t, x.q.iter().copied().collect()));
                }
                if k >= start {
                    d.path.push([out.p.x, out.p.y, out.p.z]);
                    if (k - start).is_multiple_of(every) && d.frames.len() < frames {
                        s.arm.kinematics(&x.q, &x.qd, &mut kin);
                        let pts = s.arm.capsule_positions(&kin);
                        let mut arm = vec![[0.0; 3]];
                        arm.extend(pts[..=N].iter().map(|p| [p.x, p.y, p.z]));
                        d.frames.push((t, arm));
                    }
                }
                k += 1;
            });
        })
    });
    Ok(d)
}

fn circle(c: (f64, f64), r: f64) -> Vec<(f64, f64)> {
    (0..=48)
        .map(|i| {
            let a = TAU * i as f64 / 48.0;
            (c.0 + r * a.cos(), c.1 + r * a.sin())
        })
        .collect()
}

/// One projection: `h`, `v` are the horizontal and vertical coordinate indices.
fn view(cfg: &SpatialConfig, d: &Drawn, h: usize, v: usize, title: &str) -> Chart {
    let names = ["x (m)", "y (m)", "z (m)"];
    let mut series = Vec::new();
    for o in &cfg.obstacles {
        series.push(
            Series::new(
                None,
                GREY,
                Style::Fill,
                circle((o.center[h], o.center[v]), o.radius),
            )
            .alpha(0.4),
        );
    }
    let n = d.frames.len().max(1);
    for (i, (t, arm)) in d.frames.iter().enumerate() {
        let label = (i == 0 || i + 1 == n).then(|| format!("arm at t = {t:.2} s"));
        series.push(
            Series::new(
                label,
                PALETTE[i % PALETTE.len()],
                Style::LineMarkers { width: 3, size: 3 },
                arm.iter().map(|p| (p[h], p[v])).collect(),
            )
            .alpha(0.8),
        );
    }
    series.push(Series::new(
        Some("tool path".into()),
        DARK,
        Style::Line(1),
        d.path.iter().map(|p| (p[h], p[v])).collect(),
    ));
    // Equal scales: both axes span the same length, centred on the drawing.
    let pts = d.frames.iter().flat_map(|(_, a)| a.iter());
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in pts {
        for (k, &c) in [h, v].iter().enumerate() {
            lo[k] = lo[k].min(p[c]);
            hi[k] = hi[k].max(p[c]);
        }
    }
    let half = 0.55 * (hi[0] - lo[0]).max(hi[1] - lo[1]).max(0.1);
    let mid = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    Chart {
        title: title.into(),
        x_label: names[h].into(),
        y_label: names[v].into(),
        series,
        x_range: Some((mid[0] - half, mid[0] + half)),
        y_range: Some((mid[1] - half, mid[1] + half)),
        legend: true,
        ..Default::default()
    }
}

/// Draws the figure to PREFIX.png and PREFIX.svg.
pub fn draw(
    cfg: &SpatialConfig,
    from: f64,
    span: Option<f64>,
    frames: usize,
    prefix: &Path,
) -> Result<()> {
    if !(from.is_finite() && from >= 0.0) {
        bail!("--from {from}: must be a time ≥ 0 s");
    }
    if !(1..=8).contains(&frames) {
        bail!("--frames {frames}: must be 1 to 8");
    }
    let span = span.unwrap_or(cfg.task.period);
    if !(span.is_finite() && span > 0.0) {
        bail!("--span {span}: must be a duration > 0 s");
    }
    let d = simulate(cfg, from, span, frames)?;
    let joints = Chart {
        title: format!(
            "joint angles (feedback μ = {} from t = {} s)",
            cfg.feedback.mu, cfg.feedback.t_on
        ),
        x_label: "t (s)".into(),
        y_label: "q (rad)".into(),
        series: (0..d.joints.first().map_or(0, |j| j.1.len()))
            .map(|i| {
                Series::new(
                    Some(format!("q{}", i + 1)),
                    PALETTE[i % PALETTE.len()],
                    Style::Line(1),
                    d.joints.iter().map(|(t, q)| (*t, q[i])).collect(),
                )
            })
            .collect(),
        rules: vec![Rule {
            value: cfg.feedback.t_on,
            vertical: true,
            color: DARK,
            label: Some("feedback on".into()),
        }],
        legend: true,
        ..Default::default()
    };
    let w = format!("{:.1}–{:.1} s", from, from + span);
    Figure {
        title: Some(cfg.describe()),
        panels: vec![
            Panel::Chart(view(cfg, &d, 0, 2, &format!("side view (x–z), {w}"))),
            Panel::Chart(view(cfg, &d, 1, 2, &format!("front view (y–z), {w}"))),
            Panel::Chart(joints),
        ],
        cols: 3,
        panel_size: (560, 520),
    }
    .save(prefix)?;
    Ok(())
}
