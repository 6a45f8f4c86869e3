//! The Panda through the real processes: `chaosd demo --robot panda`, a daemon and a plant on a
//! spatial config taking live 3-D changes (kept across a daemon restart), and the handshake
//! refusing a planar plant.

use std::time::Duration;
use tests::live::*;
use tests::*;

const PANDA: &str = control::config::spatial::PANDA_PAPER;

#[test]
fn the_panda_demo_runs_daemon_and_plant_inside_the_limits_and_the_feedback_shows() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("panda-demo"));
    let out = dir.path().join("out");
    let o = std::process::Command::new(bin("chaosd"))
        .args(["demo", "--robot", "panda", "--details", "--duration", "14"])
        .args(["--output", out.to_str().unwrap()])
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(o.status.success(), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("panda (panda_link0 → panda_link8), 7 joints, position task"),
        "{stdout}"
    );
    assert!(
        stdout.contains(
            "0 states outside a position or speed limit, 0 commands beyond an acceleration, jerk or effort limit"
        ),
        "{stdout}"
    );
    let s = read_json(&out.join("daemon-summary.json"));
    assert!(s["counters"]["ticks"].as_u64().unwrap() > 10_000, "{s}");
    assert_eq!(s["counters"]["faults"], 0, "{s}");
    assert_tracks(&[&s], 1e-3);
    // The preset's feedback and damping act from the start: over 2-7 s the self-motion is
    // still settling onto its cycle, over the last 5 s it is periodic (offline −0.75 /s).
    assert!(s["period_residual_before"].is_null(), "{s}");
    let start = s["period_residual_start"].as_f64().unwrap();
    assert!(start > 1e-3, "{start}: {s}");
    assert_residual_falls(&s, start, 100.0, f64::INFINITY);
    assert!(stdout.contains("from the start"), "{stdout}");
    let limits = &s["joint_limits"];
    assert!(
        limits["min_position_margin"].as_f64().unwrap() > 0.0,
        "{limits}"
    );
    assert!(
        limits["peak_speed_fraction"].as_f64().unwrap() <= 1.0,
        "{limits}"
    );
}

#[test]
fn a_live_panda_takes_spheres_and_gains_and_refuses_what_its_file_could_not_say() {
    let _g = serial();
    let sys = start("panda-live", PANDA);
    let st = status(&sys.ns);
    assert_eq!(st["n"], 7, "{st}");
    assert_eq!(st["robot"], "panda (panda_link0 → panda_link8)", "{st}");
    let (code, out, err) = ctl(&sys.ns, &["obstacle", "add", "1.0", "-1.0", "1.5", "0.05"]);
    assert_eq!(code, 0, "{out}{err}");
    let (code, out, err) = ctl(&sys.ns, &["obstacle", "ls"]);
    assert_eq!(code, 0, "{err}");
    let listed: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(
        listed[0]["center"],
        serde_json::json!([1.0, -1.0, 1.5]),
        "{out}"
    );
    for (args, says) in [
        (
            &["obstacle", "add", "1.0", "-1.0", "0.05"][..],
            "X Y Z RADIUS",
        ),
        (&["set", "kp", "1e9"][..], "law.kp"),
        (&["set", "secondary", "wobble"][..], "centring"),
        (&["set", "links", "1"][..], "unknown key"),
    ] {
        let (code, out, err) = ctl(&sys.ns, args);
        assert_ne!(code, 0, "{args:?} was accepted: {out}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
    let (code, _, err) = ctl(&sys.ns, &["set", "mu", "0.5", "projection", "full"]);
    assert_eq!(code, 0, "{err}");
    std::thread::sleep(Duration::from_millis(300));
    let st = status(&sys.ns);
    assert_eq!(
        (st["mu"].as_f64(), st["projection"].as_str()),
        (Some(0.5), Some("full")),
        "{st}"
    );
    assert_eq!(
        (st["mode"].as_str(), st["obstacles"].as_u64()),
        (Some("Run"), Some(1)),
        "{st}"
    );
    let (code, _, err) = ctl(&sys.ns, &["obstacle", "rm", "1"]);
    assert_eq!(code, 0, "{err}");
    let (code, text, err) = ctl(&sys.ns, &["status"]);
    assert_eq!(code, 0, "{err}");
    assert!(
        text.contains("arm       panda (panda_link0 → panda_link8), 7 joints"),
        "{text}"
    );

    // kill -9 and start again from the same file: the live changes come back.
    let mut sys = sys;
    sys.daemon.kill9();
    let cfg = sys.dir.path().join("config.toml");
    let args = ["run", "--config", cfg.to_str().unwrap()];
    sys.daemon = Proc::spawn("daemon2", &bin("chaosd"), &args, sys.dir.path());
    let until = std::time::Instant::now() + Duration::from_secs(15);
    let st = loop {
        let (code, out, _) = ctl(&sys.ns, &["status", "--json"]);
        if code == 0 {
            let st: serde_json::Value = serde_json::from_str(&out).unwrap();
            if st["mode"] == "Run" {
                break st;
            }
        }
        assert!(std::time::Instant::now() < until, "{}", sys.daemon.log());
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(
        (st["mu"].as_f64(), st["projection"].as_str()),
        (Some(0.5), Some("full")),
        "{st}"
    );
    assert!(
        sys.daemon.log().contains("resuming the live state"),
        "{}",
        sys.daemon.log()
    );
}

#[test]
fn a_panda_daemon_and_a_planar_plant_refuse_each_other_naming_both() {
    let _g = serial();
    let ns = unique_namespace("panda-hs");
    let dir = TempDir::new(&ns);
    let d = dir.path().join("d");
    let p = dir.path().join("p");
    std::fs::create_dir_all(&d).unwrap();
    std::fs::create_dir_all(&p).unwrap();
    let daemon_cfg = write_config(&d, &ns, "", PANDA);
    let plant_cfg = write_config(&p, &ns, "", "");
    let _daemon = Proc::spawn(
        "daemon",
        &bin("chaosd"),
        &["run", "--config", daemon_cfg.to_str().unwrap()],
        dir.path(),
    );
    let mut plant = Proc::spawn(
        "plant",
        &bin("chaosd-plant"),
        &["--config", plant_cfg.to_str().unwrap()],
        dir.path(),
    );
    let st = plant.wait_exit(Duration::from_secs(15));
    assert!(
        !st.success(),
        "the plant accepted a Panda daemon:\n{}",
        plant.log()
    );
    let log = plant.log();
    assert!(
        log.contains("is a 3-link fixed arm (links 1,1,1), daemon expects a 7-joint panda (panda_link0 → panda_link8)"),
        "{log}"
    );
}

#[test]
fn whatever_sphere_is_added_a_live_panda_tracks_or_says_blocked() {
    // The property, live, with the defaults (`plan = "auto"`: steered while there is a
    // sphere): after a sphere is added the daemon tracks to 1e-3 m or says `Blocked` with a
    // reason, within 3 · trap_time + 1 s (a plan, or a trap and a second plan); removing it
    // brings tracking back. A sphere that lands on a link is refused with that reason. Spheres drawn round the arm and its circle, seed fixed (30 more,
    // offline: the book's "Safety without deadlock").
    let _g = serial();
    let sys = start("panda-property", PANDA);
    let ns = &sys.ns;
    let (v, _) = poll_status(ns, Duration::from_secs(10), |v| tracking(v, 1e-3));
    assert!(tracking(&v, 1e-3), "no tracking before the first edit: {v}");
    let within = Duration::from_secs(7);
    let mut rng = Lcg(28);
    let mut seen = (0, 0, 0);
    let mut edits = 0;
    for k in 0..5 {
        let sphere = [
            rng.within(0.0, 0.45),
            rng.within(-0.4, 0.1),
            rng.within(0.3, 0.75),
            rng.within(0.05, 0.1),
        ];
        let args: Vec<String> = sphere.iter().map(|x| format!("{x:.3}")).collect();
        let layout = args.join(" ");
        let mut add = vec!["obstacle", "add"];
        add.extend(args.iter().map(String::as_str));
        let (code, _, err) = ctl(ns, &add);
        // A sphere drawn round the arm may land on one of its links (the shoulder is always
        // near the middle of the region): that is refused, with the reason, and nothing
        // changes (no plan, no edit to count).
        if code == 1 && err.contains("inside that obstacle") {
            eprintln!("sphere {k} ({layout}): refused, on the arm: {err}");
            seen.2 += 1;
            continue;
        }
        assert_eq!(code, 0, "{layout}: {err}");
        edits += 1;
        // The edit's own plan (each add and removal is one): the answer is to it.
        let edit = 2 * edits - 1;
        let planned = |v: &serde_json::Value| v["plan"]["newest"]["generation"] == edit;
        let (v, _) = poll_status(ns, Duration::from_secs(5), planned);
        assert!(planned(&v), "sphere {k} ({layout}) not planned: {v}");
        match answer_to_edit(ns, within) {
            Answer::Blocked(v, took) => {
                let reason = v["blocked"]["reason"].as_str().unwrap();
                assert!(!reason.is_empty(), "{v}");
                eprintln!("sphere {k} ({layout}): blocked after {took:?}: {reason}");
                seen.1 += 1;
            }
            Answer::Tracking(_, took) => {
                eprintln!("sphere {k} ({layout}): tracking after {took:?}");
                seen.0 += 1;
            }
            Answer::Neither(v) => panic!(
                "sphere {k} ({layout}): neither tracking nor blocked after {within:?}: {v}\n{}",
                sys.daemon.log()
            ),
        }
        let (v, _) = remove_and_track(ns, "1");
        assert!(
            tracking(&v, 1e-3),
            "sphere {k} ({layout}): no tracking after the removal: {v}"
        );
    }
    eprintln!(
        "tracking on {} layouts, blocked on {}, refused on the arm {}",
        seen.0, seen.1, seen.2
    );
    assert!(seen.0 + seen.1 >= 3, "{seen:?}");
    assert_eq!(status(ns)["counters"]["faults"], 0, "{}", sys.daemon.log());
}

#[test]
fn a_live_panda_steers_round_a_new_sphere_and_says_blocked_for_one_on_its_path() {
    let _g = serial();
    let top = PANDA.replace(
        "[safety]\nenabled = true\n",
        "[safety]\nenabled = true\nplan = true\n",
    );
    assert_ne!(top, PANDA, "the preset's [safety] table moved");
    let sys = start("panda-plan", &top);
    let ns = &sys.ns;
    let (v, _) = poll_status(ns, Duration::from_secs(10), |v| {
        v["plan"]["steering"] == true && tracking(v, 1e-3)
    });
    assert!(
        tracking(&v, 1e-3),
        "steered from the start: {v}\n{}",
        sys.daemon.log()
    );

    // A sphere between the arm and the circle (the filter alone loses the path on it,
    // offline: control/tests/spatial_plan.rs): the edit's cycle goes round it, tracking
    // within 5 s.
    let (code, _, err) = ctl(
        ns,
        &["obstacle", "add", "0.089", "-0.196", "0.575", "0.058"],
    );
    assert_eq!(code, 0, "{err}");
    let planned = |v: &serde_json::Value| v["plan"]["newest"]["generation"].as_u64() >= Some(1);
    let (v, took) = poll_status(ns, Duration::from_secs(8), |v| {
        planned(v) && tracking(v, 1e-3)
    });
    assert!(
        planned(&v) && tracking(&v, 1e-3),
        "after {took:?}: {v}\n{}",
        sys.daemon.log()
    );
    assert!(
        took < Duration::from_secs(5),
        "tracking back after {took:?}"
    );
    assert_eq!(v["plan"]["newest"]["found"], true, "{v}");
    // Still tracking 2 s on (a host stall in between takes the hand off for a moment).
    std::thread::sleep(Duration::from_secs(2));
    let (v, _) = poll_status(ns, Duration::from_secs(1), |v| {
        tracking(v, 1e-3) && v["mode"] == "Run"
    });
    assert!(tracking(&v, 1e-3) && v["mode"] == "Run", "{v}");

    // A sphere on the hand's path, where the hand starts each period (0.307, 0, 0.487): no
    // cycle at all, said within 1 s, and the arm held. Put there while the hand is half a
    // period away, so that it is not put on the hand (which a hold then pushes out first).
    let (v, _) = poll_status(ns, Duration::from_secs(5), |v| {
        v["t"]
            .as_f64()
            .is_some_and(|t| (0.9..1.1).contains(&t.rem_euclid(2.0)))
    });
    assert!(v["t"].as_f64().is_some(), "{v}");
    let (code, _, err) = ctl(ns, &["obstacle", "add", "0.307", "0.0", "0.487", "0.03"]);
    assert_eq!(code, 0, "{err}");
    let (v, took) = poll_status(ns, Duration::from_secs(3), |v| !v["blocked"].is_null());
    assert!(took < Duration::from_secs(1), "Blocked after {took:?}: {v}");
    let reason = v["blocked"]["reason"].as_str().unwrap();
    assert!(reason.contains("path runs through obstacle 2"), "{reason}");
    assert_eq!(
        (
            v["blocked"]["obstacle"].as_u64(),
            v["blocked"]["link"].as_u64()
        ),
        (Some(2), Some(7)),
        "{v}"
    );
    let (v, _) = poll_status(ns, Duration::from_secs(2), |v| v["mode"] == "Hold");
    assert_eq!(v["mode"], "Hold", "tracking paused while blocked: {v}");

    // Removing it ends the block, and the arm tracks again round the first sphere.
    let (v, took) = remove_and_track(ns, "2");
    assert!(
        tracking(&v, 1e-3),
        "not tracking {took:?} after the removal: {v}"
    );
    assert_eq!(status(ns)["counters"]["faults"], 0, "{}", sys.daemon.log());
}

#[test]
fn a_live_panda_the_filter_traps_now_and_then_is_caught_and_steered_without_plan() {
    let _g = serial();
    // With steering off, the filter leaves the null space now and then and the hand goes
    // millimetres off its path, never 5 cm (`law.track_loss`), never for 2 s on end
    // (`safety.trap_time`).
    let cfg = panda_grazing_two_spheres("false");
    let sys = start("panda-recur", &cfg);
    let ns = &sys.ns;
    let trapped = |v: &serde_json::Value| {
        v["plan"]["newest"]["why"] == "trap" && v["plan"]["steering"] == true
    };
    let (v, took) = poll_status(ns, Duration::from_secs(60), trapped);
    // The traps come "now and then": a run whose host stalls nudged the self-motion onto a
    // clean cycle of its own (periodic, tracking, never trapped in a minute: two of ~8 full
    // runs here) has no trap to catch, and says so; anything else untrapped is a failure.
    if !trapped(&v)
        && v["chaos"]["verdict"] == "periodic"
        && tracking(&v, 1e-3)
        && v["counters"]["faults"] == 0
    {
        eprintln!("no trap in {took:?}: the arm found a clean periodic cycle by itself");
        return;
    }
    assert!(
        trapped(&v),
        "not caught in {took:?}: {v}\n{}",
        sys.daemon.log()
    );
    let log = sys.daemon.log();
    assert!(
        log.contains("trapped at t = ")
            && log.contains("the safety filter left the null space and cost"),
        "{log}"
    );
    // Steered onto the cycle planned from where the arm was: tracking, and staying so.
    let (v, took) = poll_status(ns, Duration::from_secs(10), |v| tracking(v, 1e-3));
    assert!(
        tracking(&v, 1e-3),
        "not tracking {took:?} after the trap: {v}"
    );
    std::thread::sleep(Duration::from_secs(8));
    let (v, _) = poll_status(ns, Duration::from_secs(1), |v| {
        tracking(v, 1e-3) && v["mode"] == "Run" && v["blocked"].is_null()
    });
    assert!(
        tracking(&v, 1e-3) && v["mode"] == "Run" && v["blocked"].is_null(),
        "{v}\n{}",
        sys.daemon.log()
    );
    assert_eq!(v["counters"]["faults"], 0, "{}", sys.daemon.log());
}
