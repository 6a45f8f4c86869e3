//! The spatial planner on the Panda (`[safety] plan = true`), through the real law and the
//! real simulation: on layouts where the filter alone traps the self-motion, steering onto the
//! planned cycle tracks from every start tried, at every μ, with the clearance kept; a path
//! through a sphere is `Blocked` at once, with the reason.

use control::config::spatial::SphereEntry;
use control::model::{builtin, Chain};
use control::plan::spatial::plan_system;
use control::plan::PlanOutcome;
use control::sim::run;
use control::sim::Simulation;
use control::steer::Cycle;
use control::steer::SpatialSteer;
use control::system::SpatialSystem;
use control::Config;

fn chain() -> Chain {
    Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap()
}

/// The paper's recipe on the Panda (`panda-paper`: undamped centring, which these spheres trap)
/// with `spheres` (x, y, z, r), feedback `mu` from the start, and the start posture kicked by
/// `kick` rad on joints 1 and 3 (the path follows the start's hand).
fn config(spheres: &[[f64; 4]], mu: f64, kick: f64, plan: bool) -> Config {
    let mut c = Config::robot_preset("panda-paper").unwrap();
    c.feedback.mu = mu;
    c.feedback.t_on = 0.0;
    let q0 = c.sim.q0.as_mut().expect("the preset's start");
    q0[0] += kick;
    q0[2] -= kick;
    c.safety.plan = plan.into();
    c.spatial_mut().unwrap().obstacles = spheres.iter().copied().map(SphereEntry::of).collect();
    c
}

/// What a 40 s run shows after a 20 s transient.
struct Outcome {
    rms: f64,
    min_clearance: f64,
    steered: bool,
}

fn simulate(c: &Config) -> Outcome {
    let (set, blocked) = control::plan::setup_planned::<7>(c, &chain()).unwrap();
    assert!(blocked.is_none(), "{blocked:?}");
    let p = set.params;
    let mut sim = Simulation::spatial(set.arm, p, set.dt, set.q0, set.qd0, p.core.tau);
    let (mut sq, mut n) = (0.0, 0u64);
    let s = run(&mut sim, 40.0, 20.0, |t, _, o| {
        if t >= 20.0 {
            sq += o.tracking_error * o.tracking_error;
            n += 1;
        }
    });
    Outcome {
        rms: (sq / n as f64).sqrt(),
        min_clearance: s.min_clearance.unwrap(),
        steered: p.steer.is_some(),
    }
}

/// One sphere between the arm and the circle; one above the circle's far half and one beside
/// its lower half.
const LAYOUTS: [&[[f64; 4]]; 2] = [
    &[[0.089, -0.196, 0.575, 0.058]],
    &[[0.145, -0.233, 0.675, 0.072], [0.385, -0.315, 0.452, 0.083]],
];

#[test]
fn steering_onto_the_planned_cycle_tracks_where_the_filter_alone_traps_the_arm() {
    for spheres in LAYOUTS {
        // The trap is real: without steering, some start at μ = 0 loses the path for good.
        let free = [0.0, 0.3, -0.3].map(|k| simulate(&config(spheres, 0.0, k, false)).rms);
        assert!(free.iter().any(|&r| r > 1e-3), "{spheres:?}: {free:?}");
        for mu in [0.0, 0.2, 1.8] {
            for kick in [0.0, 0.3, -0.3] {
                let o = simulate(&config(spheres, mu, kick, true));
                let case = format!("{spheres:?} μ = {mu} kick {kick}");
                assert!(o.steered, "{case}: no plan");
                assert!(o.rms <= 1e-4, "{case}: RMS {:.2e} m", o.rms);
                // The filter's clearance (0.02 m) holds from the start on.
                assert!(o.min_clearance >= 0.0199, "{case}: {}", o.min_clearance);
            }
        }
    }
}

fn plan(spheres: &[[f64; 4]]) -> PlanOutcome {
    let c = config(spheres, 1.0, 0.0, true);
    let q0 = c.sim.start().to_vec();
    let sys = SpatialSystem {
        config: c,
        chain: chain(),
    };
    plan_system(&sys, 0.0, Some(&q0)).unwrap().outcome
}

fn found(o: PlanOutcome) -> Cycle {
    match o {
        PlanOutcome::Found(c) => c,
        PlanOutcome::Blocked(b) => panic!("blocked: {}", b.reason),
    }
}

#[test]
fn a_planned_cycle_keeps_the_clearance_and_its_spline_closes() {
    let c = found(plan(LAYOUTS[0]));
    assert_eq!(c.q.len(), 64);
    assert!(c.min_clearance >= 0.02, "{}", c.min_clearance);
    let s = SpatialSteer::of(&c, 1.0).unwrap();
    // The spline closes: the same posture one period on.
    let (a, b) = (s.cycle.sample(0.3), s.cycle.sample(0.3 + c.period));
    assert!(
        (0..7).all(|i| (a.q[i] - b.q[i]).abs() < 1e-9),
        "{a:?} {b:?}"
    );
}

#[test]
fn a_path_through_a_sphere_is_blocked_at_once_with_the_obstacle_named() {
    // A sphere on the hand's start point, on the circle.
    let o = plan(&[[0.307, 0.0, 0.487, 0.05]]);
    let PlanOutcome::Blocked(b) = o else {
        panic!("a cycle through a sphere");
    };
    assert!(
        b.reason.contains("path runs through obstacle 1"),
        "{}",
        b.reason
    );
    assert_eq!((b.obstacle, b.link), (Some(0), Some(6)));
    assert!(b.best_clearance < 0.0);
}

#[test]
fn without_spheres_a_slow_cycle_is_found() {
    let c = found(plan(&[]));
    assert!(c.min_clearance.is_infinite());
    // Every joint well inside the Panda's slowest rate limit (2.175 rad/s).
    assert!(c.max_rate > 0.0 && c.max_rate < 2.175, "{}", c.max_rate);
}

#[test]
fn a_robot_config_given_to_the_planar_planner_is_refused_not_a_panic() {
    let panda = Config::robot_preset("panda").unwrap();
    let e = control::plan::planar::PlanarProblem::from_config(&panda, 0.0, None).unwrap_err();
    assert!(e.to_string().contains("planar planner"), "{e}");
    let e = control::plan::plan_config(&panda, 0.0, None).unwrap_err();
    assert!(e.to_string().contains("spatial robot"), "{e}");
}
