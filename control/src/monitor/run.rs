//! A simulated run watched by the monitor: what the offline study and the tests measure.
//!
//! The daemon feeds its monitor from the reporter thread with the states the law ran on and the
//! law's residuals; here the simulation feeds the same numbers, every step, into the same
//! [`ChaosMonitor`]. Edits at given times change the law's parameters mid-run, as `chaosctl set`
//! does, and restart the monitor's window, as the daemon does. With `mu = "auto"` the gain comes
//! from the model at the start and after every edit, seeded as the daemon seeds it
//! ([`crate::tune`]); here it is taken at once, where the daemon takes it when its search thread
//! answers (0.5 s on the planar arm, about 8 s on the Panda).

use super::{ChaosMonitor, Edge, Evidence, MonitorSettings, Verdict};
use crate::basics::ConfigError;
use crate::law::ParamBlock;
use crate::sim::{ClosedLoopLaw, LoopFeedback, Simulation};
use crate::system::System;
use crate::target::{target, target_wanted, Release, Released, MAX_RETARGETS};
use crate::tune::{choose_gain, TuneSpec};
use crate::with_dof;
use serde::Serialize;
use std::sync::Arc;

/// A change to the law at a time, as a live `chaosctl set` would make it: the whole parameter
/// block of the edited set-up, swapped in as the daemon swaps one.
#[derive(Clone, Debug)]
pub struct Edit {
    pub t: f64,
    pub block: ParamBlock,
    /// The edited set-up (the model the gain is chosen from after the edit).
    pub system: Arc<System>,
}

impl Edit {
    /// `system` changed by `change` and validated, as the daemon validates a `set`, at time `t`.
    ///
    /// ```
    /// use control::monitor::run::Edit;
    /// let s = control::System::preset("paper", &control::system::builtin_robot).unwrap();
    /// let wider = |s: &mut control::System| {
    ///     *s.task_circle_mut().0 *= 1.1;
    ///     Ok(())
    /// };
    /// let e = Edit::of(&s, 30.0, wider).unwrap();
    /// assert_eq!(e.t, 30.0);
    /// let far = |s: &mut control::System| {
    ///     *s.task_circle_mut().0 = 9.0;
    ///     Ok(())
    /// };
    /// assert!(Edit::of(&s, 30.0, far).is_err());
    /// ```
    pub fn of(
        system: &System,
        t: f64,
        change: impl FnOnce(&mut System) -> Result<(), ConfigError>,
    ) -> Result<Self, ConfigError> {
        let mut s = system.clone();
        change(&mut s)?;
        s.validate()?;
        Ok(Self {
            t,
            block: s.param_block(),
            system: Arc::new(s),
        })
    }
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
    /// The gains the model chose (`mu = "auto"`: at the start and after each edit).
    pub model: Vec<ModelChoice>,
}

/// A gain the model chose during a watched run, or why it chose none.
#[derive(Clone, Debug, Serialize)]
pub struct ModelChoice {
    pub t: f64,
    pub mu: Option<f64>,
    /// |ρ₁| a period at `mu`, and the rate (1/s) it promises.
    pub multiplier: Option<f64>,
    pub rate: Option<f64>,
    pub error: Option<String>,
    /// The arm steered onto the chosen cycle ([`crate::target`]): when the pull was taken
    /// away and why, or why there was none.
    pub target: Option<TargetRun>,
}

/// One steering onto the model's cycle during a watched run.
#[derive(Clone, Debug, Serialize)]
pub struct TargetRun {
    /// When the steering began (s).
    pub since: f64,
    /// The steered law's miss of the cycle (rad).
    pub miss: Option<f64>,
    pub released_at: Option<f64>,
    pub released: Option<Released>,
    pub error: Option<String>,
}

/// Runs `system` as the daemon's law for `duration` s with the monitor watching; `edits`
/// sorted by time. With `mu = "auto"` the gain comes from the model, as in the daemon.
pub fn watch(system: &System, duration: f64, settings: MonitorSettings, edits: &[Edit]) -> Watched {
    with_dof!(system.n(), N => {
        let law = system.tick_law::<N>();
        let (dt, x0) = (system.sim_section().dt, system.initial_state::<N>());
        let mut sim = Simulation::of(law, dt, x0, system.feedback().max_tau);
        watch_sim(&mut sim, duration, settings, edits, Some(system))
    })
}

/// Runs `sim` (not yet stepped) for `duration` s with the monitor watching. Each edit's block
/// is swapped in before the first step at or after its time, as the daemon swaps one
/// ([`ClosedLoopLaw::take_block`]), and the monitor's window restarts with the block's τ, as
/// the daemon's does. An edit whose block is for another arm is not made. `model` is the set-up
/// `sim` runs: when its μ is "auto", the gain is chosen from it at the start and from each
/// edit's set-up after the edit (None: the speed-gradient law alone).
pub fn watch_sim<const N: usize, L: ClosedLoopLaw<N>>(
    sim: &mut Simulation<N, L>,
    duration: f64,
    settings: MonitorSettings,
    edits: &[Edit],
    model: Option<&System>,
) -> Watched {
    let longest = edits.iter().map(|e| e.block.core().tau).fold(0.0, f64::max);
    let sized = sim.reserve_delay(longest);
    debug_assert!(sized, "watch_sim takes a simulation that has not stepped");
    let mut monitor = ChaosMonitor::new(settings, sim.law.core().tau);
    let mut pending = edits.iter().peekable();
    let (mut edges, mut trace, mut effort, mut diverged) = (Vec::new(), Vec::new(), 0.0, false);
    let (dt, steps) = (sim.dt(), (duration / sim.dt()).round() as u64);
    let mut gains = model.map(|s| ModelGains::new(s.clone()));
    if let Some(g) = gains.as_mut() {
        g.choose(sim, None, 0);
    }
    for _ in 0..steps {
        let t = sim.time();
        let mut edited = None;
        while let Some(e) = pending.next_if(|e| e.t <= t) {
            if sim.law.take_block(e.block) {
                edited = Some(e);
            }
        }
        if let Some(e) = edited {
            monitor.restart(t, sim.law.core().tau);
            if let Some(g) = gains.as_mut() {
                g.system = (*e.system).clone();
                let seed = g.phase_zero.clone();
                g.choose(sim, seed.as_ref().map(|(_, x)| x.as_slice()), 0);
            }
        }
        if let Some(g) = gains.as_mut() {
            g.observe(sim);
            if let Some(tries) = g.retry_due() {
                let seed = g.phase_zero.clone();
                g.choose(sim, seed.as_ref().map(|(_, x)| x.as_slice()), tries);
            }
        }
        let LoopFeedback { mu, projection, .. } = sim.law.loop_feedback();
        let x = *sim.state();
        let out = sim.step();
        if !sim.state().is_finite() {
            diverged = true;
            break;
        }
        if let Some(g) = gains.as_mut() {
            let feedback = out.flags & crate::basics::flags::FEEDBACK_ACTIVE != 0;
            g.watch_target(sim, out.period_residual, feedback);
        }
        if out.flags & crate::basics::flags::FEEDBACK_ACTIVE != 0 {
            let r =
                crate::adapt::AutoMu::residual(projection, out.period_residual, out.null_residual);
            effort += mu * mu * r * r * dt;
        }
        let periods = monitor.evidence().periods;
        let (q, qd) = (x.q.as_slice(), x.qd.as_slice());
        if let Some(e) = monitor.push(t, q, qd, out.period_residual, out.null_residual) {
            if let (Verdict::Chaotic, Some(g)) = (e.to, gains.as_mut()) {
                g.retarget(sim);
            }
            edges.push(e);
        }
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
        model: gains.map_or_else(Vec::new, |g| g.choices),
    }
}

/// The daemon's gain search ([`crate::tune`]) on a watched run.
struct ModelGains {
    system: System,
    /// (period index, q and q̇) of the newest state at a whole period: the seed after an edit.
    phase_zero: Option<(i64, Vec<f64>)>,
    choices: Vec<ModelChoice>,
    /// The steering onto the chosen cycle under way.
    release: Option<Release>,
    /// A search that found nothing to stabilise, tried again at this period index (the
    /// retries so far), as the daemon does ([`crate::tune::RETRY_PERIODS`]).
    retry: Option<(i64, u32)>,
    /// The steering onto the newest chosen cycle, to steer the arm back when the monitor
    /// calls it chaotic again, and how often it was ([`crate::target::MAX_RETARGETS`]).
    steering: Option<crate::steer::Steering>,
    retargets: u32,
}

impl ModelGains {
    fn new(system: System) -> Self {
        Self {
            system,
            phase_zero: None,
            choices: Vec::new(),
            release: None,
            retry: None,
            steering: None,
            retargets: 0,
        }
    }

    /// The monitor called the arm chaotic: steered back onto the chosen cycle, as the daemon
    /// does.
    fn retarget<const N: usize, L: ClosedLoopLaw<N>>(&mut self, sim: &mut Simulation<N, L>) {
        let Some(steering) = self.steering.filter(|_| self.release.is_none()) else {
            return;
        };
        self.retargets += 1;
        if self.retargets > MAX_RETARGETS || sim.law.steering().is_some() {
            return;
        }
        sim.law.set_steering(Some(steering));
        self.release = Some(Release::new(sim.time(), self.system.period()));
    }

    /// The retries so far, when a retry is due at the newest whole period.
    fn retry_due(&self) -> Option<u32> {
        let (at, tries) = self.retry?;
        let now = self.phase_zero.as_ref()?.0;
        (now >= at).then_some(tries)
    }

    /// Takes the pull away once the steered arm is on its cycle, as the daemon's reporter does.
    fn watch_target<const N: usize, L: ClosedLoopLaw<N>>(
        &mut self,
        sim: &mut Simulation<N, L>,
        residual: f64,
        feedback: bool,
    ) {
        let Some(r) = self.release.as_mut() else {
            return;
        };
        let t = sim.time();
        if let Some(why) = r.observe(t, residual, feedback) {
            sim.law.set_steering(None);
            self.release = None;
            if let Some(run) = self.choices.last_mut().and_then(|c| c.target.as_mut()) {
                (run.released_at, run.released) = (Some(t), Some(why));
            }
        }
    }

    /// The steering onto the chosen cycle, unless the set-up does not want it
    /// ([`target_wanted`]) or the law already follows a steering.
    fn target<const N: usize, L: ClosedLoopLaw<N>>(
        &mut self,
        sim: &mut Simulation<N, L>,
        orbit: &crate::analysis::PeriodicOrbit,
    ) -> Option<TargetRun> {
        if !target_wanted(&self.system) || sim.law.steering().is_some() {
            return None;
        }
        let (miss, error) = match target(&self.system, orbit) {
            Ok(t) => {
                sim.law.set_steering(Some(t.steering));
                self.steering = Some(t.steering);
                self.release = Some(Release::new(sim.time(), self.system.period()));
                (Some(t.miss), None)
            }
            Err(e) => (None, Some(e.to_string())),
        };
        Some(TargetRun {
            since: sim.time(),
            miss,
            released_at: None,
            released: None,
            error,
        })
    }

    fn observe<const N: usize, L: ClosedLoopLaw<N>>(&mut self, sim: &Simulation<N, L>) {
        let period = self.system.period();
        let k = (sim.time() / period).floor() as i64;
        if self.phase_zero.as_ref().is_some_and(|(at, _)| *at == k) {
            return;
        }
        let x = sim.state();
        let coords = x.q.iter().chain(x.qd.iter()).copied().collect();
        self.phase_zero = Some((k, coords));
    }

    /// For `mu = "auto"`: the gain from the model, swapped in as the daemon's reporter hands it
    /// to the loop (a block, not an edit: the monitor goes on).
    fn choose<const N: usize, L: ClosedLoopLaw<N>>(
        &mut self,
        sim: &mut Simulation<N, L>,
        seed: Option<&[f64]>,
        tries: u32,
    ) {
        self.retry = None;
        self.steering = None;
        if tries == 0 {
            self.retargets = 0;
        }
        // The steering onto the cycle of the set-up before an edit is no longer the arm's.
        if self.release.take().is_some() {
            sim.law.set_steering(None);
        }
        if self.system.feedback().auto.is_none() {
            return;
        }
        let t = sim.time();
        let spec = TuneSpec::of(&self.system);
        let choice = match choose_gain(&self.system, seed, &spec) {
            Ok(c) => c,
            Err(e) => {
                self.retry = e.retry((t / self.system.period()).floor() as i64, tries);
                self.choices.push(ModelChoice {
                    t,
                    mu: None,
                    multiplier: None,
                    rate: None,
                    error: Some(e.to_string()),
                    target: None,
                });
                return;
            }
        };
        if let Some(s) = self.system.with_model_gain(choice.mu, choice.gamma) {
            sim.law.take_block(s.param_block());
            self.system = s;
        }
        let target = self.target(sim, &choice.orbit);
        self.choices.push(ModelChoice {
            t,
            mu: Some(choice.mu),
            multiplier: Some(choice.multiplier),
            rate: Some(choice.rate),
            error: None,
            target,
        });
    }
}
