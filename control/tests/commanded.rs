//! The Panda on the circle through every command interface, against the dynamic arm, offline
//! (`control::commanded`: the daemon's law and generator and the plant's device in one
//! loop, at 1 kHz with 4 substeps). The live processes run the same pieces.

use control::command::{CommandMode, LimitKind};
use control::commanded::run;
use control::commanded::CommandedRun;
use control::rigid_body::RigidBodyConfig;
use control::System;

fn panda(mode: CommandMode) -> System {
    let resolve: control::system::Resolve = &control::system::builtin_robot;
    let mut s = System::preset("panda", resolve).unwrap();
    if let System::Spatial(sp) = &mut s {
        sp.own_mut().command.mode = mode;
    }
    // The demo's schedule: μ = 1 from t = 20 s.
    s.schedule_feedback(control::adapt::MuSetting::Fixed(1.0), 20.0);
    s
}

fn go(system: &System, plant: &RigidBodyConfig, duration: f64) -> CommandedRun {
    let r = run::<7>(system, plant, 1e-3, 4, duration, 10.0).unwrap();
    eprintln!("{r:?}");
    r
}

#[test]
fn every_mode_tracks_and_the_feedback_still_makes_the_motion_periodic() {
    let mut rms = Vec::new();
    for mode in CommandMode::ALL {
        let r = go(&panda(mode), &RigidBodyConfig::default(), 60.0);
        rms.push((mode, r.tracking_rms));
        // The servo of position mode lags its reference: a millimetre, not microns. Velocity
        // mode's PI pull takes most of that lag back (it drifted to 2–3 mm without a pull,
        // 0.34 mm with a P pull alone).
        let bound = match mode {
            CommandMode::Position => 2e-3,
            CommandMode::Velocity => 1e-4,
            CommandMode::Acceleration | CommandMode::Torque => 1e-4,
        };
        assert!(
            r.tracking_rms <= bound,
            "{mode}: tracking RMS {:.2e} m",
            r.tracking_rms
        );
        assert!(
            r.residual_after * 10.0 <= r.residual_before,
            "{mode}: residual {:.3} -> {:.3}",
            r.residual_before,
            r.residual_after
        );
        assert!(
            r.peak_speed_fraction < 1.0,
            "{mode}: {}",
            r.peak_speed_fraction
        );
        assert_eq!(r.plant_torque_saturations, 0, "{mode}");
        assert_eq!(r.saturations[LimitKind::Position as usize], 0, "{mode}");
    }
    let of = |m| rms.iter().find(|(x, _)| *x == m).unwrap().1;
    assert!(
        of(CommandMode::Velocity) < of(CommandMode::Position),
        "{rms:?}"
    );
}

#[test]
fn torque_mode_with_an_unmodelled_kilogram_at_the_tip_stays_within_2_mm() {
    let plant = RigidBodyConfig {
        payload: 1.0,
        ..Default::default()
    };
    let r = go(&panda(CommandMode::Torque), &plant, 40.0);
    assert!(
        r.tracking_rms <= 2e-3,
        "tracking RMS {:.2e} m",
        r.tracking_rms
    );
    // The exact model does better by an order of magnitude: the payload is what costs.
    let exact = go(
        &panda(CommandMode::Torque),
        &RigidBodyConfig::default(),
        40.0,
    );
    assert!(exact.tracking_rms * 10.0 < r.tracking_rms);
}

#[test]
fn a_mode_the_arm_cannot_run_is_refused_by_name() {
    let mut s = panda(CommandMode::Torque);
    if let System::Spatial(sp) = &mut s {
        sp.own_mut().command.kp = Some(vec![1e6; 7]);
    }
    let e = run::<7>(&s, &RigidBodyConfig::default(), 1e-3, 4, 1.0, 0.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("command.kp") && e.contains("unstable"), "{e}");
    let mut s = panda(CommandMode::Position);
    if let System::Spatial(sp) = &mut s {
        sp.own_mut().command.limits.velocity = Some(vec![3.0; 7]);
    }
    let e = run::<7>(&s, &RigidBodyConfig::default(), 1e-3, 4, 1.0, 0.0)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("command.limits.velocity") && e.contains("never loosen"),
        "{e}"
    );
}

#[test]
fn the_summaries_judge_the_plants_own_motion() {
    // Torque mode on a plant 20 % heavier than the model: the summaries are of the measured
    // arm, so its tracking error is the run's own, and a shorter end is a shorter run's.
    let plant = RigidBodyConfig {
        mass_scale: 1.2,
        ..Default::default()
    };
    let system = panda(CommandMode::Torque);
    let (r, at) =
        control::commanded::run_at::<7>(&system, &plant, 1e-3, 4, 12.0, 10.0, &[11.0, 12.0])
            .unwrap();
    let whole = &at[1];
    assert_eq!(whole.duration, 12.0);
    assert!(whole.finite && at[0].finite);
    assert_eq!(whole.max_tracking_error, r.tracking_max);
    assert!((whole.rms_tracking_error - r.tracking_rms).abs() <= 1e-15 * r.tracking_rms);
    // The mismatch shows: not the model's microns.
    assert!(whole.max_tracking_error > 1e-6, "{whole:?}");
    assert!(at[0].max_tracking_error <= whole.max_tracking_error);
    assert!(whole.min_joint_margin.is_some_and(|m| m > 0.0));
    assert!(whole.max_speed_ratio > 0.0 && whole.max_speed_ratio < 1.0);
    assert!(whole.max_accel_ratio > 0.0);
    // An end past the run is refused, not summarised short.
    let e =
        control::commanded::run_at::<7>(&system, &plant, 1e-3, 4, 1.0, 0.0, &[2.0]).unwrap_err();
    assert!(e.to_string().contains("summary's end"), "{e}");
}
