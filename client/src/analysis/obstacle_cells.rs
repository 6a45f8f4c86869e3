//! One cell of `chaosctl obstacles` on any arm: a run of the law with the obstacles, its
//! statistics as one [`Summary`] and its Poincaré class, in one pass.
//!
//! The study's table, CSV and figure read only the [`Summary`], so the planar arm's disks and a
//! robot's spheres are compared the same way: the same `RunStats` counts contact, clearance and
//! the filter's activity for both. Only the simulation differs, and it is chosen here.

use super::mujoco_judge::{self, MujocoJudge, Verdict};
use anyhow::Result;
use control::analysis::{classify, ArmFlow, ClassifyConfig, Motion, Section, Trajectory};
use control::config::spatial::SpatialConfig;
use control::model::Chain;
use control::sim::{RunStats, StatsSetup};
use control::{with_dof, with_task_rows, Config, Summary};

/// One run of the study.
#[derive(serde::Serialize, Clone, Debug)]
pub struct Row {
    pub mu: f64,
    pub safety: bool,
    pub q0: Vec<f64>,
    /// Everything `simulate` reports (clearance, contact, filter activity, tracking).
    pub summary: Option<Summary>,
    pub motion: Option<Motion>,
    pub k01: Option<f64>,
    pub error: Option<String>,
    /// MuJoCo's verdict on the run (with --mujoco-judge, a robot's run that finished).
    pub verdict: Option<Result<Verdict, String>>,
}

/// One run's result, as a shard file carries it.
pub type RunResult = Result<(Summary, Motion, Option<f64>), String>;

/// The arm of a cell: the planar arm's config, or a robot's with its chain (loaded once).
// A few hundred cells built once per study: their size does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum Arm {
    Planar(Config),
    Spatial(Box<SpatialConfig>, std::sync::Arc<Chain>),
}

/// One (μ, filter, start) of the study.
#[derive(Clone, Debug)]
pub struct Cell {
    pub mu: f64,
    pub safety: bool,
    pub q0: Vec<f64>,
    pub arm: Arm,
}

/// How every cell is run and judged.
#[derive(Clone, Copy, Debug)]
pub struct Window {
    pub duration: f64,
    /// The RMS tracking error is measured from here (s).
    pub rms_from: f64,
    /// The Poincaré section is classified from here (s).
    pub section_from: f64,
    pub classify: ClassifyConfig,
}

impl std::fmt::Display for Cell {
    /// The cell's fingerprint text: its whole configuration (the chain's numbers included).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.arm {
            Arm::Planar(c) => write!(f, "{c:?}"),
            Arm::Spatial(c, chain) => write!(f, "{c:?} {chain:?}"),
        }
    }
}

/// Runs one cell.
pub fn run(cell: &Cell, w: &Window) -> RunResult {
    match &cell.arm {
        Arm::Planar(c) => run_planar(c, w),
        Arm::Spatial(c, chain) => {
            run_spatial(c, chain, w, None).unwrap_or_else(|e| Err(format!("{e:#}")))
        }
    }
}

/// Runs one cell and has MuJoCo judge a robot's run over its own geometry, from the moment the
/// capsules first got clear (a start inside an obstacle is the study's, not a motion's). The
/// planar arm has no MuJoCo model: its verdict is `None`.
pub fn run_judged(
    cell: &Cell,
    w: &Window,
    judge: &MujocoJudge,
) -> (RunResult, Option<Result<Verdict, String>>) {
    let Arm::Spatial(c, chain) = &cell.arm else {
        return (run(cell, w), None);
    };
    let mut samples = Vec::new();
    let result =
        run_spatial(c, chain, w, Some(&mut samples)).unwrap_or_else(|e| Err(format!("{e:#}")));
    let Ok((summary, _, _)) = &result else {
        return (result, None);
    };
    let from = summary.first_clear.unwrap_or(0.0);
    let n = chain.dof() + 1;
    let first = samples
        .chunks_exact(n)
        .position(|r| r[0] >= from - 1e-12)
        .unwrap_or(samples.len() / n);
    let verdict = judge
        .judge(c, chain, &samples[first * n..])
        .map_err(|e| format!("{e:#}"));
    (result, Some(verdict))
}

/// Checks a robot's cell builds, as [`run`] will build it.
pub fn check_spatial(cfg: &SpatialConfig, chain: &Chain) -> Result<()> {
    with_dof!(chain.dof(), N => cfg.setup::<N>(chain).map(|_| ()))?;
    Ok(())
}

fn run_planar(cfg: &Config, w: &Window) -> RunResult {
    with_dof!(cfg.n(), N => {
        let mut flow = ArmFlow::new(cfg.model::<N>(), cfg.law_params(), cfg.sim.dt, cfg.initial_state::<N>())
            .with_stats(w.duration, w.rms_from);
        let period = cfg.task.period;
        let mut section = Section::new(flow.coords().len(), flow.angle_coords());
        let periods = (w.duration / period + 1e-9).floor() as u64;
        for k in 0..=periods {
            let t = k as f64 * period;
            flow.advance_to(t);
            if !flow.is_finite() {
                return Err(diverged(flow.time()));
            }
            if t >= w.section_from - 1e-9 * period {
                section.push(t, &flow.coords());
            }
        }
        flow.advance_to(w.duration);
        if !flow.is_finite() {
            return Err(diverged(flow.time()));
        }
        let c = classify(&section, &w.classify);
        let summary = flow.stats().map(|s| s.summary()).ok_or("run statistics missing")?;
        Ok((summary, c.motion, c.k))
    })
}

fn diverged(t: f64) -> String {
    format!("the simulation diverged by t = {t} s")
}

/// A robot's run: the unplanned law (as the planar study runs it), strobed at t = kT as
/// `chaosctl poincare` strobes it, every step recorded by the planar arm's `RunStats`.
/// With `record`, appends `t, q1 … qN` every [`mujoco_judge::SAMPLE_S`].
fn run_spatial(
    cfg: &SpatialConfig,
    chain: &Chain,
    w: &Window,
    mut record: Option<&mut Vec<f64>>,
) -> Result<RunResult> {
    let kind = cfg.task_kind()?;
    Ok(with_dof!(chain.dof(), N => {
        let s = cfg.setup::<N>(chain)?;
        with_task_rows!(kind, |M| {
            let mut sim = s.simulation::<M>();
            let setup = StatsSetup::spatial(&s.params);
            let mut stats = RunStats::<N>::of(setup, s.dt, w.duration, w.rms_from, sim.state());
            let mut section = Section::new(2 * N, N);
            let steps = (w.duration / s.dt).round() as u64;
            let mut next = 0u64; // the next strobe's period index
            let strobe_step = |m: u64| (m as f64 * setup.period / s.dt).round() as u64;
            let mut result = None;
            let every = ((mujoco_judge::SAMPLE_S / s.dt).round() as u64).max(1);
            for _ in 0..=steps {
                let k = sim.step_index();
                let x = *sim.state();
                if let Some(r) = record.as_deref_mut().filter(|_| k % every == 0) {
                    r.push(sim.time());
                    r.extend(x.q.iter());
                }
                if k == strobe_step(next) {
                    let t = next as f64 * setup.period;
                    if t >= w.section_from - 1e-9 * setup.period {
                        let coords: Vec<f64> = x.q.iter().chain(x.qd.iter()).copied().collect();
                        section.push(t, &coords);
                    }
                    next += 1;
                }
                if k == steps {
                    break;
                }
                let out = sim.step();
                stats.record(k, &x, &out);
                if !sim.state().is_finite() {
                    result = Some(Err(diverged(sim.time())));
                    break;
                }
            }
            result.unwrap_or_else(|| {
                let c = classify(&section, &w.classify);
                Ok((stats.summary(), c.motion, c.k))
            })
        })
    }))
}
