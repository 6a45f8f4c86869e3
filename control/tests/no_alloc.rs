//! Proves the step paths allocate nothing: a counting global allocator, armed per thread.
//!
//! It lives in its own test binary because a `#[global_allocator]` applies to the whole binary.

use control::law::evaluate;
use control::{with_dof, Config, DelayLine, Kinematics, Simulation, VecN};
use rt::alloc_count::{allocations, Counting};

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn the_counter_sees_allocations() {
    // Guards against a counter that can never fire.
    let n = allocations(|| {
        let v: Vec<u8> = Vec::with_capacity(std::hint::black_box(64));
        std::hint::black_box(v);
    });
    assert_eq!(n, 1);
}

#[test]
fn control_step_and_rk4_step_allocate_nothing() {
    for preset in ["paper", "paper-obstacle", "paper-floating"] {
        let mut cfg = Config::preset(preset).unwrap();
        cfg.feedback.mu = 1.0;
        cfg.feedback.t_on = 0.1;
        with_dof!(cfg.n(), N => {
            let params = cfg.law_params();
            let model = cfg.model::<N>();
            let mut sim = Simulation::new(model, params, cfg.sim.dt, cfg.initial_state(), cfg.feedback.capacity());
            let mut kin = Kinematics::<N>::default();
            let mut delay = DelayLine::<N>::new(1000.0, VecN::<N>::zeros());
            let n = allocations(|| {
                for _ in 0..2000 {
                    std::hint::black_box(sim.step());
                }
                let x = *sim.state();
                for _ in 0..100 {
                    delay.push(x.qd);
                    let d = delay.sample(delay.len() as f64 - 10.5);
                    std::hint::black_box(evaluate(&params, &model, 1.0, x.phi, &x.q, &x.qd, &d, &mut kin));
                }
            });
            assert_eq!(n, 0, "{preset}: the step path allocated {n} times");
        });
    }
}

#[test]
fn the_safety_filter_allocates_nothing_on_any_path() {
    // Binding obstacles and limits on the paper arm (interval path, full-space fallback), on the
    // floating base (drift by a second kinematics pass), and on 4 and 5 links (the QP path).
    let mut arms = vec![];
    for preset in ["paper-obstacle", "paper-floating"] {
        let mut cfg = Config::preset(preset).unwrap();
        cfg.planar_mut().unwrap().obstacles = vec![
            control::config::ObstacleConfig {
                center: [0.0, 1.6],
                radius: 0.25,
                margin: 0.1,
            },
            control::config::ObstacleConfig {
                center: [0.5, 0.9],
                radius: 0.2,
                margin: 0.1,
            },
        ];
        arms.push(cfg);
    }
    for links in [
        vec![0.8, 0.8, 0.7, 0.7],
        vec![0.8, 0.7, 0.6, 0.5, 0.4],
        vec![0.6, 0.6, 0.5, 0.5, 0.4, 0.4, 0.3], // the most joints chaosd runs (MAX_JOINTS)
    ] {
        let mut cfg = arms[0].clone();
        cfg.sim.q0 = Some(vec![0.3; links.len()]);
        cfg.planar_mut().unwrap().arm.links = links;
        arms.push(cfg);
    }
    for mut cfg in arms {
        cfg.safety.enabled = true;
        cfg.safety.qd_max = Some(control::safety::config::Limit::All(6.0));
        cfg.safety.q_min = Some(vec![-1.5; cfg.n()]);
        cfg.safety.q_max = Some(vec![1.5; cfg.n()]);
        cfg.validate().unwrap();
        with_dof!(cfg.n(), N => {
            let params = cfg.law_params();
            let mut sim = Simulation::new(cfg.model::<N>(), params, cfg.sim.dt, cfg.initial_state(), cfg.feedback.capacity());
            let mut flags = 0;
            let n = allocations(|| {
                for _ in 0..3000 {
                    flags |= std::hint::black_box(sim.step()).flags;
                }
            });
            assert_eq!(n, 0, "{N} links: the filter allocated {n} times");
            assert!(flags & control::basics::flags::SAFETY_ACTIVE != 0, "{N} links: the filter never bound");
        });
    }
}

#[test]
fn the_robot_models_algorithms_allocate_nothing() {
    use control::model::{builtin, Chain, TipKinematics};
    use nalgebra::SVector;
    let model = Chain::from_urdf(builtin("panda").unwrap(), None, None)
        .unwrap()
        .model::<7>()
        .unwrap();
    let mut k = TipKinematics::default();
    let mut frames = control::model::Frames::default();
    let n = allocations(|| {
        for i in 0..200 {
            let x = i as f64 * 0.01;
            let (q, qd, qdd) = (
                SVector::from([x; 7]),
                SVector::from([0.5 - x; 7]),
                SVector::from([x * 2.0; 7]),
            );
            model.frames(&q, &mut frames);
            model.tip_kinematics(&q, &qd, &mut k);
            let tau = model.rnea(&q, &qd, &qdd);
            std::hint::black_box(model.mass_matrix(&q));
            std::hint::black_box(model.gravity_torques(&q));
            std::hint::black_box(model.aba(&q, &qd, &tau));
            std::hint::black_box(frames.link(&model, 3));
        }
    });
    assert_eq!(n, 0, "the model's algorithms allocated {n} times");
}

#[test]
fn the_panda_step_allocates_nothing_in_position_and_pose_with_obstacles() {
    use control::model::{builtin, Chain};
    use control::sim::Simulation;
    use control::Config;
    let chain = Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap();
    for kind in ["position", "pose"] {
        let mut cfg = Config::robot_preset("panda").unwrap();
        cfg.spatial_mut().unwrap().task.kind = kind.into();
        cfg.feedback.t_on = 0.5;
        // A sphere next to the elbow: the capsule points and rows are built on every step.
        cfg.spatial_mut()
            .unwrap()
            .obstacles
            .push(control::config::spatial::SphereEntry {
                center: [0.25, 0.0, 0.75],
                radius: 0.05,
                margin: 0.1,
            });
        cfg.law.secondary = "obstacles".into();
        let s = cfg.setup::<7>(&chain).unwrap();
        let mut sim = Simulation::spatial(s.arm, s.params, s.dt, s.q0, s.qd0, 2.0);
        let n = allocations(|| {
            for _ in 0..1500 {
                std::hint::black_box(sim.step());
            }
        });
        assert_eq!(n, 0, "{kind}: the spatial step allocated {n} times");
    }
}

#[test]
fn steering_along_a_detour_and_onto_the_cycle_allocates_nothing() {
    // The planner allocates (off the loop); the law that runs its detour, the blend and the
    // cycle must not. An arm off its path by the trap: a detour, then the cycle.
    let mut cfg = Config::default();
    cfg.planar_mut().unwrap().obstacles =
        vec![control::config::ObstacleConfig::disc(0.9, 1.1, 0.15)];
    cfg.safety.plan = control::safety::policy::PlanMode::On;
    cfg.sim.q0 = Some(vec![0.3, 1.2, 1.0]);
    cfg.sim.qd0 = Some(vec![0.0; 3]);
    let (params, blocked) = control::plan::law_params_planned(&cfg);
    assert!(blocked.is_none(), "{blocked:?}");
    let d = params.steer.and_then(|s| s.detour).expect("a detour");
    let mut sim = Simulation::new(
        cfg.model::<3>(),
        params,
        cfg.sim.dt,
        cfg.initial_state(),
        cfg.feedback.capacity(),
    );
    let steps = ((d.t_arrive + 2.0) / cfg.sim.dt) as usize;
    let mut detoured = 0;
    let n = allocations(|| {
        for _ in 0..steps {
            let out = std::hint::black_box(sim.step());
            detoured += usize::from(out.flags & control::basics::flags::DETOUR != 0);
        }
    });
    assert_eq!(n, 0, "the steered step allocated {n} times");
    assert!(
        detoured > 100 && detoured < steps,
        "{detoured} of {steps} steps on the detour"
    );
}
