//! `chaosctl plan` as a user runs it: a set-up with room for a clean cycle, one whose obstacle
//! sits on the path (blocked, with the obstacle named), and bad input.

use std::process::Command;
use tests::*;

fn plan(args: &[&str]) -> (i32, String, String) {
    let o = Command::new(bin("chaosctl"))
        .arg("plan")
        .args(args)
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into(),
        String::from_utf8_lossy(&o.stderr).into(),
    )
}

#[test]
fn plan_says_whether_a_clean_cycle_exists_and_why_not() {
    // The demo's arm with the obstacle that trapped the safety filter: a clean cycle exists.
    let (code, out, err) = plan(&["--preset", "demo", "--obstacle", "0.9,1.1,0.15", "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["exists"], true, "{v}");
    assert!(v["min_clearance_m"].as_f64().unwrap() >= 0.07, "{v}");
    assert!(v["planning_ms"].as_f64().unwrap() > 0.0, "{v}");
    assert!(v["blocked"].is_null(), "{v}");
    // An obstacle over the circle: the hand cannot pass, and the answer names the obstacle.
    let (code, out, err) = plan(&["--preset", "demo", "--obstacle", "1.5,2.0,0.2", "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["exists"], false, "{v}");
    assert_eq!(v["blocked"]["obstacle"], 1, "{v}");
    assert!(
        v["blocked"]["reason"]
            .as_str()
            .unwrap()
            .contains("obstacle 1"),
        "{v}"
    );
    // In words too.
    let (code, out, _) = plan(&["--preset", "demo", "--obstacle", "1.5,2.0,0.2"]);
    assert_eq!(code, 0);
    assert!(out.starts_with("no clean cycle: at task time"), "{out}");
}

#[test]
fn plan_says_when_the_users_own_bounds_are_what_fails() {
    // No cycle of the trap's layout runs at 0.5 rad/s; the daemon falls back to the filter's
    // physical limits, and says so instead of quietly breaking the bound.
    let args = [
        "--preset",
        "demo",
        "--obstacle",
        "0.9,1.1,0.15",
        "--max-rate",
        "0.5",
    ];
    let (code, out, err) = plan(&args);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.starts_with("no cycle keeps a margin of 0.02 m at joint rates within 0.5 rad/s; within the filter's physical limits alone a clean cycle exists"),
        "{out}"
    );
    let (_, out, _) = plan(&[&args[..], &["--json"]].concat());
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(v["exists"] == true && v["limits_only"] == true, "{v}");
    let (_, out, _) = plan(&args[..4]);
    assert!(out.starts_with("a clean cycle exists"), "{out}");
    // A bigger disc: the rate bound fails first, then the filter would brake the cycle the
    // physical limits allow. The reason says both, the user's bound first.
    let (code, out, err) = plan(&[
        "--preset",
        "demo",
        "--obstacle",
        "0.9,1.1,0.3",
        "--max-rate",
        "1",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.starts_with("no clean cycle: clean postures exist at every phase, but none links round the period with joint rates within 1.0 rad/s; within the physical limits alone: a cycle round the obstacles exists, but the safety filter would brake it"),
        "{out}"
    );
}

#[test]
fn bad_plan_input_is_refused_in_one_line() {
    for (args, says) in [
        (vec!["--obstacle", "1,2"], "expected X,Y,RADIUS"),
        (vec!["--obstacle", "1,2,-1"], "--obstacle #1"),
        (vec!["--max-rate", "0"], "--max-rate 0"),
        (vec!["--preset", "paper-floating"], "fixed-base 3-link arm"),
    ] {
        let (code, _, err) = plan(&args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
}

#[test]
fn plan_maps_where_one_more_obstacle_leaves_a_clean_cycle() {
    let dir = TempDir::new("plan-map");
    let prefix = dir.path().join("map");
    let p = prefix.to_str().unwrap();
    let (code, out, err) = plan(&[
        "--preset",
        "demo",
        "--map",
        p,
        "--map-cells",
        "5",
        "--map-radii",
        "0.2",
        "--jobs",
        "2",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("25 obstacle positions"), "{out}");
    let csv = std::fs::read_to_string(dir.path().join("map.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert_eq!(rows.len(), 25, "{csv}");
    // Far corners leave the arm alone; the grid's centre column crosses the circle.
    assert!(
        rows.iter().any(|r| r.ends_with("reached tracking")),
        "{csv}"
    );
    assert!(
        rows.iter().any(|r| r.ends_with("no clean cycle (Blocked)")),
        "{csv}"
    );
    for ext in ["png", "svg"] {
        assert!(dir.path().join(format!("map.{ext}")).exists(), "no {ext}");
    }
    let (code, _, err) = plan(&["--preset", "demo", "--map", p, "--map-cells", "1"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--map-cells 1") && err.lines().count() == 1,
        "{err}"
    );
}

#[test]
fn plan_on_the_panda_goes_round_a_sphere_and_names_one_on_the_path() {
    let dir = TempDir::new(&unique_namespace("plan-panda"));
    let csv = dir.path().join("cycle.csv");
    let (code, out, err) = plan(&[
        "--preset",
        "panda",
        "--obstacle",
        "0.089,-0.196,0.575,0.058",
        "--json",
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["exists"], true, "{v}");
    assert!(v["min_clearance_m"].as_f64().unwrap() >= 0.02, "{v}");
    assert_eq!(v["grid"]["phases"], 64, "{v}");
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.starts_with("t,q1,q2,q3,q4,q5,q6,q7\n"), "{text}");
    assert_eq!(text.lines().count(), 65);
    // A sphere on the hand's start point: no cycle, said with the sphere and the hand's link.
    let (code, out, err) = plan(&["--preset", "panda", "--obstacle", "0.307,0,0.487,0.05"]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.starts_with("no clean cycle: the path runs through obstacle 1"),
        "{out}"
    );
    for (args, says) in [
        (&["--obstacle", "0.3,0.1,0.05"][..], "X,Y,Z,RADIUS"),
        (
            &["--map", "m", "--map-offset", "nan"][..],
            "--map-offset NaN",
        ),
        (
            &["--obstacle", "0.307,0,0.487,0.05", "--map", "m"][..],
            "the config's own obstacles leave no clean cycle already (the path runs through",
        ),
        (&["--obstacle", "0.3,0.1,0.4,-1"][..], "radius"),
    ] {
        let (code, out, err) = plan(&[&["--preset", "panda"][..], args].concat());
        assert_eq!(code, 2, "{args:?} was accepted: {out}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
}

#[test]
fn plan_maps_a_slice_of_spheres_for_the_panda() {
    let dir = TempDir::new(&unique_namespace("plan-map-panda"));
    let prefix = dir.path().join("map");
    let (code, out, err) = plan(&[
        "--preset",
        "panda",
        "--map",
        prefix.to_str().unwrap(),
        "--map-cells",
        "5",
        "--map-radii",
        "0.06",
        "--jobs",
        "2",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("25 sphere positions"), "{out}");
    let csv = std::fs::read_to_string(dir.path().join("map.csv")).unwrap();
    assert!(csv.starts_with("x,y,z,radius,verdict\n"), "{csv}");
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 25, "{csv}");
    // One slice, 0.1 m in front of the path's plane (x = 0.307), from the floor up.
    for r in &rows {
        let x: f64 = r[0].parse().unwrap();
        let z: f64 = r[2].parse().unwrap();
        assert!((x - 0.207).abs() < 1e-3 && z >= -1e-9, "{r:?}");
    }
    // The slice's corners leave the arm alone; its centre column meets the hand's circle.
    let said = |v: &str| rows.iter().any(|r| r[4] == v);
    assert!(
        said("clean cycle (steered)") && said("on the path (Blocked)"),
        "{csv}"
    );
    for ext in ["png", "svg"] {
        assert!(dir.path().join(format!("map.{ext}")).exists(), "no {ext}");
    }
}

#[test]
fn simulate_steers_a_panda_whose_file_asks_for_a_plan() {
    let dir = TempDir::new(&unique_namespace("sim-plan"));
    let text = control::config::spatial::PANDA_PAPER.replace(
        "[safety]\nenabled = true\n",
        "[safety]\nenabled = true\nplan = true\n",
    ) + "\n[[obstacles]]\ncenter = [0.089, -0.196, 0.575]\nradius = 0.058\n";
    let cfg = dir.path().join("panda.toml");
    std::fs::write(&cfg, text).unwrap();
    let o = Command::new(bin("chaosctl"))
        .args(["simulate", "--config", cfg.to_str().unwrap()])
        .args(["--duration", "20", "--transient", "10", "--json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["steered"], true, "{v}");
    assert!(v["rms_tracking_error"].as_f64().unwrap() < 1e-4, "{v}");
    assert!(v["min_clearance"].as_f64().unwrap() >= 0.02, "{v}");
    assert_eq!(v["safety_left_null_space_steps"], 0, "{v}");
}

/// `chaosctl simulate --json` on `text` (a config file's text) over `duration` s, statistics
/// after half of it.
fn simulate_json(name: &str, text: &str, duration: &str, transient: &str) -> serde_json::Value {
    let dir = TempDir::new(&unique_namespace(name));
    let cfg = dir.path().join("setup.toml");
    std::fs::write(&cfg, text).unwrap();
    let o = Command::new(bin("chaosctl"))
        .args(["simulate", "--config", cfg.to_str().unwrap()])
        .args(["--duration", duration, "--transient", transient, "--json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// The demo set-up with `obstacles` (a TOML array) and `safety.plan = plan`, as a user writes
/// it.
fn demo_with(obstacles: &str, plan: &str) -> String {
    let text = control::Config::preset("demo").unwrap().to_toml();
    assert!(
        !text.contains("obstacles") && text.contains("plan = \"auto\""),
        "the demo's obstacles or plan moved"
    );
    // A top-level key comes before the first table.
    format!("obstacles = {obstacles}\n{text}").replace("plan = \"auto\"", &format!("plan = {plan}"))
}

/// A planar `simulate --json` report that tracks to 1e-4 m (RMS after the transient) and never
/// touched an obstacle.
fn tracks_cleanly(v: &serde_json::Value) {
    assert!(v["rms_tracking_error"].as_f64().unwrap() < 1e-4, "{v}");
    assert_eq!(v["time_in_contact"], 0.0, "{v}");
}

/// The only trap event of a `simulate --json` report, which must have been answered so.
fn the_one_trap<'a>(v: &'a serde_json::Value, answer: &str) -> &'a serde_json::Value {
    let traps = v["traps"].as_array().unwrap();
    assert_eq!(traps.len(), 1, "{v}");
    assert_eq!(traps[0]["answer"], answer, "{v}");
    &traps[0]
}

const NEW_USERS_OBSTACLE: &str = "[{ center = [0.9, 1.1], radius = 0.15 }]";
const OBSTACLE_ON_THE_PATH: &str = "[{ center = [1.0, 1.5], radius = 0.05 }]";

#[test]
fn simulate_steers_round_obstacles_by_default_and_says_blocked_at_once_when_it_cannot() {
    // `plan = "auto"`: with an obstacle the safety layer steers from the start, so nothing is
    // ever trapped, and the arm tracks within the targets' 20 s.
    let v = simulate_json(
        "sim-auto",
        &demo_with(NEW_USERS_OBSTACLE, "\"auto\""),
        "40",
        "20",
    );
    assert!(v["plan"].as_str().unwrap().starts_with("steering"), "{v}");
    assert_eq!(v["traps"].as_array().unwrap().len(), 0, "{v}");
    tracks_cleanly(&v);
    // No clean cycle: said at the start, as the daemon does (offline the run goes on).
    let v = simulate_json(
        "sim-auto-blk",
        &demo_with(OBSTACLE_ON_THE_PATH, "\"auto\""),
        "5",
        "1",
    );
    let blocked = the_one_trap(&v, "blocked");
    assert_eq!(blocked["t"], 0.0, "{v}");
    assert!(
        blocked["what"].as_str().unwrap().contains("obstacle 1"),
        "{v}"
    );
    // The Panda the filter grazes now and then: steered from the start, never trapped.
    let v = simulate_json(
        "sim-auto-panda",
        &panda_grazing_two_spheres("\"auto\""),
        "40",
        "20",
    );
    assert_eq!(v["steered"], true, "{v}");
    assert_eq!(v["traps"].as_array().unwrap().len(), 0, "{v}");
    assert!(v["rms_tracking_error"].as_f64().unwrap() < 1e-4, "{v}");
    assert!(v["min_clearance"].as_f64().unwrap() >= 0.0199, "{v}");
}

#[test]
fn simulate_answers_a_trap_as_the_daemon_does_with_steering_off() {
    // The new user's obstacle, there from the start, `plan = false`: the filter alone holds
    // the arm off its path; the trap watch sees it and steers onto a cycle planned from the
    // arm's posture.
    let v = simulate_json(
        "sim-trap",
        &demo_with(NEW_USERS_OBSTACLE, "false"),
        "40",
        "20",
    );
    let trap = the_one_trap(&v, "steered");
    assert!(trap["t"].as_f64().unwrap() < 10.0, "{v}");
    tracks_cleanly(&v);

    // An obstacle on the path: trapped, and no clean cycle exists: Blocked, with the reason.
    let v = simulate_json(
        "sim-blocked",
        &demo_with(OBSTACLE_ON_THE_PATH, "false"),
        "20",
        "10",
    );
    let what = the_one_trap(&v, "blocked")["what"].as_str().unwrap();
    assert!(
        what.contains("no clean cycle the arm can follow") && what.contains("obstacle 1"),
        "{what}"
    );

    // The Panda the filter traps only now and then (plan off): the graze is seen (once it
    // costs a centimetre, or twice a millimetre), and steering tracks to the law's precision
    // with the filter's clearance kept.
    let v = simulate_json("sim-recur", &panda_grazing_two_spheres("false"), "40", "20");
    assert!(
        the_one_trap(&v, "steered")["what"]
            .as_str()
            .unwrap()
            .contains("the safety filter left the null space and cost"),
        "{v}"
    );
    assert_eq!(v["steered"], false, "plan was not asked: {v}");
    assert!(v["rms_tracking_error"].as_f64().unwrap() < 1e-4, "{v}");
    assert!(v["min_clearance"].as_f64().unwrap() >= 0.0199, "{v}");
}
