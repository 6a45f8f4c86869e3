//! The offline command that still runs a robot its own way (`orbits`) with `--preset panda` or a config file that has a `[robot]` table; `simulate`, `sweep`,
//! `basins`, `lyapunov`, `poincare`, `figures` and `obstacles` run every arm through
//! [`crate::subject::Subject`].
//!
//! The flags mean what they mean for the planar arm and are applied to the spatial file the same
//! way; the run itself is [`control::law::spatial`], and the CSV keeps the planar columns
//! (t,q1..qn,qd1..qdn) so scripts that read one read the other.

use crate::setup::SetupArgs;
use anyhow::{bail, Context, Result};
use control::config::spatial::is_spatial;
use control::config::spatial::SpatialConfig;
use control::config::spatial::SpatialSetup;
use control::sim::spatial::SpatialSimulation;
use control::sim::SpatialLaw;
use control::{with_dof, with_task_rows, ArmState};
use serde::Serialize;

/// The spatial set-up named by the flags, or None for a planar one.
pub fn load(setup: &SetupArgs, mu: Option<f64>) -> Result<Option<SpatialConfig>> {
    let mut cfg = match (&setup.config, &setup.preset) {
        (Some(path), _) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read config file {}", path.display()))?;
            if !is_spatial(&text) {
                return Ok(None);
            }
            SpatialConfig::from_toml(&text).with_context(|| format!("in {}", path.display()))?
        }
        (None, Some(p)) => match SpatialConfig::preset(p) {
            Some(c) => c,
            None => return Ok(None),
        },
        (None, None) => return Ok(None),
    };
    if setup.model.is_some() {
        bail!(
            "--model applies to the planar arm; a spatial robot is given by [robot] in its config"
        );
    }
    if let Some(v) = mu {
        cfg.feedback.mu = v;
    }
    if let Some(v) = setup.tau {
        cfg.feedback.tau = Some(v);
    }
    if let Some(v) = setup.t_on {
        cfg.feedback.t_on = v;
    }
    if let Some(v) = setup.dt {
        cfg.sim.dt = v;
    }
    if let Some(v) = &setup.q0 {
        cfg.sim.q0 = Some(v.0.clone());
    }
    if let Some(v) = &setup.qd0 {
        cfg.sim.qd0 = Some(v.0.clone());
    }
    if let Some(on) = setup.safety {
        cfg.safety.enabled = on;
    }
    if let Some(p) = setup.projection {
        cfg.feedback.projection = p;
    }
    Ok(Some(cfg))
}

/// Loads the robot and calls `f` with the checked set-up, `N` the joint count and `M` the task
/// rows bound as consts.
macro_rules! with_setup {
    ($cfg:expr, |$setup:ident, $n:ident, $m:ident| $body:expr) => {
        with_setup!($cfg, |$setup, _blocked, $n, $m| $body)
    };
    ($cfg:expr, |$setup:ident, $blocked:ident, $n:ident, $m:ident| $body:expr) => {{
        let cfg: &SpatialConfig = $cfg;
        let chain = rt::robot::load(
            &cfg.robot.description,
            cfg.robot.base.as_deref(),
            cfg.robot.tip.as_deref(),
        )?;
        let kind = cfg.task_kind()?;
        with_dof!(chain.dof(), $n => {
            // With `safety.plan`, steered onto the planned cycle, as the daemon would be.
            let ($setup, $blocked): (SpatialSetup<$n>, _) = control::plan::setup_planned::<$n>(&cfg, &chain)?;
            if let Some(b) = &$blocked {
                eprintln!("safety.plan: no clean cycle, running without steering: {}", b.reason);
            }
            with_task_rows!(kind, |$m| $body)
        })
    }};
}

/// λ_max of the loop of `cfg` at gain `mu`, starting on `orbit` with its own history (the
/// `orbits --mu` scan on a spatial robot).
pub fn orbit_stability(
    cfg: &SpatialConfig,
    orbit: &control::analysis::PeriodicOrbit,
    mu: f64,
    spec: &control::analysis::StabilitySpec,
) -> Result<control::analysis::OrbitStability> {
    Ok(with_setup!(cfg, |s, N, M| {
        let mut params = s.params;
        params.core.mu = mu;
        let law = SpatialLaw::<N, M> { arm: s.arm, params };
        control::analysis::orbit_stability_of(&law, cfg.task.period, s.dt, orbit, spec)?
    }))
}

/// One seed of `orbits` on a spatial robot: where the loop with feedback gain `seed_mu` ended
/// (at a multiple of T), and the μ = 0 period-T orbit Newton's method found from there.
#[derive(Serialize)]
pub struct SpatialOrbit {
    pub seed_mu: f64,
    /// |Φ_T(x) − x| at the seed, with the feedback off: how far the seed already was from a
    /// period-T orbit.
    pub seed_residual: f64,
    pub orbit: Result<control::analysis::PeriodicOrbit, String>,
    /// ln|largest multiplier| / T at μ = 0 (1/s): > 0, unstable without the feedback.
    pub floquet_exponent: Option<f64>,
}

/// `chaosctl orbits` on a spatial robot: for each gain, run the set-up `duration` s (rounded
/// to whole periods), then find the μ = 0 loop's period-T orbit from the end state.
pub fn orbits(
    cfg: &SpatialConfig,
    gains: &[f64],
    duration: f64,
    newton: &control::analysis::NewtonConfig,
) -> Result<Vec<SpatialOrbit>> {
    use control::analysis::newton_orbit;
    use control::analysis::stroboscopic_map;
    let period = cfg.task.period;
    if cfg.feedback.tau.is_some_and(|t| (t - period).abs() > 1e-9) {
        bail!("orbits needs τ = T (feedback.tau = {:?} s, task.period = {period} s): only then does the feedback vanish on period-T orbits", cfg.feedback.tau);
    }
    let mut out = Vec::new();
    for &mu in gains {
        let found = with_setup!(cfg, |s, N, M| {
            let steps = control::analysis::period_steps(period, s.dt)?;
            let mut p = s.params;
            p.core.mu = mu;
            let mut sim =
                SpatialSimulation::<N, M>::spatial(s.arm, p, s.dt, s.q0, s.qd0, p.core.tau);
            for _ in 0..(duration / period).round() as u64 * steps {
                sim.step();
            }
            let seed = *sim.state();
            let law = SpatialLaw::<N, M> {
                arm: s.arm,
                params: s.params,
            };
            let map = |x: &ArmState<N>| stroboscopic_map(&law, s.dt, steps, x);
            let y = map(&seed);
            let seed_residual =
                ((y.q - seed.q).norm_squared() + (y.qd - seed.qd).norm_squared()).sqrt();
            (seed_residual, newton_orbit(&map, &seed, newton))
        });
        let (seed_residual, orbit) = found;
        let floquet_exponent = orbit.as_ref().ok().map(|o| o.floquet_exponent(period));
        out.push(SpatialOrbit {
            seed_mu: mu,
            seed_residual,
            orbit: orbit.map_err(|e| e.to_string()),
            floquet_exponent,
        });
    }
    Ok(out)
}
