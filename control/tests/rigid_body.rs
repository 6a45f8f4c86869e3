//! The dynamic plant's physics beyond pinocchio's trajectories: the servo, friction, the
//! payload, the torque limits, and the refusals of its config.

use control::config::spatial::PANDA_READY;
use control::model::{builtin, Chain};
use control::rigid_body::{mismatched, Drive, RigidBody, RigidBodyConfig};
use nalgebra::SVector;

type V7 = SVector<f64, 7>;

fn chain() -> Chain {
    Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap()
}

fn ready() -> V7 {
    V7::from_column_slice(&PANDA_READY)
}

fn build(cfg: &RigidBodyConfig) -> Result<RigidBody<7>, String> {
    cfg.build::<7>(
        &chain(),
        (ready(), V7::zeros()),
        V7::repeat(1e3),
        2.5e-4,
        "plant.rigid_body",
    )
    .map(|(arm, _)| arm)
    .map_err(|e| e.to_string())
}

#[test]
fn the_servo_holds_a_set_point_against_gravity_and_follows_a_moving_one() {
    let mut arm = build(&RigidBodyConfig::default()).unwrap();
    let target = ready() + V7::repeat(0.05);
    let drive = Drive::Track {
        q: target,
        qd: V7::zeros(),
        qdd: V7::zeros(),
    };
    for _ in 0..3000 {
        arm.advance(&drive, 0.0, 1e-3, 4);
    }
    assert!(
        (arm.state.q - target).amax() < 1e-6,
        "{}",
        arm.state.q - target
    );
    // A ramp at 0.2 rad/s: followed with the lag of a 30 Hz servo, no more.
    for k in 0..1000 {
        let t = k as f64 * 1e-3;
        let drive = Drive::Track {
            q: target + V7::repeat(0.2 * t),
            qd: V7::repeat(0.2),
            qdd: V7::zeros(),
        };
        arm.advance(&drive, 0.0, 1e-3, 4);
    }
    let err = (arm.state.q - (target + V7::repeat(0.2))).amax();
    assert!(err < 0.01, "lag {err}");
    // Hold keeps the position it was reached at.
    let here = arm.state.q;
    for _ in 0..500 {
        arm.advance(&Drive::Hold, 0.0, 1e-3, 4);
    }
    assert!((arm.state.q - here).amax() < 0.01);
}

#[test]
fn friction_takes_energy_out_and_torque_limits_clamp() {
    let cfg = RigidBodyConfig {
        viscous: Some(vec![0.5; 7]),
        coulomb: Some(vec![0.2; 7]),
        ..Default::default()
    };
    let mut arm = build(&cfg).unwrap();
    let mut m = *arm.model();
    m.gravity = nalgebra::Vector3::zeros();
    let mut arm2 = RigidBody::new(m, ready(), V7::repeat(1.0), V7::repeat(5.0)).with_friction(
        V7::repeat(0.5),
        V7::repeat(0.2),
        0.02,
    );
    let e0 = arm2.kinetic_energy();
    for _ in 0..3000 {
        arm2.advance(&Drive::Torque(V7::zeros()), 0.0, 1e-3, 4);
    }
    assert!(arm2.kinetic_energy() < 0.5 * e0);
    arm.advance(&Drive::Torque(V7::repeat(1e4)), 0.0, 1e-3, 4);
    assert!(arm.applied.iter().all(|t| *t == 1e3));
    assert!(arm.torque_saturations > 0);
}

#[test]
fn a_payload_adds_its_weight_at_the_tip() {
    let model = chain().model::<7>().unwrap();
    let heavy = mismatched(&model, 1.0, [0.0; 3], 1.0);
    let g0 = model.gravity_torques(&ready());
    let g1 = heavy.gravity_torques(&ready());
    // Joint 2 carries the payload's weight at the tip's horizontal distance from its axis.
    assert!((g1[1] - g0[1]).abs() > 1.0, "{} vs {}", g1[1], g0[1]);
    let scaled = mismatched(&model, 0.0, [0.0; 3], 2.0);
    assert!((scaled.gravity_torques(&ready()) - g0 * 2.0).amax() < 1e-9);
}

#[test]
fn bad_physics_is_refused_by_name() {
    let stiff = RigidBodyConfig {
        servo_kp: Some(vec![1e7; 7]),
        ..Default::default()
    };
    let e = build(&stiff).unwrap_err();
    assert!(
        e.contains("plant.rigid_body.servo_kp") && e.contains("unstable"),
        "{e}"
    );
    let damped = RigidBodyConfig {
        servo_bandwidth_hz: 2000.0,
        ..Default::default()
    };
    let e = build(&damped).unwrap_err();
    assert!(e.contains("plant.rigid_body.servo_bandwidth_hz"), "{e}");
    for (cfg, field) in [
        (
            RigidBodyConfig {
                payload: -1.0,
                ..Default::default()
            },
            "payload",
        ),
        (
            RigidBodyConfig {
                mass_scale: 0.0,
                ..Default::default()
            },
            "mass_scale",
        ),
        (
            RigidBodyConfig {
                viscous: Some(vec![0.1; 3]),
                ..Default::default()
            },
            "viscous",
        ),
        (
            RigidBodyConfig {
                noise_qd: f64::NAN,
                ..Default::default()
            },
            "noise_qd",
        ),
    ] {
        let e = build(&cfg).unwrap_err();
        assert!(e.contains(&format!("plant.rigid_body.{field}")), "{e}");
    }
}

#[test]
fn a_late_velocity_command_leaves_the_set_point_where_the_rate_took_it() {
    use control::command::{Command, CommandMode};
    use control::rigid_body::{Device, Sensor};
    let device = || Device::new(build(&RigidBodyConfig::default()).unwrap(), Sensor::exact());
    let mut c = Command::<7>::still(CommandMode::Velocity);
    c.qd = V7::repeat(0.3);
    // One device answered every period, the other misses the second (it runs on at the last
    // rate, as a robot's velocity interface does): the same rate over the same time is the
    // same motion, so the set-points and the arms agree.
    let (mut every, mut missed) = (device(), device());
    for k in 0..200 {
        every.command(&c, 1e-3, 0.0);
        if k != 1 {
            missed.command(&c, 1e-3, 0.0);
        }
        every.advance(1e-3, 4);
        missed.advance(1e-3, 4);
    }
    let (a, b) = (every.measure().q, missed.measure().q);
    assert!((a - b).amax() < 1e-12, "{}", a - b);
}

#[test]
fn a_brake_at_full_torque_is_counted_apart_from_a_command_the_arm_could_not_follow() {
    let mut m = *build(&RigidBodyConfig::default()).unwrap().model();
    m.gravity = nalgebra::Vector3::zeros();
    // Moving at 1 rad/s with 5 N·m motors: the servo's brake asks for far more.
    let mut arm = RigidBody::new(m, ready(), V7::repeat(1.0), V7::repeat(5.0)).with_servo(
        control::rigid_body::ServoGains {
            kp: V7::repeat(400.0),
            kd: V7::repeat(40.0),
        },
    );
    for _ in 0..20 {
        arm.advance(&Drive::Hold, 0.0, 1e-3, 4);
    }
    assert!(arm.brake_saturations > 0);
    assert_eq!(arm.torque_saturations, 0);
    arm.advance(&Drive::Torque(V7::repeat(1e4)), 0.0, 1e-3, 4);
    assert_eq!(arm.torque_saturations, 4);
}
