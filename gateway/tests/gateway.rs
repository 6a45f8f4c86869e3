//! Two gateways on the loopback, two real daemon + plant pairs standing in for two hosts:
//! `status`, `set mu` and `watch` through Zenoh, `fleet` listing both, a `set` refused by the
//! read-only gateway (and the daemon unchanged), and clear errors for a missing gateway.
//!
//! Gateway A (`host-a`, --allow-changes) serves daemon A; gateway B (`host-b`, read-only) serves
//! daemon B and connects to A. Every remote command goes through the *other* host's gateway, so
//! each answer crossed both gateways and the TCP link between them.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};
use tests::{live, serial, Proc};

fn gw(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_chaosd-gateway"))
        .args(args)
        .output()
        .expect("run chaosd-gateway");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

fn serve(name: &str, ns: &str, host: &str, args: &[&str], dir: &Path) -> Proc {
    let mut all = vec!["serve", "--namespace", ns, "--host", host];
    all.extend(args);
    Proc::spawn(
        name,
        Path::new(env!("CARGO_BIN_EXE_chaosd-gateway")),
        &all,
        dir,
    )
}

#[test]
fn two_gateways_status_set_watch_fleet_and_a_read_only_refusal() {
    let _g = serial();
    let a = live::start("gw-a", "");
    let b = live::start("gw-b", "");
    let (pa, pb) = (free_port(), free_port());
    let ea = format!("tcp/127.0.0.1:{pa}");
    let eb = format!("tcp/127.0.0.1:{pb}");
    let mut ga = serve(
        "gateway-a",
        &a.ns,
        "host-a",
        &["--listen", &ea, "--allow-changes"],
        a.dir.path(),
    );
    let mut gb = serve(
        "gateway-b",
        &b.ns,
        "host-b",
        &["--listen", &eb, "--connect", &ea],
        b.dir.path(),
    );

    // Both controllers appear in the fleet, seen from either gateway.
    let until = Instant::now() + Duration::from_secs(20);
    let fleet = loop {
        let (code, out, err) = gw(&["fleet", "--remote", &eb]);
        if code == 0 && out.contains("2 controller(s)") {
            break out;
        }
        assert!(
            Instant::now() < until,
            "fleet never listed both: {code} {out} {err}\ngateway A:\n{}\ngateway B:\n{}",
            ga.log(),
            gb.log()
        );
        std::thread::sleep(Duration::from_millis(250));
    };
    let line = |host: &str| {
        fleet
            .lines()
            .find(|l| l.starts_with(host))
            .unwrap_or_else(|| panic!("no {host} in:\n{fleet}"))
            .to_string()
    };
    let (la, lb) = (line("host-a"), line("host-b"));
    assert!(
        la.contains(&a.ns) && la.contains("changes-allowed") && la.contains("Run"),
        "{la}"
    );
    assert!(
        lb.contains(&b.ns) && lb.contains("read-only") && lb.contains("Run"),
        "{lb}"
    );
    assert!(ga.log().contains("CHANGES ALLOWED"), "{}", ga.log());
    assert!(gb.log().contains("READ-ONLY"), "{}", gb.log());

    // status of B's daemon through A's gateway.
    let (code, out, err) = gw(&["status", "--json", "--remote", &ea, "--namespace", &b.ns]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["namespace"], b.ns.as_str(), "{v}");
    assert_eq!(v["mode"], "Run", "{v}");
    assert_eq!(v["gateway"]["host"], "host-b", "{v}");
    assert_eq!(v["gateway"]["access"], "read-only", "{v}");
    let (code, out, _) = gw(&["status", "--remote", &ea, "--namespace", &b.ns]);
    assert_eq!(code, 0);
    assert!(
        out.contains(&format!("chaosd in namespace {}", b.ns)),
        "{out}"
    );

    // set mu on A through B's gateway: applied, as the daemon itself reports over iceoryx2.
    let before = live::status(&a.ns)["mu"].as_f64().unwrap();
    assert_ne!(before, 0.35);
    let (code, out, err) = gw(&["set", "mu", "0.35", "--remote", &eb, "--namespace", &a.ns]);
    assert_eq!(code, 0, "set through the gateway failed: {out} {err}");
    assert_eq!(live::status(&a.ns)["mu"].as_f64(), Some(0.35));
    // The daemon's own validation applies: an out-of-range value is refused by the daemon.
    let (code, _, err) = gw(&["set", "mu", "-1", "--remote", &eb, "--namespace", &a.ns]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("refused") && err.contains("mu"), "{err}");

    // set on B: its gateway is read-only, so it refuses and B's daemon is unchanged.
    let mu_b = live::status(&b.ns)["mu"].as_f64().unwrap();
    let (code, _, err) = gw(&["set", "mu", "0.35", "--remote", &ea, "--namespace", &b.ns]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("read-only") && err.contains("host-b"), "{err}");
    assert_eq!(live::status(&b.ns)["mu"].as_f64(), Some(mu_b));

    // The other control commands travel the same way: an obstacle added on A through B's
    // gateway is listed by A's daemon; listing B's is allowed on its read-only gateway, adding
    // one or switching its feedback off is refused there.
    let (code, out, err) = gw(&[
        "obstacle",
        "add",
        "5",
        "-5",
        "0.1",
        "--remote",
        &eb,
        "--namespace",
        &a.ns,
    ]);
    assert_eq!(code, 0, "{out} {err}");
    let (_, listed, _) = live::ctl(&a.ns, &["obstacle", "ls"]);
    assert!(listed.contains("-5"), "{listed}");
    let (code, out, err) = gw(&["obstacle", "ls", "--remote", &ea, "--namespace", &b.ns]);
    assert_eq!(code, 0, "{err}");
    assert!(out.trim_start().starts_with('['), "{out}");
    for args in [
        vec!["obstacle", "add", "5", "-5", "0.1"],
        vec!["dfc", "off"],
    ] {
        let mut a2 = args.clone();
        a2.extend(["--remote", &ea, "--namespace", &b.ns]);
        let (code, _, err) = gw(&a2);
        assert_eq!(code, 1, "{args:?}: {err}");
        assert!(err.contains("read-only"), "{args:?}: {err}");
    }
    let (code, out, err) = gw(&["hist", "--remote", &eb, "--namespace", &a.ns]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("lateness"), "{out}");

    // watch A through B: consecutive telemetry samples with the new μ.
    let (code, out, err) = gw(&[
        "watch",
        "--json",
        "--count",
        "3",
        "--remote",
        &eb,
        "--namespace",
        &a.ns,
    ]);
    assert_eq!(code, 0, "{err}");
    let samples: Vec<serde_json::Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(samples.len(), 3, "{out}");
    for s in &samples {
        assert_eq!(s["host"], "host-a", "{s}");
        assert_eq!(s["namespace"], a.ns.as_str(), "{s}");
        assert_eq!(s["mu"].as_f64(), Some(0.35), "{s}");
    }
    let seq: Vec<u64> = samples.iter().map(|s| s["seq"].as_u64().unwrap()).collect();
    assert!(seq.windows(2).all(|w| w[1] > w[0]), "{seq:?}");

    // Errors: no such namespace, no gateway, no --remote.
    let (code, _, err) = gw(&["status", "--remote", &ea, "--namespace", "nobody-here"]);
    assert_eq!(code, 3, "{err}");
    assert!(
        err.contains("no gateway") && err.contains("nobody-here"),
        "{err}"
    );
    let dead = format!("tcp/127.0.0.1:{}", free_port());
    let (code, _, err) = gw(&["status", "--remote", &dead, "--timeout", "1"]);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("no gateway at"), "{err}");
    let (code, _, err) = gw(&["status"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--remote"), "{err}");
    // chaosctl hands --remote commands to chaosd-gateway: the same answers, the same exit codes.
    let out = Command::new(tests::bin("chaosctl"))
        .args(["--remote", &eb, "status", "--json", "--namespace", &a.ns])
        .output()
        .unwrap();
    let body = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{body} {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(body.contains("\"host-a\""), "{body}");
    let out = Command::new(tests::bin("chaosctl"))
        .args(["status", "--remote", &dead, "--timeout", "1"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no gateway at"));

    // Both gateways stop cleanly on SIGTERM.
    assert!(
        gb.terminate(Duration::from_secs(10)).success(),
        "{}",
        gb.log()
    );
    assert!(
        ga.terminate(Duration::from_secs(10)).success(),
        "{}",
        ga.log()
    );
}

#[test]
fn bad_gateway_arguments_are_refused_before_anything_starts() {
    for (args, needle) in [
        (
            vec!["serve", "--namespace", "a/b", "--host", "h"],
            "--namespace",
        ),
        (vec!["serve", "--namespace", "a", "--host", "h/x"], "--host"),
        (
            vec![
                "serve",
                "--namespace",
                "a",
                "--host",
                "h",
                "--listen",
                "udp/1.2.3.4:5",
            ],
            "tcp/HOST:PORT",
        ),
        (
            vec![
                "serve",
                "--namespace",
                "a",
                "--namespace",
                "a",
                "--host",
                "h",
            ],
            "twice",
        ),
        (
            vec!["set", "mu", "1", "--remote", "localhost:7447"],
            "tcp/HOST:PORT",
        ),
    ] {
        let (code, _, err) = gw(&args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(
            err.contains(needle),
            "{args:?}: {needle:?} missing from {err}"
        );
        assert!(!err.contains("panicked"), "{err}");
    }
}
