//! Running as a service: systemd's notify and watchdog protocol through a fake NOTIFY_SOCKET, and
//! the Prometheus exporter scraped over real HTTP, against the real processes.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::os::unix::net::UnixDatagram;
use std::time::{Duration, Instant};
use tests::live::{self, ctl};
use tests::{bin, serial, unique_namespace, write_config, Proc, TempDir};

/// Datagrams received until `until`, with their arrival times.
fn collect(sock: &UnixDatagram, until: Instant) -> Vec<(Instant, String)> {
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    while Instant::now() < until {
        if let Ok(n) = sock.recv(&mut buf) {
            got.push((
                Instant::now(),
                String::from_utf8_lossy(&buf[..n]).into_owned(),
            ));
        }
    }
    got
}

fn pings(v: &[(Instant, String)], from: Instant, to: Instant) -> usize {
    v.iter()
        .filter(|(t, m)| *t > from && *t < to && m.lines().any(|l| l == "WATCHDOG=1"))
        .count()
}

#[test]
fn systemd_hears_ready_and_pings_only_while_the_loop_ticks() {
    let _g = serial();
    let ns = unique_namespace("watchdog");
    let dir = TempDir::new(&ns);
    let cfg = write_config(dir.path(), &ns, "", "");
    let sock_path = dir.path().join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(20)))
        .unwrap();
    let period = Duration::from_millis(400);
    let mut daemon = Proc::spawn_env(
        "daemon",
        &bin("chaosd"),
        &["run", "--config", cfg.to_str().unwrap()],
        &[
            ("NOTIFY_SOCKET", sock_path.to_str().unwrap()),
            ("WATCHDOG_USEC", &period.as_micros().to_string()),
        ],
        dir.path(),
    );

    // READY first, once the loop ticks (no plant is needed: without states it ticks in HOLD).
    let t0 = Instant::now();
    let mut first = None;
    let mut buf = [0u8; 4096];
    while first.is_none() && t0.elapsed() < Duration::from_secs(20) {
        if let Ok(n) = sock.recv(&mut buf) {
            first = Some(String::from_utf8_lossy(&buf[..n]).into_owned());
        }
    }
    let first = first.unwrap_or_else(|| panic!("no READY in 20 s; log:\n{}", daemon.log()));
    assert!(
        first.lines().any(|l| l == "READY=1"),
        "first message: {first:?}"
    );

    // Pings while the loop runs: the notifier looks four times per period.
    let start = Instant::now();
    let running = collect(&sock, start + Duration::from_millis(1500));
    let n = pings(&running, start, Instant::now());
    assert!(
        n >= 3,
        "{n} pings in 1.5 s with a 400 ms watchdog: {running:?}"
    );

    // Stall only the loop (a stuck tick); the process and its notifier thread stay alive.
    let (code, out, err) = ctl(&ns, &["debug-stall", "4000"]);
    assert_eq!(code, 0, "debug-stall: {out}{err}");
    let asked = Instant::now();
    let during = collect(&sock, asked + Duration::from_millis(6000));
    let late = pings(&during, asked + period, asked + Duration::from_millis(3000));
    assert_eq!(
        late, 0,
        "pings went on more than one watchdog period into a stalled loop: {during:?}"
    );
    let resumed = pings(
        &during,
        asked + Duration::from_millis(4200),
        asked + Duration::from_millis(6000),
    );
    assert!(
        resumed >= 1,
        "no pings after the stall ended: {during:?}\n{}",
        daemon.log()
    );
    assert!(
        daemon.log().contains("stopped ticking"),
        "the notifier thread said nothing while the loop stalled:\n{}",
        daemon.log()
    );

    let st = daemon.terminate(Duration::from_secs(15));
    assert!(st.success(), "{st:?}\n{}", daemon.log());
    let rest = collect(&sock, Instant::now() + Duration::from_millis(200));
    assert!(
        rest.iter().any(|(_, m)| m.contains("STOPPING=1")),
        "no STOPPING=1 at exit: {rest:?}"
    );
    // A bad stall is refused with one line, and nothing panics.
    let (code, _, err) = ctl(&ns, &["debug-stall", "0"]);
    assert_ne!(code, 0);
    assert!(!err.contains("panicked"), "{err}");
}

/// One HTTP/1.1 request; returns (status, body) and the time it took.
fn http(addr: &str, method: &str, path: &str) -> (u16, String, Duration) {
    let t = Instant::now();
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut text = String::new();
    s.read_to_string(&mut text).unwrap();
    let took = t.elapsed();
    let code = text
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let len: usize = head
        .lines()
        .find_map(|l| l.strip_prefix("Content-Length: "))
        .and_then(|v| v.trim().parse().ok())
        .expect("a Content-Length header");
    if method != "HEAD" {
        assert_eq!(len, body.len(), "Content-Length disagrees with the body");
    }
    (code, body.to_string(), took)
}

/// The value of the series `name{labels}` in an exposition text.
fn value(text: &str, series: &str) -> Option<f64> {
    text.lines()
        .find_map(|l| l.strip_prefix(series)?.strip_prefix(' '))
        .map(|v| match v {
            "+Inf" => f64::INFINITY,
            "NaN" => f64::NAN,
            v => v.parse().unwrap(),
        })
}

#[test]
fn the_exporter_serves_prometheus_metrics_from_a_live_daemon() {
    let _g = serial();
    let sys = live::start("exporter", "");
    let ns = &sys.ns;
    let absent = format!("{ns}-none");
    let exporter = Proc::spawn(
        "exporter",
        &bin("chaosctl"),
        &[
            "exporter",
            "--listen",
            "127.0.0.1:0",
            "--namespace",
            ns,
            "--namespace",
            &absent,
        ],
        sys.dir.path(),
    );
    let t0 = Instant::now();
    let addr = loop {
        let log = exporter.log();
        if let Some(a) = log
            .split("serving http://")
            .nth(1)
            .and_then(|r| r.split("/metrics").next())
        {
            break a.to_string();
        }
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "the exporter never said where it serves:\n{log}"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    let up = format!("chaosd_up{{namespace=\"{ns}\"}}");
    let ticks = format!("chaosd_ticks_total{{namespace=\"{ns}\"}}");
    let mut text = String::new();
    while value(&text, &up) != Some(1.0) {
        assert!(
            t0.elapsed() < Duration::from_secs(15),
            "the daemon never showed up:\n{text}"
        );
        std::thread::sleep(Duration::from_millis(100));
        text = http(&addr, "GET", "/metrics").1;
    }
    let a = value(&text, &ticks).expect("ticks");
    std::thread::sleep(Duration::from_millis(1500));
    let (code, text, took) = http(&addr, "GET", "/metrics");
    assert_eq!(code, 200);
    let b = value(&text, &ticks).expect("ticks");
    assert!(b > a, "ticks did not increase: {a} → {b}");
    for fam in [
        "chaosd_overruns_total",
        "chaosd_faults_total",
        "chaosd_rejected_samples_total",
        "chaosd_telemetry_dropped_total",
        "chaosd_mu",
        "chaosd_tau_seconds",
        "chaosd_feedback_on",
        "chaosd_tracking_error_meters",
        "chaosd_period_residual_rad_per_second",
        "chaosd_clearance_meters",
    ] {
        assert!(
            value(&text, &format!("{fam}{{namespace=\"{ns}\"}}")).is_some(),
            "{fam} missing:\n{text}"
        );
    }
    assert_eq!(
        value(
            &text,
            &format!("chaosd_mode{{namespace=\"{ns}\",mode=\"run\"}}")
        ),
        Some(1.0)
    );
    // Every kind of limit breach has its counter, from the daemon's own watch (none here).
    for kind in protocol::LIMIT_BREACH_KINDS {
        assert_eq!(
            value(
                &text,
                &format!("chaosd_limit_breaches_total{{namespace=\"{ns}\",kind=\"{kind}\"}}")
            ),
            Some(0.0),
            "{kind}:\n{text}"
        );
    }
    for q in ["0.5", "0.99", "0.999", "1"] {
        for d in ["wakeup_lateness", "compute", "state_age"] {
            let v = value(
                &text,
                &format!("chaosd_{d}_seconds{{namespace=\"{ns}\",quantile=\"{q}\"}}"),
            )
            .unwrap_or(f64::NAN);
            assert!(v.is_finite() && v >= 0.0, "{d} {q} = {v}:\n{text}");
        }
    }
    // Every series is labelled with its namespace; the absent daemon is down and has no counters.
    for l in text.lines().filter(|l| !l.starts_with('#')) {
        assert!(
            l.contains(&format!("namespace=\"{ns}\""))
                || l.contains(&format!("namespace=\"{absent}\"")),
            "{l}"
        );
    }
    assert_eq!(
        value(&text, &format!("chaosd_up{{namespace=\"{absent}\"}}")),
        Some(0.0)
    );
    assert!(!text.contains(&format!("chaosd_ticks_total{{namespace=\"{absent}\"}}")));
    eprintln!("one scrape over HTTP took {took:?}");

    assert_eq!(http(&addr, "GET", "/").0, 404);
    assert_eq!(http(&addr, "GET", "/metricsx").0, 404);
    assert_eq!(http(&addr, "POST", "/metrics").0, 405);
    assert_eq!(http(&addr, "HEAD", "/metrics").0, 200);

    // Bad arguments: one clear line, exit 2, no panic.
    for args in [
        &["exporter", "--listen", "nowhere"][..],
        &["exporter", "--namespace", "bad name!"][..],
    ] {
        let out = std::process::Command::new(bin("chaosctl"))
            .args(args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    drop(exporter);
    drop(sys);
}
