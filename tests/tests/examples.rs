//! The examples users start from run as their READMEs say.

use tests::bin;

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
