//! `[law]`, `[feedback]` and `[sim]` are one type each for every arm (issue 41): a planar file
//! and a robot's file read the same keys the same way, a key left out of a planar file means
//! what it meant in the planar form's older files, and a key of one arm's law is refused by name
//! on the other.

use control::config::{Config, SecondaryKind};
use control::system::builtin_robot;
use control::System;

fn planar(text: &str) -> Result<Config, String> {
    Config::parse(&format!("[robot]\ndescription = \"planar\"\n{text}")).map_err(|e| e.to_string())
}

/// A Panda file's head: the robot and a position task.
const PANDA: &str = r#"
[robot]
description = "panda"
[task]
kind = "position"
path = "circle"
normal = [1.0, 0.0, 0.0]
radius = 0.1
period = 2.0
"#;

fn robot(text: &str) -> Result<System, String> {
    System::parse(&format!("{PANDA}{text}"), &builtin_robot).map_err(|e| e.to_string())
}

const PANDA_START: &str = "q0 = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]";

#[test]
fn a_planar_file_that_leaves_keys_out_means_what_it_meant() {
    // The planar form's own defaults, in both of its spellings.
    for text in ["[law]\nkp = 30.0\n", "[task]\nperiod = 2.0\n"] {
        let c = planar(text).unwrap();
        assert_eq!(c.law.alpha, 1.0, "{text}");
        assert_eq!(c.law.secondary, SecondaryKind::Manipulability, "{text}");
        assert_eq!(c.law.disc_weights(), (2.0, 2.0), "{text}");
        assert_eq!(c.sim.transient, 20.0, "{text}");
        let f = &c.feedback;
        assert_eq!(
            (f.tau, f.t_on, f.max_tau),
            (Some(1.0), 5.0, Some(2.0)),
            "{text}"
        );
    }
    let older = Config::parse("[arm]\n[control]\nkp = 30.0\n[task]\nperiod = 2.0\n").unwrap();
    assert_eq!(
        (older.law.alpha, older.tau(), older.sim.transient),
        (1.0, 1.0, 20.0)
    );
    // What a file gives it keeps.
    let c = planar("[law]\nalpha = 0.5\nsecondary = \"none\"\n[feedback]\nt_on = 0.0\n").unwrap();
    assert_eq!((c.law.alpha, c.feedback.t_on), (0.5, 0.0));
    assert_eq!(c.law.secondary, SecondaryKind::None);
}

#[test]
fn a_robots_file_reads_the_same_sections_with_its_own_defaults() {
    let s = robot(&format!("[sim]\n{PANDA_START}\n")).unwrap();
    let System::Spatial(r) = &s else {
        panic!("the Panda is a robot")
    };
    let c = &r.config;
    assert_eq!((c.law.alpha, c.sim.transient, c.sim.dt), (0.0, 0.0, 1e-3));
    assert_eq!(c.law.secondary, SecondaryKind::None);
    // τ follows the task's period; the delay line is 60 s unless the file says otherwise.
    assert_eq!((s.feedback().tau, s.feedback().max_tau), (2.0, 60.0));
    let short = robot(&format!(
        "[feedback]\nmu = 0.2\nmax_tau = 3.0\n[sim]\n{PANDA_START}\n"
    ))
    .unwrap();
    assert_eq!(short.feedback().max_tau, 3.0);
    let e = robot(&format!(
        "[feedback]\nmu = 0.2\ntau = 4.0\nmax_tau = 3.0\n[sim]\n{PANDA_START}\n"
    ))
    .unwrap_err();
    assert!(
        e.contains("feedback.tau") && e.contains("max_tau = 3"),
        "{e}"
    );
}

#[test]
fn a_key_of_one_arms_law_is_refused_by_name_on_the_other() {
    for (key, line) in [
        ("law.null_damping", "null_damping = 4.0"),
        ("law.null_speed", "null_speed = 1.0"),
        ("law.metric", "metric = \"speed\""),
        ("law.obstacle_weight", "obstacle_weight = 3.0"),
    ] {
        let e = planar(&format!("[law]\n{line}\n")).unwrap_err();
        assert!(e.contains(key) && e.contains("robot's key"), "{line}: {e}");
    }
    for (key, line) in [("law.w1", "w1 = 3.0"), ("law.w2", "w2 = 3.0")] {
        let e = robot(&format!("[law]\n{line}\n[sim]\n{PANDA_START}\n")).unwrap_err();
        assert!(
            e.contains(key) && e.contains("obstacle_weight"),
            "{line}: {e}"
        );
    }
    let e = robot("[sim]\ndt = 0.001\n").unwrap_err();
    assert!(
        e.contains("sim.q0") && e.contains("start of its own"),
        "{e}"
    );
    let e = robot(&format!("[sim]\n{PANDA_START}\nphi0 = 0.3\n")).unwrap_err();
    assert!(e.contains("sim.phi0") && e.contains("floating base"), "{e}");
}

#[test]
fn each_arm_prints_only_its_own_keys_and_reads_them_back_equal() {
    let c = planar("[law]\nw1 = 3.0\n").unwrap();
    let text = c.to_toml();
    assert!(
        text.contains("w1 = 3.0") && !text.contains("null_damping"),
        "{text}"
    );
    assert_eq!(Config::parse(&text).unwrap(), c);
    let s = System::preset("panda", &builtin_robot).unwrap();
    let text = s.to_toml();
    assert!(!text.contains("w1") && !text.contains("phi0"), "{text}");
    assert_eq!(
        System::parse(&text, &builtin_robot).unwrap().to_toml(),
        text
    );
}
