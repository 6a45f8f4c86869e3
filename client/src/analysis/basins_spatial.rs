//! `chaosctl basins` on a spatial robot: the planar command's map (one start coordinate varied
//! down the rows, μ across), each cell a run of the spatial loop.
//!
//! Only the runs differ: the classification, the naming of orbits, the CSV, the printed map
//! and the figure are the planar command's own ([`super::basins_map::finish`]), so the two maps
//! read the same way.

use super::basins_map::{coord_name, finish, BasinsCmd, MapBase, RunEnd};
use super::parallel::{jobs, run_all};
use super::shard::{self, Loaded};
use anyhow::{bail, Result};
use control::config::spatial::SpatialConfig;

/// μ values when `--mu` is not given: a spatial run costs 10× a planar one.
const DEFAULT_MU: &str = "0:2:0.5";

/// The validated map: one config per grid point, rows (starts) outer, μ inner.
struct Plan<'a> {
    cfg: &'a SpatialConfig,
    mus: Vec<f64>,
    fixed: Vec<f64>,
    cells: Vec<SpatialConfig>,
    /// Each cell's (varied coordinate, μ).
    at: Vec<(f64, f64)>,
}

fn plan<'a>(args: &BasinsCmd, cfg: &'a SpatialConfig) -> Result<Plan<'a>> {
    super::check_run_window(args.duration, args.transient)?;
    let mus = match &args.model.mu {
        Some(r) => r.0.clone(),
        None => super::parse_range(DEFAULT_MU).map_err(anyhow::Error::msg)?,
    };
    let n = cfg.sim.start().len();
    if args.vary.joint >= n {
        bail!("--vary: the arm has {n} joints, so the varied coordinate must be q1..q{n} or qd1..qd{n}");
    }
    let fixed = if args.vary.rate {
        cfg.sim.qd0.clone().unwrap_or_else(|| vec![0.0; n])
    } else {
        cfg.sim.start().to_vec()
    };
    let (mut cells, mut at) = (Vec::new(), Vec::new());
    for &v in &args.vary.values {
        for &mu in &mus {
            let mut c = cfg.clone();
            c.feedback.mu = mu;
            let mut x = fixed.clone();
            x[args.vary.joint] = v;
            if args.vary.rate {
                c.sim.qd0 = Some(x);
            } else {
                c.sim.q0 = Some(x);
            }
            // Refused here, by name, rather than as a failed cell of the map.
            crate::spatial::check(&c)
                .map_err(|e| anyhow::anyhow!("start with the varied coordinate = {v}: {e:#}"))?;
            cells.push(c);
            at.push((v, mu));
        }
    }
    Ok(Plan {
        cfg,
        mus,
        fixed,
        cells,
        at,
    })
}

/// The grid a shard file names: the run window, the classifier, the varied coordinate and
/// every cell's whole config.
fn grid(args: &BasinsCmd, plan: &Plan) -> Result<shard::Grid> {
    let window = format!(
        "spatial {} {} {:?} {:?}",
        args.duration,
        args.transient,
        args.classify.config()?,
        args.vary
    );
    let parts = std::iter::once(window).chain(plan.cells.iter().map(|c| format!("{c:?}")));
    let labels = plan
        .at
        .iter()
        .map(|(v, mu)| format!("{} = {v}, μ = {mu}", coord_name(&args.vary)))
        .collect();
    Ok(shard::Grid::new("basins", parts, labels))
}

pub fn run(args: &BasinsCmd, cfg: &SpatialConfig) -> Result<()> {
    let plan = plan(args, cfg)?;
    let classify = args.classify.config()?;
    let work = |c: &SpatialConfig| {
        crate::spatial::run_end(c, args.duration, args.transient, &classify)
            .map(|(class, rms, last)| RunEnd {
                motion: class.motion,
                k01: class.k,
                rms_tracking_error: rms,
                final_coords: last,
            })
            .map_err(|e| format!("{e:#}"))
    };
    if let Some(s) = args.shard {
        let grid = grid(args, &plan)?;
        shard::run_shard(&grid, s, &plan.cells, &args.output, jobs(args.jobs), work)?;
        return Ok(());
    }
    let runs = run_all(&plan.cells, jobs(args.jobs), "basins", work)?;
    plan.finish(args, &runs)
}

/// `chaosctl merge` of a spatial robot's basins shards: the unsharded run's CSV, map and plot.
pub fn merge(args: &BasinsCmd, cfg: &SpatialConfig, files: Vec<Loaded>) -> Result<()> {
    let plan = plan(args, cfg)?;
    let runs: Vec<Result<RunEnd, String>> = shard::collect(&grid(args, &plan)?, files)?;
    plan.finish(args, &runs)
}

impl Plan<'_> {
    fn finish(&self, args: &BasinsCmd, runs: &[Result<RunEnd, String>]) -> Result<()> {
        let cfg = self.cfg;
        let refine = |points: &[Vec<f64>]| -> Vec<Option<String>> {
            points
                .iter()
                .map(|p| crate::spatial::refine(cfg, p))
                .collect()
        };
        let base = MapBase {
            n: self.fixed.len(),
            floating: false,
            fixed: self.fixed.clone(),
            mus: self.mus.clone(),
            cells: self.at.clone(),
            refine: Box::new(refine),
        };
        finish(args, &base, runs)
    }
}
