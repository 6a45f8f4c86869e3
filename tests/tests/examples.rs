//! The examples users start from run as their READMEs say.

use tests::{assert_tracks, bin};

#[test]
fn the_own_urdf_example_tracks_its_circle_on_the_xarm7_inside_its_limits() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let o = std::process::Command::new(bin("chaosctl"))
        .current_dir(&root)
        .args(["simulate", "--config", "examples/own-urdf/xarm7.toml"])
        .args(["--duration", "10", "--transient", "2", "--json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(s["n"], 7, "{s}");
    assert!(s["rms_tracking_error"].as_f64().unwrap() < 1e-4, "{s}");
    assert!(s["min_joint_margin"].as_f64().unwrap() > 0.0, "{s}");
    assert!(s["max_speed_ratio"].as_f64().unwrap() <= 1.0, "{s}");
    assert_eq!(s["nonfinite_steps"], 0, "{s}");
}

#[test]
fn the_custom_task_example_runs_as_chaosd_and_plain_chaosd_names_what_is_missing() {
    let _g = tests::serial();
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let cfg = "examples/custom-task/panda-posture.toml";
    // chaosd itself has no such task, and says where one comes from.
    let o = std::process::Command::new(bin("chaosd"))
        .current_dir(&root)
        .args(["check-config", "--config", cfg])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("ready-posture") && err.contains("examples/custom-task"),
        "{err}"
    );
    // The example's program is chaosd with the task registered: the whole demo runs on it.
    let ns = tests::unique_namespace("custom-task");
    let dir = tests::TempDir::new(&ns);
    let out = dir.path().join("out");
    let o = std::process::Command::new(bin("chaosd-posture"))
        .current_dir(&root)
        .args(["demo", "--config", cfg, "--duration", "8", "--t-on", "3"])
        .args(["--namespace", &ns, "--output", out.to_str().unwrap()])
        .output()
        .unwrap();
    let log = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(o.status.success(), "{log}");
    assert!(log.contains("7 joints"), "{log}");
    let s = tests::read_json(&out.join("daemon-summary.json"));
    assert_tracks(&[&s], 1e-3);
    assert_eq!(s["counters"]["nonfinite"], 0, "{s}");
}
