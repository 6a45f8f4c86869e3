//! The stability of an orbit of a spatial closed loop. The trajectory is the planar arm's
//! [`ArmFlow`] on a [`crate::sim::SpatialLaw`] (λ_max, the section and its class of a URDF arm come from
//! [`super::analyse_flow`], the same code and norm as the planar arm's); what is spatial here is
//! starting on an orbit of the chain's own stroboscopic map.

use super::closed_loop::ArmFlow;
use super::lyapunov::Trajectory;
use crate::sim::spatial::SpatialSimulation;

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
