//! The real `chaosd-bench` binary: a tiny latency run between two processes, and the peer's
//! error path that the parent relies on to report a failed child. A watchdog kills a wedged run
//! (a failure, not a timing assertion).

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

static SERIAL: Mutex<()> = Mutex::new(());

/// Runs that pin busy processes to both cores (latency) or inject faults into a live system
/// (soak) take turns: on 2 cores, one would starve the other.
fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

fn exe() -> &'static str {
    env!("CARGO_BIN_EXE_chaosd-bench")
}

fn scratch(test: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("chaosd-bench-it-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs `args`, killing the process if it is still running after `limit`.
/// The stdout of a run that must have succeeded (else both streams, in the failure message).
fn succeeded(out: &Output) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "stdout:\n{stdout}\nstderr:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

fn run(args: &[&str], cwd: &Path, limit: Duration) -> Output {
    let mut child = Command::new(exe())
        .args(args)
        .current_dir(cwd)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let until = Instant::now() + limit;
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > until {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!(
                "chaosd-bench {args:?} still running after {limit:?}; stderr:\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

#[test]
fn a_small_latency_run_reports_every_transport() {
    let _g = serial();
    let dir = scratch("latency");
    let out = run(
        &[
            "--out",
            "o",
            "latency",
            "--rounds",
            "2",
            "--round-trips",
            "200",
            "--priority",
            "0",
        ],
        &dir,
        Duration::from_secs(300),
    );
    let stdout = succeeded(&out);
    for label in [
        "shared-memory spin flag (floor)",
        "iceoryx2 pub-sub, busy polling",
        "Listener wait",
        "WaitSet wait",
        "Unix domain socket",
        "UDP over 127.0.0.1",
        "crossbeam channel",
    ] {
        let row = stdout
            .lines()
            .find(|l| l.starts_with("| ") && l.contains(label))
            .unwrap_or_else(|| panic!("no row for {label}:\n{stdout}"));
        assert!(!row.contains("n/a"), "{label} has no data: {row}");
    }
    assert!(
        stdout.contains("iceoryx2 polling p50 / spin floor p50"),
        "{stdout}"
    );
    let files = dir.join("o/latency");
    for f in [
        "shm-spin.hgrm",
        "iox-poll.hgrm",
        "udp.hgrm",
        "latency.png",
        "latency.svg",
        "latency.md",
        "latency.hlog",
    ] {
        let p = files.join(f);
        assert!(
            p.metadata().map(|m| m.len() > 0).unwrap_or(false),
            "{} missing or empty",
            p.display()
        );
    }
    // Each recorded series holds rounds × round trips values.
    let hgrm = std::fs::read_to_string(files.join("unix.hgrm")).unwrap();
    assert!(hgrm.contains("Total count    =          400"), "{hgrm}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_peer_reports_its_errors_on_the_line_the_parent_reads() {
    let dir = scratch("peer");
    let out = run(
        &[
            "__latency-peer",
            "--namespace",
            "not/valid",
            "--shm-fd=-1",
            "--unix-fd=-1",
            "--udp-port",
            "9",
            "--core",
            "0",
        ],
        &dir,
        Duration::from_secs(60),
    );
    assert!(!out.status.success());
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout.lines().next().unwrap_or_default();
    assert!(
        line.starts_with("error ") && line.contains("namespace"),
        "{stdout}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_options_are_refused_before_anything_runs() {
    let dir = scratch("opts");
    let out = run(
        &["--out", "o", "jitter", "--priority", "99"],
        &dir,
        Duration::from_secs(60),
    );
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("99"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = run(
        &["--out", "o", "e2e", "--rates", "50000"],
        &dir,
        Duration::from_secs(60),
    );
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("between 100 and 10000 Hz"));
    assert!(
        !dir.join("o/jitter").exists(),
        "nothing is written for a refused run"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_soak_arguments_get_one_short_error() {
    let dir = scratch("soak-opts");
    for (args, want) in [
        (
            &["soak", "--seconds", "1"][..],
            "must be between 5 and 86400",
        ),
        (&["soak", "--seconds", "nan"], "must be between 5 and 86400"),
        (&["soak", "--seconds", "ten"], "invalid value 'ten'"),
        (&["soak", "--seconds", "10", "--seed", "-3"], "error:"),
        (
            &["soak", "--seconds", "10", "--faults", "meteor"],
            "invalid value 'meteor'",
        ),
        (&["soak"], "--seconds"),
    ] {
        let out = run(args, &dir, Duration::from_secs(60));
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} was accepted");
        assert!(
            err.contains(want) && !err.contains("panicked"),
            "{args:?}: {err}"
        );
        assert!(err.len() < 1024, "{args:?}: a long error: {err}");
    }
    assert!(
        !dir.join("out/bench/soak").exists(),
        "nothing runs for a refused soak"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The 60 s soak that CI runs, against the real binaries: faults are injected, the verdict table
/// is printed and the run passes (exit 0), which includes "nothing left behind". The watchdog is
/// a hang guard, not a timing assertion.
#[test]
fn a_one_minute_soak_injects_faults_and_passes() {
    let _g = serial();
    let dir = scratch("soak");
    let out = run(
        &["--out", "o", "soak", "--seconds", "60", "--seed", "5"],
        &dir,
        Duration::from_secs(600),
    );
    let stdout = succeeded(&out);
    assert!(stdout.contains("**Verdict: PASS**"), "{stdout}");
    // At least two faults were injected, each detected and recovered.
    let injected: usize = stdout
        .lines()
        .filter(|l| {
            l.starts_with("| ")
                && (l.contains("restart")
                    || l.contains("SIG")
                    || l.contains("hog")
                    || l.contains("rogue")
                    || l.contains("burst"))
        })
        .filter_map(|l| l.split('|').nth(2)?.trim().parse::<usize>().ok())
        .sum();
    assert!(injected >= 2, "{stdout}");
    let row = stdout
        .lines()
        .find(|l| l.contains("recording windows checked (lost)"))
        .unwrap_or_else(|| panic!("no window row:\n{stdout}"));
    assert!(row.contains("(0)") && !row.contains("| 0 (0)"), "{row}");
    let left = stdout
        .lines()
        .find(|l| l.contains("leftovers"))
        .unwrap_or_else(|| panic!("no leftover row:\n{stdout}"));
    assert!(left.contains("| 0 (checked "), "{left}");
    assert!(dir.join("o/soak/soak.md").is_file());
    std::fs::remove_dir_all(&dir).ok();
}

/// `compute --quick` with a pinocchio timings file: the robot model table has a row per
/// implementation and operation, chaosd's calls allocate nothing and the naive ones do, the
/// file's numbers are shown with their ratio, and the k row says whether k was built.
#[test]
fn compute_reports_the_robot_model_table() {
    let _g = serial();
    let dir = scratch("compute");
    let rows: Vec<String> = [
        "rnea",
        "crba",
        "crba_world",
        "aba",
        "aba_world",
        "gravity",
        "fk_jacobian",
        "fk_jdot_qd",
        "fk_jacobian_jdot_qd",
    ]
    .iter()
    .map(|k| {
        format!(
            r#""{k}": {{"label": "{k}", "p50_ns": 4321.0, "p90_ns": 4400.0, "p99_ns": 5000.0, "p999_ns": 6000.0, "max_ns": 9000.0}}"#
        )
    })
    .collect();
    let json = format!(
        r#"{{"pinocchio_version": "9.9.9", "flags": "-O3", "template_instantiation": false, "cpu": "test", "tip": "panda_link8", "dof": 7, "rows": {{{}}}}}"#,
        rows.join(", ")
    );
    std::fs::write(dir.join("pin.json"), json).unwrap();
    let out = run(
        &[
            "--quick",
            "--out",
            "o",
            "compute",
            "--pinocchio",
            "pin.json",
        ],
        &dir,
        Duration::from_secs(600),
    );
    let stdout = succeeded(&out);
    let row = |op: &str, who: &str| {
        stdout
            .lines()
            .find(|l| l.starts_with(&format!("| {op}")) && l.contains(who))
            .unwrap_or_else(|| panic!("no row {op} / {who}:\n{stdout}"))
            .split('|')
            .map(|c| c.trim().to_string())
            .collect::<Vec<_>>()
    };
    for op in ["FK + tip Jacobian + J̇q̇", "RNEA", "CRBA", "ABA", "gravity"] {
        let c = row(op, "chaosd");
        assert_eq!(c[8], "0", "chaosd allocates in {op}: {c:?}");
        assert_eq!(c[9], "1.0×", "{c:?}");
        let n = row(op, "naive");
        assert!(n[8].parse::<f64>().unwrap() > 0.0, "{n:?}");
        let p = row(op, "pinocchio 9.9.9");
        assert_eq!(p[3], "4.32 µs", "{p:?}");
        assert!(p[9].ends_with('×'), "{p:?}");
    }
    for op in ["FK + tip Jacobian + J̇q̇", "RNEA", "CRBA", "ABA"] {
        let c = row(op, "chaosd");
        assert!(
            c[10].ends_with(": met") || c[10].ends_with(": MISSED"),
            "{c:?}"
        );
    }
    let k = row("FK + tip Jacobian (no J̇q̇)", "k 0.32");
    if cfg!(feature = "k-crate") {
        assert!(k[3].ends_with("µs") || k[3].ends_with("ns"), "{k:?}");
    } else {
        assert!(k[2].contains("not built"), "{k:?}");
    }
    assert!(stdout.contains("Targets (Panda, p50)"), "{stdout}");
    assert!(dir.join("o/compute/model-rnea-chaosd.hgrm").is_file());
    std::fs::remove_dir_all(&dir).ok();
}
