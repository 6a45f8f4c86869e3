//! The spatial law's pieces against finite differences, and the closed loop on the Panda.

use control::arm::spatial::*;
use control::law::spatial::*;
use control::model::{builtin, Chain};
use control::resolve::Projection;
use control::resolve::{damped_pinv_m, min_eigenvalue};
use control::safety::rows::segment_row;
use control::safety::rows::BarrierGains;
use control::safety::SafetyParams;
use control::secondary::spatial::centring;
use control::secondary::spatial::manipulability;
use control::secondary::spatial::potential;
use control::secondary::spatial::*;
use control::sim::run;
use control::sim::Simulation;
use control::task::pose::*;
use control::task::{Path, Shape, Vec3};
use nalgebra::{Rotation3, SMatrix, SVector};

type V7 = SVector<f64, 7>;

fn panda(tool: Vec3) -> SpatialArm<7> {
    let chain = Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap();
    let mut arm = SpatialArm::new(chain.model::<7>().unwrap());
    arm.tool = tool;
    arm.radii = [0.06, 0.06, 0.06, 0.06, 0.05, 0.05, 0.04];
    arm
}

/// The same arm with capsules of their own: each link's ends off its joint line, in its body's
/// frame (`robot.capsules`), so a point's motion on its body is checked off the axes too.
fn panda_own_capsules(tool: Vec3) -> SpatialArm<7> {
    let mut arm = panda(tool);
    arm.ends = Some(std::array::from_fn(|j| {
        let s = j as f64;
        [
            Vec3::new(0.03, -0.02 * s, -0.05),
            Vec3::new(-0.04, 0.05, 0.08 + 0.01 * s),
        ]
    }));
    arm
}

/// The capsules' end points at `q`, `qd`.
fn capsule_points(arm: &SpatialArm<7>, q: &V7, qd: &V7) -> CapsulePoints<7> {
    let k = kin(arm, q, qd);
    let mut store = CapsulePoints::<7>::default();
    arm.capsule_points(&k, qd, &mut store);
    store
}

fn view(points: &CapsulePoints<7>) -> control::arm::point::Links<'_, 7, 3> {
    match points {
        CapsulePoints::Chain(p) => control::arm::point::Links::chain(p),
        CapsulePoints::Pairs(a, b) => control::arm::point::Links::pairs(a, b),
    }
}

fn state(seed: u64) -> (V7, V7) {
    let mut x = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut r = || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    (V7::from_fn(|_, _| 1.5 * r()), V7::from_fn(|_, _| r()))
}

fn kin(arm: &SpatialArm<7>, q: &V7, qd: &V7) -> SpatialKinematics<7> {
    let mut k = SpatialKinematics::default();
    arm.kinematics(q, qd, &mut k);
    k
}

#[test]
fn tool_jacobian_and_drift_match_finite_differences() {
    let arm = panda(Vec3::new(0.05, -0.02, 0.1));
    let h = 1e-6;
    for seed in 0..5 {
        let (q, qd) = state(seed);
        let k = kin(&arm, &q, &qd);
        let (a, b) = (kin(&arm, &(q - qd * h), &qd), kin(&arm, &(q + qd * h), &qd));
        let v = (b.p - a.p) / (2.0 * h);
        assert!((v - k.jac.fixed_rows::<3>(0) * qd).norm() < 1e-8);
        // J̇q̇ = d/dt (J q̇) at fixed q̇.
        let jd = (b.jac * qd - a.jac * qd) / (2.0 * h);
        assert!(
            (jd - k.jdot_qd).norm() < 1e-6,
            "{}",
            (jd - k.jdot_qd).norm()
        );
    }
}

fn fd_gradient(f: impl Fn(&V7) -> f64, q: &V7) -> V7 {
    let h = 1e-6;
    V7::from_fn(|i, _| {
        let mut e = V7::zeros();
        e[i] = h;
        (f(&(q + e)) - f(&(q - e))) / (2.0 * h)
    })
}

#[test]
fn manipulability_gradient_matches_finite_differences_for_3_and_6_rows() {
    let arm = panda(Vec3::new(0.04, 0.0, 0.1));
    for seed in 0..6 {
        let (q, _) = state(seed);
        let k = kin(&arm, &q, &V7::zeros());
        let j3: SMatrix<f64, 3, 7> = k.jac.fixed_rows::<3>(0).into_owned();
        let (w, g) = manipulability(&arm, &k, &j3);
        let f = |q: &V7| {
            let k = kin(&arm, q, &V7::zeros());
            manipulability(&arm, &k, &k.jac.fixed_rows::<3>(0).into_owned()).0
        };
        assert!((w - f(&q)).abs() < 1e-15);
        let fd = fd_gradient(f, &q);
        assert!((g - fd).norm() < 1e-6 * (1.0 + fd.norm()), "{g} {fd}");
        let (_, g6) = manipulability(&arm, &k, &k.jac);
        let f6 = |q: &V7| {
            let k = kin(&arm, q, &V7::zeros());
            manipulability(&arm, &k, &k.jac).0
        };
        let fd6 = fd_gradient(f6, &q);
        assert!((g6 - fd6).norm() < 1e-6 * (1.0 + fd6.norm()), "{g6} {fd6}");
    }
}

#[test]
fn centring_and_potential_gradients_match_finite_differences() {
    for arm in [
        panda(Vec3::new(0.0, 0.0, 0.1)),
        panda_own_capsules(Vec3::new(0.0, 0.0, 0.1)),
    ] {
        potential_gradient_matches(&arm);
    }
}

fn potential_gradient_matches(arm: &SpatialArm<7>) {
    let (lo, hi) = (
        [-2.9, -1.8, -2.9, -3.1, -2.9, 0.0, -2.9],
        [2.9, 1.8, 2.9, -0.1, 2.9, 3.8, 2.9],
    );
    let points_at = |q: &V7| capsule_points(arm, q, &V7::zeros());
    for seed in 0..6 {
        let (q, _) = state(seed);
        let (_, g) = centring(&q, &lo, &hi);
        let fd = fd_gradient(|q| centring(q, &lo, &hi).0, &q);
        assert!((g - fd).norm() < 1e-7);
        // A sphere near the elbow, so some capsules are inside its zone.
        let p = points_at(&q);
        let mut spheres = SphereSet::default();
        spheres
            .push(Sphere {
                center: view(&p).link(3).0.pos + Vec3::new(0.05, 0.03, -0.02),
                radius: 0.05,
                margin: 0.1,
            })
            .unwrap();
        let (h, g) = potential(arm, &view(&p), &spheres, 2.0);
        assert!(h > 0.0);
        let fd = fd_gradient(
            |q| potential(arm, &view(&points_at(q)), &spheres, 2.0).0,
            &q,
        );
        assert!((g - fd).norm() < 1e-6 * (1.0 + fd.norm()), "{g} {fd}");
    }
}

#[test]
fn capsule_rows_give_the_barrier_second_derivative() {
    for arm in [
        panda(Vec3::new(0.0, 0.0, 0.1)),
        panda_own_capsules(Vec3::new(0.0, 0.0, 0.1)),
    ] {
        assert_eq!(capsule_rows_match(&arm), 48);
    }
}

/// Rows of three links against a ball off their middles and ends, against finite differences of
/// the barrier along a motion; how many were checked.
fn capsule_rows_match(arm: &SpatialArm<7>) -> usize {
    let g = BarrierGains {
        k0: 100.0,
        k1: 20.0,
        push_out_speed: 0.1,
    };
    let h_of = |q: &V7, qd: &V7, j: usize, c: Vec3| {
        let p = capsule_points(arm, q, qd);
        let (a, b) = view(&p).link(j);
        segment_row(a, b, c, 0.1, g).unwrap()
    };
    let mut checked = 0;
    for seed in 0..8 {
        let (q, qd) = state(seed);
        let qdd = V7::from_fn(|i, _| 0.3 * (i as f64 - 3.0));
        let k = kin(arm, &q, &qd);
        for j in [1usize, 3, 5] {
            let [a, b] = arm.capsule_segments(&k)[j];
            // Off the middle of the link (interior piece) and off its far end (point piece).
            for c in [
                (a + b) * 0.5 + Vec3::new(0.2, -0.1, 0.15),
                b + (b - a) * 0.5 + Vec3::new(0.05, 0.05, 0.0),
            ] {
                let (h0, row, rhs) = h_of(&q, &qd, j, c);
                let dt = 1e-5;
                let at = |s: f64| {
                    let q = q + qd * s + qdd * (0.5 * s * s);
                    let qd = qd + qdd * s;
                    h_of(&q, &qd, j, c).0
                };
                let hdot = (at(dt) - at(-dt)) / (2.0 * dt);
                let hddot = (at(dt) - 2.0 * h0 + at(-dt)) / (dt * dt);
                let drift = g.rhs(h0, hdot) - rhs;
                let predicted = row.dot(&qdd) + drift;
                assert!(
                    (predicted - hddot).abs() < 1e-3 * (1.0 + hddot.abs()),
                    "link {j}: {predicted} vs {hddot}"
                );
                checked += 1;
            }
        }
    }
    checked
}

#[test]
fn jacobi_eigenvalue_and_pseudo_inverse() {
    let m = SMatrix::<f64, 3, 3>::new(4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 1.0);
    let e = m.symmetric_eigenvalues().min();
    assert!((min_eigenvalue(m) - e).abs() < 1e-12);
    // A rank-deficient task: damped, finite, and flagged by λ > 0.
    let mut j = SMatrix::<f64, 6, 7>::zeros();
    j[(0, 0)] = 1.0;
    let (p, smin, lambda) = damped_pinv_m(&j, 0.05, 0.05);
    assert!(smin < 1e-12 && lambda > 0.0 && p.iter().all(|v| v.is_finite()));
}

fn panda_params(arm: &SpatialArm<7>, kind: TaskKind) -> (SpatialParams, V7) {
    let q0 = V7::from_row_slice(&[0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]);
    let k = kin(arm, &q0, &V7::zeros());
    let path = Path::new(Shape::Circle, k.p - Vec3::z() * 0.15, Vec3::x(), 0.15, 2.0).unwrap();
    let mut safety = SafetyParams::off();
    safety.q_min[..7].copy_from_slice(&[
        -2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973,
    ]);
    safety.q_max[..7].copy_from_slice(&[2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973]);
    let p = SpatialParams {
        core: control::law::LawCore {
            kp: 40.0,
            kv: 15.0,
            alpha: 20.0,
            secondary: control::Secondary::Centring,
            damping_threshold: 0.05,
            damping_max: 0.05,
            mu: 3.0,
            tau: 2.0,
            t_on: 0.0,
            feedback: true,
            projection: Projection::NullSpace,
            auto_mu: None,
            safety,
            track_loss: 0.05,
            pause: false,
        },
        task: SpatialTask {
            kind,
            path,
            orientation: Rotation3::from_matrix_unchecked(k.rot),
        },
        spheres: SphereSet::default(),
        weight: 2.0,
        null_damping: 0.0,
        null_speed: 0.0,
        joint_weights: None,
        steer: None,
    };
    (p, q0)
}

#[test]
fn the_panda_tracks_its_circle_in_position_and_pose() {
    let arm = panda(Vec3::new(0.0, 0.0, 0.1034));
    for kind in [TaskKind::Position, TaskKind::Pose] {
        let (p, q0) = panda_params(&arm, kind);
        let mut qd0 = V7::zeros();
        qd0[0] = 0.1;
        let mut sim = Simulation::spatial(arm, p, 0.001, q0, qd0, 2.0);
        let s = run(&mut sim, 20.0, 5.0, |_, _, _| {});
        assert!(s.finite && s.max_tracking_error < 1e-6, "{kind:?}: {s:?}");
        assert!(s.max_orientation_error < 1e-6, "{kind:?}: {s:?}");
    }
}

#[test]
fn centring_with_projected_feedback_makes_the_self_motion_periodic() {
    // The study's finding (docs/panda-study.md): each alone fails, together they converge.
    let arm = panda(Vec3::new(0.0, 0.0, 0.1034));
    let mut qd0 = V7::zeros();
    (qd0[0], qd0[2]) = (0.1, -0.1);
    let summary = |alpha: f64, mu: f64| {
        let (mut p, q0) = panda_params(&arm, TaskKind::Position);
        (p.core.alpha, p.core.mu) = (alpha, mu);
        let mut sim = Simulation::spatial(arm, p, 0.001, q0, qd0, 2.0);
        run(&mut sim, 150.0, 5.0, |_, _, _| {})
    };
    let both = summary(20.0, 3.0);
    assert!(both.period_residual_final.unwrap() < 1e-2, "{both:?}");
    assert!(both.min_joint_margin.unwrap() > 0.3, "{both:?}");
    let pyragas_only = summary(0.0, 3.0);
    assert!(
        pyragas_only.period_residual_final.unwrap() > 0.1,
        "{pyragas_only:?}"
    );
    let centring_only = summary(20.0, 0.0);
    assert!(centring_only.max_joint_speed > 5.0, "{centring_only:?}");
}

#[test]
fn the_panda_preset_is_periodic_fast_inside_every_limit() {
    // docs/panda-study.md, "A set-up that is fast and robust": centring α = 160 with null-space
    // damping k_d = 8 decays at about −0.75 /s on its cycle (μ = 0.25), where the paper's recipe
    // (`panda-paper`, undamped) decays at −0.05 /s at best. From the preset's start, 40 s (20
    // periods) take the residual below 1e-6 (`panda-paper` is at about 1 rad/s then), with the
    // jerk and every joint's position, speed and acceleration inside the Panda's limits, filter
    // off.
    use control::Config;
    let chain = Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap();
    let summary = |name: &str| {
        let mut cfg = Config::robot_preset(name).unwrap();
        cfg.safety.enabled = false;
        cfg.feedback.t_on = 0.0;
        let s = cfg.setup::<7>(&chain).unwrap();
        let mut sim = Simulation::spatial(s.arm, s.params, s.dt, s.q0, s.qd0, 2.0);
        run(&mut sim, 40.0, 5.0, |_, _, _| {})
    };
    let panda = summary("panda");
    assert!(panda.period_residual_final.unwrap() < 1e-6, "{panda:?}");
    assert!(panda.min_joint_margin.unwrap() > 0.1, "{panda:?}");
    assert!(panda.max_speed_ratio < 1.0, "{panda:?}");
    assert!(panda.max_accel_ratio < 1.0, "{panda:?}");
    assert!(panda.max_jerk_ratio < 1.0, "{panda:?}");
    let paper = summary("panda-paper");
    assert!(paper.period_residual_final.unwrap() > 1e-2, "{paper:?}");
}

#[test]
fn the_speed_cap_keeps_a_far_start_inside_the_acceleration_limits() {
    // Start 15 of the first box draw of scripts/panda-study/basins.sh (awk's, 2026-12-01; the
    // study now draws with `chaosctl starts`): the joints far from mid-range, where the
    // centring pull α∇c asks more than the Panda's acceleration limits on the first ticks.
    // Capped at 1 rad/s (law.null_speed, the preset's) it asks less than 60 %, and the arm still
    // becomes periodic inside every limit.
    use control::Config;
    let chain = Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap();
    let summary = |null_speed: f64| {
        let mut cfg = Config::robot_preset("panda").unwrap();
        cfg.safety.enabled = false;
        cfg.law.null_speed = null_speed;
        cfg.sim.q0 = Some(vec![
            -0.9089, 0.9704, -0.3261, -0.4154, -2.0598, 0.9374, -1.1082,
        ]);
        cfg.sim.qd0 = Some(vec![
            -0.1563, 0.0009, -0.0341, -0.1401, -0.0457, -0.0637, -0.1334,
        ]);
        let s = cfg.setup::<7>(&chain).unwrap();
        let mut sim = Simulation::spatial(s.arm, s.params, s.dt, s.q0, s.qd0, 2.0);
        run(&mut sim, 60.0, 0.0, |_, _, _| {})
    };
    let uncapped = summary(0.0);
    assert!(uncapped.max_accel_ratio > 1.3, "{uncapped:?}");
    let capped = summary(1.0);
    assert!(capped.max_accel_ratio < 0.6, "{capped:?}");
    assert!(capped.max_speed_ratio < 1.0, "{capped:?}");
    assert!(capped.min_joint_margin.unwrap() > 0.1, "{capped:?}");
    assert!(capped.period_residual_final.unwrap() < 1e-9, "{capped:?}");
    // Without damping there is no velocity to cap: the file says so.
    let mut cfg = Config::robot_preset("panda").unwrap();
    cfg.law.null_damping = 0.0;
    let e = cfg.setup::<7>(&chain).unwrap_err().to_string();
    assert!(e.contains("law.null_speed"), "{e}");
}

#[test]
fn the_panda_preset_builds_and_bad_keys_are_named() {
    use control::Config;
    let chain = Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap();
    let cfg = Config::robot_preset("panda").unwrap();
    let s = cfg.setup::<7>(&chain).unwrap();
    // Limits from the URDF and Franka's acceleration table.
    assert_eq!(s.params.core.safety.qd_max[4], 2.61);
    assert_eq!(s.params.core.safety.qdd_max[1], 7.5);
    assert_eq!(s.params.core.safety.q_max[3], -0.0698);
    // The tool starts on its path.
    let k = kin(&s.arm, &s.q0, &V7::zeros());
    assert!((s.params.task.path.position(0.0) - k.p).norm() < 1e-12);
    // It round-trips through TOML.
    assert_eq!(Config::from_robot_toml(&cfg.to_toml()).unwrap(), cfg);
    let bad = |edit: &dyn Fn(&mut Config), field: &str| {
        let mut c = cfg.clone();
        edit(&mut c);
        let e = c.setup::<7>(&chain).unwrap_err().to_string();
        assert!(e.contains(field), "{field}: {e}");
    };
    bad(
        &|c| c.spatial_mut().unwrap().task.kind = "orbit".into(),
        "task.kind",
    );
    bad(
        &|c| c.spatial_mut().unwrap().task.radius = f64::NAN,
        "task.radius",
    );
    bad(
        &|c| c.spatial_mut().unwrap().task.normal = [0.0; 3],
        "task.normal",
    );
    bad(
        &|c| c.sim.q0.as_mut().and_then(Vec::pop).map(drop).unwrap_or(()),
        "sim.q0",
    );
    bad(&|c| c.law.secondary = "curiosity".into(), "law.secondary");
    // A projection that is neither is refused where the file is read, as on the planar arm.
    let key = format!("projection = \"{}\"", cfg.feedback.projection);
    let text = cfg.to_toml();
    assert!(text.contains(&key), "{text}");
    let e = Config::from_robot_toml(&text.replace(&key, "projection = \"sideways\""))
        .unwrap_err()
        .to_string();
    assert!(e.contains("sideways") && e.contains("null-space"), "{e}");
    bad(&|c| c.safety.velocity_scale = 1.5, "safety.velocity_scale");
    bad(
        &|c| c.spatial_mut().unwrap().robot.link_radii = Some(vec![0.1; 3]),
        "robot.link_radii",
    );
    // Finite but no arm's: the last capsule's length overflowed to infinity.
    bad(
        &|c| c.spatial_mut().unwrap().robot.tool = [1e308, 0.0, 0.0],
        "robot.tool",
    );
    bad(
        &|c| c.spatial_mut().unwrap().robot.tool = [0.0, 0.0, 10.5],
        "at most 10 m",
    );
    // Accepted by their types, refused as runs: the planar arm's sampled-loop rules, the delay
    // line's bound and the arm's reach.
    bad(&|c| c.sim.dt = 0.5, "law.kv");
    bad(&|c| c.law.kp = 1e12, "law.kp");
    bad(
        &|c| c.spatial_mut().unwrap().task.period = 0.01,
        "task.period",
    );
    bad(&|c| c.feedback.tau = Some(1e9), "feedback.tau");
    bad(&|c| c.sim.duration = 1e12, "sim.duration");
    bad(
        &|c| c.spatial_mut().unwrap().task.radius = 5.0,
        "task.radius",
    );
    assert!(Config::from_robot_toml("[robot]\ndescription = \"panda\"\nwheels = 4\n").is_err());
    assert!(Config::robot_preset("paper").is_none());
}

#[test]
fn the_closed_form_3x3_eigenvalue_agrees_with_jacobi() {
    use control::resolve::min_eigenvalue_3;
    for seed in 0..20 {
        let (q, _) = state(seed);
        let m = SMatrix::<f64, 3, 7>::from_fn(|r, c| (q[c] * (r as f64 + 1.0)).sin());
        let a = m * m.transpose();
        assert!((min_eigenvalue_3(&a) - min_eigenvalue(a)).abs() < 1e-12 * (1.0 + a.norm()));
    }
    // Repeated and zero eigenvalues.
    assert!(min_eigenvalue_3(&SMatrix::<f64, 3, 3>::identity()) == 1.0);
    let r1 = nalgebra::Vector3::new(1.0, 2.0, 3.0);
    assert!(min_eigenvalue_3(&(r1 * r1.transpose())).abs() < 1e-12);
}
