//! The analysis tools on the real closed loop: known structure that any correct implementation
//! must reproduce (docs/science.md, "Measuring chaos").

use control::analysis::{
    analyse, close_returns, find_orbit, orbit_stability, ClassifyConfig, LyapunovSpec, Motion,
    NewtonConfig, PeriodicOrbit, RunSpec, StabilitySpec, Verdict,
};
use control::{ArmState, Config, VecN};

fn config(mu: f64, q0: [f64; 3]) -> Config {
    let mut cfg = Config::preset("paper").unwrap();
    cfg.feedback.mu = mu;
    cfg.sim.q0 = Some(q0.to_vec());
    cfg.validate().unwrap();
    cfg
}

fn spec(lyapunov: bool) -> RunSpec {
    RunSpec {
        duration: 300.0,
        transient: 100.0,
        lyapunov: lyapunov.then(LyapunovSpec::default),
        classify: ClassifyConfig::default(),
    }
}

fn state(x: &[f64]) -> ArmState<3> {
    ArmState {
        q: VecN::<3>::from_column_slice(&x[..3]),
        qd: VecN::<3>::from_column_slice(&x[3..6]),
        phi: 0.0,
    }
}

#[test]
fn uncontrolled_self_motion_is_chaotic() {
    let cfg = config(
        0.0,
        [
            0.0,
            std::f64::consts::FRAC_PI_2,
            std::f64::consts::FRAC_PI_2,
        ],
    );
    let a = analyse::<3>(
        cfg.model(),
        cfg.law_params(),
        cfg.sim.dt,
        cfg.initial_state(),
        &spec(true),
    )
    .unwrap();
    let l = a.lyapunov.unwrap();
    assert!(l.lambda_max - 2.0 * l.stderr > 0.1, "{l:?}");
    assert!(
        matches!(a.classification.motion, Motion::Irregular { .. }),
        "{:?}",
        a.classification
    );
    assert_eq!(a.section.len(), 201);
}

#[test]
fn feedback_orbit_is_period_one_and_a_newton_fixed_point_with_the_tracking_multipliers() {
    let cfg = config(0.2, [0.3, 1.2, 1.9]);
    let (model, params) = (cfg.model::<3>(), cfg.law_params());
    let a = analyse::<3>(model, params, cfg.sim.dt, cfg.initial_state(), &spec(true)).unwrap();
    match a.classification.motion {
        Motion::Periodic {
            period: 1,
            residual,
        } => assert!(residual < 1e-9, "{residual}"),
        m => panic!("expected period-1, got {m:?}"),
    }
    let l = a.lyapunov.unwrap();
    assert!(l.lambda_max + 2.0 * l.stderr < 0.0, "{l:?}");

    // The settled state is (to the discretisation error) a period-T orbit of the μ = 0 loop.
    let orbit = find_orbit(
        &model,
        &params,
        cfg.sim.dt,
        &state(&a.final_coords),
        &NewtonConfig::default(),
    )
    .unwrap();
    assert!(orbit.residual < 1e-10);
    let shift: f64 = orbit
        .coords()
        .iter()
        .zip(&a.final_coords)
        .map(|(o, f)| (control::basics::wrap_angle(o - f)).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(
        shift < 1e-3,
        "controlled orbit {shift} away from the μ = 0 orbit"
    );

    // The task-space error obeys ë + K_v ė + K_p e = 0 exactly, so four multipliers are e^{sT} for
    // the roots s of s² + 15 s + 40, each twice (x and y).
    let (kp, kv) = (params.core.kp, params.core.kv);
    let disc = (kv * kv - 4.0 * kp).sqrt();
    for s in [(-kv + disc) / 2.0, (-kv - disc) / 2.0] {
        let want = (s * params.task.period).exp();
        let close = orbit
            .multipliers
            .iter()
            .filter(|m| m[1].abs() < 1e-6 && (m[0] - want).abs() < 1e-5 * want.max(1e-3))
            .count();
        assert_eq!(close, 2, "multiplier {want} in {:?}", orbit.multipliers);
    }
}

fn hyperbolic_and_elliptic_orbits() -> (PeriodicOrbit, PeriodicOrbit, Config) {
    let cfg = config(
        0.0,
        [
            0.0,
            std::f64::consts::FRAC_PI_2,
            std::f64::consts::FRAC_PI_2,
        ],
    );
    let (model, params) = (cfg.model::<3>(), cfg.law_params());
    let chaos = analyse::<3>(
        model,
        params,
        cfg.sim.dt,
        cfg.initial_state(),
        &RunSpec {
            transient: 20.0,
            ..spec(false)
        },
    )
    .unwrap();
    let hyperbolic = close_returns(&chaos.section, 8)
        .into_iter()
        .filter_map(|i| {
            find_orbit(
                &model,
                &params,
                cfg.sim.dt,
                &state(chaos.section.point(i)),
                &NewtonConfig::default(),
            )
            .ok()
        })
        .find(|o| o.max_multiplier() > 2.0 && o.multipliers[0][1] == 0.0)
        .expect("a hyperbolic period-T orbit among the close returns");
    let settled = config(0.1, [0.3, 1.2, 1.9]);
    let a = analyse::<3>(
        model,
        settled.law_params(),
        cfg.sim.dt,
        settled.initial_state(),
        &spec(false),
    )
    .unwrap();
    let elliptic = find_orbit(
        &model,
        &params,
        cfg.sim.dt,
        &state(&a.final_coords),
        &NewtonConfig::default(),
    )
    .unwrap();
    (hyperbolic, elliptic, cfg)
}

#[test]
fn on_orbit_exponent_is_the_floquet_exponent_and_feedback_stabilises_the_elliptic_orbit() {
    let (hyperbolic, elliptic, cfg) = hyperbolic_and_elliptic_orbits();
    let model = cfg.model::<3>();
    let mut params = cfg.law_params();
    // μ = 0 on a saddle: Benettin from the orbit measures ln|ρ_max| / T (before the reference leaves;
    // two periods let the separation align with the unstable direction).
    let short = StabilitySpec {
        settle: 2.0,
        duration: 6.0,
        blocks: 2,
        leave_tol: 1e-3,
        ..StabilitySpec::default()
    };
    let s = orbit_stability(&model, &params, cfg.sim.dt, &hyperbolic, &short).unwrap();
    let want = hyperbolic.floquet_exponent(1.0);
    assert!(
        (s.lyapunov.lambda_max - want).abs() < 0.01 * want,
        "λ = {:?}, ln ρ = {want}",
        s.lyapunov
    );
    assert_eq!(s.verdict, Verdict::Unstable);

    // The elliptic orbit (|ρ| = 1 at μ = 0) is marginal without feedback and stable with μ = 0.2,
    // measured through the delay-equation path (history in the norm).
    assert!(
        (elliptic.max_multiplier() - 1.0).abs() < 1e-4,
        "{:?}",
        elliptic.multipliers
    );
    let s0 = orbit_stability(
        &model,
        &params,
        cfg.sim.dt,
        &elliptic,
        &StabilitySpec::default(),
    )
    .unwrap();
    assert!(s0.lyapunov.lambda_max.abs() < 0.05, "{:?}", s0.lyapunov);
    params.core.mu = 0.2;
    let s1 = orbit_stability(
        &model,
        &params,
        cfg.sim.dt,
        &elliptic,
        &StabilitySpec::default(),
    )
    .unwrap();
    assert_eq!(s1.verdict, Verdict::Stable, "{s1:?}");
    assert!(s1.max_distance < 1e-3, "{s1:?}");

    // The delayed loop's leading Floquet multiplier, Benettin's λ_max and the measured decay on
    // the section are three views of one rate, and agree to 0.01 /s (docs/science.md).
    let f = s1
        .floquet
        .as_ref()
        .expect("μ ≠ 0: the delayed loop's spectrum");
    assert!(f.converged, "{f:?}");
    assert!(f.exponent < -0.1, "{f:?}");
    assert!(
        (f.exponent - s1.lyapunov.lambda_max).abs() < 0.01,
        "{f:?} {s1:?}"
    );
    let measured = s1.section_rate.expect("a measurable decay");
    assert!((f.exponent - measured).abs() < 0.01, "{f:?} vs {measured}");
    // At μ = 0 the loop is an ordinary differential equation: no delayed spectrum.
    assert!(s0.floquet.is_none());
}

#[test]
fn bad_specs_are_errors_not_panics() {
    let cfg = config(0.0, [0.0, 1.0, 1.0]);
    let run = |s: RunSpec| {
        analyse::<3>(
            cfg.model(),
            cfg.law_params(),
            cfg.sim.dt,
            cfg.initial_state(),
            &s,
        )
    };
    let mut s = spec(true);
    s.lyapunov.as_mut().unwrap().window = [100.0, 400.0];
    assert!(run(s).unwrap_err().to_string().contains("window"));
    let mut s = spec(true);
    s.transient = 300.0;
    assert!(run(s).is_err());
    let mut s = spec(true);
    s.lyapunov.as_mut().unwrap().renorm = 0.0;
    assert!(run(s).is_err());
    let mut floating = cfg.clone();
    floating.planar_mut().unwrap().arm.model = control::config::ModelKind::Floating;
    let o = find_orbit::<3>(
        &floating.model(),
        &floating.law_params(),
        1e-3,
        &cfg.initial_state(),
        &NewtonConfig::default(),
    );
    assert!(o.unwrap_err().to_string().contains("fixed-base"));
}

/// The delayed loop's spectrum is that of a discretised history (one sample per step): halving dt
/// doubles the history's samples, and the leading multiplier must not move (the convergence check
/// of a semi-discretisation). The elliptic orbit of the paper preset at μ = 0.2, from its printed
/// strobe point.
#[test]
fn the_delayed_spectrum_converges_as_the_history_grid_is_refined() {
    use control::analysis::{delay_multipliers, ArmFlow, FloquetSpec, Trajectory};
    let cfg = config(0.0, [0.0, 1.0, 1.0]);
    let model = cfg.model::<3>();
    let seed = state(&[1.550, -0.488, -0.934, -4.361, 9.229, -4.001]);
    let rate = |dt: f64| {
        let mut p = cfg.law_params();
        let orbit = find_orbit(&model, &p, dt, &seed, &NewtonConfig::default()).unwrap();
        p.core.mu = 0.2;
        p.core.t_on = p.task.period;
        let mut flow = ArmFlow::new(model, p, dt, orbit.state::<3>());
        flow.advance_to(p.task.period);
        let steps = (p.task.period / dt).round() as u64;
        let f = delay_multipliers(flow.sim(), steps, &FloquetSpec::default()).unwrap();
        assert!(f.converged, "{f:?}");
        assert_eq!(f.dimension, 6 + 3 * steps as usize);
        f
    };
    let (coarse, fine) = (rate(1e-3), rate(5e-4));
    assert!(
        (coarse.exponent - fine.exponent).abs() < 1e-3,
        "{coarse:?} {fine:?}"
    );
    assert!((coarse.exponent + 0.213).abs() < 0.005, "{coarse:?}");
    let (a, b) = (coarse.multipliers[0], fine.multipliers[0]);
    assert!(
        (a[0] - b[0]).hypot(a[1].abs() - b[1].abs()) < 1e-3,
        "{a:?} {b:?}"
    );
}
