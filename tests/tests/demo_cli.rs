//! `chaosd demo` as a person runs it: into a pipe that closes early, and with its plant killed.

use std::time::{Duration, Instant};
use tests::*;

#[test]
fn a_demo_piped_into_head_does_not_panic_and_still_finishes() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("demo-pipe"));
    let err = dir.path().join("stderr.txt");
    let script = format!(
        "set -o pipefail; '{}' demo --duration 3 --output '{}' 2>'{}' | head -1 >/dev/null",
        bin("chaosd").display(),
        dir.path().join("out").display(),
        err.display()
    );
    let st = std::process::Command::new("bash")
        .args(["-c", &script])
        .status()
        .unwrap();
    let stderr = std::fs::read_to_string(&err).unwrap_or_default();
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(st.success(), "{st:?}\n{stderr}");
    // It went on to the end: the summaries exist, and every file it wrote is the operator's
    // alone (the plant's log included, which is opened for the child, not by rt::files::write).
    assert!(dir.path().join("out/daemon-summary.json").exists());
    use std::os::unix::fs::PermissionsExt;
    for f in std::fs::read_dir(dir.path().join("out")).unwrap() {
        let f = f.unwrap();
        let mode = f.metadata().unwrap().permissions().mode() & 0o777;
        let want = if f.file_type().unwrap().is_dir() {
            0o700
        } else {
            0o600
        };
        assert_eq!(mode, want, "{} is {mode:o}", f.path().display());
    }
}

#[test]
fn a_demo_whose_plant_was_killed_fails_and_lists_only_real_files() {
    let _g = serial();
    let dir = TempDir::new(&unique_namespace("demo-kill"));
    let out = dir.path().join("out");
    let mut demo = Proc::spawn(
        "demo",
        &bin("chaosd"),
        &[
            "demo",
            "--details",
            "--duration",
            "5",
            "--output",
            out.to_str().unwrap(),
        ],
        dir.path(),
    );
    let until = Instant::now() + Duration::from_secs(10);
    let pid = loop {
        let log = demo.log();
        if let Some(p) = log
            .split("plant pid ")
            .nth(1)
            .and_then(|r| r.split(',').next())
        {
            break p.trim().parse::<i32>().unwrap();
        }
        assert!(Instant::now() < until, "no plant pid in:\n{log}");
        std::thread::sleep(Duration::from_millis(50));
    };
    std::thread::sleep(Duration::from_millis(1500));
    // SAFETY: kill(2) on the demo's own child, as a crash would.
    unsafe { libc::kill(pid, libc::SIGKILL) };
    let st = demo.wait_exit(Duration::from_secs(30));
    let log = demo.log();
    assert!(!st.success(), "a demo whose plant died must fail:\n{log}");
    assert!(log.contains("did not exit cleanly"), "{log}");
    let summaries = log
        .lines()
        .find(|l| l.starts_with("summaries"))
        .unwrap_or_default();
    assert!(
        !summaries.contains("plant-summary.json"),
        "lists a file that was never written: {summaries}"
    );
    assert!(summaries.contains("daemon-summary.json"), "{summaries}");
}
