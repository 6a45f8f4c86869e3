//! `chaosctl figures`: the paper's pictures of one run — time courses (its Figs. 2 and 7), phase
//! portraits (Figs. 3 and 8) and stroboscopic Poincaré sections (Figs. 4 and 9) — plus what the
//! paper does not show: the period residual |q̇(t) − q̇(t − T)| on a log scale, which says whether and
//! when the motion became periodic, and, with obstacles, the clearance over time.
//!
//! Run it once with `--mu 0` (before control) and once with the feedback on (after control).
//! Every arm gets the same pictures: one run ([`TraceRun`], a [`LoopVisitor`] on the planar arm's
//! loop or a URDF robot's: `--preset panda`, or a file with a `[robot]` table) fills one
//! [`Trace`], and one drawing code reads it.

use super::{fmt_list, fmt_num, ClassifyArgs};
use crate::plot::{Chart, Figure, Panel, Rule, Series, Style, GREY, PALETTE};
use crate::setup::ModelArgs;
use crate::subject::{LoopVisitor, Start, Subject};
use anyhow::{bail, Result};
use clap::Args;
use control::analysis::{classify, Classification, ClassifyConfig, Section};
use control::sim::ClosedLoopLaw;
use control::{RunStats, Simulation};
use plotters::style::RGBColor;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct FiguresCmd {
    #[command(flatten)]
    pub model: ModelArgs,
    /// Simulated time (s).
    #[arg(long, default_value_t = 300.0)]
    pub duration: f64,
    /// The Poincaré section and the statistics start here (s) [default: 20, or half a shorter
    /// run].
    #[arg(long)]
    pub transient: Option<f64>,
    /// Seconds shown in the phase portraits, START:END (default: the last 20 s).
    #[arg(long = "phase-window", value_parser = super::parse_window)]
    pub phase_window: Option<[f64; 2]>,
    #[command(flatten)]
    pub classify: ClassifyArgs,
    /// Directory for the images.
    #[arg(long = "output-dir", default_value = "figures")]
    pub output_dir: PathBuf,
    /// File name stem (default: mu<μ>, e.g. mu0.2): writes <stem>_time, _phase, _poincare and
    /// _residual, each as .png and .svg.
    #[arg(long)]
    pub name: Option<String>,
}

impl FiguresCmd {
    /// `--transient`, or its default ([`crate::setup::transient_or`]).
    pub fn transient(&self) -> f64 {
        crate::setup::transient_or(self.transient, 20.0, self.duration)
    }
}

/// A run sampled densely for plotting.
pub struct Trace {
    pub n: usize,
    pub t: Vec<f64>,
    /// q[i][k]: joint i at sample k.
    pub q: Vec<Vec<f64>>,
    pub qd: Vec<Vec<f64>>,
    pub residual: Vec<f64>,
    pub clearance: Vec<f64>,
    pub section: Section,
    pub numbers: Numbers,
    /// Time between kept samples (s).
    pub stride_dt: f64,
}

/// What the figures print of a run, whichever arm ran it.
#[derive(Clone, Debug, Default)]
pub struct Numbers {
    pub period_residual_before: Option<f64>,
    pub period_residual_final: Option<f64>,
    pub rms_tracking_error: f64,
    pub max_tracking_error: f64,
    /// Smallest clearance (m) to an obstacle's surface; None without obstacles.
    pub min_clearance: Option<f64>,
    /// Time (s) some link was inside an obstacle's safety zone (radius + margin).
    pub time_in_safety_zone: f64,
}

/// What the titles say of a run: its gain, switch-on, start, period and obstacle margin.
pub struct Labels {
    pub mu: f64,
    /// The feedback is on at some point of the run.
    pub on: bool,
    pub t_on: f64,
    pub q0: Vec<f64>,
    pub period: f64,
    pub duration: f64,
    /// The smallest obstacle margin (m); +∞ without obstacles.
    pub margin: f64,
}

impl Trace {
    /// An empty trace of `n` joints with room for `cap` samples, one every `stride_dt` s.
    fn with_capacity(n: usize, cap: usize, stride_dt: f64) -> Self {
        let rows = || (0..n).map(|_| Vec::with_capacity(cap)).collect();
        Trace {
            n,
            t: Vec::with_capacity(cap),
            q: rows(),
            qd: rows(),
            residual: Vec::with_capacity(cap),
            clearance: Vec::with_capacity(cap),
            section: Section::new(2 * n, n),
            numbers: Numbers::default(),
            stride_dt,
        }
    }

    /// Keeps the sample at `t`: the state before the step and what the law said at it.
    fn keep(&mut self, t: f64, q: &[f64], qd: &[f64], residual: f64, clearance: f64) {
        self.t.push(t);
        for i in 0..self.n {
            self.q[i].push(q[i]);
            self.qd[i].push(qd[i]);
        }
        self.residual.push(residual);
        self.clearance.push(clearance);
    }

    /// Time with an obstacle clearance below zero (a link inside an obstacle), from the samples.
    pub fn contact_time(&self) -> f64 {
        self.clearance.iter().filter(|c| **c < 0.0).count() as f64 * self.stride_dt
    }
    /// The last sampled time in contact.
    pub fn last_contact(&self) -> Option<f64> {
        self.t
            .iter()
            .zip(&self.clearance)
            .rev()
            .find(|(_, c)| **c < 0.0)
            .map(|(t, _)| *t)
    }
}

/// The run the figures draw: `duration` s, every `stride`-th step kept, the section at t = kT ≥
/// `transient` (the end included).
struct TraceRun {
    duration: f64,
    stride: u64,
    transient: f64,
}

impl LoopVisitor for TraceRun {
    type Out = Trace;
    fn visit<const N: usize, L: ClosedLoopLaw<N>>(
        self,
        mut sim: Simulation<N, L>,
        _: Start<'_>,
    ) -> Result<Trace> {
        let (dt, stride, transient) = (sim.dt(), self.stride, self.transient);
        let setup = sim.law.stats_setup();
        let per = control::analysis::period_steps(setup.period, dt)?;
        let steps = (self.duration / dt).round() as u64;
        let x0 = *sim.state();
        let mut stats = RunStats::of(setup, dt, self.duration, transient, &x0);
        let cap = (steps / stride + 2) as usize;
        let mut tr = Trace::with_capacity(N, cap, stride as f64 * dt);
        for k in 0..=steps {
            let x = *sim.state();
            if !x.is_finite() {
                bail!(
                    "the simulation diverged (non-finite state at t = {} s)",
                    k as f64 * dt
                );
            }
            let t = k as f64 * dt;
            if k % per == 0 && t >= transient - 1e-9 {
                let coords: Vec<f64> = x.q.iter().chain(x.qd.iter()).copied().collect();
                tr.section.push(t, &coords);
            }
            if k == steps {
                break;
            }
            let out = sim.step();
            stats.record(k, &x, &out);
            if k % stride == 0 {
                tr.keep(
                    t,
                    x.q.as_slice(),
                    x.qd.as_slice(),
                    out.period_residual,
                    out.clearance,
                );
            }
        }
        let s = stats.summary();
        tr.numbers = Numbers {
            period_residual_before: s.period_residual_before,
            period_residual_final: s.period_residual_final,
            rms_tracking_error: s.rms_tracking_error,
            max_tracking_error: s.max_tracking_error,
            min_clearance: s.min_clearance,
            time_in_safety_zone: s.time_in_safety_zone,
        };
        Ok(tr)
    }
}

/// Panels of the section: q̇_i against q_i at t = kT. Samples from `highlight_from` on are drawn
/// large and coloured, earlier ones small and grey, so a section that collapses onto a few points
/// late in the run shows it.
pub fn section_panels(section: &Section, n: usize, highlight_from: f64) -> Vec<Panel> {
    let late = section
        .times
        .iter()
        .filter(|t| **t >= highlight_from)
        .count();
    (0..n)
        .map(|i| {
            let (mut early, mut recent) = (Vec::new(), Vec::new());
            for (t, p) in section.times.iter().zip(section.points()) {
                if *t >= highlight_from {
                    &mut recent
                } else {
                    &mut early
                }
                .push((p[i], p[n + i]));
            }
            let label = |s: String| if i == 0 { Some(s) } else { None };
            let mut series = vec![Series::new(
                label(format!("t < {highlight_from:.0} s")),
                RGBColor(175, 175, 175),
                Style::Markers {
                    size: 2,
                    filled: true,
                },
                early,
            )];
            series.push(Series::new(
                label(format!("t ≥ {highlight_from:.0} s ({late} points)")),
                PALETTE[0],
                Style::Markers {
                    size: 3,
                    filled: true,
                },
                recent,
            ));
            Panel::Chart(Chart {
                title: format!("joint {}", i + 1),
                x_label: format!("q{} at t = kT (rad)", i + 1),
                y_label: format!("dq{}/dt at t = kT (rad/s)", i + 1),
                series,
                legend: i == 0,
                ..Default::default()
            })
        })
        .collect()
}

fn describe(c: &Classification) -> String {
    let mut s = c.motion.label();
    if let Some(k) = c.k {
        s.push_str(&format!(", 0-1 test K = {k:.2}"));
    } else if let Some(r) = c.returns.first() {
        s.push_str(&format!(", return distance {r:.1e}"));
    }
    s
}

pub fn run(args: FiguresCmd) -> Result<()> {
    check_transient(&args)?;
    let subject = Subject::load(&args.model.setup, args.model.mu)?;
    subject.check()?;
    let run = TraceRun {
        duration: args.duration,
        stride: stride(subject.dt()),
        transient: args.transient(),
    };
    let tr = subject.run_loop(run)?;
    let f = subject.feedback();
    let labels = Labels {
        mu: f.mu,
        on: f.enabled && f.mu != 0.0,
        t_on: f.t_on,
        q0: subject.q0(),
        period: subject.period(),
        duration: args.duration,
        margin: subject.obstacle_margin(),
    };
    let phase = args
        .phase_window
        .unwrap_or([(args.duration - 20.0).max(args.transient()), args.duration]);
    if phase[0] < 0.0 || phase[1] > args.duration + 1e-9 {
        bail!(
            "--phase-window {}:{}: must lie inside the run, 0:{}",
            phase[0],
            phase[1],
            args.duration
        );
    }
    let classify_cfg: ClassifyConfig = args.classify.config()?;
    draw(
        &args,
        &labels,
        &tr,
        phase,
        &classify(&tr.section, &classify_cfg),
    )
}

/// The longest run the figures draw (s): every 10 ms kept, a 7-joint run of this length is
/// about 140 MB of samples; a longer one would exhaust memory before it drew anything.
const MAX_DURATION: f64 = 1e4;

/// `--duration` in (0, [`MAX_DURATION`]] and `--transient` inside `[0, --duration)`.
fn check_transient(args: &FiguresCmd) -> Result<()> {
    if !(args.duration > 0.0 && args.duration <= MAX_DURATION) {
        bail!(
            "--duration {}: must be a number of seconds in (0, {MAX_DURATION}] (the figures keep a sample every 10 ms)",
            args.duration
        );
    }
    if !(args.transient() >= 0.0 && args.transient() < args.duration) {
        bail!(
            "--transient {}: must be in [0, --duration = {})",
            args.transient(),
            args.duration
        );
    }
    Ok(())
}

/// Every 10 ms of the run, at least every step.
fn stride(dt: f64) -> u64 {
    ((0.01 / dt).round() as u64).max(1)
}

/// The four figures of one run, and the summary printed after them.
fn draw(
    args: &FiguresCmd,
    cfg: &Labels,
    tr: &Trace,
    phase: [f64; 2],
    class: &Classification,
) -> Result<()> {
    let stem = args
        .name
        .clone()
        .unwrap_or_else(|| format!("mu{}", fmt_num(cfg.mu)));
    let prefix = |what: &str| args.output_dir.join(format!("{stem}_{what}"));
    let (mu, on) = (cfg.mu, cfg.on);
    let when = if on {
        format!("μ = {mu}, feedback on at t = {} s", cfg.t_on)
    } else {
        "μ = 0 (no feedback)".into()
    };
    let start = format!("q0 = ({})", fmt_list(&cfg.q0));
    let (fig_t, fig_p, fig_s) = if on { ("7", "8", "9") } else { ("2", "3", "4") };
    let mut written: Vec<PathBuf> = Vec::new();

    // Time courses: the whole run and its last three periods.
    let last = (args.duration - 3.0 * cfg.period).max(0.0);
    let mut panels = Vec::new();
    for i in 0..tr.n {
        let pts: Vec<(f64, f64)> = tr.t.iter().zip(&tr.q[i]).map(|(t, q)| (*t, *q)).collect();
        let tail: Vec<(f64, f64)> = pts.iter().filter(|p| p.0 >= last).copied().collect();
        let rules = if on {
            vec![Rule {
                value: cfg.t_on,
                vertical: true,
                color: PALETTE[1],
                label: Some(format!("feedback on (t = {} s)", cfg.t_on)),
            }]
        } else {
            vec![]
        };
        panels.push(Panel::Chart(Chart {
            title: format!("q{}(t), whole run", i + 1),
            x_label: "t (s)".into(),
            y_label: format!("q{} (rad)", i + 1),
            series: vec![Series::new(None, PALETTE[0], Style::Line(1), pts)],
            rules,
            legend: on && i == 0,
            ..Default::default()
        }));
        panels.push(Panel::Chart(Chart {
            title: format!("q{}(t), last 3 periods", i + 1),
            x_label: "t (s)".into(),
            y_label: format!("q{} (rad)", i + 1),
            series: vec![Series::new(None, PALETTE[0], Style::Line(2), tail)],
            ..Default::default()
        }));
    }
    written.extend(
        Figure {
            title: Some(format!(
                "Joint angles, {when}, {start} (cf. the paper's Fig. {fig_t})"
            )),
            panels,
            cols: 2,
            panel_size: (520, 210),
        }
        .save(&prefix("time"))?,
    );

    // Phase portraits.
    let panels = (0..tr.n)
        .map(|i| {
            let pts: Vec<(f64, f64)> =
                tr.t.iter()
                    .enumerate()
                    .filter(|(_, t)| **t >= phase[0] && **t <= phase[1])
                    .map(|(k, _)| (tr.q[i][k], tr.qd[i][k]))
                    .collect();
            Panel::Chart(Chart {
                title: format!("joint {}", i + 1),
                x_label: format!("q{} (rad)", i + 1),
                y_label: format!("dq{}/dt (rad/s)", i + 1),
                series: vec![Series::new(None, PALETTE[0], Style::Line(1), pts).alpha(0.7)],
                ..Default::default()
            })
        })
        .collect();
    written.extend(
        Figure {
            title: Some(format!(
                "Phase portraits, t = {:.0}–{:.0} s, {when} (cf. the paper's Fig. {fig_p})",
                phase[0], phase[1]
            )),
            panels,
            cols: tr.n,
            panel_size: (400, 380),
        }
        .save(&prefix("phase"))?,
    );

    // Poincaré section.
    written.extend(
        Figure {
            title: Some(format!(
                "Poincaré section t = kT, {}: {} (cf. the paper's Fig. {fig_s})",
                if on {
                    format!("μ = {mu}")
                } else {
                    "μ = 0".into()
                },
                describe(class)
            )),
            panels: section_panels(&tr.section, tr.n, phase[0]),
            cols: tr.n,
            panel_size: (400, 380),
        }
        .save(&prefix("poincare"))?,
    );

    // Period residual (and clearance).
    let floor = 1e-16;
    let resid: Vec<(f64, f64)> =
        tr.t.iter()
            .zip(&tr.residual)
            .filter(|(t, _)| **t >= cfg.period)
            .map(|(t, r)| (*t, r.max(floor).log10()))
            .collect();
    let mut panels = vec![Panel::Chart(Chart {
        title: "distance from period T".into(),
        x_label: "t (s)".into(),
        y_label: "log10 |dq/dt(t) − dq/dt(t − T)|  (rad/s)".into(),
        series: vec![Series::new(None, PALETTE[0], Style::Line(1), resid)],
        rules: if on {
            vec![Rule {
                value: cfg.t_on,
                vertical: true,
                color: PALETTE[1],
                label: Some("feedback on".into()),
            }]
        } else {
            vec![]
        },
        legend: on,
        ..Default::default()
    })];
    if tr.numbers.min_clearance.is_some() {
        let contact = tr.contact_time();
        let margin = cfg.margin;
        let clear: Vec<(f64, f64)> =
            tr.t.iter()
                .zip(&tr.clearance)
                .map(|(t, c)| (*t, *c))
                .collect();
        panels.push(Panel::Chart(Chart {
            title: format!(
                "obstacle clearance: min {:+.3} m; {:.1} s of {} s inside a safety zone, {contact:.1} s in contact",
                tr.numbers.min_clearance.unwrap_or(f64::NAN),
                tr.numbers.time_in_safety_zone,
                args.duration
            ),
            x_label: "t (s)".into(),
            y_label: "distance arm–obstacle surface (m)".into(),
            series: vec![Series::new(None, PALETTE[0], Style::Line(1), clear)],
            rules: vec![
                Rule {
                    value: 0.0,
                    vertical: false,
                    color: PALETTE[1],
                    label: Some("contact".into()),
                },
                Rule {
                    value: margin,
                    vertical: false,
                    color: GREY,
                    label: Some(format!("safety margin {margin} m")),
                },
            ],
            legend: true,
            ..Default::default()
        }));
    }
    let rows = panels.len();
    let title = format!("Does the motion become periodic? {when}, {start}");
    // Wide enough for the title: a 7-joint start is a long line.
    let width = 1000.max(9 * title.chars().count() as u32);
    written.extend(
        Figure {
            title: Some(title),
            panels,
            cols: 1,
            panel_size: (width, if rows > 1 { 280 } else { 340 }),
        }
        .save(&prefix("residual"))?,
    );

    print_summary(cfg, tr, class, &written);
    Ok(())
}

fn print_summary(cfg: &Labels, tr: &Trace, class: &Classification, files: &[PathBuf]) {
    let s = &tr.numbers;
    println!(
        "chaosd figures: μ = {}, q0 = ({}), {} s",
        cfg.mu,
        fmt_list(&cfg.q0),
        cfg.duration
    );
    println!(
        "  Poincaré section  {} ({} points)",
        describe(class),
        tr.section.len()
    );
    println!(
        "  period residual   before feedback {}, last 10 periods {}",
        s.period_residual_before
            .map(|v| format!("{v:.3e} rad/s"))
            .unwrap_or_else(|| "n/a".into()),
        s.period_residual_final
            .map(|v| format!("{v:.3e} rad/s"))
            .unwrap_or_else(|| "n/a".into())
    );
    println!(
        "  tracking          RMS {:.3e} m, max {:.3e} m",
        s.rms_tracking_error, s.max_tracking_error
    );
    if let Some(c) = s.min_clearance {
        println!(
            "  obstacles         min clearance {c:+.4} m, {:.2} s inside a safety zone, {:.2} s in contact \
             (clearance < 0, sampled every {} s), the last at t = {}",
            s.time_in_safety_zone,
            tr.contact_time(),
            tr.stride_dt,
            tr.last_contact().map(|t| format!("{t:.2} s")).unwrap_or_else(|| "never".into())
        );
    }
    for f in files
        .iter()
        .filter(|f| f.extension().is_some_and(|e| e == "png"))
    {
        println!("  wrote             {} (+ .svg)", f.display());
    }
}
