//! The robot model against golden data from pinocchio, an independent implementation.
//!
//! `scripts/golden/pinocchio_fixtures.py` wrote the fixtures (the Panda and planar arm of
//! `robots/`, and six makers' URDFs from example-robot-data, copied unmodified into
//! `fixtures/urdf/`); this test needs no Python. Each quantity goes through
//! `Chain::evaluate`, the function `chaosctl robot eval` prints, and must agree to 1e-9,
//! relative where the value is larger than 1.

use control::model::{Chain, Frames};
use nalgebra::SVector;
use serde_json::Value;
use std::path::{Path, PathBuf};

const TOL: f64 = 1e-9;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

fn close(what: &str, ours: &[f64], theirs: &[f64], ctx: &str) -> f64 {
    assert_eq!(ours.len(), theirs.len(), "{ctx}: {what} length");
    let mut worst: f64 = 0.0;
    for (i, (a, b)) in ours.iter().zip(theirs).enumerate() {
        let err = (a - b).abs() / b.abs().max(1.0);
        assert!(
            err <= TOL,
            "{ctx}: {what}[{i}] = {a}, pinocchio {b} (error {err:.2e})"
        );
        worst = worst.max(err);
    }
    worst
}

/// Every chain joint's child link frame, row-major 4×4 each.
fn link_poses(chain: &Chain, q: &[f64]) -> Vec<f64> {
    control::with_dof!(chain.dof(), N => {
        let model = chain.model::<N>().unwrap();
        let mut frames = Frames::<N>::default();
        model.frames(&SVector::<f64, N>::from_column_slice(q), &mut frames);
        (0..N)
            .flat_map(|i| {
                let m = frames.link(&model, i).matrix();
                (0..16).map(move |k| m[(k / 4, k % 4)])
            })
            .collect()
    })
}

fn check(name: &str) {
    let path = repo().join(format!("control/tests/fixtures/pinocchio/{name}.json"));
    let fixture: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let urdf = std::fs::read_to_string(repo().join(fixture["source"].as_str().unwrap())).unwrap();
    let chain = Chain::from_urdf(
        &urdf,
        Some(fixture["base"].as_str().unwrap()),
        Some(fixture["tip"].as_str().unwrap()),
    )
    .unwrap_or_else(|e| panic!("{name}: {e}"));
    let joints: Vec<&str> = chain.joints.iter().map(|j| j.name.as_str()).collect();
    let expected: Vec<&str> = fixture["joints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j.as_str().unwrap())
        .collect();
    assert_eq!(joints, expected, "{name}: chain joints");
    let mut worst: f64 = 0.0;
    for (c, case) in fixture["cases"].as_array().unwrap().iter().enumerate() {
        let ctx = format!("{name} case {c}");
        let e = chain
            .evaluate(
                &floats(&case["q"]),
                &floats(&case["qd"]),
                &floats(&case["qdd"]),
                &floats(&case["tau"]),
            )
            .unwrap();
        for (what, ours) in e.named() {
            worst = worst.max(close(what, ours, &floats(&case[what]), &ctx));
        }
        let links = link_poses(&chain, &floats(&case["q"]));
        worst = worst.max(close(
            "link_poses",
            &links,
            &floats(&case["link_poses"]),
            &ctx,
        ));
    }
    eprintln!("{name}: worst relative error {worst:.2e}");
}

#[test]
fn panda_matches_pinocchio() {
    check("panda");
}

#[test]
fn planar3_matches_pinocchio() {
    check("planar3");
}

#[test]
fn example_robot_data_panda_with_hand_matches_pinocchio() {
    check("erd_panda");
}

#[test]
fn ur5_matches_pinocchio() {
    check("ur5");
}

#[test]
fn ur3_matches_pinocchio() {
    check("ur3_gripper");
}

#[test]
fn xarm7_matches_pinocchio() {
    check("xarm7");
}

#[test]
fn kinova_with_a_turned_base_matches_pinocchio() {
    check("kinova");
}

#[test]
fn unitree_z1_with_a_locked_gripper_matches_pinocchio() {
    check("z1");
}

#[test]
fn prismatic_joints_turned_axes_and_a_tilted_base_match_pinocchio() {
    check("quirks");
}

#[test]
fn tiago_torso_and_arm_eight_joints_match_pinocchio() {
    check("tiago_no_hand");
}

#[test]
fn talos_two_torso_joints_and_an_arm_nine_joints_match_pinocchio() {
    check("talos_reduced");
}

#[test]
fn a_twelve_joint_chain_at_full_capacity_matches_pinocchio() {
    check("snake12");
}
