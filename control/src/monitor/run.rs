//! A simulated run watched by the monitor: what the offline study and the tests measure.
//!
//! The daemon feeds its monitor from the reporter thread with the states the law ran on and the
//! law's residuals; here the simulation feeds the same numbers, every step, into the same
//! [`ChaosMonitor`]. Edits at given times change the law's parameters mid-run, as `chaosctl set`
//! does, and restart the monitor's window, as the daemon does.

use super::{ChaosMonitor, Edge, Evidence, MonitorSettings, Verdict};
use crate::config::Config;
use crate::law::LawParams;
use crate::resolve::ControlOutput;
use crate::resolve::Projection;
use crate::sim::spatial::SpatialSimulation;
use crate::sim::{ArmState, Simulation};
use crate::with_dof;
use serde::Serialize;

/// A change to the law at a time, as a live `chaosctl set` would make it.
pub struct Edit<'a> {
    pub t: f64,
    pub apply: &'a dyn Fn(&mut LawParams),
}

/// One period of a watched run.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct PeriodPoint {
    pub t: f64,
    pub mu: f64,
    pub residual: f64,
    pub verdict: Verdict,
}

/// What a watched run saw.
#[derive(Clone, Debug, Serialize)]
pub struct Watched {
    pub edges: Vec<Edge>,
    pub last: Evidence,
    pub mu_final: f64,
    pub trace: Vec<PeriodPoint>,
    /// ∫ |Pyragas term|² dt over the run: μ² times the squared residual it acts on.
    pub effort: f64,
    /// When the verdict last became what it ended as (s), if it ended periodic.
    pub settled_at: Option<f64>,
    /// The run stopped early: the state was no longer finite.
    pub diverged: bool,
}

/// A closed-loop simulation the monitor can watch: the planar [`Simulation`] or the spatial
/// [`crate::sim::spatial::SpatialSimulation`].
pub trait Stepped<const N: usize> {
    fn time(&self) -> f64;
    fn state(&self) -> ArmState<N>;
    /// One step of dt; the law's output at its start.
    fn step(&mut self) -> ControlOutput<N>;
    /// (μ now, where the feedback acts, dt).
    fn feedback(&self) -> (f64, Projection, f64);
}

impl<const N: usize> Stepped<N> for Simulation<N> {
    fn time(&self) -> f64 {
        Simulation::time(self)
    }
    fn state(&self) -> ArmState<N> {
        *Simulation::state(self)
    }
    fn step(&mut self) -> ControlOutput<N> {
        Simulation::step(self)
    }
    fn feedback(&self) -> (f64, Projection, f64) {
        (self.params.mu, self.params.projection, self.dt())
    }
}

impl<const N: usize, const M: usize> Stepped<N> for SpatialSimulation<N, M> {
    fn time(&self) -> f64 {
        SpatialSimulation::time(self)
    }
    fn state(&self) -> ArmState<N> {
        *SpatialSimulation::state(self)
    }
    fn step(&mut self) -> ControlOutput<N> {
        SpatialSimulation::step(self)
    }
    fn feedback(&self) -> (f64, Projection, f64) {
        (self.params.mu, self.params.projection, self.dt())
    }
}

/// Runs `cfg` (planar) for `duration` s with the monitor watching; `edits` sorted by time.
pub fn watch(cfg: &Config, duration: f64, settings: MonitorSettings, edits: &[Edit]) -> Watched {
    with_dof!(cfg.n(), N => watch_n::<N>(cfg, duration, settings, edits))
}

fn watch_n<const N: usize>(
    cfg: &Config,
    duration: f64,
    settings: MonitorSettings,
    edits: &[Edit],
) -> Watched {
    let params = cfg.law_params();
    let max_tau = cfg.feedback.max_tau;
    let mut sim = Simulation::new(
        cfg.model::<N>(),
        params,
        cfg.sim.dt,
        cfg.initial_state::<N>(),
        max_tau,
    );
    let mut pending = edits.iter().peekable();
    watch_sim(&mut sim, duration, settings, params.tau, |t, sim| {
        let mut edited = false;
        while let Some(e) = pending.next_if(|e| e.t <= t) {
            // As in the daemon: a new block adapts with the config's γ from the current μ.
            sim.params.auto_mu = params.auto_mu;
            (e.apply)(&mut sim.params);
            edited = true;
        }
        edited.then_some(sim.params.tau)
    })
}

/// Runs `sim` for `duration` s with a monitor for period `tau` watching. Before each step,
/// `edit(t, sim)` may change the simulation; it returns the new τ when it did (the monitor's
/// window then restarts, as the daemon's does after an edit).
pub fn watch_sim<const N: usize, S: Stepped<N>>(
    sim: &mut S,
    duration: f64,
    settings: MonitorSettings,
    tau: f64,
    mut edit: impl FnMut(f64, &mut S) -> Option<f64>,
) -> Watched {
    let mut monitor = ChaosMonitor::new(settings, tau);
    let (mut edges, mut trace, mut effort, mut diverged) = (Vec::new(), Vec::new(), 0.0, false);
    let steps = (duration / sim.feedback().2).round() as u64;
    for _ in 0..steps {
        let t = sim.time();
        if let Some(tau) = edit(t, sim) {
            monitor.restart(t, tau);
        }
        let (mu, projection, dt) = sim.feedback();
        let x = sim.state();
        let out = sim.step();
        if !sim.state().is_finite() {
            diverged = true;
            break;
        }
        if out.flags & crate::basics::flags::FEEDBACK_ACTIVE != 0 {
            let r =
                crate::adapt::AutoMu::residual(projection, out.period_residual, out.null_residual);
            effort += mu * mu * r * r * dt;
        }
        let periods = monitor.evidence().periods;
        let (q, qd) = (x.q.as_slice(), x.qd.as_slice());
        edges.extend(monitor.push(t, q, qd, out.period_residual, out.null_residual));
        let e = monitor.evidence();
        if e.periods != periods {
            trace.push(PeriodPoint {
                t,
                mu,
                residual: e.residual,
                verdict: e.verdict,
            });
        }
    }
    let last = *monitor.evidence();
    let settled_at = (last.verdict == Verdict::Periodic).then_some(last.since);
    Watched {
        edges,
        last,
        mu_final: sim.feedback().0,
        trace,
        effort,
        settled_at,
        diverged,
    }
}
