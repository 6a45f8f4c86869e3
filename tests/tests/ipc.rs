//! The daemon and the plant as separate processes over iceoryx2, each test in its own namespace.

use control::{Config, Kinematics, VecN};
use iceoryx2::port::update_connections::UpdateConnections as _;
use protocol::{flags, monotonic_ns, Mode, ServiceNames, StateSample};
use std::time::Duration;
use tests::*;

const RUN: u32 = Mode::Run as u32;
const HOLD: u32 = Mode::Hold as u32;

fn start_system(test: &str) -> (String, TempDir, std::path::PathBuf, Proc, Proc, Monitor) {
    let ns = unique_namespace(test);
    let dir = TempDir::new(&ns);
    let cfg = write_config(dir.path(), &ns, "", "");
    let (plant, daemon) = tests::live::spawn_pair(dir.path(), &cfg);
    let m = Monitor::new(&ns);
    (ns, dir, cfg, plant, daemon, m)
}

fn run_commands(m: &Monitor) -> usize {
    m.seen_commands.iter().filter(|c| c.mode == RUN).count()
}

#[test]
fn end_effector_converges_onto_the_circle_and_commands_answer_states() {
    let _g = serial();
    let (_ns, dir, _cfg, mut plant, mut daemon, mut m) = start_system("converge");
    m.wait_for("the daemon to run", Duration::from_secs(15), |m| {
        run_commands(m) > 50
    });
    std::thread::sleep(Duration::from_secs(4));
    m.clear();
    m.wait_for("a second of traffic", Duration::from_secs(5), |m| {
        run_commands(m) > 1000 && m.seen_states.len() > 1000
    });

    // Every command answers a state that was really published, with its stamp.
    let mut matched = 0;
    for c in m.seen_commands.iter().filter(|c| c.mode == RUN) {
        if let Some(s) = m
            .seen_states
            .iter()
            .find(|s| s.seq == c.state_seq && s.plant_id != 0)
        {
            assert_eq!(
                s.stamp_ns, c.state_stamp_ns,
                "command {} answers state {} with a wrong stamp",
                c.seq, c.state_seq
            );
            // A command is stamped with its tick's time, taken when the tick woke; a state the
            // plant published between that wake-up and the read is still used (the daemon
            // accepts stamps up to its future slack, one period, 1 ms here, ahead of the tick).
            // The stricter check (command stamp ≥ state stamp) failed once in a full test run.
            assert!(
                c.stamp_ns + 1_000_000 >= s.stamp_ns,
                "a command precedes the state it answers by more than the future slack: {} < {}",
                c.stamp_ns,
                s.stamp_ns
            );
            matched += 1;
        }
    }
    assert!(
        matched > 900,
        "only {matched} commands matched a state seen on the wire"
    );
    let seqs: Vec<u64> = m.seen_commands.iter().map(|c| c.seq).collect();
    assert!(
        seqs.windows(2).all(|w| w[1] > w[0]),
        "command sequence numbers must increase"
    );

    // The end effector is on the circle (|p − c| = r) over IPC.
    let cfg = Config::preset("paper").unwrap();
    let model = cfg.model::<3>();
    let mut k = Kinematics::default();
    let mut off = Vec::new();
    for s in m.seen_states.iter().rev().take(500) {
        model.kinematics(
            0.0,
            &VecN::<3>::from_column_slice(&s.q[..3]),
            &VecN::<3>::zeros(),
            &mut k,
        );
        let r = (k.p - nalgebra::Vector2::new(1.0, 2.0)).norm();
        off.push((r - 0.5).abs());
    }
    off.sort_by(f64::total_cmp);

    assert!(
        daemon.terminate(Duration::from_secs(10)).success(),
        "daemon log:\n{}",
        daemon.log()
    );
    assert!(
        plant.terminate(Duration::from_secs(10)).success(),
        "plant log:\n{}",
        plant.log()
    );
    let d = read_json(&dir.path().join("out/daemon-summary.json"));
    assert_eq!(d["counters"]["rejected_invalid"], 0);
    let p = read_json(&dir.path().join("out/plant-summary.json"));
    assert!(p["round_trip"]["count"].as_u64().unwrap() > 1000, "{p}");
    assert_tracks(&[&d, &p], 1e-2);
    // The start is ~1 m off; what remains is the sampled-data loop's lag (1 kHz, zero-order hold,
    // up to one period of state age) at joint speeds up to ~20 rad/s: millimetres. A host stall
    // of either process in the last half second takes the hand centimetres off for a moment:
    // then most of it must still be on the circle.
    let (median, worst) = (off[off.len() / 2], off[off.len() - 1]);
    let ok = if disturbed(&[&d, &p]) {
        median < 5e-3
    } else {
        worst < 2e-2
    };
    assert!(
        ok,
        "end effector is {worst} m (median {median} m) off the circle: {d}"
    );
}

#[test]
fn a_killed_plant_sends_the_daemon_to_hold_and_a_restarted_one_back_to_run() {
    let _g = serial();
    let (_ns, dir, cfg, mut plant, mut daemon, mut m) = start_system("plant-restart");
    m.wait_for("the daemon to run", Duration::from_secs(15), |m| {
        run_commands(m) > 200
    });
    let first_plant = m.seen_states.last().unwrap().plant_id;
    plant.kill9();
    m.clear();
    m.wait_for("HOLD commands", Duration::from_secs(5), |m| {
        m.seen_commands.iter().any(|c| c.mode == HOLD)
    });
    let mut plant2 = Proc::spawn(
        "plant2",
        &bin("chaosd-plant"),
        &["--config", cfg.to_str().unwrap()],
        dir.path(),
    );
    m.clear();
    m.wait_for(
        "RUN commands answering the new plant",
        Duration::from_secs(15),
        |m| {
            m.seen_states.iter().any(|s| s.plant_id != first_plant)
                && m.seen_commands.iter().filter(|c| c.mode == RUN).count() > 100
        },
    );
    let new_id = m
        .seen_states
        .iter()
        .rev()
        .find(|s| s.plant_id != first_plant)
        .unwrap()
        .plant_id;
    assert_ne!(new_id, first_plant);
    assert!(daemon.terminate(Duration::from_secs(10)).success());
    plant2.terminate(Duration::from_secs(10));
    let d = read_json(&dir.path().join("out/daemon-summary.json"));
    assert!(d["counters"]["holds_entered"].as_u64().unwrap() >= 1, "{d}");
    assert!(
        d["counters"]["plant_restarts"].as_u64().unwrap() >= 1,
        "{d}"
    );
}

#[test]
fn a_killed_daemon_makes_the_plant_brake_and_a_restarted_one_takes_over() {
    let _g = serial();
    let (_ns, dir, cfg, mut plant, mut daemon, mut m) = start_system("daemon-restart");
    m.wait_for("the daemon to run", Duration::from_secs(15), |m| {
        run_commands(m) > 200
    });
    let first_daemon = m.seen_commands.last().unwrap().daemon_id;
    m.poll();
    assert!(
        m.seen_states.last().unwrap().qd[..3]
            .iter()
            .any(|v| v.abs() > 0.1),
        "the arm should be moving"
    );
    daemon.kill9();
    m.clear();
    m.wait_for(
        "the plant to time out and brake to rest",
        Duration::from_secs(5),
        |m| {
            m.seen_states.last().is_some_and(|s| {
                s.flags & flags::COMMAND_TIMEOUT != 0
                    && s.flags & flags::BRAKING != 0
                    && s.qd[..3].iter().all(|v| v.abs() < 1e-3)
            })
        },
    );
    let mut daemon2 = Proc::spawn(
        "daemon2",
        &bin("chaosd"),
        &["run", "--config", cfg.to_str().unwrap()],
        dir.path(),
    );
    m.clear();
    m.wait_for(
        "the new daemon to drive the plant",
        Duration::from_secs(15),
        |m| {
            m.seen_commands
                .iter()
                .filter(|c| c.mode == RUN && c.daemon_id != first_daemon)
                .count()
                > 100
                && m.seen_states
                    .last()
                    .is_some_and(|s| s.flags & (flags::COMMAND_TIMEOUT | flags::BRAKING) == 0)
        },
    );
    assert!(daemon2.terminate(Duration::from_secs(10)).success());
    assert!(plant.terminate(Duration::from_secs(10)).success());
    let p = read_json(&dir.path().join("out/plant-summary.json"));
    assert!(
        p["counters"]["command_timeouts"].as_u64().unwrap() >= 1,
        "{p}"
    );
    assert!(
        p["counters"]["daemon_restarts"].as_u64().unwrap() >= 1,
        "{p}"
    );
}

#[test]
fn nan_and_stale_states_are_rejected_and_never_answered() {
    let _g = serial();
    let ns = unique_namespace("bad-samples");
    let dir = TempDir::new(&ns);
    let cfg = write_config(dir.path(), &ns, "", "");
    // The test is the plant here, so it can send what a broken bridge might.
    let node = node();
    let names = ServiceNames::new(&ns).unwrap();
    let svc = protocol::open_state_service(&node, &names).unwrap();
    let publisher = svc.publisher_builder().create().unwrap();
    // A plant describes its arm first (the handshake), or the daemon never runs it.
    let info = protocol::handshake::open_plant_info_service(&node, &names)
        .unwrap()
        .publisher_builder()
        .create()
        .unwrap();
    info.send_copy(protocol::ArmInfo::new(4242, &[1.0; 3], None))
        .unwrap();
    let mut daemon = Proc::spawn(
        "daemon",
        &bin("chaosd"),
        &["run", "--config", cfg.to_str().unwrap()],
        dir.path(),
    );
    let mut m = Monitor::new(&ns);
    let mut s = StateSample {
        plant_id: 4242,
        n: 3,
        flags: flags::SIMULATED,
        ..StateSample::default()
    };
    s.q[1] = 1.57;
    s.q[2] = 1.57;
    let publish = |s: &mut StateSample| {
        s.stamp_ns = monotonic_ns();
        publisher.send_copy(*s).unwrap();
    };
    // Good states until the daemon answers.
    let mut seq = 0;
    let until = std::time::Instant::now() + Duration::from_secs(15);
    while m.seen_commands.iter().filter(|c| c.mode == RUN).count() < 50 {
        assert!(
            std::time::Instant::now() < until,
            "daemon never answered:\n{}",
            daemon.log()
        );
        s.seq = seq;
        seq += 1;
        publish(&mut s);
        // Hands the description to the daemon once it subscribes.
        let _ = info.update_connections();
        std::thread::sleep(Duration::from_millis(1));
        m.poll();
    }
    // A NaN state, alone long enough for several ticks to see it.
    let nan_seq = seq;
    let mut bad = s;
    bad.seq = nan_seq;
    bad.qd[1] = f64::NAN;
    publish(&mut bad);
    std::thread::sleep(Duration::from_millis(5));
    // A stale one: newer than the last good state but delivered 20 ms late (a stalled plant).
    let stale_seq = seq + 1;
    let mut old = s;
    old.seq = stale_seq;
    old.stamp_ns = s.stamp_ns + 1;
    std::thread::sleep(Duration::from_millis(20));
    publisher.send_copy(old).unwrap();
    std::thread::sleep(Duration::from_millis(5));
    // An out-of-order one (a sequence number already used).
    let mut replay = s;
    replay.seq = 3;
    publish(&mut replay);
    std::thread::sleep(Duration::from_millis(5));
    for k in 0..200 {
        s.seq = stale_seq + 1 + k;
        publish(&mut s);
        std::thread::sleep(Duration::from_millis(1));
    }
    m.poll();
    assert!(
        daemon.terminate(Duration::from_secs(10)).success(),
        "{}",
        daemon.log()
    );
    m.poll();
    for c in &m.seen_commands {
        if c.mode == RUN {
            assert!(
                c.state_seq != nan_seq && c.state_seq != stale_seq,
                "the daemon answered a rejected state: {c:?}"
            );
        }
    }
    assert!(
        m.seen_commands
            .iter()
            .any(|c| c.mode == RUN && c.state_seq > stale_seq),
        "the daemon stopped answering good states"
    );
    let d = read_json(&dir.path().join("out/daemon-summary.json"));
    assert!(
        d["counters"]["rejected_invalid"].as_u64().unwrap() >= 1,
        "{d}"
    );
    assert!(
        d["counters"]["rejected_stale"].as_u64().unwrap() >= 1,
        "{d}"
    );
    assert!(
        d["counters"]["rejected_out_of_order"].as_u64().unwrap() >= 1,
        "{d}"
    );
}

#[test]
fn shutdown_writes_readable_histogram_files() {
    let _g = serial();
    let (_ns, dir, _cfg, mut plant, mut daemon, mut m) = start_system("histograms");
    m.wait_for("the daemon to run", Duration::from_secs(15), |m| {
        run_commands(m) > 500
    });
    assert!(daemon.terminate(Duration::from_secs(10)).success());
    assert!(plant.terminate(Duration::from_secs(10)).success());
    let out = dir.path().join("out");
    for f in [
        "daemon-lateness.hgrm",
        "daemon-compute.hgrm",
        "daemon-state-age.hgrm",
        "plant-round-trip.hgrm",
        "plant-lateness.hgrm",
        "plant-step.hgrm",
    ] {
        let text = std::fs::read_to_string(out.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        let rows: Vec<Vec<f64>> = text
            .lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty() && !l.contains("Percentile"))
            .map(|l| {
                l.split_whitespace()
                    .map(|x| x.parse::<f64>().unwrap())
                    .collect()
            })
            .collect();
        assert!(rows.len() > 10, "{f} has {} rows", rows.len());
        assert!(
            rows.windows(2)
                .all(|w| w[1][0] >= w[0][0] && w[1][1] >= w[0][1]),
            "{f}: values and percentiles must not decrease"
        );
        assert_eq!(
            rows.last().unwrap()[1],
            1.0,
            "{f} must end at the 100th percentile"
        );
        let total: u64 = text
            .lines()
            .find(|l| l.contains("Total count"))
            .unwrap()
            .rsplit('=')
            .next()
            .unwrap()
            .trim()
            .trim_end_matches(']')
            .trim()
            .parse()
            .unwrap();
        assert_eq!(
            rows.last().unwrap()[2] as u64,
            total,
            "{f}: the last TotalCount is the total"
        );
        assert!(total > 400, "{f}: {total} values");
    }
    for f in ["daemon.hlog", "plant.hlog"] {
        let text = std::fs::read_to_string(out.join(f)).unwrap();
        assert!(
            text.contains("#[StartTime:") && text.lines().any(|l| l.starts_with("Tag=")),
            "{f}:\n{text}"
        );
    }
    let d = read_json(&out.join("daemon-summary.json"));
    assert!(d["lateness"]["count"].as_u64().unwrap() > 400);
    let p = read_json(&out.join("plant-summary.json"));
    let step = &p["step"];
    assert!(step["count"].as_u64().unwrap() > 400, "{p}");
    assert!(step["p50_us"].as_f64().unwrap() > 0.0, "{p}");
}

#[test]
fn bad_configs_and_arguments_are_refused_with_the_field_named() {
    let ns = unique_namespace("bad-config");
    let dir = TempDir::new(&ns);
    let cases = [
        ("[daemon]\nrate_hz = 20\n", "daemon.rate_hz"),
        ("[control]\nkp = -1\n", "control.kp"),
        ("[feedback]\ntau = 9\n", "feedback.tau"),
        ("[daemon]\nnamespace = \"no spaces\"\n", "daemon.namespace"),
        ("[plant]\nsubsteps = 0\n", "plant.substeps"),
        ("[daemon]\nwait = \"nap\"\n", "nap"),
        ("not = [toml\n", "cannot parse config"),
    ];
    for (i, (text, field)) in cases.iter().enumerate() {
        let p = dir.path().join(format!("bad{i}.toml"));
        std::fs::write(&p, text).unwrap();
        let p = p.to_str().unwrap();
        // The plant only reads [plant]; the daemon only [daemon]; both read the shared sections.
        let check = |exe: &str, args: &[&str]| {
            let out = std::process::Command::new(bin(exe))
                .args(args)
                .output()
                .unwrap();
            let err = String::from_utf8_lossy(&out.stderr);
            (out.status.code(), err.to_string())
        };
        let relevant_daemon = !field.starts_with("plant.");
        let relevant_plant = !field.starts_with("daemon.") && *field != "nap";
        if relevant_daemon {
            let (code, err) = check("chaosd", &["run", "--config", p]);
            assert_eq!(code, Some(2), "chaosd accepted {text:?}: {err}");
            assert!(
                err.contains(field) && !err.contains("panicked"),
                "chaosd on {text:?}: {err}"
            );
        }
        if relevant_plant {
            let (code, err) = check("chaosd-plant", &["--config", p]);
            assert_eq!(code, Some(2), "chaosd-plant accepted {text:?}: {err}");
            assert!(
                err.contains(field) && !err.contains("panicked"),
                "chaosd-plant on {text:?}: {err}"
            );
        }
    }
    for args in [
        &["run", "--config", "/nonexistent.toml"][..],
        &["run", "--preset", "nope"],
        &["run", "--duration=-1"],
        &["run", "--namespace", "a/b"],
    ] {
        let out = std::process::Command::new(bin("chaosd"))
            .args(args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.starts_with("chaosd: error:") && !err.contains("panicked"),
            "{args:?}: {err}"
        );
    }
    // Arguments clap itself refuses get its usage message and exit code 2.
    for args in [
        &["run", "--duration", "-1"][..],
        &["run", "--wait", "nap"],
        &["frobnicate"],
    ] {
        let out = std::process::Command::new(bin("chaosd"))
            .args(args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains("error:") && !err.contains("panicked"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn the_demo_runs_end_to_end_and_leaves_nothing_running() {
    let _g = serial();
    let ns = unique_namespace("demo");
    let dir = TempDir::new(&ns);
    let out = dir.path().join("out");
    // Short, unprivileged-friendly settings; the README's command uses the defaults.
    let mut demo = Proc::spawn(
        "demo",
        &bin("chaosd"),
        &[
            "demo",
            "--duration",
            "12",
            "--namespace",
            &ns,
            "--output",
            out.to_str().unwrap(),
            "--wait",
            "sleep",
        ],
        dir.path(),
    );
    let st = demo.wait_exit(Duration::from_secs(60));
    let log = demo.log();
    assert!(st.success(), "{log}");
    // The defaults a newcomer gets: the Panda, each state answered in the same cycle.
    assert!(log.contains("7 joints"), "{log}");
    assert!(log.contains("state trigger"), "{log}");
    for want in [
        "== chaosd demo report ==",
        "tracking error",
        "period residual",
        "chaos monitor",
        "command round trip    p50",
        "compute per tick",
        "wake-up lateness",
        "problems",
        "safety",
        "details",
    ] {
        assert!(log.contains(want), "report lacks {want:?}:\n{log}");
    }
    // One screen: the short report is a dozen lines at most; the rest is in report.txt.
    let report: Vec<&str> = log
        .lines()
        .skip_while(|l| !l.starts_with("== chaosd demo report =="))
        .filter(|l| !l.contains(" INFO ") && !l.contains(" WARN "))
        .collect();
    assert!((6..=13).contains(&report.len()), "{report:#?}");
    let full = std::fs::read_to_string(out.join("report.txt")).unwrap();
    for want in [
        "state age at tick",
        "answered in time",
        "real-time set-up",
        "faults",
    ] {
        assert!(full.contains(want), "report.txt lacks {want:?}:\n{full}");
        assert!(
            !report.iter().any(|l| l.starts_with(want)),
            "the short report shows {want:?}:\n{log}"
        );
    }
    assert!(full.lines().count() > report.len(), "{full}");
    assert!(
        !log.contains("LARGER"),
        "the feedback should reduce the residual:\n{log}"
    );
    for f in [
        "daemon-summary.json",
        "plant-summary.json",
        "daemon-lateness.hgrm",
        "plant-round-trip.hgrm",
        "daemon.hlog",
        "config.toml",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let d = read_json(&out.join("daemon-summary.json"));
    // The `panda` preset's feedback acts from the start: the report compares 2-7 s with the
    // last 5 s.
    assert!(d["period_residual_before"].is_null(), "{d}");
    let (start, after) = (
        d["period_residual_start"].as_f64().unwrap(),
        d["period_residual_after"].as_f64().unwrap(),
    );
    assert!(after < start, "residual {start} → {after}");
    assert!(
        log.contains("over 2-7 s →") && log.contains("from the start"),
        "{log}"
    );
    // The plant was a child of the demo: it must be gone.
    let plant_pid = log
        .split("plant pid ")
        .nth(1)
        .and_then(|s| s.split(',').next())
        .and_then(|s| s.trim().parse::<i32>().ok())
        .expect("plant pid in the banner");
    // SAFETY: signal 0 only checks for existence.
    assert_ne!(
        unsafe { libc::kill(plant_pid, 0) },
        0,
        "the demo left its plant (pid {plant_pid}) running"
    );
}
