//! One cell of `chaosctl obstacles` on any arm: a run of the law with the obstacles, its
//! statistics as one [`Summary`] and its Poincaré class, in one pass.
//!
//! The study's table, CSV and figure read only the [`Summary`], so the planar arm's disks and a
//! robot's spheres are compared the same way: the same `RunStats` counts contact, clearance and
//! the filter's activity for both. Only the simulation differs, and it is chosen here.

use super::mujoco_judge::{self, MujocoJudge, Verdict};
use crate::subject::{LoopVisitor, Start, Subject};
use anyhow::Result;
use control::analysis::{classify, ClassifyConfig, Motion, Section};
use control::sim::{ClosedLoopLaw, RunStats};
use control::{Simulation, Summary};

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

/// One (μ, filter, start) of the study.
#[derive(Clone, Debug)]
pub struct Cell {
    pub mu: f64,
    pub safety: bool,
    pub q0: Vec<f64>,
    /// The set-up at this cell's gain, filter and start.
    pub arm: Subject,
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
        write!(f, "{}", self.arm)
    }
}

/// Runs one cell: the law alone (never steered onto a planned cycle, on any arm).
pub fn run(cell: &Cell, w: &Window) -> RunResult {
    let run = CellRun { w, record: None };
    cell.arm
        .run_law(run)
        .unwrap_or_else(|e| Err(format!("{e:#}")))
}

/// Runs one cell and has MuJoCo judge a robot's run over its own geometry, from the moment the
/// capsules first got clear (a start inside an obstacle is the study's, not a motion's). The
/// planar arm has no MuJoCo model: its verdict is `None`.
pub fn run_judged(
    cell: &Cell,
    w: &Window,
    judge: &MujocoJudge,
) -> (RunResult, Option<Result<Verdict, String>>) {
    let control::System::Spatial(robot) = cell.arm.system() else {
        return (run(cell, w), None);
    };
    let (c, chain) = (&robot.config, &robot.chain);
    let mut samples = Vec::new();
    let run = CellRun {
        w,
        record: Some(&mut samples),
    };
    let result = cell
        .arm
        .run_law(run)
        .unwrap_or_else(|e| Err(format!("{e:#}")));
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

/// A cell's run, strobed at t = kT as `chaosctl poincare` strobes it, every step recorded by
/// `RunStats`; with `record`, `t, q1 … qN` appended every [`mujoco_judge::SAMPLE_S`].
struct CellRun<'a> {
    w: &'a Window,
    record: Option<&'a mut Vec<f64>>,
}

impl LoopVisitor for CellRun<'_> {
    type Out = RunResult;
    fn visit<const N: usize, L: ClosedLoopLaw<N>>(
        mut self,
        mut sim: Simulation<N, L>,
        _: Start<'_>,
    ) -> Result<RunResult> {
        let (w, dt) = (self.w, sim.dt());
        let setup = sim.law.stats_setup();
        let floating = sim.law.is_floating();
        let mut stats = RunStats::<N>::of(setup, dt, w.duration, w.rms_from, sim.state());
        let mut section = Section::new(2 * N + usize::from(floating), N + usize::from(floating));
        let steps = (w.duration / dt).round() as u64;
        let mut next = 0u64; // the next strobe's period index
        let strobe_step = |m: u64| (m as f64 * setup.period / dt).round() as u64;
        let every = ((mujoco_judge::SAMPLE_S / dt).round() as u64).max(1);
        for _ in 0..=steps {
            let k = sim.step_index();
            let x = *sim.state();
            if let Some(r) = self.record.as_deref_mut().filter(|_| k % every == 0) {
                r.push(sim.time());
                r.extend(x.q.iter());
            }
            if k == strobe_step(next) {
                let t = next as f64 * setup.period;
                if t >= w.section_from - 1e-9 * setup.period {
                    let phi = floating.then_some(x.phi);
                    let coords: Vec<f64> = phi
                        .into_iter()
                        .chain(x.q.iter().copied())
                        .chain(x.qd.iter().copied())
                        .collect();
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
                return Ok(Err(diverged(sim.time())));
            }
        }
        let c = classify(&section, &w.classify);
        Ok(Ok((stats.summary(), c.motion, c.k)))
    }
}

fn diverged(t: f64) -> String {
    format!("the simulation diverged by t = {t} s")
}
