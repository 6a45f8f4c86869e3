//! `chaosctl basins` on a spatial robot: the planar command's map (one start coordinate varied
//! down the rows, μ across), each cell a run of the spatial loop.
//!
//! Only the runs differ: the classification, the naming of orbits, the CSV, the printed map
//! and the figure are the planar command's own ([`super::basins_map::finish`]), so the two maps
//! read the same way.

use super::basins_map::{finish, BasinsCmd, MapBase, RunEnd};
use super::parallel::{jobs, run_all};
use anyhow::{bail, Result};
use control::config::spatial::SpatialConfig;

/// μ values when `--mu` is not given: a spatial run costs 10× a planar one.
const DEFAULT_MU: &str = "0:2:0.5";

pub fn run(args: &BasinsCmd, cfg: &SpatialConfig) -> Result<()> {
    if args.shard.is_some() {
        bail!("--shard: sharded basins run the planar arm only so far");
    }
    super::check_run_window(args.duration, args.transient)?;
    let classify = args.classify.config()?;
    let mus = match &args.model.mu {
        Some(r) => r.0.clone(),
        None => super::parse_range(DEFAULT_MU).map_err(anyhow::Error::msg)?,
    };
    let n = cfg.sim.q0.len();
    if args.vary.joint >= n {
        bail!("--vary: the arm has {n} joints, so the varied coordinate must be q1..q{n} or qd1..qd{n}");
    }
    let fixed = if args.vary.rate {
        cfg.sim.qd0.clone().unwrap_or_else(|| vec![0.0; n])
    } else {
        cfg.sim.q0.clone()
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
                c.sim.q0 = x;
            }
            // Refused here, by name, rather than as a failed cell of the map.
            crate::spatial::check(&c)
                .map_err(|e| anyhow::anyhow!("start with the varied coordinate = {v}: {e:#}"))?;
            cells.push(c);
            at.push((v, mu));
        }
    }
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
    let runs = run_all(&cells, jobs(args.jobs), "basins", work)?;
    let refine = |points: &[Vec<f64>]| -> Vec<Option<String>> {
        points
            .iter()
            .map(|p| crate::spatial::refine(cfg, p))
            .collect()
    };
    let base = MapBase {
        n,
        floating: false,
        fixed,
        mus,
        cells: at,
        refine: Box::new(refine),
    };
    finish(args, &base, &runs)
}
