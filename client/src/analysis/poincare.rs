//! `chaosctl poincare`: the stroboscopic section at t = kT of one run, its classification
//! (period-p, converging, quasi-periodic, irregular; the rule is in `control::analysis::poincare`),
//! the evidence behind the verdict, a CSV of the points and a plot, on any arm.

use super::figures::section_panels;
use super::{fmt_list, ClassifyArgs};
use crate::plot::{with_ext, Chart, Figure, Panel, Series, Style, PALETTE};
use crate::setup::ModelArgs;
use crate::subject::Subject;
use anyhow::{Context, Result};
use clap::Args;
use control::analysis::{Classification, RunSpec};
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct PoincareCmd {
    #[command(flatten)]
    pub model: ModelArgs,
    /// Simulated time (s).
    #[arg(long, default_value_t = 300.0)]
    pub duration: f64,
    /// The section records t = kT from here on (s) [default: 100, or half a shorter run].
    #[arg(long)]
    pub transient: Option<f64>,
    #[command(flatten)]
    pub classify: ClassifyArgs,
    /// Output prefix: writes PREFIX.csv, PREFIX.png and PREFIX.svg.
    #[arg(long, default_value = "poincare")]
    pub output: PathBuf,
    /// Print the classification as JSON.
    #[arg(long)]
    pub json: bool,
}

impl PoincareCmd {
    /// `--transient`, or its default ([`crate::setup::transient_or`]).
    pub fn transient(&self) -> f64 {
        crate::setup::transient_or(self.transient, 100.0, self.duration)
    }
}

#[derive(Serialize)]
struct Report<'a> {
    mu: f64,
    q0: Vec<f64>,
    points: usize,
    first: f64,
    last: f64,
    #[serde(flatten)]
    classification: &'a Classification,
}

pub fn run(args: PoincareCmd) -> Result<()> {
    crate::plot::make_room(&args.output)?;
    let subject = Subject::load(&args.model.setup, args.model.mu)?;
    subject.check()?;
    super::check_run_window(args.duration, args.transient())?;
    let spec = RunSpec {
        duration: args.duration,
        transient: args.transient(),
        lyapunov: None,
        classify: args.classify.config()?,
    };
    let run = subject.analyse(&spec)?;
    let who = Run {
        n: subject.n(),
        mu: subject.mu(),
        q0: subject.q0(),
    };
    report(&args, &spec, &who, &run.section, &run.classification)
}

/// Which run a section belongs to, for the CSV header and the titles.
pub struct Run {
    pub n: usize,
    pub mu: f64,
    pub q0: Vec<f64>,
}

/// Writes the CSV and the figure, and prints (or prints as JSON) the verdict.
fn report(
    args: &PoincareCmd,
    spec: &RunSpec,
    who: &Run,
    sec: &control::analysis::Section,
    c: &Classification,
) -> Result<()> {
    let csv = with_ext(&args.output, "csv");
    {
        let file = std::fs::File::create(&csv)
            .with_context(|| format!("cannot create {}", csv.display()))?;
        let mut w = std::io::BufWriter::new(file);
        let n = who.n;
        let offset = sec.dim - 2 * n;
        let mut header = String::from("t");
        if offset == 1 {
            header.push_str(",phi");
        }
        (1..=n).for_each(|i| header.push_str(&format!(",q{i}")));
        (1..=n).for_each(|i| header.push_str(&format!(",qd{i}")));
        writeln!(w, "{header}")?;
        for (t, p) in sec.times.iter().zip(sec.points()) {
            write!(w, "{t}")?;
            for v in p {
                write!(w, ",{v:.12e}")?;
            }
            writeln!(w)?;
        }
        w.flush()?;
    }
    // Plot: q̇_i against q_i, and the return distances over time.
    let n = who.n;
    let offset = sec.dim - 2 * n;
    let shifted = sec_without_phi(sec, offset);
    let (t0, t1) = (
        sec.times.first().copied().unwrap_or(0.0),
        sec.times.last().copied().unwrap_or(0.0),
    );
    let mut panels = section_panels(&shifted, n, (t1 - 0.25 * (t1 - t0)).round());
    let p = c.motion.period().unwrap_or(1);
    let ret: Vec<(f64, f64)> = sec
        .return_distances(p)
        .iter()
        .enumerate()
        .map(|(k, d)| (sec.times[k + p], d.max(1e-16).log10()))
        .collect();
    panels.push(Panel::Chart(Chart {
        title: format!(
            "return distance after {p} period{}",
            if p > 1 { "s" } else { "" }
        ),
        x_label: "t (s)".into(),
        y_label: format!("log10 |x(t) − x(t − {p}T)|"),
        series: vec![Series::new(None, PALETTE[1], Style::Line(1), ret)],
        ..Default::default()
    }));
    let k =
        c.k.map(|k| format!(", 0-1 test K = {k:.2}"))
            .unwrap_or_default();
    let files = Figure {
        title: Some(format!(
            "Poincaré section t = kT, μ = {}, q0 = ({}): {}{k}",
            who.mu,
            fmt_list(&who.q0),
            c.motion.label()
        )),
        panels,
        cols: n + 1,
        panel_size: (420, 400),
    }
    .save(&args.output)?;
    if args.json {
        let r = Report {
            mu: who.mu,
            q0: who.q0.clone(),
            points: sec.len(),
            first: sec.times.first().copied().unwrap_or(f64::NAN),
            last: sec.times.last().copied().unwrap_or(f64::NAN),
            classification: c,
        };
        println!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(());
    }
    println!(
        "chaosd Poincaré section: μ = {}, q0 = ({}), t = kT from {} to {} s ({} points)",
        who.mu,
        fmt_list(&who.q0),
        sec.times.first().copied().unwrap_or(f64::NAN),
        sec.times.last().copied().unwrap_or(f64::NAN),
        sec.len()
    );
    println!("  class            {}", c.motion.label());
    match c.motion {
        control::analysis::Motion::Converging { residual, contraction, .. } => println!(
            "  converging       last return distance {residual:.2e}, shrinking ×{contraction:.3} per period"
        ),
        control::analysis::Motion::TooShort { points } => println!(
            "  too short        {points} points; at least {} are needed (lower --transient or raise --duration)",
            spec.classify.min_points
        ),
        _ => {}
    }
    if !c.returns.is_empty() {
        println!(
            "  return distances max |x_k − x_(k−p)| over the last {} samples, p = 1..{}: {}",
            spec.classify.window,
            c.returns.len(),
            c.returns
                .iter()
                .map(|r| format!("{r:.1e}"))
                .collect::<Vec<_>>()
                .join(" ")
        );
    }
    if let Some(k) = c.k {
        println!(
            "  0-1 test         K = {k:.3} (≥ {} irregular, below: regular)",
            spec.classify.chaos_threshold
        );
    }
    println!(
        "  wrote            {}, {}",
        csv.display(),
        files
            .iter()
            .map(|f| f.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}

/// The section without a leading φ coordinate (floating base), for the q/q̇ panels.
fn sec_without_phi(sec: &control::analysis::Section, offset: usize) -> control::analysis::Section {
    if offset == 0 {
        return sec.clone();
    }
    let mut out = control::analysis::Section::new(sec.dim - offset, sec.angles - offset);
    for (t, p) in sec.times.iter().zip(sec.points()) {
        out.push(*t, &p[offset..]);
    }
    out
}
