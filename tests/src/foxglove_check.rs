//! Foxglove's own readers on chaosd's output: `scripts/foxglove-check` (Node, with the npm
//! packages the Foxglove app reads data with) decodes a recording or the live view, validates
//! every message against its schemas, and prints what it read as one JSON line.
//!
//! It runs when `CHAOSD_FOXGLOVE_CHECK` names that folder with its `node_modules` installed
//! (`npm ci --prefix scripts/foxglove-check`). Without it a test says it skipped the check; with
//! `CHAOSD_REQUIRE_FOXGLOVE_CHECK` set too, skipping fails the test (CI sets both).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// The check's folder, or `None` (said on stderr) when this machine is not set up for it.
pub fn configured() -> Option<PathBuf> {
    let Some(dir) = std::env::var_os("CHAOSD_FOXGLOVE_CHECK") else {
        assert!(
            std::env::var_os("CHAOSD_REQUIRE_FOXGLOVE_CHECK").is_none(),
            "CHAOSD_REQUIRE_FOXGLOVE_CHECK is set but CHAOSD_FOXGLOVE_CHECK is not"
        );
        eprintln!("CHAOSD_FOXGLOVE_CHECK not set: Foxglove's readers not run (CI runs them)");
        return None;
    };
    let dir = PathBuf::from(dir);
    assert!(
        dir.join("node_modules").is_dir(),
        "CHAOSD_FOXGLOVE_CHECK={} has no node_modules: run `npm ci --prefix {0}`",
        dir.display()
    );
    Some(dir)
}

/// Runs `node check.mjs ARGS…` with its output kept in `scratch`, and returns the JSON line it
/// printed; `None` when the check is not set up (see [`configured`]). A non-zero exit fails the
/// test with the check's own message; so does running past `limit` (the child is killed).
pub fn run(args: &[&str], scratch: &Path, limit: Duration) -> Option<serde_json::Value> {
    static RUNS: AtomicUsize = AtomicUsize::new(0);
    let dir = configured()?;
    let n = RUNS.fetch_add(1, Ordering::Relaxed);
    let (out, err) = (
        scratch.join(format!("foxglove-check-{n}.out")),
        scratch.join(format!("foxglove-check-{n}.err")),
    );
    let mut child = Command::new("node")
        .arg(dir.join("check.mjs"))
        .args(args)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&out).expect("check output file"))
        .stderr(std::fs::File::create(&err).expect("check error file"))
        .spawn()
        .unwrap_or_else(|e| panic!("cannot run node (Node.js >= 20 is needed): {e}"));
    let until = Instant::now() + limit;
    let status = loop {
        if let Some(st) = child.try_wait().expect("wait for node") {
            break Some(st);
        }
        if Instant::now() > until {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let read = |p: &Path| std::fs::read_to_string(p).unwrap_or_default();
    let (stdout, stderr) = (read(&out), read(&err));
    let status = status.unwrap_or_else(|| {
        panic!("foxglove-check {args:?} still running after {limit:?}; stderr:\n{stderr}")
    });
    assert!(
        status.success(),
        "foxglove-check {args:?} failed ({status}):\n{stderr}{stdout}"
    );
    let line = stdout.lines().rfind(|l| !l.trim().is_empty()).unwrap_or("");
    Some(serde_json::from_str(line).unwrap_or_else(|e| panic!("not JSON ({e}): {stdout}")))
}

/// A log time the check printed (ns since the Unix epoch, a string: JSON numbers past 2^53
/// are not exact in JavaScript).
pub fn ns(v: &serde_json::Value) -> u64 {
    v.as_str()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("not a log time: {v}"))
}

/// An array of numbers the check printed, as the bits of each f64 (so that "equal" is bit for
/// bit, -0.0 apart from 0.0).
pub fn bits(v: &serde_json::Value) -> Vec<u64> {
    let a = v.as_array().unwrap_or_else(|| panic!("not an array: {v}"));
    a.iter()
        .map(|x| x.as_f64().unwrap_or_else(|| panic!("not a number: {x}")))
        .map(f64::to_bits)
        .collect()
}
