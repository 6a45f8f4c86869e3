//! The closed-loop arm as a [`Trajectory`]: the simulation of `sim.rs`, plus the norm and the
//! perturbation that Benettin's method needs.
//!
//! The state is (φ, q, q̇) and, when the delayed feedback is in use (μ ≠ 0), also the history of
//! q̇ held by the simulation's delay line: with μ ≠ 0 the closed loop is a delay differential
//! equation, and two trajectories with equal (q, q̇) but different histories evolve differently.
//! The delay line should be built with `max_tau = tau`, so that the slots hold exactly the τ window
//! (plus two slots); both members of a pair push equally often, so slot i holds the same grid time
//! in both.

use super::lyapunov::{
    generic_direction, history_distance2, rescale_history, shift_history, Trajectory,
};
use crate::arm::{ArmModel, VecN};
use crate::law::LawParams;
use crate::sim::{ArmState, ClosedLoopLaw, RunStats, Simulation};
use crate::tick_law::TickLaw;

/// One closed-loop trajectory of any arm's law, optionally recording run statistics on the way.
#[derive(Clone, Debug)]
pub struct ArmFlow<const N: usize, L: ClosedLoopLaw<N> = TickLaw<N>> {
    sim: Simulation<N, L>,
    /// The delay history is part of the state (feedback on with μ ≠ 0).
    delay_state: bool,
    /// The base attitude is part of the state (floating base).
    floating: bool,
    stats: Option<Box<RunStats<N>>>,
}

impl<const N: usize> ArmFlow<N> {
    /// The planar arm from `initial` at t = 0. The delay line holds exactly τ (see the module docs).
    pub fn new(model: ArmModel<N>, params: LawParams, dt: f64, initial: ArmState<N>) -> Self {
        let sim = Simulation::new(model, params, dt, initial, params.core.tau);
        Self::of(sim)
    }
}

impl<const N: usize, L: ClosedLoopLaw<N>> ArmFlow<N, L> {
    /// The trajectory `sim` runs from where it stands. For the history distance to be the τ
    /// window's, its delay line should hold exactly τ (`max_tau = tau`, see the module docs).
    pub fn of(sim: Simulation<N, L>) -> Self {
        Self {
            delay_state: sim.law.loop_feedback().delay_is_state,
            floating: sim.law.is_floating(),
            sim,
            stats: None,
        }
    }

    /// Records [`RunStats`] on this trajectory (not on the perturbed partner of a pair).
    pub fn with_stats(mut self, duration: f64, transient: f64) -> Self {
        let setup = self.sim.law.stats_setup();
        let stats = RunStats::of(setup, self.sim.dt(), duration, transient, self.sim.state());
        self.stats = Some(Box::new(stats));
        self
    }

    pub fn sim(&self) -> &Simulation<N, L> {
        &self.sim
    }
    pub fn state(&self) -> &ArmState<N> {
        self.sim.state()
    }
    pub fn stats(&self) -> Option<&RunStats<N>> {
        self.stats.as_deref()
    }
    /// Whether the delay history counts as state (μ ≠ 0).
    pub fn has_delay_state(&self) -> bool {
        self.delay_state
    }

    /// The stroboscopic coordinates of the current state: [φ (floating only)], q, q̇. The first
    /// [`Self::angle_coords`] of them are angles.
    pub fn coords(&self) -> Vec<f64> {
        let x = self.sim.state();
        let mut v = Vec::with_capacity(2 * N + 1);
        if self.floating {
            v.push(x.phi);
        }
        v.extend(x.q.iter());
        v.extend(x.qd.iter());
        v
    }

    /// How many leading entries of [`Self::coords`] are angles (compared modulo 2π).
    pub fn angle_coords(&self) -> usize {
        N + usize::from(self.floating)
    }
}

impl<const N: usize, L: ClosedLoopLaw<N>> Trajectory for ArmFlow<N, L> {
    fn time(&self) -> f64 {
        self.sim.time()
    }

    fn advance_to(&mut self, t: f64) {
        let target = (t / self.sim.dt()).round().max(0.0) as u64;
        while self.sim.step_index() < target {
            let k = self.sim.step_index();
            let x = *self.sim.state();
            let out = self.sim.step();
            if let Some(s) = self.stats.as_mut() {
                s.record(k, &x, &out);
            }
            if !self.sim.state().is_finite() {
                return;
            }
        }
    }

    fn is_finite(&self) -> bool {
        self.sim.state().is_finite()
    }

    fn distance2(&self, other: &Self) -> f64 {
        let (a, b) = (self.sim.state(), other.sim.state());
        let mut d2 = (b.q - a.q).norm_squared() + (b.qd - a.qd).norm_squared();
        if self.floating {
            d2 += (b.phi - a.phi).powi(2);
        }
        if self.delay_state {
            d2 += history_distance2(self.sim.delay(), other.sim.delay());
        }
        d2
    }

    fn rescale(&self, other: &mut Self, factor: f64) {
        let a = *self.sim.state();
        let b = other.sim.state_mut();
        b.q = a.q + (b.q - a.q) * factor;
        b.qd = a.qd + (b.qd - a.qd) * factor;
        b.phi = a.phi + (b.phi - a.phi) * factor;
        if self.delay_state {
            rescale_history(self.sim.delay(), other.sim.delay_mut(), factor);
        }
    }

    /// Displaces q and q̇ along a generic direction and, for the delay equation, shifts the whole
    /// stored history of q̇ by the same δq̇ (before t = 0 the history is q̇(0) by convention, so a
    /// perturbed q̇(0) perturbs the history with it).
    fn perturbed(&self, eps: f64) -> Self {
        let mut p = self.clone();
        p.stats = None;
        let mut dir = generic_direction(2 * N + 1);
        let dq = VecN::<N>::from_fn(|_, _| eps * dir.next().unwrap_or(1.0));
        let dqd = VecN::<N>::from_fn(|_, _| eps * dir.next().unwrap_or(1.0));
        let x = p.sim.state_mut();
        x.q += dq;
        x.qd += dqd;
        if self.floating {
            x.phi += eps * dir.next().unwrap_or(1.0);
        }
        if self.delay_state {
            shift_history(p.sim.delay_mut(), &dqd);
        }
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    #[test]
    fn rescale_and_distance_agree_including_history() {
        let mut cfg = Config::preset("paper").unwrap();
        cfg.feedback.mu = 1.0;
        cfg.feedback.t_on = 0.0;
        let a = ArmFlow::<3>::new(cfg.model(), cfg.law_params(), 1e-3, cfg.initial_state());
        assert!(a.has_delay_state());
        let mut pair = (a.clone(), a.perturbed(1e-6));
        pair.0.advance_to(1.5);
        pair.1.advance_to(1.5);
        let d = pair.0.distance2(&pair.1).sqrt();
        assert!(d > 0.0);
        let hist = history_distance2(pair.0.sim.delay(), pair.1.sim.delay());
        assert!(hist > 0.0 && hist < d * d);
        pair.0.rescale(&mut pair.1, 0.5);
        let d2 = pair.0.distance2(&pair.1).sqrt();
        assert!((d2 / d - 0.5).abs() < 1e-9, "{d2} vs {d}");
        // μ = 0: the history is not state.
        let b = ArmFlow::<3>::new(
            cfg.model(),
            Config::preset("paper").unwrap().law_params(),
            1e-3,
            cfg.initial_state(),
        );
        assert!(!b.has_delay_state());
    }
}
