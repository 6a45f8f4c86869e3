//! `chaosctl basins`: where does each start end up, for each μ, on any arm?
//!
//! A family of initial states (one coordinate of the start varied over a range, the others fixed)
//! is run at every μ of a range. Each run's Poincaré section is classified; a run that settles on a
//! period-1 orbit is matched against the orbits already seen (the same orbit of the μ = 0 loop is
//! stabilised at every μ where it is stable, shifted only by the discretisation error), so the map
//! shows *which* orbit each start reaches, and where the motion stays chaotic. If the paper's
//! window held generically, its column range would be one colour.
//!
//! Every cell is one [`Subject::analyse`] run without a Lyapunov partner, so the planar arm's map
//! and a robot's are made, sharded and merged by the same code.

use super::basins_map::{coord_name, finish, BasinsCmd, MapBase, RunEnd};
use super::parallel::jobs;
use super::shard::{self, Loaded};
use crate::subject::Subject;
use anyhow::{bail, Context, Result};
use control::analysis::RunSpec;

/// The validated map: one set-up per grid point, rows (starts) outer, μ inner.
struct Plan {
    base: Subject,
    mus: Vec<f64>,
    spec: RunSpec,
    cells: Vec<Subject>,
}

fn plan(args: &BasinsCmd) -> Result<Plan> {
    let mus = args.model.mus("0:3:0.1")?;
    let base = Subject::load(&args.model.setup, None)?;
    let n = base.n();
    if args.vary.joint >= n {
        bail!("--vary: the arm has {n} joints, so the varied coordinate must be q1..q{n} or qd1..qd{n}");
    }
    let spec = spec(args, &base)?;
    let mut cells = Vec::new();
    for &v in &args.vary.values {
        for &mu in &mus {
            let mut c = base.clone();
            c.set_mu(mu);
            let mut x = c.start_coords(args.vary.rate);
            x[args.vary.joint] = v;
            // Refused here, by name, rather than as a failed cell of the map.
            let c = c
                .with_start_coords(args.vary.rate, x)
                .with_context(|| format!("start with {} = {v}", coord_name(&args.vary)))?;
            cells.push(c);
        }
    }
    Ok(Plan {
        base,
        mus,
        spec,
        cells,
    })
}

/// The run of every cell: the section from `--transient`, long enough to classify.
fn spec(args: &BasinsCmd, base: &Subject) -> Result<RunSpec> {
    super::check_run_window(args.duration, args.transient())?;
    let spec = RunSpec {
        duration: args.duration,
        transient: args.transient(),
        lyapunov: None,
        classify: args.classify.config()?,
    };
    let period = base.period();
    spec.validate(period, base.dt())?;
    let points =
        (args.duration / period + 1e-9).floor() - (args.transient() / period - 1e-9).ceil() + 1.0;
    if points < spec.classify.min_points as f64 {
        bail!(
            "--duration {} with --transient {}: the section would have {points} points, and classifying it needs at least {}",
            args.duration,
            args.transient(),
            spec.classify.min_points
        );
    }
    Ok(spec)
}

/// The grid a shard file names: the run, the varied coordinate and every cell's whole set-up.
fn grid(args: &BasinsCmd, plan: &Plan) -> shard::Grid {
    let parts = [format!("{:?}", plan.spec), format!("{:?}", args.vary)]
        .into_iter()
        .chain(plan.cells.iter().map(|c| format!("{c}")));
    let labels = plan
        .cells
        .iter()
        .map(|c| {
            let x = c.start_coords(args.vary.rate)[args.vary.joint];
            format!("{} = {x}, μ = {}", coord_name(&args.vary), c.mu())
        })
        .collect();
    shard::Grid::new("basins", parts, labels)
}

fn run_end(c: &Subject, spec: &RunSpec) -> Result<RunEnd, String> {
    c.analyse(spec)
        .map(|a| RunEnd {
            motion: a.classification.motion,
            k01: a.classification.k,
            rms_tracking_error: a.summary.rms_tracking_error,
            final_coords: a.final_coords,
        })
        .map_err(|e| format!("{e:#}"))
}

pub fn run(args: BasinsCmd) -> Result<()> {
    crate::plot::make_room(&args.output)?;
    let plan = plan(&args)?;
    let threads = jobs(args.jobs);
    let work = |c: &Subject| run_end(c, &plan.spec);
    let grid = || grid(&args, &plan);
    let (items, out) = (&plan.cells, &args.output);
    let Some(runs) = shard::run_or_shard("basins", args.shard, grid, items, out, threads, work)?
    else {
        return Ok(());
    };
    let base = plan.map_base(&args);
    finish(&args, &base, &runs)
}

/// `chaosctl merge` of basins shards: the same CSV, map and plot as the unsharded run.
pub fn merge(args: BasinsCmd, files: Vec<Loaded>) -> Result<()> {
    let plan = plan(&args)?;
    let runs: Vec<Result<RunEnd, String>> = shard::collect(&grid(&args, &plan), files)?;
    let base = plan.map_base(&args);
    finish(&args, &base, &runs)
}

impl Plan {
    fn map_base<'a>(&'a self, args: &BasinsCmd) -> MapBase<'a> {
        let rate = args.vary.rate;
        MapBase {
            n: self.base.n(),
            floating: self.base.floating(),
            fixed: self.base.start_coords(rate),
            mus: self.mus.clone(),
            cells: self
                .cells
                .iter()
                .map(|c| (c.start_coords(rate)[args.vary.joint], c.mu()))
                .collect(),
            refine: Box::new(|points| points.iter().map(|p| self.base.refine(p)).collect()),
        }
    }
}
