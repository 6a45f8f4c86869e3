//! `chaosctl robot` end to end through the built binary: `eval --json` reproduces pinocchio's
//! golden numbers for the built-in Panda and for a maker's URDF given by path, with exactly the
//! documented keys; every bad input is one line on stderr and exit code 2.

use serde_json::Value;
use std::process::{Command, Output};

fn chaosctl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_chaosctl"))
        .args(args)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .output()
        .expect("run chaosctl")
}

fn list(v: &Value) -> String {
    let nums: Vec<String> = v
        .as_array()
        .unwrap()
        .iter()
        .map(|x| format!("{:?}", x.as_f64().unwrap()))
        .collect();
    nums.join(",")
}

/// Runs `robot eval` on every case of a golden fixture and compares every key.
fn matches_fixture(name: &str, robot: &str) {
    let path = format!(
        "{}/../control/tests/fixtures/pinocchio/{name}.json",
        env!("CARGO_MANIFEST_DIR")
    );
    let fixture: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let (base, tip) = (
        fixture["base"].as_str().unwrap(),
        fixture["tip"].as_str().unwrap(),
    );
    for case in fixture["cases"].as_array().unwrap().iter().take(4) {
        let (q, qd, qdd, tau) = (
            list(&case["q"]),
            list(&case["qd"]),
            list(&case["qdd"]),
            list(&case["tau"]),
        );
        let args = [
            "robot", "eval", robot, "--base", base, "--tip", tip, "--q", &q, "--qd", &qd, "--qdd",
            &qdd, "--tau", &tau, "--json",
        ];
        let out = chaosctl(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let got: Value = serde_json::from_slice(&out.stdout).unwrap();
        let keys: Vec<&String> = got.as_object().unwrap().keys().collect();
        let mut expected = vec![
            "aba",
            "gravity",
            "jacobian",
            "jdot_qd",
            "mass_matrix",
            "rnea",
            "tip_pose",
        ];
        expected.sort();
        let mut keys: Vec<&str> = keys.iter().map(|k| k.as_str()).collect();
        keys.sort();
        assert_eq!(keys, expected);
        for k in expected {
            let (a, b) = (got[k].as_array().unwrap(), case[k].as_array().unwrap());
            assert_eq!(a.len(), b.len(), "{name} {k}");
            for (x, y) in a.iter().zip(b) {
                let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
                assert!(
                    (x - y).abs() <= 1e-9 * y.abs().max(1.0),
                    "{name} {k}: {x} vs pinocchio {y}"
                );
            }
        }
    }
}

#[test]
fn eval_json_matches_pinocchio_on_the_builtin_panda() {
    matches_fixture("panda", "panda");
}

#[test]
fn eval_json_matches_pinocchio_on_a_makers_urdf_by_path() {
    matches_fixture("ur5", "control/tests/fixtures/urdf/ur5.urdf");
}

#[test]
fn show_lists_joints_limits_and_masses() {
    let out = chaosctl(&["robot", "show", "panda"]);
    assert!(out.status.success());
    let s = String::from_utf8_lossy(&out.stdout);
    for needle in [
        "panda_joint1",
        "panda_joint7",
        "2.8973",
        "2.1750",
        "87.0000",
        "total mass 16.062 kg",
        "reach",
    ] {
        assert!(s.contains(needle), "{needle:?} missing from:\n{s}");
    }
}

fn refused(args: &[&str], needles: &[&str]) {
    let out = chaosctl(args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "{args:?}: one line, got {err}"
    );
    for n in needles {
        assert!(err.contains(n), "{args:?}: {n:?} missing from: {err}");
    }
}

#[test]
fn bad_inputs_are_one_clear_line() {
    refused(
        &["robot", "show", "ur10"],
        &["no built-in robot named \"ur10\"", "panda, planar3"],
    );
    refused(
        &["robot", "show", "/no/such/arm.urdf"],
        &["cannot read", "/no/such/arm.urdf"],
    );
    refused(
        &["robot", "show", "control/tests/fixtures/urdf/ur5.urdf"],
        &["3 leaf links", "\"tool0\" (6)", "\"base\" (0)", "--tip"],
    );
    refused(
        &["robot", "show", "panda", "--tip", "panda_hand"],
        &["no link named \"panda_hand\""],
    );
    refused(
        &["robot", "show", "panda", "--tip", "panda_link9"],
        &["did you mean \"panda_link0\" or \"panda_link1\""],
    );
    refused(
        &["robot", "eval", "panda", "--q", "0,0,0"],
        &["--q has 3 entries", "expected 7 (one per joint)"],
    );
    refused(
        &["robot", "eval", "panda", "--qd", "0,0,0,NaN,0,0,0"],
        &["--qd", "\"NaN\"", "finite"],
    );
    refused(
        &["robot", "eval", "panda", "--tau", "1,2,x,4,5,6,7"],
        &["--tau", "\"x\""],
    );
    refused(
        &["robot", "eval", "planar3", "--gravity", "0,0"],
        &["--gravity has 2 entries"],
    );
    refused(&["robot", "show", "Cargo.toml"], &["not XML"]);
}

#[test]
fn show_warns_of_a_body_nearly_without_inertia() {
    let dir = std::env::temp_dir().join(format!("chaosctl-robot-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("feather.urdf");
    let link = |name: &str, m: &str, i: &str| {
        format!(
            r#"<link name="{name}"><inertial><mass value="{m}"/><inertia ixx="{i}" ixy="0" ixz="0" iyy="{i}" iyz="0" izz="{i}"/></inertial></link>"#
        )
    };
    let joint = |name: &str, parent: &str, child: &str| {
        format!(
            r#"<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/><origin xyz="0.5 0 0"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="1" effort="10"/></joint>"#
        )
    };
    let text = format!(
        r#"<robot name="feather"><link name="a"/>{}{}{}{}</robot>"#,
        link("b", "1", "0.1"),
        link("c", "1e-30", "1e-35"),
        joint("j1", "a", "b"),
        joint("j2", "b", "c")
    );
    std::fs::write(&path, text).unwrap();
    let o = chaosctl(&["robot", "show", path.to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{out}");
    assert!(
        out.contains("warning: the mass matrix at q = 0 has condition number"),
        "{out}"
    );
    let panda = chaosctl(&["robot", "show", "panda"]);
    assert!(!String::from_utf8_lossy(&panda.stdout).contains("warning"));
    let _ = std::fs::remove_dir_all(&dir);
}
