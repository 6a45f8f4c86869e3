//! chaosctl against a live daemon and plant: steering, refusals, concurrency, recording, shutdown.

use protocol::{ServiceNames, TelemetrySample};
use std::path::Path;
use std::time::{Duration, Instant};
use tests::live::*;
use tests::*;

struct Telemetry {
    _node: iceoryx2::node::Node<iceoryx2::prelude::ipc::Service>,
    sub: iceoryx2::port::subscriber::Subscriber<
        iceoryx2::prelude::ipc::Service,
        TelemetrySample,
        (),
    >,
}

impl Telemetry {
    fn new(ns: &str) -> Self {
        let node = node();
        let svc = protocol::control::open_telemetry_service(&node, &ServiceNames::new(ns).unwrap())
            .unwrap();
        let sub = svc.subscriber_builder().create().unwrap();
        Self { _node: node, sub }
    }
    /// Telemetry samples over `secs` seconds.
    fn collect(&self, secs: f64) -> Vec<TelemetrySample> {
        let until = Instant::now() + Duration::from_secs_f64(secs);
        let mut v = Vec::new();
        while Instant::now() < until {
            while let Ok(Some(s)) = self.sub.receive() {
                v.push(*s);
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        v
    }
}

/// The median of a window's period residuals.
fn median_residual(v: &[TelemetrySample]) -> f64 {
    let mut x: Vec<f64> = v
        .iter()
        .map(|t| t.period_residual)
        .filter(|r| r.is_finite())
        .collect();
    assert!(!x.is_empty(), "no telemetry");
    x.sort_by(f64::total_cmp);
    x[x.len() / 2]
}

/// The median of the quietest second of a window `seconds` long. One burst of late ticks
/// kicks the self-motion for a second or two, and any statistic over the whole window
/// follows it: in one full run 190 overruns in 2 s took a residual settled at 0.004-0.03 rad/s
/// back to 0.4 just as the window opened. The feedback's effect is the level the motion
/// settles to between kicks; the chaotic motion has no second that quiet.
fn quietest_second(v: &[TelemetrySample], seconds: f64) -> f64 {
    let per = ((v.len() as f64 / seconds).round() as usize).max(1);
    v.chunks(per)
        .filter(|c| c.len() == per)
        .map(median_residual)
        .fold(f64::INFINITY, f64::min)
}

/// Overruns in one telemetry window that say the host stalled the loop (a 10 ms stall makes
/// ten).
const STALL_OVERRUNS: u64 = 10;

/// The periods the loop overran over a window of telemetry.
fn overruns_in(v: &[TelemetrySample]) -> u64 {
    match (v.first(), v.last()) {
        (Some(a), Some(b)) => b.overruns.saturating_sub(a.overruns),
        _ => 0,
    }
}

#[test]
fn set_mu_and_dfc_on_change_the_loop_and_the_period_residual_falls() {
    let _g = serial();
    let mut s = start("dfc", NEAR_ORBIT);
    let tel = Telemetry::new(&s.ns);
    tel.collect(1.5);
    let before = tel.collect(3.0);
    assert!(before.iter().all(|t| t.feedback_active == 0 && t.mu == 0.0));
    let r_before = quietest_second(&before, 3.0);

    let (code, out, err) = ctl(&s.ns, &["set", "mu", "0.5"]);
    assert_eq!(code, 0, "{out}{err}");
    let (code, _, err) = ctl(&s.ns, &["dfc", "on"]);
    assert_eq!(code, 0, "{err}");
    // Offline the feedback needs ~10 s; live, late ticks kick the self-motion (100–300
    // overruns in this test's 25 s on this VM). Its quietest second in the 10 s after a 5 s
    // settle is compared with the quietest second before.
    tel.collect(5.0);
    let after = tel.collect(10.0);
    assert!(
        after.iter().all(|t| t.mu == 0.5 && t.feedback_active == 1),
        "telemetry must show the new μ with the feedback applied"
    );
    let mut r_after = quietest_second(&after, 10.0);
    // A host that kept kicking the motion (a stall's overruns in the window) gets two more
    // windows for it to settle between kicks; a quiet one does not.
    let mut window = after.clone();
    for _ in 0..2 {
        if r_after < r_before / 2.0 || overruns_in(&window) < STALL_OVERRUNS {
            break;
        }
        window = tel.collect(10.0);
        r_after = r_after.min(quietest_second(&window, 10.0));
        eprintln!("stalls in the window: another 10 s, quietest second {r_after:.4} rad/s");
    }
    let last = window.last().unwrap();
    let series: Vec<String> = after
        .iter()
        .step_by(6)
        .map(|t| format!("{:.3}", t.period_residual))
        .collect();
    eprintln!(
        "period residual: {r_before:.4} rad/s before, {r_after:.4} rad/s with feedback; overruns {}, holds {}, rejected {}; late max {:.0} µs; after-window series {:?}",
        last.overruns, last.holds, last.rejected, after.iter().map(|t| t.lateness_max_us).fold(0.0, f64::max), series
    );
    // Offline the same start falls ~8× in 15 s; the live loop shares the machine with the test.
    assert!(
        r_after < r_before / 2.0,
        "period residual {r_before} rad/s before, {r_after} rad/s after feedback\n{}",
        s.daemon.log()
    );
    assert_eq!(status(&s.ns)["counters"]["params_applied"], 2);

    let (code, _, err) = ctl(&s.ns, &["dfc", "off"]);
    assert_eq!(code, 0, "{err}");
    let off = tel.collect(1.0);
    assert!(off
        .last()
        .is_some_and(|t| t.feedback_on == 0 && t.feedback_active == 0));
    assert!(s.daemon.terminate(Duration::from_secs(10)).success());
    s.plant.terminate(Duration::from_secs(10));
}

#[test]
fn bad_requests_are_refused_and_the_loop_keeps_running_unchanged() {
    let _g = serial();
    let mut s = start("refuse", "");
    let before = status(&s.ns);
    for (args, want) in [
        (&["set", "mu", "-1"][..], "feedback.mu"),
        (&["set", "kp", "1e9"], "law.kp"),
        (&["set", "frobnicate", "2"], "unknown key"),
        (&["set", "tau", "2.5"], "max_tau"),
        (&["set", "mu", "1", "tau", "9"], "max_tau"),
        (&["obstacle", "add", "0", "1", "-0.2"], "radius"),
        (&["obstacle", "rm", "4"], "no obstacle 4"),
        (
            &["record", "start", "../../etc/x.csv"],
            "inside the output directory",
        ),
        (&["record", "stop"], "not recording"),
    ] {
        let (code, out, err) = ctl(&s.ns, args);
        assert_eq!(code, 1, "{args:?} should be refused: {out} {err}");
        assert!(
            err.contains(want) && err.contains("refused"),
            "{args:?}: {err}"
        );
    }
    // Usage errors are the client's own (exit 2) and never reach the daemon.
    for args in [
        &["set"][..],
        &["dfc", "maybe"],
        &["obstacle", "add", "x", "1", "1"],
    ] {
        let (code, _, err) = ctl(&s.ns, args);
        assert_eq!(code, 2, "{args:?}: {err}");
    }
    std::thread::sleep(Duration::from_millis(300));
    let after = status(&s.ns);
    for k in ["mu", "tau", "kp", "obstacles", "t_on"] {
        assert_eq!(before[k], after[k], "{k} changed");
    }
    assert_eq!(after["counters"]["params_applied"], 0);
    assert_eq!(after["mode"], "Run");
    assert!(
        after["counters"]["ticks"].as_u64() > before["counters"]["ticks"].as_u64(),
        "the loop stopped"
    );
    assert!(s.daemon.terminate(Duration::from_secs(10)).success());
    s.plant.terminate(Duration::from_secs(10));
}

#[test]
fn watch_shows_the_command_interface_and_the_limiter() {
    let _g = serial();
    let mut s = start("watch-line", "");
    let (code, out, err) = ctl(&s.ns, &["watch", "--count", "3"]);
    assert_eq!(code, 0, "{err}");
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 3, "{out}");
    // The planar arm is commanded in accelerations; its pass-through limiter clamps nothing.
    assert!(
        lines
            .iter()
            .all(|l| l.contains("| Run  | acceleration, clamped 0 |")),
        "{out}"
    );
    let (code, out, err) = ctl(&s.ns, &["watch", "--json", "--count", "1"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["interface"], "acceleration", "{v}");
    assert!(v["device"].is_null(), "{v}");
    assert_eq!(v["saturations"]["jerk"], 0, "{v}");
    assert!(s.daemon.terminate(Duration::from_secs(10)).success());
    s.plant.terminate(Duration::from_secs(10));
}

#[test]
fn two_clients_at_once_both_get_answers() {
    let _g = serial();
    let mut s = start("clients", "");
    let ns = s.ns.clone();
    let workers: Vec<_> = (0..2)
        .map(|w| {
            let ns = ns.clone();
            std::thread::spawn(move || {
                (0..15)
                    .map(|i| {
                        let args: &[&str] = if (i + w) % 2 == 0 {
                            &["status", "--json"]
                        } else {
                            &["hist"]
                        };
                        ctl(&ns, args).0
                    })
                    .collect::<Vec<_>>()
            })
        })
        .collect();
    for w in workers {
        let codes = w.join().unwrap();
        assert!(codes.iter().all(|c| *c == 0), "{codes:?}");
    }
    assert!(s.daemon.terminate(Duration::from_secs(10)).success());
    s.plant.terminate(Duration::from_secs(10));
}

#[test]
fn a_recording_reads_back_and_matches_the_telemetry() {
    let _g = serial();
    let mut s = start("record", "");
    let tel = Telemetry::new(&s.ns);
    let (code, out, err) = ctl(&s.ns, &["record", "start", "rec/run.csv"]);
    assert_eq!(code, 0, "{err}");
    let path: serde_json::Value = serde_json::from_str(&out).unwrap();
    let path = Path::new(path["path"].as_str().unwrap()).to_path_buf();
    assert!(
        path.starts_with(s.dir.path().join("out")),
        "{}",
        path.display()
    );
    let samples = tel.collect(1.5);
    let (code, out, _) = ctl(&s.ns, &["record", "stop"]);
    assert_eq!(code, 0);
    let rows: serde_json::Value = serde_json::from_str(&out).unwrap();
    // Owner-only: the recording, its directory and the daemon's other files.
    use std::os::unix::fs::PermissionsExt;
    for p in [
        path.clone(),
        path.parent().unwrap().to_path_buf(),
        s.dir.path().join("out/config.toml"),
    ] {
        let mode = std::fs::metadata(&p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode & 0o077, 0, "{} has mode {mode:o}", p.display());
    }
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(&header[..4], &["t", "state_seq", "state_stamp_ns", "phi"]);
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let data: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(data.len() as u64, rows["rows"].as_u64().unwrap());
    assert!(data.len() > 500, "{} rows in 1.5 s at 1 kHz", data.len());
    // Every telemetry sample taken while recording names a state that is in the file, with the
    // same joint angles and rates.
    let mut matched = 0;
    for t in &samples {
        if let Some(row) = data
            .iter()
            .find(|r| r[col("state_seq")].parse::<u64>().ok() == Some(t.state_seq))
        {
            for (i, name) in ["q1", "q2", "q3", "qd1", "qd2", "qd3"].iter().enumerate() {
                let v: f64 = row[col(name)].parse().unwrap();
                let want = if i < 3 { t.q[i] } else { t.qd[i - 3] };
                assert!(
                    (v - want).abs() <= 1e-10 * (1.0 + want.abs()),
                    "{name}: file {v}, telemetry {want}"
                );
            }
            matched += 1;
        }
    }
    assert!(
        matched >= samples.len().saturating_sub(3) && matched > 10,
        "{matched} of {} telemetry samples found in the recording",
        samples.len()
    );
    assert!(s.daemon.terminate(Duration::from_secs(10)).success());
    s.plant.terminate(Duration::from_secs(10));
}

#[test]
fn shutdown_ends_the_daemon_cleanly() {
    let _g = serial();
    let mut s = start("shutdown", "");
    let seen = status(&s.ns)["counters"]["ticks"].as_u64().unwrap();
    let (code, out, _) = ctl(&s.ns, &["shutdown"]);
    assert_eq!((code, out.trim()), (0, "shutting down"));
    let st = s.daemon.wait_exit(Duration::from_secs(10));
    assert!(st.success(), "{}", s.daemon.log());
    // The exit summary covers the whole run: at least every tick the daemon had reported.
    let d = read_json(&s.dir.path().join("out/daemon-summary.json"));
    let ticks = d["counters"]["ticks"].as_u64().unwrap();
    assert!(
        seen > 0 && ticks >= seen,
        "summary has {ticks} ticks, status had already reported {seen}"
    );
    assert!(s.dir.path().join("out/daemon-lateness.hgrm").exists());
    // Nobody answers any more: a clear error naming the namespace, exit 3, no hang.
    let t0 = Instant::now();
    let (code, _, err) = ctl(&s.ns, &["status"]);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains(&s.ns), "{err}");
    assert!(t0.elapsed() < Duration::from_secs(5));
    s.plant.terminate(Duration::from_secs(10));
}

#[test]
fn without_a_daemon_requests_fail_fast_with_the_namespace_named() {
    let ns = unique_namespace("nobody");
    for args in [&["status"][..], &["set", "mu", "1"], &["shutdown"]] {
        let (code, _, err) = ctl(&ns, args);
        assert_eq!(code, 3, "{args:?}: {err}");
        assert!(
            err.contains(&ns) && err.contains("is the daemon running"),
            "{err}"
        );
    }
    let t0 = Instant::now();
    let (code, _, err) = ctl(&ns, &["watch", "--timeout", "0.5"]);
    assert_eq!(code, 3, "{err}");
    assert!(
        err.contains(&ns) && t0.elapsed() < Duration::from_secs(5),
        "{err}"
    );
    let (code, _, err) = ctl("bad/ns", &["status"]);
    assert_eq!(code, 2, "{err}");
}
