//! `chaosctl sweep`: λ_max and the Poincaré classification over a μ range and several initial
//! states, in parallel, on any arm; writes CSV and the λ_max-versus-μ plot (the paper's Fig. 6)
//! beside the final period residual.
//!
//! Every cell is one [`Subject::analyse`] run, so the planar arm and a robot fill the same row
//! from the same statistics, and a sharded sweep of either merges the same way.

use super::parallel::jobs;
use super::shard::{self, Grid, Loaded, Shard};
use super::{fmt_list, ClassifyArgs, LyapunovArgs, ScanModelArgs, StartArgs};
use crate::plot::{Chart, Figure, Panel, Series, Style, DARK, PALETTE};
use crate::subject::Subject;
use anyhow::{Context, Result};
use clap::Args;
use control::analysis::{Motion, RunSpec};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Args, Debug)]
pub struct SweepCmd {
    #[command(flatten)]
    pub model: ScanModelArgs,
    #[command(flatten)]
    pub starts: StartArgs,
    #[command(flatten)]
    pub lyapunov: LyapunovArgs,
    #[command(flatten)]
    pub classify: ClassifyArgs,
    /// Worker threads (default: every core).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Output prefix: writes PREFIX.csv, PREFIX.png and PREFIX.svg.
    #[arg(long, default_value = "sweep")]
    pub output: PathBuf,
    /// Print the rows as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Run only shard I of N (0 ≤ I < N; grid point k goes to shard k mod N) and write
    /// PREFIX.shard-I-of-N.json; `chaosctl merge` makes the CSV and plot from all N.
    #[arg(long, value_parser = shard::parse_shard, value_name = "I/N")]
    pub shard: Option<Shard>,
}

/// One (start, μ) cell of the sweep; a shard file carries exactly this per grid point.
#[derive(Serialize, Deserialize, Clone, Debug, Default)]
pub struct Row {
    pub mu: f64,
    pub start: usize,
    pub q0: Vec<f64>,
    pub lambda_max: Option<f64>,
    pub stderr: Option<f64>,
    pub motion: Option<Motion>,
    /// max |x_k − x_(k−1)| over the last samples of the section.
    pub return1: Option<f64>,
    pub k01: Option<f64>,
    pub rms_tracking_error: Option<f64>,
    pub max_tracking_error: Option<f64>,
    pub track_lost_fraction: Option<f64>,
    pub min_clearance: Option<f64>,
    pub time_in_safety_zone: Option<f64>,
    /// |q̇(t) − q̇(t − T)| over the last periods (rad/s): how periodic the run ended.
    pub residual_final: Option<f64>,
    /// How far the joints moved from one period to the next at the end (rad).
    pub drift_per_period: Option<f64>,
    pub max_joint_speed: Option<f64>,
    /// The smallest distance to a joint's position limit (rad; none without limits).
    pub min_joint_margin: Option<f64>,
    /// Why the run has no result (e.g. it diverged).
    pub error: Option<String>,
}

/// The validated sweep: its grid points (start index, set-up) in CSV row order.
struct Plan {
    base: Subject,
    mus: Vec<f64>,
    starts: Vec<Subject>,
    spec: RunSpec,
    items: Vec<(usize, Subject)>,
}

fn plan(args: &SweepCmd) -> Result<Plan> {
    let mus = args.model.mus("0:3:0.1")?;
    let base = Subject::load(&args.model.setup, None)?;
    let starts = base.starts(&args.starts, args.model.setup.q0.is_some())?;
    let classify = args.classify.config()?;
    let spec = args.lyapunov.spec(base.period(), base.dt(), classify)?;
    let mut items = Vec::new();
    for &mu in &mus {
        for (i, s) in starts.iter().enumerate() {
            let mut c = s.clone();
            c.set_mu(mu);
            c.check()
                .with_context(|| format!("μ = {mu}, start {}", i + 1))?;
            items.push((i, c));
        }
    }
    Ok(Plan {
        base,
        mus,
        starts,
        spec,
        items,
    })
}

fn grid(plan: &Plan) -> Grid {
    let parts = std::iter::once(format!("{:?}", plan.spec))
        .chain(plan.items.iter().map(|(i, c)| format!("{i} {c}")));
    let labels = plan
        .items
        .iter()
        .map(|(i, c)| format!("μ = {}, start {}", c.mu(), i + 1))
        .collect();
    Grid::new("sweep", parts, labels)
}

pub fn run(args: SweepCmd) -> Result<()> {
    crate::plot::make_room(&args.output)?;
    let plan = plan(&args)?;
    let threads = jobs(args.jobs);
    let work = |(i, c): &(usize, Subject)| row(*i, c, &plan.spec);
    let t0 = Instant::now();
    let grid = || grid(&plan);
    let (items, out) = (&plan.items, &args.output);
    let Some(rows) = shard::run_or_shard("sweep", args.shard, grid, items, out, threads, work)?
    else {
        return Ok(());
    };
    finish(
        &args,
        &plan,
        &rows,
        Some((t0.elapsed().as_secs_f64(), threads)),
    )
}

/// `chaosctl merge` of sweep shards: the same CSV, plot and table as the unsharded run.
pub fn merge(args: SweepCmd, files: Vec<Loaded>) -> Result<()> {
    let plan = plan(&args)?;
    let rows: Vec<Row> = shard::collect(&grid(&plan), files)?;
    finish(&args, &plan, &rows, None)
}

/// Writes the CSV and plot and prints the table; `timing` is (wall s, threads) of a local run.
fn finish(args: &SweepCmd, plan: &Plan, rows: &[Row], timing: Option<(f64, usize)>) -> Result<()> {
    let (mus, starts, spec) = (&plan.mus, &plan.starts, &plan.spec);
    let csv = crate::plot::with_ext(&args.output, "csv");
    write_csv(&csv, rows)?;
    let files = plot(&args.output, rows, plan)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    println!("λ_max (1/s) ± standard error, and the Poincaré section's class, per initial state:");
    for (i, s) in starts.iter().enumerate() {
        println!("  start {}: q0 = ({})", i + 1, fmt_list(&s.q0()));
    }
    print_grid(rows, starts.len(), mus, 34, |r| {
        match (&r.error, r.lambda_max, r.stderr, r.motion) {
            (Some(e), ..) => format!("error: {}", e.chars().take(26).collect::<String>()),
            (None, Some(l), Some(se), Some(m)) => format!("{l:+.3} ± {se:.3}  {}", m.label()),
            _ => "n/a".into(),
        }
    });
    println!("\nhow the run ended: period residual |q̇(t) − q̇(t − T)| (rad/s), fastest joint (rad/s), smallest margin to a joint limit (rad):");
    print_grid(rows, starts.len(), mus, 34, |r| {
        let f = |v: Option<f64>| v.map_or("—".into(), |x| format!("{x:.2e}"));
        format!(
            "{}  {}  {}",
            f(r.residual_final),
            f(r.max_joint_speed),
            r.min_joint_margin.map_or("—".into(), |x| format!("{x:.3}"))
        )
    });
    if rows.iter().any(|r| r.min_clearance.is_some()) {
        println!("\nobstacle: smallest clearance (m, < 0: a link crosses the obstacle) and time inside the safety zone (s, over the whole run):");
        print_grid(rows, starts.len(), mus, 26, |r| {
            match (r.min_clearance, r.time_in_safety_zone) {
                (Some(c), Some(z)) => format!("{c:+.3} m, {z:6.1} s in zone"),
                _ => "n/a".into(),
            }
        });
    }
    let runs = rows.len();
    let sim = runs as f64 * spec.duration;
    if let Some((wall, threads)) = timing {
        println!(
        "\n{runs} runs ({} μ × {} starts), {} s each with a Lyapunov partner: {:.0} s of closed loop \
         ({:.0} trajectory-seconds with the partners) in {wall:.2} s wall on {threads} thread{} = \
         {:.0} simulated s per wall s ({:.0} counting partners)",
        mus.len(),
        starts.len(),
        spec.duration,
        sim,
        2.0 * sim,
        if threads == 1 { "" } else { "s" },
        sim / wall,
        2.0 * sim / wall
    );
    } else {
        println!(
            "\n{runs} runs ({} μ × {} starts), merged from shards",
            mus.len(),
            starts.len()
        );
    }
    super::print_written(&[std::slice::from_ref(&csv), &files[..]].concat());
    Ok(())
}

fn row(start: usize, s: &Subject, spec: &RunSpec) -> Row {
    let mut r = Row {
        mu: s.mu(),
        start,
        q0: s.q0(),
        ..Row::default()
    };
    match s.analyse(spec) {
        Ok(a) => {
            if let Some(l) = &a.lyapunov {
                r.lambda_max = Some(l.lambda_max);
                r.stderr = Some(l.stderr);
            }
            r.motion = Some(a.classification.motion);
            r.return1 = a.classification.returns.first().copied();
            r.k01 = a.classification.k;
            let m = &a.summary;
            r.rms_tracking_error = Some(m.rms_tracking_error);
            r.max_tracking_error = Some(m.max_tracking_error);
            r.track_lost_fraction = Some(m.track_lost_fraction);
            r.min_clearance = m.min_clearance;
            r.time_in_safety_zone = m.min_clearance.map(|_| m.time_in_safety_zone);
            r.residual_final = m.period_residual_final;
            r.drift_per_period = m.drift_per_period;
            r.max_joint_speed = Some(m.max_joint_speed);
            r.min_joint_margin = m.min_joint_margin;
        }
        Err(e) => r.error = Some(format!("{e:#}")),
    }
    r
}

fn opt(v: Option<f64>) -> String {
    v.map(|x| format!("{x:.6e}")).unwrap_or_default()
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    let file =
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = std::io::BufWriter::new(file);
    writeln!(
        w,
        "mu,start,q0,lambda_max,stderr,motion,period,return1,k01,rms_tracking_error,max_tracking_error,\
         track_lost_fraction,min_clearance,time_in_safety_zone,residual_final,drift_per_period,\
         max_joint_speed,min_joint_margin,error"
    )?;
    for r in rows {
        let q0 =
            r.q0.iter()
                .map(|v| format!("{v}"))
                .collect::<Vec<_>>()
                .join(" ");
        let numbers = [
            r.return1,
            r.k01,
            r.rms_tracking_error,
            r.max_tracking_error,
            r.track_lost_fraction,
            r.min_clearance,
            r.time_in_safety_zone,
            r.residual_final,
            r.drift_per_period,
            r.max_joint_speed,
            r.min_joint_margin,
        ];
        let mut cells: Vec<String> = numbers.iter().map(|v| opt(*v)).collect();
        cells[1] = r.k01.map(|k| format!("{k:.4}")).unwrap_or_default();
        writeln!(
            w,
            "{},{},{q0},{},{},{},{},{},{}",
            r.mu,
            r.start,
            opt(r.lambda_max),
            opt(r.stderr),
            r.motion
                .map(|m| m.label().replace("→ ", "converging-"))
                .unwrap_or_default(),
            r.motion
                .and_then(|m| m.period())
                .map(|p| p.to_string())
                .unwrap_or_default(),
            cells.join(","),
            r.error.as_deref().unwrap_or("").replace(',', ";")
        )?;
    }
    w.flush()?;
    Ok(())
}

/// A table with a row per μ and a column per start, each cell `cell(row)` padded to `width`.
fn print_grid(
    rows: &[Row],
    starts: usize,
    mus: &[f64],
    width: usize,
    cell: impl Fn(&Row) -> String,
) {
    print!("{:>6}", "μ");
    for i in 0..starts {
        print!("  {:<width$}", format!("start {}", i + 1));
    }
    println!();
    for &mu in mus {
        print!("{mu:>6.2}");
        for r in rows.iter().filter(|r| r.mu == mu) {
            print!("  {:<width$}", cell(r));
        }
        println!();
    }
}

fn plot(prefix: &Path, rows: &[Row], plan: &Plan) -> Result<Vec<PathBuf>> {
    let (lambda, residual) = (
        lambda_series(rows, &plan.starts),
        residual_series(rows, &plan.starts),
    );
    let w = plan
        .spec
        .lyapunov
        .map(|l| l.window)
        .unwrap_or([0.0, plan.spec.duration]);
    let mu_max = rows.iter().map(|r| r.mu).fold(0.0, f64::max);
    // The paper's claimed window is the paper's arm's.
    let marks = super::lambda_plot_marks(if plan.base.is_planar_3_link() {
        mu_max
    } else {
        0.0
    });
    let (tau, t_on) = plan.base.tau_and_t_on();
    let chart = Chart {
        title: format!(
            "λ_max averaged over {:.0}–{:.0} s, τ = {tau} s, feedback on at {t_on} s",
            w[0], w[1],
        ),
        x_label: "Pyragas gain μ (1/s)".into(),
        y_label: "largest Lyapunov exponent λ_max (1/s)".into(),
        series: lambda,
        bands: marks.0,
        rules: marks.1,
        legend: true,
        ..Default::default()
    };
    let residual = Chart {
        title: "period residual over the last periods".into(),
        x_label: "Pyragas gain μ (1/s)".into(),
        y_label: "log₁₀ |q̇(t) − q̇(t − T)| (rad/s)".into(),
        series: residual,
        legend: true,
        ..Default::default()
    };
    Figure {
        title: Some(format!(
            "Largest Lyapunov exponent vs delayed-feedback gain (cf. the paper's Fig. 6): {}",
            plan.base.describe()
        )),
        panels: vec![Panel::Chart(chart), Panel::Chart(residual)],
        cols: 2,
        panel_size: (800, 520),
    }
    .save(prefix)
}

/// λ_max ± its standard error per start, and the periodic cells marked.
fn lambda_series(rows: &[Row], starts: &[Subject]) -> Vec<Series> {
    let mut series = Vec::new();
    for (i, s) in starts.iter().enumerate() {
        let mine: Vec<&Row> = rows
            .iter()
            .filter(|r| r.start == i && r.lambda_max.is_some())
            .collect();
        let pts = mine
            .iter()
            .map(|r| (r.mu, r.lambda_max.unwrap_or(f64::NAN)))
            .collect();
        let err = mine.iter().map(|r| r.stderr.unwrap_or(0.0)).collect();
        series.push(
            Series::new(
                Some(format!("q0 = ({})", fmt_list(&s.q0()))),
                PALETTE[i % PALETTE.len()],
                Style::LineMarkers { width: 2, size: 3 },
                pts,
            )
            .yerr(err),
        );
    }
    let periodic: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| matches!(r.motion, Some(Motion::Periodic { .. })))
        .filter_map(|r| r.lambda_max.map(|l| (r.mu, l)))
        .collect();
    series.push(Series::new(
        Some("section periodic (period-p)".into()),
        DARK,
        Style::Markers {
            size: 7,
            filled: false,
        },
        periodic,
    ));
    series
}

/// log₁₀ of the final period residual per start.
fn residual_series(rows: &[Row], starts: &[Subject]) -> Vec<Series> {
    (0..starts.len())
        .map(|i| {
            let pts = rows
                .iter()
                .filter(|r| r.start == i)
                .filter_map(|r| {
                    r.residual_final
                        .filter(|v| *v > 0.0)
                        .map(|v| (r.mu, v.log10()))
                })
                .collect();
            Series::new(
                Some(format!("start {}", i + 1)),
                PALETTE[i % PALETTE.len()],
                Style::LineMarkers { width: 2, size: 3 },
                pts,
            )
        })
        .collect()
}
