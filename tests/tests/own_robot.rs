//! A robot nobody tuned for, through the real processes: a start the arm cannot hold and a body
//! without mass are refused before the first command with the physical cause, and a run that
//! breaks a limit says so on the one-screen report's problems line (and in its summary).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use tests::*;

fn text(o: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn demo(cfg: &Path, out: &Path, args: &[&str]) -> Output {
    Command::new(bin("chaosd"))
        .args(["demo", "--config", cfg.to_str().unwrap()])
        .args(args)
        .args(["--output", out.to_str().unwrap()])
        .output()
        .unwrap()
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// The Panda with every `<inertial>` of `links` removed (a URDF that forgot them).
fn panda_without_inertials(links: &[&str]) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/panda.urdf");
    let mut s = std::fs::read_to_string(path).unwrap();
    for l in links {
        let open = format!("<link name=\"{l}\">");
        let start = s.find(&open).expect("the link is in the Panda's URDF");
        let end = start + s[start..].find("</link>").unwrap();
        if let Some(i) = s[start..end].find("<inertial>") {
            let j = s[start..end].find("</inertial>").unwrap() + "</inertial>".len();
            s.replace_range(start + i..start + j, "");
        }
    }
    s
}

#[test]
fn a_start_the_arm_cannot_hold_is_refused_by_joint_and_number_in_every_torque_driven_mode() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("cannot-hold"));
    // Joint 4 carries 18.57 N·m of gravity at the ready pose; its limit tightened to 15.
    let cfg = write(
        dir.path(),
        "weak.toml",
        &format!(
            "{}\n[command.limits]\ntorque = [87.0, 87.0, 87.0, 15.0, 12.0, 12.0, 12.0]\n",
            control::config::spatial::PANDA_PAPER
        ),
    );
    let out = dir.path().join("out");
    let cause = "joint 4 (\"panda_joint4\") cannot hold the start posture: gravity there needs 18.57 N·m and its effort limit is 15.00 N·m";
    // The daemon refuses first in both: its start-up check of the motion's effort asks about
    // the start before the motion. (The rigid-body plant, on its own, refuses the same start.)
    for (mode, who) in [("torque", "chaosd:"), ("position", "chaosd:")] {
        let o = demo(&cfg, &out, &["--mode", mode, "--duration", "3"]);
        let all = text(&o);
        assert!(!o.status.success(), "{mode}: {all}");
        assert!(
            all.contains(&format!("{who} error: {cause}")),
            "{mode}: {all}"
        );
        assert!(!all.contains("== chaosd demo report =="), "{mode}: {all}");
    }
}

#[test]
fn a_body_without_mass_is_named_never_a_nan() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("massless"));
    let urdf = write(
        dir.path(),
        "massless.urdf",
        &panda_without_inertials(&["panda_link7"]),
    );
    let o = Command::new(bin("chaosctl"))
        .args(["robot", "eval", urdf.to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    let all = text(&o);
    assert!(!o.status.success(), "{all}");
    assert!(
        !all.contains("null") && !all.contains("NaN"),
        "a non-finite number printed: {all}"
    );
    let cause = "joint 7 (\"panda_joint7\") moves no mass or inertia";
    assert!(
        all.contains(&format!("aba is not finite at this state: {cause}")),
        "{all}"
    );
    let show = Command::new(bin("chaosctl"))
        .args(["robot", "show", urdf.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(show.status.success() && text(&show).contains(&format!("warning: {cause}")));
    let cfg = write(
        dir.path(),
        "massless.toml",
        &control::config::spatial::PANDA_PAPER.replace(
            "description = \"panda\"",
            &format!("description = {:?}", urdf.to_str().unwrap()),
        ),
    );
    let out = dir.path().join("out");
    let o = demo(&cfg, &out, &["--mode", "torque", "--duration", "3"]);
    let all = text(&o);
    assert!(!o.status.success() && all.contains(cause), "{all}");
    // A body is not needed to command accelerations to the kinematic plant.
    let o = demo(&cfg, &out, &["--mode", "acceleration", "--duration", "3"]);
    assert!(o.status.success(), "{}", text(&o));
}

#[test]
fn a_limit_breach_is_on_the_problems_line_with_its_count_and_worst_joint() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("breach"));
    // Filter and limiter off, and a start above joint 1's speed limit (2.175 rad/s): the law
    // brakes it in one tick, past the acceleration limit. Nothing hides either.
    let base = control::config::spatial::PANDA_PAPER;
    assert!(!base.contains("[command]"));
    let text_cfg = base.replace("[safety]\nenabled = true", "[safety]\nenabled = false")
        + "\n[command]\nlimiter = false\n";
    let text_cfg = match text_cfg.find("qd0 = ") {
        Some(i) => {
            let end = i + text_cfg[i..].find('\n').unwrap();
            format!(
                "{}qd0 = [3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]{}",
                &text_cfg[..i],
                &text_cfg[end..]
            )
        }
        None => text_cfg.replace("[sim]", "[sim]\nqd0 = [3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]"),
    };
    assert!(text_cfg.contains("limiter = false") && text_cfg.contains("enabled = false"));
    let cfg = write(dir.path(), "breach.toml", &text_cfg);
    let out = dir.path().join("out");
    let o = demo(&cfg, &out, &["--duration", "3"]);
    let all = text(&o);
    assert!(o.status.success(), "{all}");
    let problems = all
        .lines()
        .find(|l| l.starts_with("problems"))
        .unwrap_or_else(|| panic!("no problems line: {all}"));
    // The start is 138 % of the limit; a host stall while the law brakes (the plant holds the
    // braking command longer) can only make the peak larger, so the bound is one-sided.
    let speed = "states above a speed limit (worst joint 1, ";
    let peak = problems
        .find(speed)
        .and_then(|i| problems[i + speed.len()..].split(" %").next())
        .and_then(|p| p.parse::<f64>().ok())
        .unwrap_or_else(|| panic!("no speed breach of joint 1: {problems}"));
    assert!(
        peak >= 130.0 && problems.contains("commands above an acceleration limit (worst joint 1,"),
        "{problems}"
    );
    let s = read_json(&out.join("daemon-summary.json"));
    let l = &s["joint_limits"];
    assert!(l["speed_outside"].as_u64().unwrap() >= 1, "{l}");
    assert_eq!(l["peak_speed_joint"], 1, "{l}");
    assert!(l["peak_speed_fraction"].as_f64().unwrap() > 1.3, "{l}");
}

#[test]
fn an_obstacle_dropped_onto_the_arm_is_refused_with_the_reason_and_nothing_changes() {
    let _g = serial();
    // Joints 1 and 2 of the Panda meet at (0, 0, 0.333) whatever the joints do: a sphere
    // there is inside the first capsule (radius 0.08) at every moment.
    let sys = tests::live::start("on-the-arm", control::config::spatial::PANDA_PAPER);
    let (code, _, err) =
        tests::live::ctl_once(&sys.ns, &["obstacle", "add", "0.0", "0.0", "0.333", "0.05"]);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("a link of the arm is 0.130 m inside that obstacle"),
        "{err}"
    );
    let (code, out, _) = tests::live::ctl_once(&sys.ns, &["obstacle", "ls"]);
    assert_eq!((code, out.trim()), (0, "[]"));
    // A sphere clear of the arm is taken, numbered from 1, and the answer says what changed.
    let (code, out, err) =
        tests::live::ctl_once(&sys.ns, &["obstacle", "add", "1.0", "-1.0", "1.5", "0.05"]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("obstacles[1].radius: (none) → 0.05")
            && out.contains("applied at the next tick"),
        "{out}"
    );
    let (_, out, _) = tests::live::ctl_once(&sys.ns, &["obstacle", "ls"]);
    assert!(out.contains("\"number\": 1"), "{out}");
    let (code, _, err) = tests::live::ctl_once(&sys.ns, &["obstacle", "rm", "0"]);
    assert!(code == 1 && err.contains("numbered from 1"), "{err}");
    let (code, out, err) = tests::live::ctl_once(&sys.ns, &["set", "mu", "0.5"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        out.trim(),
        "feedback.mu: 1.0 → 0.5\napplied at the next tick"
    );
}

/// An arm nobody here tuned for, from example-robot-data (`control/tests/fixtures/urdf`), with
/// the recipe a new user starts from: the Panda's paper set-up's law (centring α = 20, μ = 1 in
/// the null space from the start), a 0.1 m circle in 2 s, q̈ limits of 10 rad/s² (a URDF has
/// none), and a start posture the arm can hold.
struct Arm {
    file: &'static str,
    base: &'static str,
    tip: &'static str,
    q0: &'static str,
}

const ARMS: [Arm; 3] = [
    Arm {
        file: "baxter.urdf",
        base: "base",
        tip: "left_gripper",
        q0: "[0.0, -0.8, 0.0, 2.0, 0.0, 1.0, 0.0]",
    },
    Arm {
        file: "pr2.urdf",
        base: "torso_lift_link",
        tip: "l_wrist_roll_link",
        q0: "[0.5, 1.3, 1.5, -1.5, 0.0, -0.5, 0.0]",
    },
    Arm {
        file: "tiago_no_hand.urdf",
        base: "torso_lift_link",
        tip: "arm_7_link",
        q0: "[0.5, 0.0, -1.5, 1.5, 0.0, 0.0, 0.0]",
    },
];

fn arm_config(arm: &Arm, q0: &str) -> String {
    let urdf = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../control/tests/fixtures/urdf")
        .join(arm.file);
    let qdd_max = vec![10.0; q0.split(',').count()];
    format!(
        "[robot]\ndescription = {:?}\nbase = {:?}\ntip = {:?}\n\n\
         [task]\nkind = \"position\"\npath = \"circle\"\nnormal = [1.0, 0.0, 0.0]\nradius = 0.1\nperiod = 2.0\n\n\
         [law]\nalpha = 20.0\nsecondary = \"centring\"\n\n\
         [feedback]\nmu = 1.0\nt_on = 0.0\nprojection = \"null-space\"\n\n\
         [safety]\nenabled = true\nqdd_max = {qdd_max:?}\n\n\
         [sim]\ndt = 0.001\nduration = 20.0\ntransient = 2.0\nq0 = {q0}\n\n\
         [daemon]\nhold_after = 500\n",
        urdf.to_str().unwrap(),
        arm.base,
        arm.tip
    )
}

/// Every command interface, and position mode through the UDP bridge.
const EVERY_MODE: [&[&str]; 5] = [
    &["--mode", "acceleration"],
    &["--mode", "position"],
    &["--mode", "velocity"],
    &["--mode", "torque"],
    &["--mode", "position", "--bridge", "udp"],
];

#[test]
fn three_arms_nobody_tuned_for_track_in_every_mode_inside_every_limit() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("own-arms"));
    for arm in &ARMS {
        tracks_inside_every_limit(arm, &EVERY_MODE, dir.path());
    }
}

/// Each of `runs` of `arm` (6 s demos) tracks to 1 mm RMS without a fault or a state or command
/// outside a limit.
///
/// A run whose loop the host stalled for a period or more (a sleep that woke 1 ms late or
/// later) and that missed the tracking bound runs once more, and must meet it then: through the
/// UDP bridge such a stall makes the device miss cycles and brake, and each brake restarts the
/// stream (seen in full runs: 371 missed device cycles, 3 brakes, 1.2 cm, after stalls over
/// 2 ms; 67 missed cycles, 1 brake, 3.6 mm, after a 1.96 ms stall; 0.33 mm alone). Limits and
/// faults are judged on every run, stalled or not.
fn tracks_inside_every_limit(arm: &Arm, runs: &[&[&str]], dir: &Path) {
    let rms_max = 1e-3;
    let cfg = write(dir, "arm.toml", &arm_config(arm, arm.q0));
    for args in runs {
        let what = format!("{} {}", arm.file, args.join(" "));
        let out = dir.join("out");
        let mut all_args = args.to_vec();
        all_args.extend(["--duration", "6", "--details"]);
        let mut attempt = 0;
        let (s, all) = loop {
            attempt += 1;
            let _ = std::fs::remove_dir_all(&out);
            let o = demo(&cfg, &out, &all_args);
            let all = text(&o);
            assert!(o.status.success(), "{what}: {all}");
            let s = read_json(&out.join("daemon-summary.json"));
            assert_eq!(s["counters"]["faults"], 0, "{what}: {all}");
            let l = &s["joint_limits"];
            assert_eq!(
                (l["states_outside"].as_u64(), l["commands_outside"].as_u64()),
                (Some(0), Some(0)),
                "{what}: {all}"
            );
            let rms = s["tracking_rms_m"].as_f64().unwrap();
            let stall_ns = s["counters"]["late_wakes"]["max_ns"].as_u64().unwrap_or(0);
            if rms > rms_max && stall_ns >= 1_000_000 && attempt == 1 {
                eprintln!(
                    "{what}: tracking RMS {rms:.2e} m after a {stall_ns} ns host stall: once more"
                );
                continue;
            }
            break (s, all);
        };
        let rms = s["tracking_rms_m"].as_f64().unwrap();
        let l = &s["joint_limits"];
        eprintln!("{what}: tracking RMS {rms:.2e} m, {l}");
        assert!(rms <= rms_max, "{what}: tracking RMS {rms} m\n{all}");
    }
}

/// A mobile manipulator's torso and arm as one redundant chain of 8 joints (TIAGo's prismatic
/// torso lift under its 7-joint arm, the same recipe as the arms above): it loads (its model is
/// checked against pinocchio in `control/tests/model_pinocchio.rs`) and tracks in every command
/// interface inside every limit. The torso lifts at 0.07 m/s against the arm's ~2 rad/s, so
/// `law.metric = "auto"` takes the speed-weighted pseudo-inverse (`control::law::metric`); with
/// the minimum-norm one the torso was handed a share of the circle it could not follow and the
/// tool tracked to 2 cm.
#[test]
fn a_torso_and_an_arm_eight_joints_track_in_every_mode_inside_every_limit() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("eight-joints"));
    let tiago = Arm {
        file: "tiago_no_hand.urdf",
        base: "base_link",
        tip: "arm_7_link",
        q0: "[0.15, 0.5, 0.0, -1.5, 1.5, 0.0, 0.0, 0.0]",
    };
    tracks_inside_every_limit(&tiago, &EVERY_MODE, dir.path());
}

#[test]
fn baxter_at_a_start_its_shoulder_cannot_hold_is_refused_in_torque_driven_modes() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("baxter-weak"));
    // The start: gravity needs 50.2 N·m at left_s1, whose limit is 50 (the real arm
    // has a spring there that its URDF does not model).
    let q0 = "[0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0]";
    let cfg = write(dir.path(), "baxter.toml", &arm_config(&ARMS[0], q0));
    refused_in_torque_driven_modes(
        &cfg,
        &dir.path().join("out"),
        &["joint 2 (\"left_s1\") cannot hold the start posture: gravity there needs 50.20 N·m and its effort limit is 50.00 N·m"],
    );
}

/// `cfg` is refused before the first command in torque, position and velocity modes, the
/// message saying each of `says`.
fn refused_in_torque_driven_modes(cfg: &Path, out: &Path, says: &[&str]) {
    for mode in ["torque", "position", "velocity"] {
        let o = demo(cfg, out, &["--mode", mode, "--duration", "3"]);
        let all = text(&o);
        assert!(!o.status.success(), "{mode}: {all}");
        assert!(says.iter().all(|s| all.contains(s)), "{mode}: {all}");
    }
}

#[test]
fn a_start_whose_motion_needs_more_than_a_joint_has_is_refused_before_the_first_command() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("pr2-strain"));
    // PR2's left arm held out further: it holds the start, but the circle from there needs
    // more than the shoulder lift's 30 N·m (run anyway, it tracked to 8 mm with the servo's
    // torque clamped in 9607 substeps).
    let q0 = "[0.8, 1.0, 1.5, -1.8, 0.0, -0.5, 0.0]";
    let cfg = write(dir.path(), "pr2.toml", &arm_config(&ARMS[1], q0));
    let out = dir.path().join("out");
    refused_in_torque_driven_modes(
        &cfg,
        &out,
        &[
            "joint 2 (\"l_shoulder_lift_joint\") cannot carry the motion from this start",
            "its effort limit is 30.00 N·m",
        ],
    );
    // The ideal arm's interface integrates q̈ whatever it costs: it runs.
    let o = demo(&cfg, &out, &["--mode", "acceleration", "--duration", "2"]);
    assert!(o.status.success(), "{}", text(&o));
}
