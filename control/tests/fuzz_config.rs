//! Property tests for the config parser (cargo fuzz needs a nightly toolchain, which this project
//! does not use): any text gives a config or a short error, never a panic, and anything the
//! validation accepts runs without a non-finite command.

use control::{with_dof, Config, Simulation};
use proptest::prelude::*;
use proptest::strategy::ValueTree;

/// Keys of every table, with values that are often out of range.
const KEYS: &[&str] = &[
    "robot.links",
    "robot.model",
    "robot.base_mass",
    "task.center",
    "task.radius",
    "task.period",
    "law.kp",
    "law.kv",
    "law.alpha",
    "law.secondary",
    "law.damping_max",
    "feedback.mu",
    "feedback.tau",
    "feedback.t_on",
    "feedback.capacity()",
    "feedback.projection",
    "sim.dt",
    "sim.duration",
    "sim.q0",
    "sim.qd0",
    "safety.enabled",
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
];

fn value() -> impl Strategy<Value = String> {
    let num = prop_oneof![
        Just("0".to_string()),
        Just("-1".to_string()),
        Just("nan".to_string()),
        Just("inf".to_string()),
        Just("1e308".to_string()),
        (-1e4f64..1e4).prop_map(|x| format!("{x:?}")),
        (0.0f64..3.0).prop_map(|x| format!("{x:?}")),
    ];
    prop_oneof![
        num.clone(),
        prop::collection::vec(num, 0..8).prop_map(|v| format!("[{}]", v.join(", "))),
        "[a-z-]{0,12}".prop_map(|s| format!("{s:?}")),
        Just("true".to_string()),
        Just("{ x = 1 }".to_string()),
    ]
}

/// A file in the shared form (`[robot] description = "planar"`) or, as often, in the older one
/// (`[arm]`, `[control]`).
fn toml_doc() -> impl Strategy<Value = String> {
    let keys = prop::collection::vec((prop::sample::select(KEYS), value()), 0..10);
    (keys, any::<bool>()).prop_map(|(kv, older)| {
        let mut by_table: std::collections::BTreeMap<&str, Vec<String>> = Default::default();
        if !older {
            by_table.insert("robot", vec!["description = \"planar\"".into()]);
        }
        for (k, v) in kv {
            let (t, key) = k.split_once('.').unwrap();
            let t = match (older, t) {
                (true, "robot") => "arm",
                (true, "law") => "control",
                _ => t,
            };
            by_table.entry(t).or_default().push(format!("{key} = {v}"));
        }
        by_table
            .iter()
            .map(|(t, lines)| {
                // A repeated key is a TOML error; keep the first.
                let mut seen = std::collections::HashSet::new();
                let body: Vec<&String> = lines
                    .iter()
                    .filter(|l| seen.insert(l.split(" = ").next().unwrap().to_string()))
                    .collect();
                format!(
                    "[{t}]\n{}\n",
                    body.iter()
                        .map(|s| s.as_str())
                        .collect::<Vec<_>>()
                        .join("\n")
                )
            })
            .collect()
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1500))]

    #[test]
    fn any_text_gives_a_config_or_a_short_error(text in "\\PC{0,400}") {
        if let Err(e) = Config::parse(&text) {
            prop_assert!(e.to_string().len() < 1024, "{} bytes", e.to_string().len());
        }
    }

    #[test]
    fn whatever_validation_accepts_runs_finite(doc in toml_doc()) {
        match Config::parse(&doc) {
            Err(e) => prop_assert!(e.to_string().len() < 1024),
            Ok(mut cfg) => {
                cfg.safety.enabled = true;
                prop_assume!(cfg.validate().is_ok());
                with_dof!(cfg.n(), N => {
                    let mut sim = Simulation::new(cfg.model::<N>(), cfg.law_params(), cfg.sim.dt, cfg.initial_state(), cfg.feedback.capacity());
                    for _ in 0..200 {
                        let o = sim.step();
                        prop_assert!(o.qdd.iter().all(|v| v.is_finite()), "{doc}");
                    }
                    prop_assert!(sim.state().is_finite(), "{doc}");
                });
            }
        }
    }
}

#[test]
fn the_generator_reaches_valid_configs() {
    // Guards the property above against a generator that only ever makes refused files.
    let mut runner = proptest::test_runner::TestRunner::deterministic();
    let mut valid = 0;
    for _ in 0..500 {
        let doc = toml_doc().new_tree(&mut runner).unwrap().current();
        valid += usize::from(Config::parse(&doc).is_ok());
    }
    assert!(
        valid > 50,
        "only {valid} of 500 generated configs are valid"
    );
}
