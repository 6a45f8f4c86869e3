//! The chaos analysis of a spatial closed loop: the stroboscopic section and the stability of an
//! orbit. The trajectory is the planar arm's [`ArmFlow`] on a [`SpatialLaw`], so λ_max and the
//! Poincaré class of a URDF arm come from the same code and the same norm (q, q̇ and, with
//! feedback, the stored q̇ history) as the planar arm's.

use super::closed_loop::ArmFlow;
use super::lyapunov::Trajectory;
use crate::sim::spatial::SpatialSimulation;
use crate::sim::SpatialLaw;

/// The stroboscopic section x(kT) = (q, q̇) of `sim` from `transient` to `duration` (q compared
/// modulo 2π, as for the planar arm), and its classification by the planar arm's rule.
pub fn section<const N: usize, const M: usize>(
    sim: &mut ArmFlow<N, SpatialLaw<N, M>>,
    duration: f64,
    transient: f64,
    cfg: &super::ClassifyConfig,
) -> (super::Section, super::Classification) {
    let period = sim.sim().law.params.task.path.period;
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
    super::orbits::check_stability_run(period, params.core.tau, dt, spec)?;
    let mut p = *params;
    p.core.t_on = period;
    p.core.auto_mu = None;
    let x = orbit.state::<N>();
    let mut sim = ArmFlow::of(SpatialSimulation::<N, M>::spatial(
        *arm, p, dt, x.q, x.qd, p.core.tau,
    ));
    sim.advance_to(period);
    super::orbits::stability_on_orbit(sim, orbit, period, params.core.mu, spec)
}
