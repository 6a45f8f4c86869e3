//! What every end-to-end test of `chaosctl` does: run the built binary, take its output, check
//! a refusal, and keep its files in a scratch folder of its own.

#![allow(dead_code)] // each test file uses its own share of these

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The built `chaosctl` with `args`, in the package's folder as `cargo test` runs it.
pub fn chaosctl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_chaosctl"))
        .args(args)
        .output()
        .expect("run chaosctl")
}

/// Its standard output, after checking that it succeeded.
pub fn ok(args: &[&str]) -> String {
    let out = chaosctl(args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{args:?} failed: {err}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Fails with exit code 2 and a message containing every `needle`, without a panic; its stderr.
pub fn refused(args: &[&str], needles: &[&str]) -> String {
    let out = chaosctl(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(
        out.status.code(),
        Some(2),
        "{args:?} should fail with 2: {err}"
    );
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: {n:?} missing from: {err}");
    }
    err
}

/// A fresh folder for one test: `chaosctl-GROUP-PID-NAME` in the temporary directory.
pub fn scratch(group: &str, name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("chaosctl-{group}-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A path as an argument.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}
