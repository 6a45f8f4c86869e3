//! `chaosctl sweep`: λ_max and the Poincaré classification over a μ range and several initial
//! states, in parallel; writes CSV and the λ_max-versus-μ plot (the paper's Fig. 6).

use super::parallel::{jobs, run_all};
use super::shard::{self, Grid, Loaded, Shard};
use super::{analyse_config, fmt_list, ClassifyArgs, LyapunovArgs, ScanModelArgs, StartArgs};
use crate::plot::{Chart, Figure, Panel, Series, Style, DARK, PALETTE};
use anyhow::{Context, Result};
use clap::Args;
use control::analysis::{Motion, RunSpec};
use control::config::spatial::SpatialConfig;
use control::Config;
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

/// One (start, μ) cell of the sweep.
#[derive(Serialize, Deserialize, Clone, Debug)]
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
    /// Why the run has no result (e.g. it diverged).
    pub error: Option<String>,
}

/// The validated sweep: its grid points (start index, config) in CSV row order.
struct Plan {
    base: Config,
    mus: Vec<f64>,
    starts: Vec<Config>,
    spec: RunSpec,
    items: Vec<(usize, Config)>,
}

fn plan(args: &SweepCmd) -> Result<Plan> {
    let (base, mus) = args.model.load("0:3:0.1")?;
    let starts = args.starts.configs(&base, args.model.setup.q0.is_some())?;
    let classify = args.classify.config()?;
    let spec = args.lyapunov.spec(&base, classify)?;
    let mut items: Vec<(usize, Config)> = Vec::new();
    for &mu in &mus {
        for (i, s) in starts.iter().enumerate() {
            let mut c = s.clone();
            c.feedback.mu = mu;
            c.validate()?;
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
        .chain(plan.items.iter().map(|(i, c)| format!("{i} {c:?}")));
    let labels = plan
        .items
        .iter()
        .map(|(i, c)| format!("μ = {}, start {}", c.feedback.mu, i + 1))
        .collect();
    Grid::new("sweep", parts, labels)
}

pub fn run(args: SweepCmd) -> Result<()> {
    if let Some(cfg) = crate::spatial::load(&args.model.setup, None)? {
        return spatial(&args, &cfg);
    }
    let plan = plan(&args)?;
    let threads = jobs(args.jobs);
    let work = |(i, c): &(usize, Config)| row(*i, c, &plan.spec);
    if let Some(s) = args.shard {
        shard::run_shard(&grid(&plan), s, &plan.items, &args.output, threads, work)?;
        return Ok(());
    }
    let t0 = Instant::now();
    let rows = run_all(&plan.items, threads, "sweep", work)?;
    finish(
        &args,
        &plan,
        &rows,
        Some((t0.elapsed().as_secs_f64(), threads)),
    )
}

/// `chaosctl merge` of sweep shards: the same CSV, plot and table as the unsharded run.
pub fn merge(args: SweepCmd, files: Vec<Loaded>) -> Result<()> {
    if let Some(cfg) = crate::spatial::load(&args.model.setup, None)? {
        return spatial_merge(&args, &cfg, files);
    }
    let plan = plan(&args)?;
    let rows: Vec<Row> = shard::collect(&grid(&plan), files)?;
    finish(&args, &plan, &rows, None)
}

/// Writes the CSV and plot and prints the table; `timing` is (wall s, threads) of a local run.
fn finish(args: &SweepCmd, plan: &Plan, rows: &[Row], timing: Option<(f64, usize)>) -> Result<()> {
    let (base, mus, starts, spec) = (&plan.base, &plan.mus, &plan.starts, &plan.spec);
    let csv = crate::plot::with_ext(&args.output, "csv");
    write_csv(&csv, rows)?;
    let files = plot(&args.output, rows, starts, base, spec)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    print_table(rows, starts, mus);
    if rows.iter().any(|r| r.min_clearance.is_some()) {
        print_obstacles(rows, starts, mus);
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

fn row(start: usize, cfg: &Config, spec: &RunSpec) -> Row {
    let mut r = Row {
        mu: cfg.feedback.mu,
        start,
        q0: cfg.q0(),
        lambda_max: None,
        stderr: None,
        motion: None,
        return1: None,
        k01: None,
        rms_tracking_error: None,
        max_tracking_error: None,
        track_lost_fraction: None,
        min_clearance: None,
        time_in_safety_zone: None,
        error: None,
    };
    match analyse_config(cfg, spec) {
        Ok(a) => {
            if let Some(l) = &a.lyapunov {
                r.lambda_max = Some(l.lambda_max);
                r.stderr = Some(l.stderr);
            }
            r.motion = Some(a.classification.motion);
            r.return1 = a.classification.returns.first().copied();
            r.k01 = a.classification.k;
            r.rms_tracking_error = Some(a.summary.rms_tracking_error);
            r.max_tracking_error = Some(a.summary.max_tracking_error);
            r.track_lost_fraction = Some(a.summary.track_lost_fraction);
            r.min_clearance = a.summary.min_clearance;
            r.time_in_safety_zone = a
                .summary
                .min_clearance
                .map(|_| a.summary.time_in_safety_zone);
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
         track_lost_fraction,min_clearance,time_in_safety_zone,error"
    )?;
    for r in rows {
        let q0 =
            r.q0.iter()
                .map(|v| format!("{v}"))
                .collect::<Vec<_>>()
                .join(" ");
        writeln!(
            w,
            "{},{},{q0},{},{},{},{},{},{},{},{},{},{},{},{}",
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
            opt(r.return1),
            r.k01.map(|k| format!("{k:.4}")).unwrap_or_default(),
            opt(r.rms_tracking_error),
            opt(r.max_tracking_error),
            opt(r.track_lost_fraction),
            opt(r.min_clearance),
            opt(r.time_in_safety_zone),
            r.error.as_deref().unwrap_or("").replace(',', ";")
        )?;
    }
    w.flush()?;
    Ok(())
}

fn print_table(rows: &[Row], starts: &[Config], mus: &[f64]) {
    println!("λ_max (1/s) ± standard error, and the Poincaré section's class, per initial state:");
    for (i, s) in starts.iter().enumerate() {
        println!("  start {}: q0 = ({})", i + 1, fmt_list(&s.q0()));
    }
    print!("{:>6}", "μ");
    for i in 0..starts.len() {
        print!("  {:<34}", format!("start {}", i + 1));
    }
    println!();
    for &mu in mus {
        print!("{mu:>6.2}");
        for r in rows.iter().filter(|r| r.mu == mu) {
            let cell = match (&r.error, r.lambda_max, r.stderr, r.motion) {
                (Some(e), ..) => format!("error: {}", e.chars().take(26).collect::<String>()),
                (None, Some(l), Some(se), Some(m)) => format!("{l:+.3} ± {se:.3}  {}", m.label()),
                _ => "n/a".into(),
            };
            print!("  {cell:<34}");
        }
        println!();
    }
}

fn print_obstacles(rows: &[Row], starts: &[Config], mus: &[f64]) {
    println!("\nobstacle: smallest clearance (m, < 0: a link crosses the obstacle) and time inside the safety zone (s, over the whole run):");
    print!("{:>6}", "μ");
    for i in 0..starts.len() {
        print!("  {:<26}", format!("start {}", i + 1));
    }
    println!();
    for &mu in mus {
        print!("{mu:>6.2}");
        for r in rows.iter().filter(|r| r.mu == mu) {
            let cell = match (r.min_clearance, r.time_in_safety_zone) {
                (Some(c), Some(z)) => format!("{c:+.3} m, {z:6.1} s in zone"),
                _ => "n/a".into(),
            };
            print!("  {cell:<26}");
        }
        println!();
    }
}

/// The sweep on a spatial robot: one start (the config's), λ_max and the run's summary per μ;
/// sharded over μ like the planar grid.
fn spatial(args: &SweepCmd, cfg: &SpatialConfig) -> Result<()> {
    let plan = spatial_plan(args, cfg)?;
    let threads = jobs(args.jobs);
    let work =
        |&(i, mu): &(usize, f64)| crate::spatial_sweep::row(&plan.starts[i], i, mu, &plan.spec);
    if let Some(s) = args.shard {
        let grid = spatial_grid(&plan);
        shard::run_shard(&grid, s, &plan.items, &args.output, threads, work)?;
        return Ok(());
    }
    let t0 = Instant::now();
    let rows = run_all(&plan.items, threads, "sweep", work)?;
    spatial_finish(
        args,
        cfg,
        &plan.spec,
        &rows,
        Some(t0.elapsed().as_secs_f64()),
    )
}

/// A spatial robot's sweep: one config per start, and the grid points (start, μ) in CSV row
/// order (μ outer, as for the planar arm).
struct SpatialPlan {
    spec: crate::spatial_sweep::Spec,
    starts: Vec<SpatialConfig>,
    items: Vec<(usize, f64)>,
}

/// The μ values, the starts (`--start`, repeated, or the config's `sim.q0`) and the run of each.
fn spatial_plan(args: &SweepCmd, cfg: &SpatialConfig) -> Result<SpatialPlan> {
    let mus = match &args.model.mu {
        Some(r) => r.0.clone(),
        None => super::parse_range("0:3:0.25").map_err(anyhow::Error::msg)?,
    };
    let l = &args.lyapunov;
    let spec = crate::spatial_sweep::Spec::new(l.duration, l.window, l.d0, l.blocks);
    let mut starts = vec![cfg.clone()];
    if !args.starts.starts.is_empty() {
        starts = args
            .starts
            .starts
            .iter()
            .map(|q0| {
                let mut c = cfg.clone();
                c.sim.q0 = Some(q0.0.clone());
                c
            })
            .collect();
    }
    for (i, c) in starts.iter().enumerate() {
        // Fail early, once a start, on one that cannot run.
        crate::spatial_sweep::check(c).with_context(|| format!("start {}", i + 1))?;
    }
    let items = mus
        .iter()
        .flat_map(|&mu| (0..starts.len()).map(move |i| (i, mu)))
        .collect();
    Ok(SpatialPlan {
        spec,
        starts,
        items,
    })
}

fn spatial_grid(plan: &SpatialPlan) -> Grid {
    let parts = [format!("spatial {:?}", plan.spec)]
        .into_iter()
        .chain(plan.starts.iter().map(|c| format!("{c:?}")))
        .chain(plan.items.iter().map(|(i, mu)| format!("{i} {mu:?}")));
    let labels = plan
        .items
        .iter()
        .map(|(i, mu)| format!("μ = {mu}, start {}", i + 1))
        .collect();
    Grid::new("sweep", parts, labels)
}

/// `chaosctl merge` of a spatial robot's sweep shards.
fn spatial_merge(args: &SweepCmd, cfg: &SpatialConfig, files: Vec<Loaded>) -> Result<()> {
    let plan = spatial_plan(args, cfg)?;
    let rows: Vec<crate::spatial_sweep::SpatialRow> = shard::collect(&spatial_grid(&plan), files)?;
    spatial_finish(args, cfg, &plan.spec, &rows, None)
}

/// Writes the CSV and figure and prints the table; `wall` is a local run's time.
fn spatial_finish(
    args: &SweepCmd,
    cfg: &SpatialConfig,
    spec: &crate::spatial_sweep::Spec,
    rows: &[crate::spatial_sweep::SpatialRow],
    wall: Option<f64>,
) -> Result<()> {
    crate::spatial_sweep::write(&args.output, rows, cfg, spec)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    crate::spatial_sweep::print(rows);
    let took = wall.map_or(String::new(), |w| format!(" in {w:.1} s"));
    println!(
        "{} runs{took}; wrote {} and its .png/.svg",
        rows.len(),
        crate::plot::with_ext(&args.output, "csv").display()
    );
    Ok(())
}

fn plot(
    prefix: &Path,
    rows: &[Row],
    starts: &[Config],
    base: &Config,
    spec: &RunSpec,
) -> Result<Vec<PathBuf>> {
    let mut series = Vec::new();
    for (i, s) in starts.iter().enumerate() {
        let mine: Vec<&Row> = rows
            .iter()
            .filter(|r| r.start == i && r.lambda_max.is_some())
            .collect();
        let pts: Vec<(f64, f64)> = mine
            .iter()
            .map(|r| (r.mu, r.lambda_max.unwrap_or(f64::NAN)))
            .collect();
        let err: Vec<f64> = mine.iter().map(|r| r.stderr.unwrap_or(0.0)).collect();
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
    let w = spec
        .lyapunov
        .map(|l| l.window)
        .unwrap_or([0.0, spec.duration]);
    let mu_max = rows.iter().map(|r| r.mu).fold(0.0, f64::max);
    let marks = super::lambda_plot_marks(mu_max);
    let chart = Chart {
        title: format!(
            "λ_max averaged over {:.0}–{:.0} s, τ = {} s, feedback on at {} s",
            w[0],
            w[1],
            base.tau(),
            base.feedback.t_on
        ),
        x_label: "Pyragas gain μ (1/s)".into(),
        y_label: "largest Lyapunov exponent λ_max (1/s)".into(),
        series,
        bands: marks.0,
        rules: marks.1,
        legend: true,
        ..Default::default()
    };
    Figure {
        title: Some(
            "Largest Lyapunov exponent vs delayed-feedback gain (cf. the paper's Fig. 6)".into(),
        ),
        panels: vec![Panel::Chart(chart)],
        cols: 1,
        panel_size: (1000, 560),
    }
    .save(prefix)
}
