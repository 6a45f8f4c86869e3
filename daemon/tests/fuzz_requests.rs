//! Property tests for control requests: any argument text gives a new valid configuration or a
//! one-line refusal under 1 kB, never a panic, on the planar arm and on the Panda alike; an
//! accepted change always passes the loop's stability check.

use control::Config;
use daemon::requests::{apply_obstacle_add, apply_obstacle_remove, apply_set, recording_path};
use proptest::prelude::*;

const KEYS: &[&str] = &[
    "mu",
    "tau",
    "t_on",
    "feedback",
    "projection",
    "kp",
    "kv",
    "alpha",
    "secondary",
    "w1",
    "task.center",
    "task.radius",
    "task.period",
    "safety",
    "safety.clearance",
    "safety.qd_max",
    "safety.qdd_max",
    "safety.q_min",
    "safety.q_max",
    "safety.k0",
    "safety.k1",
    "safety.push_out_speed",
    "safety.k_rate",
    "safety.guard_time",
    "safety.velocity_scale",
    "obstacle_weight",
    "null_damping",
    "metric",
    "max_tau",
    "bogus",
];

fn token() -> impl Strategy<Value = String> {
    prop_oneof![
        prop::sample::select(KEYS).prop_map(str::to_string),
        (-1e4f64..1e4).prop_map(|x| format!("{x}")),
        (0.0f64..2.0).prop_map(|x| format!("{x}")),
        prop::sample::select(
            &[
                "on",
                "off",
                "inf",
                "-inf",
                "nan",
                "1e999",
                "null-space",
                "none"
            ][..]
        )
        .prop_map(str::to_string),
        "\\PC{0,12}",
    ]
}

/// The planar demo and the Panda, loaded once.
fn arms() -> &'static [control::System] {
    static ARMS: std::sync::OnceLock<Vec<control::System>> = std::sync::OnceLock::new();
    ARMS.get_or_init(|| {
        vec![
            control::System::Planar(Config::preset("demo").unwrap()),
            rt::robot::preset("panda").unwrap(),
        ]
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    #[test]
    fn set_accepts_only_what_validation_and_the_loop_accept(tokens in prop::collection::vec(token(), 0..8)) {
        let args = tokens.join(" ");
        for system in arms() {
            match apply_set(system, &args, 1e-3) {
                Ok(c) => {
                    prop_assert!(c.validate().is_ok(), "{args}");
                    prop_assert!(c.check_step(1e-3, "1 kHz").is_ok(), "{args}");
                }
                Err(e) => prop_assert!(e.len() < 1024 && !e.contains('\n'), "{args}: {e}"),
            }
        }
    }

    #[test]
    fn obstacle_and_recording_arguments_never_panic(text in "\\PC{0,60}") {
        for system in arms() {
            if let Err(e) = apply_obstacle_add(system, &text, 1e-3) {
                prop_assert!(e.len() < 1024);
            }
            if let Err(e) = apply_obstacle_remove(system, &text, 1e-3) {
                prop_assert!(e.len() < 1024);
            }
        }
        let _ = recording_path(std::path::Path::new("/nonexistent-chaosd-out"), &text);
    }
}
