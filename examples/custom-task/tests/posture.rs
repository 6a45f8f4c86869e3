//! The posture task does what it says, through the real law: on the Panda's circle it keeps
//! the arm nearer its ready posture than the preset's centring task does, and the hand tracks as
//! well; and a config naming a task nobody registered is refused by name.

use control::sim::run;
use control::Config;

const CONFIG: &str = include_str!("../panda-posture.toml");

/// Registered once per test binary (the registry is frozen at its first registration).
fn register() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        control::secondary::custom::register(&[(custom_task::NAME, &custom_task::PANDA_READY)])
            .unwrap()
    });
}

/// Mean distance from the ready posture over the last 10 s of 40, and the RMS tracking error.
fn run_with(secondary: &str) -> (f64, f64) {
    let mut cfg = Config::from_robot_toml(CONFIG).unwrap();
    cfg.law.secondary = secondary.into();
    let chain = rt::robot::load("panda", None, None).unwrap();
    let s = cfg.setup::<7>(&chain).unwrap();
    let mut sim = s.simulation();
    let ready = nalgebra::SVector::<f64, 7>::from_column_slice(custom_task::PANDA_READY.q_ref);
    let (mut sum, mut n) = (0.0, 0u32);
    let summary = run(&mut sim, 40.0, 5.0, |t, x, _| {
        if t >= 30.0 {
            sum += (x.q - ready).norm();
            n += 1;
        }
    });
    assert!(
        summary.finite && summary.nonfinite_steps == 0,
        "{summary:?}"
    );
    (sum / f64::from(n), summary.rms_tracking_error)
}

#[test]
fn the_posture_task_keeps_the_arm_nearer_its_ready_posture_and_tracks_as_well() {
    register();
    let (posture, track) = run_with(custom_task::NAME);
    let (centring, track_centring) = run_with("centring");
    eprintln!("‖q − q_ready‖ {posture:.4} rad (posture) vs {centring:.4} (centring); tracking {track:.2e} vs {track_centring:.2e} m");
    assert!(
        posture < 0.5 * centring,
        "‖q − q_ready‖: {posture:.3} rad with the posture task, {centring:.3} with centring"
    );
    assert!(track < 1e-4, "tracking {track:.2e} m");
    assert!(track_centring < 1e-4, "tracking {track_centring:.2e} m");
}

#[test]
fn a_config_naming_an_unregistered_task_is_refused_with_the_names_it_could_take() {
    register();
    let mut cfg = Config::from_robot_toml(CONFIG).unwrap();
    cfg.law.secondary = "elbow-up".into();
    let chain = rt::robot::load("panda", None, None).unwrap();
    let Err(e) = cfg.setup::<7>(&chain) else {
        panic!("a task nobody registered was accepted")
    };
    let e = e.to_string();
    assert!(e.contains("elbow-up") && e.contains("ready-posture"), "{e}");
}

#[test]
fn a_task_cannot_take_a_built_in_name_or_register_twice() {
    use control::secondary::custom::register as reg;
    use control::secondary::custom::RegisterError;
    register();
    assert_eq!(
        reg(&[("again", &custom_task::PANDA_READY)]),
        Err(RegisterError::AlreadyRegistered)
    );
    // Names are checked before the registry is touched.
    assert!(matches!(
        reg(&[("centring", &custom_task::PANDA_READY)]),
        Err(RegisterError::BadName(_))
    ));
}
