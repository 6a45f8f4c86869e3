//! A simulated run watched by the monitor: what the offline study and the tests measure.
//!
//! The daemon feeds its monitor from the reporter thread with the states the law ran on and the
//! law's residuals; here the simulation feeds the same numbers, every step, into the same
//! [`ChaosMonitor`]. Edits at given times change the law's parameters mid-run, as `chaosctl set`
//! does, and restart the monitor's window, as the daemon does.

use super::{ChaosMonitor, Edge, Evidence, MonitorSettings, Verdict};
use crate::config::Config;
use crate::law::LawParams;
use crate::sim::{ClosedLoopLaw, LoopFeedback, Simulation};
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
    let max_tau = cfg.feedback.capacity();
    let mut sim = Simulation::new(
        cfg.model::<N>(),
        params,
        cfg.sim.dt,
        cfg.initial_state::<N>(),
        max_tau,
    );
    let mut pending = edits.iter().peekable();
    watch_sim(&mut sim, duration, settings, params.core.tau, |t, sim| {
        let mut edited = false;
        while let Some(e) = pending.next_if(|e| e.t <= t) {
            // As in the daemon: a new block adapts with the config's γ from the current μ.
            sim.law.params.core.auto_mu = params.core.auto_mu;
            (e.apply)(&mut sim.law.params);
            edited = true;
        }
        edited.then_some(sim.law.params.core.tau)
    })
}

/// Runs `sim` for `duration` s with a monitor for period `tau` watching. Before each step,
/// `edit(t, sim)` may change the simulation; it returns the new τ when it did (the monitor's
/// window then restarts, as the daemon's does after an edit).
pub fn watch_sim<const N: usize, L: ClosedLoopLaw<N>>(
    sim: &mut Simulation<N, L>,
    duration: f64,
    settings: MonitorSettings,
    tau: f64,
    mut edit: impl FnMut(f64, &mut Simulation<N, L>) -> Option<f64>,
) -> Watched {
    let mut monitor = ChaosMonitor::new(settings, tau);
    let (mut edges, mut trace, mut effort, mut diverged) = (Vec::new(), Vec::new(), 0.0, false);
    let (dt, steps) = (sim.dt(), (duration / sim.dt()).round() as u64);
    for _ in 0..steps {
        let t = sim.time();
        if let Some(tau) = edit(t, sim) {
            monitor.restart(t, tau);
        }
        let LoopFeedback { mu, projection, .. } = sim.law.loop_feedback();
        let x = *sim.state();
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
        mu_final: sim.law.loop_feedback().mu,
        trace,
        effort,
        settled_at,
        diverged,
    }
}
