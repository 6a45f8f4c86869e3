//! Stop signals as supervisors send them: several at once must still give a clean stop.

use std::time::Duration;
use tests::live::*;
use tests::*;

fn signal_twice(p: &Proc) {
    for _ in 0..2 {
        // SAFETY: kill(2) on our own child.
        unsafe { libc::kill(p.pid() as i32, libc::SIGTERM) };
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn a_second_stop_signal_does_not_cut_the_clean_stop_short() {
    let _g = serial();
    let mut sys = start("signals", "");
    std::thread::sleep(Duration::from_millis(500));
    // Both processes get two SIGTERMs 1 ms apart, as `timeout` and a supervisor would send.
    signal_twice(&sys.daemon);
    signal_twice(&sys.plant);
    let d = sys.daemon.wait_exit(Duration::from_secs(15));
    let p = sys.plant.wait_exit(Duration::from_secs(15));
    assert!(d.success(), "daemon: {d:?}\n{}", sys.daemon.log());
    assert!(p.success(), "plant: {p:?}\n{}", sys.plant.log());
    let out = sys.dir.path().join("out");
    for f in [
        "daemon-summary.json",
        "daemon-lateness.hgrm",
        "daemon.hlog",
        "plant-summary.json",
        "plant-round-trip.hgrm",
    ] {
        assert!(out.join(f).exists(), "{f} was not written");
    }
    let summary = read_json(&out.join("daemon-summary.json"));
    assert!(
        summary["counters"]["ticks"].as_u64().unwrap() > 100,
        "{summary}"
    );
}

#[test]
fn a_shutdown_request_followed_by_a_supervisors_sigterm_still_stops_cleanly() {
    let _g = serial();
    let mut sys = start("signals-shutdown", "");
    std::thread::sleep(Duration::from_millis(500));
    // `chaosctl shutdown`, then at once the SIGTERM a supervisor sends when it stops the unit.
    let (code, _, err) = ctl(&sys.ns, &["shutdown"]);
    assert_eq!(code, 0, "{err}");
    signal_twice(&sys.daemon);
    let d = sys.daemon.wait_exit(Duration::from_secs(15));
    assert!(d.success(), "daemon: {d:?}\n{}", sys.daemon.log());
    let out = sys.dir.path().join("out");
    for f in ["daemon-summary.json", "daemon-lateness.hgrm", "daemon.hlog"] {
        assert!(out.join(f).exists(), "{f} was not written");
    }
    // The plant, left without a controller, still stops cleanly on its own SIGTERMs.
    signal_twice(&sys.plant);
    let p = sys.plant.wait_exit(Duration::from_secs(15));
    assert!(p.success(), "plant: {p:?}\n{}", sys.plant.log());
}
