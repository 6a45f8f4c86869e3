//! The chaos analysis of a spatial closed loop: the Lyapunov driver's trajectory and the
//! stroboscopic section, so λ_max and the Poincaré class of a URDF arm come from the same code
//! and the same norm (q, q̇ and, with feedback, the stored q̇ history) as the planar arm's.

use super::lyapunov::{
    generic_direction, history_distance2, rescale_history, shift_history, Trajectory,
};
use crate::arm::VecN;
use crate::sim::spatial::SpatialSimulation;

impl<const N: usize, const M: usize> Trajectory for SpatialSimulation<N, M> {
    fn time(&self) -> f64 {
        SpatialSimulation::time(self)
    }
    fn advance_to(&mut self, t: f64) {
        let target = (t / self.dt).round().max(0.0) as u64;
        while self.step_index < target {
            self.step();
            if !self.state.is_finite() {
                return;
            }
        }
    }
    fn is_finite(&self) -> bool {
        self.state.is_finite()
    }
    fn distance2(&self, other: &Self) -> f64 {
        let (a, b) = (&self.state, &other.state);
        let mut d2 = (b.q - a.q).norm_squared() + (b.qd - a.qd).norm_squared();
        if self.params.mu != 0.0 && self.params.feedback {
            d2 += history_distance2(&self.delay, &other.delay);
        }
        d2
    }
    fn rescale(&self, other: &mut Self, factor: f64) {
        let a = self.state;
        let b = &mut other.state;
        b.q = a.q + (b.q - a.q) * factor;
        b.qd = a.qd + (b.qd - a.qd) * factor;
        if self.params.mu != 0.0 && self.params.feedback {
            rescale_history(&self.delay, &mut other.delay, factor);
        }
    }
    fn perturbed(&self, eps: f64) -> Self {
        let mut o = self.clone();
        let dir: Vec<f64> = generic_direction(2 * N).collect();
        for i in 0..N {
            o.state.q[i] += eps * dir[i];
            o.state.qd[i] += eps * dir[N + i];
        }
        if self.params.mu != 0.0 && self.params.feedback {
            let dqd = VecN::<N>::from_fn(|i, _| eps * dir[N + i]);
            shift_history(&mut o.delay, &dqd);
        }
        o
    }
}

/// The stroboscopic section x(kT) = (q, q̇) of `sim` from `transient` to `duration` (q compared
/// modulo 2π, as for the planar arm), and its classification by the planar arm's rule.
pub fn section<const N: usize, const M: usize>(
    sim: &mut SpatialSimulation<N, M>,
    duration: f64,
    transient: f64,
    cfg: &super::ClassifyConfig,
) -> (super::Section, super::Classification) {
    let period = sim.params.task.path.period;
    let mut sec = super::Section::new(2 * N, N);
    let periods = (duration / period + 1e-9).floor() as u64;
    for k in 0..=periods {
        let t = k as f64 * period;
        sim.advance_to(t);
        if !sim.state().is_finite() {
            break;
        }
        if t >= transient - 1e-9 * period {
            let x = sim.state();
            let coords: Vec<f64> = x.q.iter().chain(x.qd.iter()).copied().collect();
            sec.push(t, &coords);
        }
    }
    let class = super::classify(&sec, cfg);
    (sec, class)
}

/// λ_max of a spatial loop at `params.mu`, starting on `orbit` (a period-T orbit of the loop
/// without feedback, found by `newton_orbit` on [`crate::sim::spatial::stroboscopic_map`]) with its
/// own history: the planar arm's [`super::orbits::orbit_stability`] for a URDF chain.
pub fn orbit_stability<const N: usize, const M: usize>(
    arm: &crate::arm::spatial::SpatialArm<N>,
    params: &crate::law::spatial::SpatialParams,
    dt: f64,
    orbit: &super::PeriodicOrbit,
    spec: &super::StabilitySpec,
) -> Result<super::OrbitStability, super::OrbitError> {
    let period = params.task.path.period;
    super::orbits::check_stability_run(period, params.tau, dt, spec)?;
    let mut p = *params;
    p.t_on = period;
    let x = orbit.state::<N>();
    let mut sim = SpatialSimulation::<N, M>::new(*arm, p, dt, x.q, x.qd, p.tau);
    sim.advance_to(period);
    let coords = |s: &SpatialSimulation<N, M>| -> Vec<f64> {
        let x = s.state();
        x.q.iter().chain(x.qd.iter()).copied().collect()
    };
    super::orbits::stability_on_orbit(sim, coords, 2 * N, N, orbit, period, params.mu, spec)
}
