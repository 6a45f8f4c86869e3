//! Safety without deadlock on a live daemon and plant (issue 25): an obstacle edit that leaves
//! the arm no way round says `Blocked` at once, with the reason, in status, watch and the log,
//! and holds the arm; removing it brings tracking back. Whatever obstacle is added, the daemon
//! is tracking or `Blocked` within the stated times, and the run replays bit for bit with the
//! planner's handovers in it.

use serde_json::Value;
use std::path::Path;
use std::time::{Duration, Instant};
use tests::live::*;
use tests::*;

fn replay(path: &Path) -> (i32, String) {
    let out = std::process::Command::new(bin("chaosctl"))
        .arg("replay")
        .arg(path)
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    (out.status.code().unwrap_or(-1), text)
}

#[test]
fn an_obstacle_with_no_way_round_blocks_at_once_and_removing_it_resumes_tracking() {
    let _g = serial();
    let ns = unique_namespace("blocked");
    let dir = TempDir::new(&ns);
    // Steering from the start: the handovers then reach the replay recording too.
    let cfg = write_config(dir.path(), &ns, "", "[safety]\nplan = true\n");
    let c = cfg.to_str().unwrap();
    let mut daemon = Proc::spawn(
        "daemon",
        &bin("chaosd"),
        &["run", "--config", c, "--record", "blocked.replay"],
        dir.path(),
    );
    let mut plant = Proc::spawn("plant", &bin("chaosd-plant"), &["--config", c], dir.path());
    let (v, _) = poll_status(&ns, Duration::from_secs(15), |v| {
        v["mode"] == "Run" && v["plan"]["steering"] == true
    });
    assert!(
        v["mode"] == "Run" && v["plan"]["steering"] == true,
        "{v}\n{}",
        daemon.log()
    );
    // The start is off the planner's grid, so the steering begins with a short detour; the
    // issue's live bound (1e-3 m within 5 s) is asked, not the offline 1e-4 (one loaded run of
    // the whole suite measured 2.2e-4 m at 5 s).
    let (v, _) = poll_status(&ns, Duration::from_secs(5), |v| tracking(v, 1e-3));
    assert!(tracking(&v, 1e-3), "steered on an open layout: {v}");

    // A disc over the circle's right-hand point: the hand must pass through it. (It may land
    // on the arm: chaosctl's own start-up makes the moment uncertain. That the hold brakes
    // under the filter and never coasts into it is `controller`'s unit test, to the tick.)
    let (code, _, err) = ctl(&ns, &["obstacle", "add", "1.5", "2.0", "0.2"]);
    assert_eq!(code, 0, "{err}");
    let (v, took) = poll_status(&ns, Duration::from_secs(3), blocked);
    assert!(took < Duration::from_secs(1), "Blocked after {took:?}: {v}");
    let b = &v["blocked"];
    assert_eq!(b["action"], "hold", "{v}");
    assert_eq!(b["obstacle"], 1, "{v}");
    let reason = b["reason"].as_str().unwrap();
    assert!(reason.contains("obstacle 1"), "{reason}");
    let (v, _) = poll_status(&ns, Duration::from_secs(2), |v| v["mode"] == "Hold");
    assert_eq!(v["mode"], "Hold", "tracking paused while blocked: {v}");
    assert_eq!(v["plan"]["steering"], false, "{v}");
    // Said by status (human), watch and the log.
    let (_, human, _) = ctl(&ns, &["status"]);
    assert!(
        human.contains("BLOCKED") && human.contains("obstacle 1"),
        "{human}"
    );
    let (code, out, err) = ctl(&ns, &["watch", "--json", "--count", "1"]);
    assert_eq!(code, 0, "{err}");
    let w: Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(w["blocked"], "hold", "{out}");
    assert!(daemon.log().contains("BLOCKED at t ="), "{}", daemon.log());

    // Removing it ends the block, and the arm tracks again.
    let (code, _, err) = ctl(&ns, &["obstacle", "rm", "1"]);
    assert_eq!(code, 0, "{err}");
    let (v, took) = poll_status(&ns, Duration::from_secs(3), |v| !blocked(v));
    assert!(
        took < Duration::from_secs(1),
        "still blocked after {took:?}: {v}"
    );
    let (v, took) = poll_status(&ns, Duration::from_secs(8), |v| tracking(v, 1e-3));
    assert!(
        tracking(&v, 1e-3),
        "not tracking {took:?} after the removal: {v}"
    );
    assert!(
        took < Duration::from_secs(5),
        "tracking back after {took:?}"
    );

    let (code, _, err) = ctl(&ns, &["shutdown"]);
    assert_eq!(code, 0, "{err}");
    assert!(daemon.wait_exit(Duration::from_secs(15)).success());
    plant.terminate(Duration::from_secs(10));
    let summary = read_json(&dir.path().join("out/daemon-summary.json"));
    assert_eq!(summary["blocked_entered"], 1, "{summary}");

    // The steering and the hold are in the recording, and it replays bit for bit.
    let rec = dir.path().join("out/blocked.replay");
    let text = std::fs::read_to_string(&rec).unwrap();
    for (kind, what) in [("\nS ", "a steering handover"), ("\nB ", "a blocked hold")] {
        assert!(text.contains(kind), "no {what} recorded");
    }
    let (code, out) = replay(&rec);
    assert_eq!(code, 0, "{out}");
    let words: Vec<&str> = out.split_whitespace().collect();
    assert_eq!(words[0], words[2], "{out}");
}

#[test]
fn best_effort_runs_on_with_the_flag_raised_from_the_start() {
    let _g = serial();
    let ns = unique_namespace("besteffort");
    let dir = TempDir::new(&ns);
    let top = "[safety]\nwhen_blocked = \"best-effort\"\n\
               [[control.obstacles]]\ncenter = [1.5, 2.0]\nradius = 0.2\n";
    let cfg = write_config(dir.path(), &ns, "", top);
    let (_plant, daemon) = spawn_pair(dir.path(), &cfg);
    let (v, _) = poll_status(&ns, Duration::from_secs(15), |v| {
        v["mode"] == "Run" && blocked(v)
    });
    assert!(
        v["mode"] == "Run" && v["blocked"]["action"] == "best-effort",
        "{v}\n{}",
        daemon.log()
    );
    assert!(v["blocked"]["since"].as_f64().is_some(), "{v}");
}

#[test]
fn whatever_obstacle_is_added_the_daemon_tracks_or_says_blocked() {
    // The property, live: after an obstacle edit the daemon is tracking (≤ 1e-3 m) or `Blocked`
    // with a reason within 3 · trap_time (a trap, then steering that did not help), and a
    // removal brings tracking back. Layouts drawn round the arm's reach, seed fixed.
    let _g = serial();
    let sys = start("property", "");
    let (v, _) = poll_status(&sys.ns, Duration::from_secs(10), |v| tracking(v, 1e-3));
    assert!(tracking(&v, 1e-3), "no tracking before the first edit: {v}");
    let trap_time = 2.0;
    let mut rng = Lcg(25);
    let mut seen = (0, 0);
    for k in 0..5 {
        let (x, y) = (-0.2 + 1.9 * rng.uniform(), 0.6 + 2.2 * rng.uniform());
        let r = 0.08 + 0.17 * rng.uniform();
        let layout = format!("({x:.2}, {y:.2}) r {r:.2}");
        let args = [format!("{x:.3}"), format!("{y:.3}"), format!("{r:.3}")];
        let (code, _, err) = ctl(&sys.ns, &["obstacle", "add", &args[0], &args[1], &args[2]]);
        assert_eq!(code, 0, "{layout}: {err}");
        let within = Duration::from_secs_f64(3.0 * trap_time + 1.0);
        match answer_to_edit(&sys.ns, within) {
            Answer::Blocked(v, _) => {
                assert!(!v["blocked"]["reason"].as_str().unwrap().is_empty(), "{v}");
                seen.1 += 1;
            }
            Answer::Tracking(..) => seen.0 += 1,
            Answer::Neither(v) => {
                panic!("layout {k} {layout}: neither tracking nor blocked after {within:?}: {v}")
            }
        }
        let (v, _) = remove_and_track(&sys.ns, "1");
        assert!(
            tracking(&v, 1e-3),
            "layout {k} {layout}: no tracking after the removal: {v}"
        );
    }
    eprintln!("tracking on {} layouts, blocked on {}", seen.0, seen.1);
    let v = status(&sys.ns);
    assert_eq!(v["counters"]["faults"], 0, "{v}");
}

#[test]
fn the_obstacle_that_trapped_a_new_user_is_gone_round_and_tracked_within_5_s() {
    // The issue's own story: the default daemon, and `obstacle add 0.9 1.1 0.15` a few seconds
    // in. The filter alone held the arm 0.2 m off its path, silently. Now the planner finds a
    // clean cycle round the obstacle (by a joint-space detour when the arm is on its wrong
    // side), and the arm tracks it to 1e-3 m within 5 s of the edit, without a fault.
    let _g = serial();
    let sys = start("newuser", "");
    let (v, _) = poll_status(&sys.ns, Duration::from_secs(10), |v| {
        tracking(v, 1e-3) && v["t"].as_f64().is_some_and(|t| t >= 4.0)
    });
    assert!(tracking(&v, 1e-3), "no tracking before the edit: {v}");
    let (code, _, err) = ctl(&sys.ns, &["obstacle", "add", "0.9", "1.1", "0.15"]);
    assert_eq!(code, 0, "{err}");
    let edited = Instant::now();
    let (v, took) = poll_status(&sys.ns, Duration::from_secs(8), |v| {
        tracking(v, 1e-3) && v["obstacles"] == 1 && v["plan"]["newest"]["generation"] == 1
    });
    assert!(
        tracking(&v, 1e-3) && took <= Duration::from_secs(5),
        "not tracking 5 s after the edit ({took:?}, {:?} since): {v}",
        edited.elapsed()
    );
    assert_eq!(v["counters"]["faults"], 0, "{v}");
    eprintln!(
        "tracking again {took:?} after the edit; detour: {}",
        v["plan"]["detour"]
    );
}
