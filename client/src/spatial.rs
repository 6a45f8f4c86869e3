//! The offline commands that still run a robot their own way (`simulate`, `orbits`, `monitor`'s
//! watched runs) with `--preset panda` or a config file that has a `[robot]`
//! table; `sweep`, `basins`, `lyapunov` and `poincare` run every arm through [`crate::subject::Subject`].
//!
//! The flags mean what they mean for the planar arm and are applied to the spatial file the same
//! way; the run itself is [`control::law::spatial`], and the CSV keeps the planar columns
//! (t,q1..qn,qd1..qdn) so scripts that read one read the other.

use crate::setup::SetupArgs;
use crate::traps::{OfflineTraps, TrapEvent};
use anyhow::{bail, Context, Result};
use control::config::spatial::is_spatial;
use control::config::spatial::SpatialConfig;
use control::config::spatial::SpatialSetup;
use control::sim::spatial::run_steering;
use control::sim::spatial::SpatialSimulation;
use control::sim::Summary;
use control::steer::Steering;
use control::system::SpatialSystem;
use control::{with_dof, with_task_rows, ArmState, System};
use serde::Serialize;
use std::io::Write;
use std::path::Path;

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

/// What `simulate --json` prints for a spatial robot.
#[derive(Serialize)]
pub struct SpatialReport {
    pub robot: String,
    pub n: usize,
    pub task: String,
    pub mu: f64,
    pub tau: f64,
    pub t_on: f64,
    pub projection: String,
    pub secondary: String,
    /// Steered onto a planned clean cycle (`safety.plan`), which replaces the secondary task.
    pub steered: bool,
    /// The trap watch's answers, as the daemon would give them (safety on).
    pub traps: Vec<TrapEvent>,
    pub alpha: f64,
    pub dt: f64,
    pub final_q: Vec<f64>,
    pub final_qd: Vec<f64>,
    #[serde(flatten)]
    pub summary: Summary,
}

/// `chaosctl simulate` on a spatial robot.
pub fn simulate(
    cfg: &mut SpatialConfig,
    duration: Option<f64>,
    transient: Option<f64>,
    csv: Option<&Path>,
    stride: u64,
    json: bool,
) -> Result<()> {
    if let Some(d) = duration {
        cfg.sim.duration = d;
    }
    if let Some(t) = transient {
        cfg.sim.transient = t;
    }
    let mut out = match csv {
        Some(p) => Some(std::io::BufWriter::new(
            std::fs::File::create(p).with_context(|| format!("cannot create {}", p.display()))?,
        )),
        None => None,
    };
    // The trap watch plans for the whole set-up, as the daemon's does.
    let system = System::Spatial(Box::new(SpatialSystem {
        config: cfg.clone(),
        chain: rt::robot::load(
            &cfg.robot.description,
            cfg.robot.base.as_deref(),
            cfg.robot.tip.as_deref(),
        )?,
    }));
    let report = with_setup!(cfg, |s, blocked, N, M| {
        if let Some(w) = out.as_mut() {
            let q: Vec<String> = (1..=N).map(|i| format!("q{i}")).collect();
            let qd: Vec<String> = (1..=N).map(|i| format!("qd{i}")).collect();
            writeln!(w, "t,{},{}", q.join(","), qd.join(","))?;
        }
        let mut sim = s.simulation::<M>();
        let mut err = None;
        let mut k = 0u64;
        let mut traps = OfflineTraps::new(system.clone(), s.params.steer.map(Steering::Spatial));
        if let Some(b) = &blocked {
            traps.blocked_at_start(b);
        }
        let summary = run_steering(&mut sim, s.duration, s.transient, |t, x, o| {
            if let Some(w) = out.as_mut() {
                if k.is_multiple_of(stride) && err.is_none() {
                    let row: Vec<String> =
                        x.q.iter()
                            .chain(x.qd.iter())
                            .map(|v| format!("{v:.9}"))
                            .collect();
                    err = writeln!(w, "{t:.6},{}", row.join(",")).err();
                }
            }
            k += 1;
            traps.observe(t, o.flags, o.tracking_error, x.q.as_slice())
        });
        if let Some(e) = err {
            return Err(e.into());
        }
        let x = sim.state();
        let mut r = report(cfg, N, s.dt, x.q.as_slice(), x.qd.as_slice(), summary);
        r.steered = s.params.steer.is_some();
        r.traps = traps.events;
        r
    });
    if let Some(mut w) = out {
        w.flush()?;
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print(&report);
        if let Some(p) = csv {
            println!("  trajectory       {} (every {stride} steps)", p.display());
        }
    }
    Ok(())
}

fn report(
    cfg: &SpatialConfig,
    n: usize,
    dt: f64,
    q: &[f64],
    qd: &[f64],
    summary: Summary,
) -> SpatialReport {
    SpatialReport {
        robot: cfg.robot.description.clone(),
        n,
        task: format!("{} {}", cfg.task.kind, cfg.task.path),
        mu: cfg.feedback.mu,
        tau: cfg.feedback.tau.unwrap_or(cfg.task.period),
        t_on: cfg.feedback.t_on,
        projection: cfg.feedback.projection.name().into(),
        secondary: cfg.law.secondary.name().into(),
        steered: false,
        traps: Vec::new(),
        alpha: cfg.law.alpha,
        dt,
        final_q: q.to_vec(),
        final_qd: qd.to_vec(),
        summary,
    }
}

fn opt(v: Option<f64>, unit: &str) -> String {
    v.map(|x| format!("{x:.3e} {unit}"))
        .unwrap_or_else(|| "n/a".into())
}

/// The human report.
pub fn print(r: &SpatialReport) {
    let s = &r.summary;
    let secondary = if r.steered {
        "none: steered onto a planned clean cycle (safety.plan)".to_string()
    } else {
        format!("{} (α = {})", r.secondary, r.alpha)
    };
    println!(
        "{} ({} joints), {} task, {} s: secondary {secondary}, feedback μ = {} τ = {} s from t = {} s ({})",
        r.robot, r.n, r.task, s.duration, r.mu, r.tau, r.t_on, r.projection
    );
    println!(
        "  tracking error   rms {:.3e} m, max {:.3e} m",
        s.rms_tracking_error, s.max_tracking_error
    );
    if s.max_orientation_error > 0.0 {
        println!("  orientation err  max {:.3e} rad", s.max_orientation_error);
    }
    println!(
        "  period residual  before {} → final {}",
        opt(s.period_residual_before, "rad/s"),
        opt(s.period_residual_final, "rad/s")
    );
    println!(
        "  joint drift      {} per period (last two periods)",
        opt(s.drift_per_period, "rad")
    );
    println!(
        "  joint speeds     fastest {:.3} rad/s (joint {}); closest to its limit: joint {} at {:.0}%",
        s.max_joint_speed,
        s.max_joint_speed_joint,
        s.max_speed_ratio_joint,
        100.0 * s.max_speed_ratio
    );
    println!(
        "  joint commands   max {:.0}% of the acceleration limit, {:.0}% of the jerk limit",
        100.0 * s.max_accel_ratio,
        100.0 * s.max_jerk_ratio
    );
    println!(
        "  joint margin     min {} to a position limit",
        opt(s.min_joint_margin, "rad")
    );
    if let Some(c) = s.min_clearance {
        println!("  clearance        min {c:.3} m");
    }
    println!(
        "  safety filter    active {:.2} s, left the null space {} steps, infeasible {} steps",
        s.safety_active_time, s.safety_left_null_space_steps, s.safety_infeasible_steps
    );
    crate::traps::print(&r.traps);
    if !s.finite {
        println!("  the state became non-finite: the run stopped early");
    }
    println!(
        "  final q          {:?}",
        r.final_q
            .iter()
            .map(|v| (v * 1e4).round() / 1e4)
            .collect::<Vec<_>>()
    );
}

/// A run of `duration` s with the daemon's chaos monitor watching (`chaosctl monitor`).
pub fn watch(
    cfg: &SpatialConfig,
    duration: f64,
    settings: control::monitor::MonitorSettings,
) -> Result<control::monitor::run::Watched> {
    Ok(with_setup!(cfg, |s, N, M| {
        let mut sim = s.simulation::<M>();
        control::monitor::run::watch_sim(&mut sim, duration, settings, s.params.core.tau, |_, _| {
            None
        })
    }))
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
        let mut p = s.params;
        p.core.mu = mu;
        control::analysis::spatial::orbit_stability::<N, M>(&s.arm, &p, s.dt, orbit, spec)?
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
    use control::sim::spatial::stroboscopic_map;
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
            let map = |x: &ArmState<N>| stroboscopic_map::<N, M>(&s.arm, &s.params, s.dt, steps, x);
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

/// Newton's method at μ = 0 from a section point (q, q̇) of a run of `cfg`: one line on the
/// period-T orbit there (residual, largest multiplier, how many on the unit circle), or None.
pub fn refine(cfg: &SpatialConfig, point: &[f64]) -> Option<String> {
    use control::analysis::{newton_orbit, NewtonConfig};
    let found = (|| -> Result<control::analysis::PeriodicOrbit> {
        Ok(with_setup!(cfg, |s, N, M| {
            if point.len() != 2 * N {
                bail!("a section point of {} numbers for {N} joints", point.len());
            }
            let steps = control::analysis::period_steps(s.params.task.path.period, s.dt)?;
            let map = |x: &ArmState<N>| {
                control::sim::spatial::stroboscopic_map::<N, M>(&s.arm, &s.params, s.dt, steps, x)
            };
            let seed = ArmState::<N> {
                q: control::VecN::<N>::from_fn(|i, _| point[i]),
                qd: control::VecN::<N>::from_fn(|i, _| point[N + i]),
                phi: 0.0,
            };
            newton_orbit(&map, &seed, &NewtonConfig::default())?
        }))
    })();
    let o = found.ok()?;
    let on_circle = o
        .multipliers
        .iter()
        .filter(|m| (m[0].hypot(m[1]) - 1.0).abs() < 1e-3)
        .count();
    Some(format!(
        "at μ = 0 a period-T orbit (Newton residual {:.1e}), largest |ρ| = {:.4}, {on_circle} of {} multipliers on the unit circle",
        o.residual,
        o.max_multiplier(),
        o.multipliers.len()
    ))
}
