//! The dynamic plant against pinocchio: trajectories of the forward dynamics, and energy.
//!
//! `scripts/golden/dynamics_trajectories.py` integrated the Panda's forward dynamics with
//! pinocchio's ABA and RK4 at a step of 10 µs (the true trajectory to ~1e-10 rad) from three
//! starts: a free swing under gravity, a constant torque, and a spin without gravity. The plant
//! steps as the plant process does (1 kHz, 4 RK4 substeps) and must stay within 1e-6 rad of it
//! over 1 s (docs/science.md, "Spatial arms" "Dynamics"; issue 24's target). No friction, no noise, no limits.

use control::model::Chain;
use control::rigid_body::{Drive, RigidBody};
use nalgebra::{SVector, Vector3};
use serde_json::Value;
use std::path::Path;

type V7 = SVector<f64, 7>;

fn v7(v: &Value) -> V7 {
    let x: Vec<f64> = v
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    V7::from_column_slice(&x)
}

fn fixture() -> (Chain, Value) {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let text = std::fs::read_to_string(
        repo.join("control/tests/fixtures/pinocchio/panda_trajectories.json"),
    )
    .unwrap();
    let f: Value = serde_json::from_str(&text).unwrap();
    let urdf = std::fs::read_to_string(repo.join(f["source"].as_str().unwrap())).unwrap();
    let chain = Chain::from_urdf(&urdf, f["base"].as_str(), f["tip"].as_str()).unwrap();
    (chain, f)
}

fn plant(chain: &Chain, case: &Value) -> RigidBody<7> {
    let mut model = chain.model::<7>().unwrap();
    let g: Vec<f64> = case["gravity"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    model.gravity = Vector3::from_column_slice(&g);
    RigidBody::new(
        model,
        v7(&case["q0"]),
        v7(&case["qd0"]),
        V7::repeat(f64::INFINITY),
    )
}

#[test]
fn trajectories_match_pinocchio_within_1e_6_rad_after_1_s() {
    let (chain, f) = fixture();
    for case in f["cases"].as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let mut arm = plant(&chain, case);
        let drive = Drive::Torque(v7(&case["tau"]));
        let mut tick = 0;
        for s in case["samples"].as_array().unwrap() {
            let until = (s["t"].as_f64().unwrap() * 1000.0).round() as usize;
            while tick < until {
                arm.advance(&drive, 0.0, 1e-3, 4);
                tick += 1;
            }
            let dq = (arm.state.q - v7(&s["q"])).amax();
            assert!(dq <= 1e-6, "{name} at t = {}: |Δq| = {dq:.2e}", s["t"]);
            let ke = s["kinetic_energy"].as_f64().unwrap();
            let dke = (arm.kinetic_energy() - ke).abs() / ke.max(1.0);
            assert!(
                dke <= 1e-6,
                "{name} at t = {}: kinetic energy off by {dke:.2e}",
                s["t"]
            );
        }
    }
}

#[test]
fn without_gravity_or_friction_energy_drifts_less_than_1e_6_over_10_s() {
    let (chain, f) = fixture();
    let case = &f["cases"].as_array().unwrap()[2];
    assert_eq!(case["name"], "no_gravity");
    let mut arm = plant(&chain, case);
    let e0 = arm.kinetic_energy();
    let drive = Drive::Torque(V7::zeros());
    let mut worst: f64 = 0.0;
    for _ in 0..10_000 {
        arm.advance(&drive, 0.0, 1e-3, 4);
        worst = worst.max((arm.kinetic_energy() - e0).abs() / e0);
    }
    assert!(worst <= 1e-6, "relative energy drift {worst:.2e}");
}
