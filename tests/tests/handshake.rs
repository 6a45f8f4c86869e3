//! The handshake between a real daemon and real plants: a mismatched pair is refused by both
//! sides with a message naming both arms, the daemon never sends it a RUN command, and a plant
//! restart is judged again.

use protocol::Mode;
use std::path::{Path, PathBuf};
use std::time::Duration;
use tests::*;

const RUN: u32 = Mode::Run as u32;

/// A config in its own subdirectory of `dir` (so two processes of one test do not share an
/// output directory), in namespace `ns`, with `top` before `[daemon]`.
fn config_in(dir: &Path, sub: &str, ns: &str, top: &str) -> PathBuf {
    let d = dir.join(sub);
    std::fs::create_dir_all(&d).unwrap();
    write_config(&d, ns, "", top)
}

fn plant(name: &str, cfg: &Path, dir: &Path) -> Proc {
    Proc::spawn(
        name,
        &bin("chaosd-plant"),
        &["--config", cfg.to_str().unwrap()],
        dir,
    )
}

/// Waits until `proc`'s log contains `text`.
fn wait_for_log(proc: &Proc, text: &str, limit: Duration) {
    let until = std::time::Instant::now() + limit;
    while !proc.log().contains(text) {
        assert!(
            std::time::Instant::now() < until,
            "{} never said {text:?}; log:\n{}",
            proc.name,
            proc.log()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn a_plant_with_more_links_is_refused_by_both_sides() {
    let _g = serial();
    let ns = unique_namespace("hs-links");
    let dir = TempDir::new(&ns);
    let daemon_cfg = config_in(dir.path(), "d", &ns, "");
    let plant_cfg = config_in(
        dir.path(),
        "p",
        &ns,
        "[arm]\nlinks = [1.0, 1.0, 1.0, 1.0]\n",
    );
    let mut daemon = Proc::spawn(
        "daemon",
        &bin("chaosd"),
        &["run", "--config", daemon_cfg.to_str().unwrap()],
        dir.path(),
    );
    let mut m = Monitor::new(&ns);
    let mut p = plant("plant", &plant_cfg, dir.path());
    let expected = format!(
        "plant \"{ns}\" is a 4-link fixed arm (links 1,1,1,1), daemon expects a 3-link fixed arm (links 1,1,1); refusing"
    );
    // The plant exits non-zero, and says why.
    let st = p.wait_exit(Duration::from_secs(15));
    assert!(
        !st.success(),
        "the plant accepted a 3-link daemon:\n{}",
        p.log()
    );
    assert!(p.log().contains(&expected), "plant log:\n{}", p.log());
    // The daemon says it once, keeps it in `status`, and holds.
    wait_for_log(&daemon, &expected, Duration::from_secs(5));
    assert_eq!(
        daemon.log().matches(&expected).count(),
        1,
        "{}",
        daemon.log()
    );
    let s = live::status(&ns);
    assert_eq!(s["handshake"].as_str(), Some(expected.as_str()), "{s}");
    let (code, human, _) = live::ctl(&ns, &["status"]);
    assert_eq!(code, 0);
    assert!(human.contains(&format!("handshake {expected}")), "{human}");
    m.poll();
    assert!(
        m.seen_commands.iter().all(|c| c.mode != RUN),
        "the daemon sent a RUN command to a mismatched plant"
    );
    assert!(daemon.terminate(Duration::from_secs(10)).success());
}

#[test]
fn a_restarted_plant_with_other_link_lengths_is_refused_and_a_matching_one_runs_again() {
    let _g = serial();
    let ns = unique_namespace("hs-lengths");
    let dir = TempDir::new(&ns);
    let cfg = config_in(dir.path(), "d", &ns, "");
    let other_cfg = config_in(dir.path(), "p", &ns, "[arm]\nlinks = [1.0, 1.0, 1.25]\n");
    // The matched pair runs.
    let (mut p1, mut daemon) = live::spawn_pair(dir.path(), &cfg);
    let mut m = Monitor::new(&ns);
    m.wait_for("the matched pair to run", Duration::from_secs(15), |m| {
        m.seen_commands.iter().filter(|c| c.mode == RUN).count() > 100
    });
    assert!(live::status(&ns)["handshake"].is_null());
    // The plant restarts with other link lengths: refused, and never run.
    let ignored_before = live::status(&ns)["counters"]["not_agreed"]
        .as_u64()
        .unwrap();
    p1.kill9();
    let mut p2 = plant("plant2", &other_cfg, dir.path());
    let expected = format!(
        "plant \"{ns}\" is a 3-link fixed arm (links 1,1,1.25), daemon expects a 3-link fixed arm (links 1,1,1); refusing"
    );
    wait_for_log(&daemon, &expected, Duration::from_secs(10));
    // Commands already queued from the first plant are drained before p2's states can be seen.
    m.clear();
    let st = p2.wait_exit(Duration::from_secs(15));
    assert!(!st.success(), "plant2 accepted the daemon:\n{}", p2.log());
    assert!(p2.log().contains(&expected), "plant2 log:\n{}", p2.log());
    m.poll();
    let ignored = live::status(&ns)["counters"]["not_agreed"]
        .as_u64()
        .unwrap();
    assert!(
        ignored > ignored_before,
        "the daemon saw no state of plant2 ({ignored} ignored)"
    );
    assert!(
        m.seen_commands.iter().all(|c| c.mode != RUN),
        "the daemon sent RUN commands to a plant with other link lengths: {:?}",
        m.seen_commands.iter().find(|c| c.mode == RUN)
    );
    assert_eq!(
        live::status(&ns)["handshake"].as_str(),
        Some(expected.as_str())
    );
    // A matching plant again: judged again, agreed, run.
    let mut p3 = plant("plant3", &cfg, dir.path());
    m.clear();
    m.wait_for(
        "RUN with the matching plant",
        Duration::from_secs(15),
        |m| m.seen_commands.iter().filter(|c| c.mode == RUN).count() > 100,
    );
    assert!(live::status(&ns)["handshake"].is_null());
    assert!(daemon.terminate(Duration::from_secs(10)).success());
    assert!(p3.terminate(Duration::from_secs(10)).success());
}
