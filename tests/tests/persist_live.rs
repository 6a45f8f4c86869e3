//! A daemon restart keeps what the operator changed live, controller time, and a FAULT.

use std::time::{Duration, Instant};
use tests::live::*;
use tests::*;

fn wait_mode(ns: &str, mode: &str) -> serde_json::Value {
    let until = Instant::now() + Duration::from_secs(15);
    loop {
        let (code, out, _) = ctl(ns, &["status", "--json"]);
        if code == 0 {
            let st: serde_json::Value = serde_json::from_str(&out).unwrap();
            if st["mode"] == mode {
                return st;
            }
        }
        assert!(Instant::now() < until, "never reached {mode}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn restart_daemon(sys: &mut System, name: &str, extra: &[&str]) {
    sys.daemon.kill9();
    let cfg = sys.dir.path().join("config.toml");
    let mut args = vec!["run", "--config", cfg.to_str().unwrap()];
    args.extend_from_slice(extra);
    sys.daemon = Proc::spawn(name, &bin("chaosd"), &args, sys.dir.path());
}

#[test]
fn a_restarted_daemon_resumes_live_changes_time_and_a_fault() {
    let _g = serial();
    let mut sys = start("persist", "");
    let ns = sys.ns.clone();
    for args in [
        &["set", "mu", "0.7", "kp", "35"][..],
        &["obstacle", "add", "0", "1.6", "0.2"][..],
    ] {
        let (code, _, err) = ctl(&ns, args);
        assert_eq!(code, 0, "{args:?}: {err}");
    }
    std::thread::sleep(Duration::from_millis(1500));
    let t_before = status(&ns)["t"].as_f64().unwrap();

    // kill -9 and start again from the same file: the live changes and time come back.
    restart_daemon(&mut sys, "daemon2", &[]);
    let st = wait_mode(&ns, "Run");
    assert_eq!(
        (st["mu"].as_f64(), st["kp"].as_f64()),
        (Some(0.7), Some(35.0)),
        "{st}"
    );
    assert_eq!(st["obstacles"], 1, "{st}");
    assert!(
        st["t"].as_f64().unwrap() >= t_before,
        "controller time went back: {st}"
    );
    assert!(
        sys.daemon.log().contains("resuming the live state"),
        "{}",
        sys.daemon.log()
    );

    // A FAULT survives a crash: the restarted daemon brakes until an operator resumes.
    let (code, _, err) = ctl(&ns, &["set", "safety", "off", "safety.qd_max", "1"]);
    assert_eq!(code, 0, "{err}");
    wait_mode(&ns, "Fault");
    std::thread::sleep(Duration::from_millis(100));
    restart_daemon(&mut sys, "daemon3", &[]);
    let st = wait_mode(&ns, "Fault");
    assert!(
        st["fault"].as_str().unwrap().contains("last stopped"),
        "{st}"
    );
    std::thread::sleep(Duration::from_millis(500));
    assert_eq!(status(&ns)["mode"], "Fault", "a restored FAULT must hold");
    let (code, _, err) = ctl(&ns, &["set", "safety", "on"]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = ctl(&ns, &["resume"]);
    assert_eq!(code, 0, "{err}");
    wait_mode(&ns, "Run");

    // --fresh starts from the file alone.
    restart_daemon(&mut sys, "daemon4", &["--fresh"]);
    let st = wait_mode(&ns, "Run");
    assert_eq!(
        (st["mu"].as_f64(), st["obstacles"].as_u64()),
        (Some(0.0), Some(0)),
        "{st}"
    );
    assert!(st["t"].as_f64().unwrap() < 5.0, "{st}");

    // A file edited since the state was saved wins over the live changes made before the edit.
    let (code, _, err) = ctl(&ns, &["set", "mu", "0.4"]);
    assert_eq!(code, 0, "{err}");
    std::thread::sleep(Duration::from_millis(300));
    let cfg = sys.dir.path().join("config.toml");
    let text = std::fs::read_to_string(&cfg).unwrap();
    std::fs::write(&cfg, format!("[control]\nkp = 30.0\n{text}")).unwrap();
    restart_daemon(&mut sys, "daemon5", &[]);
    let st = wait_mode(&ns, "Run");
    assert_eq!(
        (st["mu"].as_f64(), st["kp"].as_f64()),
        (Some(0.0), Some(30.0)),
        "{st}"
    );
    assert!(
        sys.daemon
            .log()
            .contains("changed since the live state was saved"),
        "{}",
        sys.daemon.log()
    );
}
