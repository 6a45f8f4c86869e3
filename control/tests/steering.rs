//! Steering onto a planned clean cycle (`[safety] plan`), through the real law and the real
//! simulation: it leaves a run untouched when off (and, by default, without obstacles), tracks
//! exactly and periodically on an open layout, and gets the arm out of the trap the local
//! filter alone holds it in.

use control::{Config, RunStats, Simulation, Summary};

/// The demo's arm, with `obstacles` (x, y, r) and the planner on or off, run for `duration` s.
fn run(obstacles: &[(f64, f64, f64)], plan: bool, duration: f64) -> (Summary, bool) {
    let mut cfg = Config::preset("demo").unwrap();
    cfg.planar_mut().unwrap().obstacles = obstacles
        .iter()
        .map(|&(x, y, r)| control::config::ObstacleConfig::disc(x, y, r))
        .collect();
    cfg.safety.plan = plan.into();
    cfg.sim.duration = duration;
    cfg.sim.transient = duration / 2.0;
    let (s, steered, blocked) = simulate(&cfg);
    assert!(blocked.is_none(), "{blocked:?}");
    (s, steered)
}

/// Runs `cfg` (validated here) with its planned steering, if any, over `sim.duration`: the
/// summary after `sim.transient`, whether it steered, and why not when the planner found no
/// cycle.
fn simulate(cfg: &Config) -> (Summary, bool, Option<control::steer::Blocked>) {
    cfg.validate().unwrap();
    let (params, blocked) = control::plan::law_params_planned(cfg);
    let (duration, transient) = (cfg.sim.duration, cfg.sim.transient);
    let x0 = cfg.initial_state::<3>();
    let mut sim = Simulation::new(
        cfg.model::<3>(),
        params,
        cfg.sim.dt,
        x0,
        cfg.feedback.capacity(),
    );
    let mut stats = RunStats::new(&params, cfg.sim.dt, duration, transient, &x0);
    for k in 0..(duration / cfg.sim.dt).round() as u64 {
        let x = *sim.state();
        let out = sim.step();
        stats.record(k, &x, &out);
    }
    (stats.summary(), params.steer.is_some(), blocked)
}

#[test]
fn off_it_changes_nothing() {
    let mut cfg = Config::preset("demo").unwrap();
    cfg.safety.plan = control::safety::policy::PlanMode::Off;
    let (p, b) = control::plan::law_params_planned(&cfg);
    assert_eq!(p, cfg.law_params());
    assert!(b.is_none() && p.steer.is_none());
}

#[test]
fn by_default_it_steers_only_where_there_is_an_obstacle_to_keep_clear_of() {
    // Without obstacles the paper's chaos stays: the planned steering is not handed over.
    let mut cfg = Config::preset("demo").unwrap();
    assert_eq!(cfg.safety.plan, control::safety::policy::PlanMode::Auto);
    assert_eq!(control::plan::law_params_planned(&cfg).0, cfg.law_params());
    cfg.planar_mut().unwrap().obstacles =
        vec![control::config::ObstacleConfig::disc(0.9, 1.1, 0.15)];
    assert!(control::plan::law_params_planned(&cfg).0.steer.is_some());
    // The filter off: nothing to steer for.
    cfg.safety.enabled = false;
    assert!(control::plan::law_params_planned(&cfg).0.steer.is_none());
    // An arm without a planner runs as before with `auto`; `true` is refused there.
    let mut cfg = Config::preset("paper-floating").unwrap();
    cfg.safety.enabled = true;
    cfg.planar_mut().unwrap().obstacles =
        vec![control::config::ObstacleConfig::disc(0.9, 1.1, 0.15)];
    cfg.validate().unwrap();
    assert!(control::plan::law_params_planned(&cfg).0.steer.is_none());
}

#[test]
fn plan_takes_true_false_or_auto_in_a_file() {
    for (v, mode) in [
        ("true", control::safety::policy::PlanMode::On),
        ("false", control::safety::policy::PlanMode::Off),
        ("\"auto\"", control::safety::policy::PlanMode::Auto),
    ] {
        let c = Config::from_toml_str(&format!("[safety]\nplan = {v}\n")).unwrap();
        assert_eq!(c.safety.plan, mode, "{v}");
        let back = Config::from_toml_str(&c.to_toml()).unwrap();
        assert_eq!(back.safety.plan, mode, "{v} round trip");
    }
    for bad in ["\"sometimes\"", "3"] {
        let e = Config::from_toml_str(&format!("[safety]\nplan = {bad}\n")).unwrap_err();
        assert!(
            e.to_string().contains("true, false or \"auto\""),
            "{bad}: {e}"
        );
    }
}

#[test]
fn on_an_open_layout_the_arm_tracks_exactly_on_a_periodic_cycle() {
    let (s, steered) = run(&[], true, 40.0);
    assert!(steered);
    assert!(s.rms_tracking_error < 1e-6, "{s:?}");
    assert!(s.period_residual_final.unwrap() < 1e-6, "{s:?}");
}

#[test]
fn round_the_trap_the_arm_tracks_exactly_without_contact() {
    // The layout where the filter alone holds the arm centimetres off the circle: steered onto
    // the planned cycle (refined until the filter has nothing to do on it, fed forward), the
    // arm tracks to the law's own precision and the filter never acts.
    let trap = [(0.9, 1.1, 0.15)];
    let (alone, _) = run(&trap, false, 40.0);
    let (steered, on) = run(&trap, true, 40.0);
    assert!(on);
    assert!(alone.rms_tracking_error > 1e-2, "{alone:?}");
    assert_eq!(steered.time_in_contact, Some(0.0), "{steered:?}");
    assert!(steered.rms_tracking_error < 1e-6, "{steered:?}");
    assert_eq!(steered.safety_active_time, 0.0, "{steered:?}");
}

#[test]
fn plan_is_refused_where_the_planner_cannot_go() {
    let mut cfg = Config::preset("paper-floating").unwrap();
    cfg.safety.enabled = true;
    cfg.safety.plan = control::safety::policy::PlanMode::On;
    let e = cfg.validate().unwrap_err().to_string();
    assert!(e.contains("safety.plan"), "{e}");
    let mut cfg = Config::preset("demo").unwrap();
    cfg.safety.plan_hz = 0.0;
    let e = cfg.validate().unwrap_err().to_string();
    assert!(e.contains("safety.plan_hz"), "{e}");
}

/// The arm of the default set-up (the daemon's, no obstacles) at `t` s, simulated.
fn posture_at(t: f64) -> [f64; 3] {
    control::plan::posture_at(&Config::default(), t).1
}

#[test]
fn a_new_obstacle_on_the_wrong_side_of_the_arm_gets_a_detour() {
    // `chaosctl obstacle add 0.9 1.1 0.15` at t = 5 s trapped the arm 0.2 m off its path: clean
    // cycles exist round this obstacle, but from the arm's posture at 5 s none can be reached
    // with the hand on the path. At 3 s one can. The planner tells them apart, and gives the
    // arm at 5 s a joint-space detour onto the cycle instead.
    use control::plan::{plan_config, PlanOutcome};
    let mut cfg = Config::default();
    cfg.planar_mut().unwrap().obstacles =
        vec![control::config::ObstacleConfig::disc(0.9, 1.1, 0.15)];
    let at = |t: f64| match plan_config(&cfg, t, Some(posture_at(t))).unwrap().outcome {
        PlanOutcome::Found(c) => c,
        PlanOutcome::Blocked(b) => panic!("blocked at {t} s: {}", b.reason),
    };
    let c = at(5.0);
    let why = c.unreachable.as_ref().expect("unreachable tracking");
    assert!(
        why.reason.contains("none the arm can reach"),
        "{}",
        why.reason
    );
    assert_eq!(why.obstacle, Some(0), "{why:?}");
    let d = c.detour.expect("a detour");
    assert!(
        d.t_start == 5.0 && d.t_arrive > d.t_start + d.duration,
        "{d:?}"
    );
    let c = at(3.0);
    assert!(c.unreachable.is_none() && c.detour.is_none(), "{c:?}");
    // Without the arm's posture, a cycle exists and no detour is asked for.
    match plan_config(&cfg, 5.0, None).unwrap().outcome {
        PlanOutcome::Found(c) => assert!(c.detour.is_none()),
        PlanOutcome::Blocked(b) => panic!("{}", b.reason),
    }
}

/// One run of the daemon's set-up (filter on, steering on) from `q0` at `mu` with `obstacles`:
/// (steered, RMS tracking error over 20–40 s, smallest clearance to any obstacle's surface once
/// the arm first kept the filter's clearance: a start may begin inside it).
fn steered_run(obstacles: &[(f64, f64, f64)], q0: [f64; 3], mu: f64) -> (bool, f64, f64) {
    let mut cfg = Config::default();
    cfg.planar_mut().unwrap().obstacles = obstacles
        .iter()
        .map(|&(x, y, r)| control::config::ObstacleConfig::disc(x, y, r))
        .collect();
    cfg.safety.plan = control::safety::policy::PlanMode::On;
    cfg.feedback.mu = mu;
    cfg.feedback.enabled = mu > 0.0;
    cfg.sim.q0 = Some(q0.to_vec());
    cfg.sim.qd0 = Some(vec![0.0; 3]);
    cfg.sim.duration = 40.0;
    cfg.sim.transient = 20.0;
    let (s, steered, _) = simulate(&cfg);
    (
        steered,
        s.rms_tracking_error,
        s.min_clearance_after_clear.unwrap_or(f64::INFINITY),
    )
}

#[test]
fn steered_starts_keep_clear_and_track_exactly_where_the_way_is_open() {
    // Issue 25's targets over starts × μ (0, 0.2, 1.8): five starts, the open layout and two
    // with an obstacle. Every run keeps the filter's clearance and tracks to 1e-4 m after 20 s.
    let starts = [
        [1.5501, -0.4884, -0.9343],
        [0.3, 1.2, 1.0],
        [1.2, -1.2, 1.5],
        [0.8, 0.4, 0.9],
        [2.0, -1.6, -0.2],
    ];
    // Starts 1 and 2 begin with the hand 0.28 and 0.39 m off the circle (start 1 with a link
    // inside the third layout's obstacle): they reach the cycle by a joint-space detour.
    let layouts: [&[(f64, f64, f64)]; 3] = [&[], &[(0.9, 1.1, 0.15)], &[(1.0, 1.1, 0.1)]];
    let clearance = Config::default().safety.clearance;
    for (l, layout) in layouts.iter().enumerate() {
        for q0 in starts {
            for mu in [0.0, 0.2, 1.8] {
                let (steered, rms, min) = steered_run(layout, q0, mu);
                eprintln!("layout {l} start {q0:?} mu {mu}: steered {steered} rms {rms:.2e} clearance {min:.3}");
                assert!(
                    min >= clearance - 2e-3,
                    "layout {l} {q0:?} μ {mu}: clearance {min}"
                );
                assert!(steered && rms < 1e-4, "layout {l} {q0:?} μ {mu}: {rms}");
            }
        }
    }
}
