//! The Panda commanded as real arms are, through the real processes: torque mode against the
//! rigid-body plant, a device that stops with a named reflex error when the limiter is off (and
//! the daemon's FAULT that names it), and the start-up refusals of a set-up that cannot run.

use std::path::Path;
use std::process::{Command, Output};
use tests::*;

fn demo(out: &Path, args: &[&str]) -> Output {
    Command::new(bin("chaosd"))
        .args(["demo", "--robot", "panda"])
        .args(args)
        .args(["--output", out.to_str().unwrap()])
        .output()
        .unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn torque_mode_tracks_on_the_rigid_body_plant_and_the_feedback_still_works() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("torque-demo"));
    let out = dir.path().join("out");
    let o = demo(
        &out,
        &[
            "--mode",
            "torque",
            "--trigger",
            "state",
            "--duration",
            "14",
            "--t-on",
            "5",
        ],
    );
    let all = text(&o);
    assert!(o.status.success(), "{all}");
    assert!(all.contains("command               torque mode"), "{all}");
    let s = read_json(&out.join("daemon-summary.json"));
    assert_eq!(s["command"]["mode"], "torque", "{s}");
    assert_eq!(s["counters"]["faults"], 0, "{s}");
    assert_eq!(s["device_stops"], 0, "{s}");
    assert!(s["tracking_rms_m"].as_f64().unwrap() < 1e-3, "{s}");
    let before = s["period_residual_before"].as_f64().unwrap();
    let after = s["period_residual_after"].as_f64().unwrap();
    assert!(before > 0.3 && after < 0.6 * before, "{before} → {after}");
    // The plant ran the dynamics: it measured torques, and the file says so.
    let cfg = std::fs::read_to_string(out.join("config.toml")).unwrap();
    assert!(cfg.contains("rigid-body"), "{cfg}");
}

#[test]
fn without_the_limiter_the_device_stops_and_the_daemon_names_the_joint_and_the_rule() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("reflex-demo"));
    let out = dir.path().join("out");
    let o = demo(
        &out,
        &[
            "--mode",
            "position",
            "--bridge",
            "udp",
            "--no-limiter",
            "--duration",
            "4",
        ],
    );
    let all = text(&o);
    assert!(all.contains("limiter OFF"), "{all}");
    let s = read_json(&out.join("daemon-summary.json"));
    assert!(s["device_stops"].as_u64().unwrap() >= 1, "{s}");
    let first = s["first_device_stop"].as_str().unwrap();
    assert!(first.contains("the device stopped: joint "), "{first}");
    assert!(
        first.contains("limit") || first.contains("discontinuity"),
        "{first}"
    );
    let f = read_json(&out.join("fakebot-summary.json"));
    assert!(f["counters"]["reflex_stops"].as_u64().unwrap() >= 1, "{f}");
}

#[test]
fn a_set_up_that_cannot_run_is_refused_at_start_up_by_name() {
    let dir = TempDir::new(&unique_namespace("command-refusals"));
    let panda = control::spatial::config::PANDA;
    for (extra, says) in [
        ("[command]\nmode = \"effort\"\n", "effort"),
        (
            "[command]\nmode = \"torque\"\nkp = [1e9, 1e9, 1e9, 1e9, 1e9, 1e9, 1e9]\n",
            "command.kp",
        ),
        (
            "[command.limits]\njerk = [9e9, 1, 1, 1, 1, 1, 1]\n",
            "command.limits.jerk",
        ),
    ] {
        let path = dir.path().join("bad.toml");
        std::fs::write(&path, format!("{panda}\n{extra}")).unwrap();
        let o = Command::new(bin("chaosd"))
            .args(["check-config", "--config", path.to_str().unwrap()])
            .output()
            .unwrap();
        let all = text(&o);
        assert!(!o.status.success() && all.contains(says), "{extra}: {all}");
        assert!(!all.contains("panicked"), "{all}");
    }
    // Torque commands to an arm without masses: the plant refuses, naming the field.
    let path = dir.path().join("torque.toml");
    std::fs::write(&path, format!("{panda}\n[command]\nmode = \"torque\"\n")).unwrap();
    let o = Command::new(bin("chaosd-plant"))
        .args(["--config", path.to_str().unwrap(), "--duration", "1"])
        .output()
        .unwrap();
    let all = text(&o);
    assert!(
        !o.status.success() && all.contains("plant.dynamics"),
        "{all}"
    );
}
