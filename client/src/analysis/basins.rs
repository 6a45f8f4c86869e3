//! `chaosctl basins`: where does each start end up, for each μ?
//!
//! A family of initial states (one coordinate of the start varied over a range, the others fixed)
//! is run at every μ of a range. Each run's Poincaré section is classified; a run that settles on a
//! period-1 orbit is matched against the orbits already seen (the same orbit of the μ = 0 loop is
//! stabilised at every μ where it is stable, shifted only by the discretisation error), so the map
//! shows *which* orbit each start reaches, and where the motion stays chaotic. If the paper's
//! window held generically, its column range would be one colour.

use super::basins_map::{coord_name, finish, BasinsCmd, MapBase, RunEnd};
use super::parallel::{jobs, run_all};
use super::shard::{self, Loaded};
use super::{analyse_config, check_config, fmt_list};
use anyhow::{bail, Context, Result};
use control::analysis::{find_orbit, NewtonConfig, RunSpec};
use control::config::ModelKind;
use control::{with_dof, ArmState, Config, VecN};

/// The validated map: one config per grid point, rows (starts) outer, μ inner.
struct Plan {
    base: Config,
    mus: Vec<f64>,
    spec: RunSpec,
    cells: Vec<Config>,
}

fn plan(args: &BasinsCmd) -> Result<Plan> {
    let (base, mus) = args.model.load("0:3:0.1")?;
    let n = base.n();
    if args.vary.joint >= n {
        bail!("--vary: the arm has {n} joints, so the varied coordinate must be q1..q{n} or qd1..qd{n}");
    }
    super::check_run_window(args.duration, args.transient)?;
    let spec = RunSpec {
        duration: args.duration,
        transient: args.transient,
        lyapunov: None,
        classify: args.classify.config()?,
    };
    spec.validate(base.task.period, base.sim.dt)?;
    let points = (args.duration / base.task.period + 1e-9).floor()
        - (args.transient / base.task.period - 1e-9).ceil()
        + 1.0;
    if points < spec.classify.min_points as f64 {
        bail!(
            "--duration {} with --transient {}: the section would have {points} points, and classifying it needs at least {}",
            args.duration,
            args.transient,
            spec.classify.min_points
        );
    }
    let mut cells: Vec<Config> = Vec::new();
    for &v in &args.vary.values {
        for &mu in &mus {
            let mut c = base.clone();
            c.feedback.mu = mu;
            let mut x = if args.vary.rate { c.qd0() } else { c.q0() };
            x[args.vary.joint] = v;
            if args.vary.rate {
                c.sim.qd0 = Some(x);
            } else {
                c.sim.q0 = Some(x);
            }
            c.validate()?;
            check_config(&c)
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

fn grid(args: &BasinsCmd, plan: &Plan) -> shard::Grid {
    let parts = [format!("{:?}", plan.spec), format!("{:?}", args.vary)]
        .into_iter()
        .chain(plan.cells.iter().map(|c| format!("{c:?}")));
    let labels = plan
        .cells
        .iter()
        .map(|c| {
            let x = if args.vary.rate { c.qd0() } else { c.q0() }[args.vary.joint];
            format!("{} = {x}, μ = {}", coord_name(&args.vary), c.feedback.mu)
        })
        .collect();
    shard::Grid::new("basins", parts, labels)
}

fn run_end(c: &Config, spec: &RunSpec) -> Result<RunEnd, String> {
    analyse_config(c, spec)
        .map(|a| RunEnd {
            motion: a.classification.motion,
            k01: a.classification.k,
            rms_tracking_error: a.summary.rms_tracking_error,
            final_coords: a.final_coords,
        })
        .map_err(|e| format!("{e:#}"))
}

pub fn run(args: BasinsCmd) -> Result<()> {
    if let Some(cfg) = crate::spatial::load(&args.model.setup, None)? {
        return super::basins_spatial::run(&args, &cfg);
    }
    let plan = plan(&args)?;
    let threads = jobs(args.jobs);
    let work = |c: &Config| run_end(c, &plan.spec);
    if let Some(s) = args.shard {
        shard::run_shard(
            &grid(&args, &plan),
            s,
            &plan.cells,
            &args.output,
            threads,
            work,
        )?;
        return Ok(());
    }
    let runs = run_all(&plan.cells, threads, "basins", work)?;
    let base = plan.map_base(&args);
    finish(&args, &base, &runs)
}

impl Plan {
    fn map_base<'a>(&'a self, args: &BasinsCmd) -> MapBase<'a> {
        let start = |c: &Config| if args.vary.rate { c.qd0() } else { c.q0() };
        MapBase {
            n: self.base.n(),
            floating: self.base.arm.model == ModelKind::Floating,
            fixed: start(&self.base),
            mus: self.mus.clone(),
            cells: self
                .cells
                .iter()
                .map(|c| (start(c)[args.vary.joint], c.feedback.mu))
                .collect(),
            refine: Box::new(|points| refine(&self.base, points)),
        }
    }
}

/// `chaosctl merge` of basins shards: the same CSV, map and plot as the unsharded run.
pub fn merge(args: BasinsCmd, files: Vec<Loaded>) -> Result<()> {
    if let Some(cfg) = crate::spatial::load(&args.model.setup, None)? {
        return super::basins_spatial::merge(&args, &cfg, files);
    }
    let plan = plan(&args)?;
    let runs: Vec<Result<RunEnd, String>> = shard::collect(&grid(&args, &plan), files)?;
    let base = plan.map_base(&args);
    finish(&args, &base, &runs)
}

/// Newton-refines each settled orbit at μ = 0 (fixed base only), to tie the map to `orbits`.
fn refine(base: &Config, points: &[Vec<f64>]) -> Vec<Option<String>> {
    if base.arm.model != ModelKind::Fixed || (base.tau() - base.task.period).abs() > 1e-9 {
        return vec![None; points.len()];
    }
    let n = base.n();
    points
        .iter()
        .map(|x| {
            with_dof!(n, N => {
                let seed = ArmState::<N> {
                    q: VecN::<N>::from_fn(|i, _| x[i]),
                    qd: VecN::<N>::from_fn(|i, _| x[N + i]),
                    phi: 0.0,
                };
                find_orbit(&base.model::<N>(), &base.law_params(), base.sim.dt, &seed, &NewtonConfig::default())
                    .ok()
                    .map(|o| {
                        format!(
                            "the μ = 0 orbit through q = ({}), leading Floquet multiplier {}",
                            fmt_list(&o.q),
                            super::orbits::kind(&o)
                        )
                    })
            })
        })
        .collect()
}
