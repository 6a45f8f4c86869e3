//! A live daemon and plant for a test, and chaosctl against them.
//!
//! Every system gets its own namespace and directory; `Proc` kills both processes when the
//! `System` is dropped, whatever the test's outcome.

use crate::deadline::Deadline;
use crate::{bin, unique_namespace, write_config, Proc, TempDir};
use std::path::Path;
use std::time::{Duration, Instant};

/// Runs chaosctl; returns (exit code, stdout, stderr). An `obstacle add` that the daemon
/// refuses because a link is inside the obstacle at that moment is tried again, for 5 s, as
/// the arm moves on: these tests put obstacles where the arm passes, at moments they cannot
/// choose (`own_robot` tests the refusal itself).
pub fn ctl(ns: &str, args: &[&str]) -> (i32, String, String) {
    let until = Instant::now() + Duration::from_secs(5);
    loop {
        let (code, out, err) = ctl_once(ns, args);
        let on_the_arm = code == 1 && err.contains("inside that obstacle");
        if !(on_the_arm && args.starts_with(&["obstacle", "add"]) && Instant::now() < until) {
            return (code, out, err);
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// [`ctl`] without the retry.
pub fn ctl_once(ns: &str, args: &[&str]) -> (i32, String, String) {
    let out = std::process::Command::new(bin("chaosctl"))
        .args(args)
        .args(["--namespace", ns])
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

pub fn status(ns: &str) -> serde_json::Value {
    let (code, out, err) = ctl(ns, &["status", "--json"]);
    assert_eq!(code, 0, "status failed: {err}");
    serde_json::from_str(&out).unwrap()
}

/// Polls `status --json` until `done` holds or `within` passes; the last status either way
/// (null while the daemon does not answer yet), and how long it took. Both count from the
/// last host stall when there was one ([`Deadline`]).
pub fn poll_status(
    ns: &str,
    within: Duration,
    done: impl Fn(&serde_json::Value) -> bool,
) -> (serde_json::Value, Duration) {
    let mut deadline = Deadline::new(within);
    loop {
        let (code, out, _) = ctl(ns, &["status", "--json"]);
        let v = if code == 0 {
            serde_json::from_str(&out).unwrap()
        } else {
            serde_json::Value::Null
        };
        deadline.observe(&v);
        if done(&v) || deadline.passed() {
            if deadline.stalls() > 0 {
                eprintln!(
                    "{} host stall(s) pushed the deadline back",
                    deadline.stalls()
                );
            }
            return (v, deadline.took());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A point near the paper's period-1 orbit (the one μ = 0.1 converges to), nudged off it: without
/// feedback the motion stays off the orbit; with it, it returns.
pub const NEAR_ORBIT: &str = "[sim]\nq0 = [1.550079628, -0.488376467, -0.934331288]\nqd0 = [-4.311482957, 9.229261970, -4.051303515]\n\
                          [feedback]\nmu = 0.0\nenabled = false\n";

pub struct System {
    pub ns: String,
    pub dir: TempDir,
    pub plant: Proc,
    pub daemon: Proc,
}

pub fn start(test: &str, top: &str) -> System {
    start_with_daemon(test, top, "")
}

/// [`start`] with extra `[daemon]` lines.
pub fn start_with_daemon(test: &str, top: &str, daemon_lines: &str) -> System {
    let ns = unique_namespace(test);
    let dir = TempDir::new(&ns);
    let cfg = write_config(dir.path(), &ns, daemon_lines, top);
    let c = cfg.to_str().unwrap().to_string();
    let daemon = Proc::spawn(
        "daemon",
        &bin("chaosd"),
        &["run", "--config", &c],
        dir.path(),
    );
    let plant = Proc::spawn("plant", &bin("chaosd-plant"), &["--config", &c], dir.path());
    let until = Instant::now() + Duration::from_secs(15);
    loop {
        let (code, out, _) = ctl(&ns, &["status", "--json"]);
        if code == 0 && serde_json::from_str::<serde_json::Value>(&out).unwrap()["mode"] == "Run" {
            break;
        }
        assert!(
            Instant::now() < until,
            "daemon never ran; daemon log:\n{}\nplant log:\n{}",
            daemon.log(),
            plant.log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    System {
        ns,
        dir,
        plant,
        daemon,
    }
}

/// Starts `chaosd-plant` and `chaosd run` on one config file, logging into `dir`.
pub fn spawn_pair(dir: &Path, cfg: &Path) -> (Proc, Proc) {
    let c = cfg.to_str().expect("a UTF-8 config path");
    let plant = Proc::spawn("plant", &bin("chaosd-plant"), &["--config", c], dir);
    let daemon = Proc::spawn("daemon", &bin("chaosd"), &["run", "--config", c], dir);
    (plant, daemon)
}

/// The daemon is blocked (`status --json`'s `blocked` is not null).
pub fn blocked(v: &serde_json::Value) -> bool {
    !v["blocked"].is_null()
}

/// Tracking within `tol` m over the daemon's last report window, and not blocked.
pub fn tracking(v: &serde_json::Value, tol: f64) -> bool {
    !blocked(v)
        && v["tracking_error_recent"]
            .as_f64()
            .is_some_and(|e| e <= tol)
}

/// How the daemon answered an edit: its status then, and after how long.
pub enum Answer {
    /// Tracking within 1e-3 m in two status reads in a row, 0.5 s apart.
    Tracking(serde_json::Value, Duration),
    Blocked(serde_json::Value, Duration),
    /// Neither within the time allowed.
    Neither(serde_json::Value),
}

/// Polls the daemon of `ns` after an edit until it tracks or says `Blocked`, for `within`
/// (from the last host stall when there was one: [`Deadline`]).
pub fn answer_to_edit(ns: &str, within: Duration) -> Answer {
    let mut deadline = Deadline::new(within);
    let mut good = 0;
    loop {
        let v = status(ns);
        deadline.observe(&v);
        good = if tracking(&v, 1e-3) { good + 1 } else { 0 };
        if blocked(&v) {
            return Answer::Blocked(v, deadline.took());
        }
        if good >= 2 {
            return Answer::Tracking(v, deadline.took());
        }
        if deadline.passed() {
            return Answer::Neither(v);
        }
        std::thread::sleep(Duration::from_millis(500));
    }
}

/// A small deterministic generator for layouts drawn at random, seed fixed.
pub struct Lcg(pub u64);

impl Lcg {
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn within(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
}

/// Removes obstacle number `index` (from 1) from the daemon of `ns` and waits, 8 s at most, for tracking
/// within 1e-3 m again: the status then, and how long it took.
pub fn remove_and_track(ns: &str, index: &str) -> (serde_json::Value, Duration) {
    let (code, _, err) = ctl(ns, &["obstacle", "rm", index]);
    assert_eq!(code, 0, "obstacle rm {index}: {err}");
    poll_status(ns, Duration::from_secs(8), |v| tracking(v, 1e-3))
}
