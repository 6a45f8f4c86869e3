//! `chaosctl … | head -1`: a reader that goes away must not make chaosctl panic (exit 101).

use std::os::fd::{FromRawFd, OwnedFd};
use std::os::unix::process::ExitStatusExt;
use std::process::{Command, Stdio};
use tests::bin;

/// Runs chaosctl with its stdout a pipe nobody reads any more (the read end is closed first).
fn into_a_closed_pipe(args: &[&str]) -> (std::process::ExitStatus, String) {
    let mut fds = [0; 2];
    // SAFETY: `fds` has room for the two descriptors pipe(2) returns.
    assert_eq!(unsafe { libc::pipe(fds.as_mut_ptr()) }, 0);
    // SAFETY: both descriptors were just created and are owned here alone.
    let (read, write) = unsafe { (OwnedFd::from_raw_fd(fds[0]), OwnedFd::from_raw_fd(fds[1])) };
    drop(read);
    let out = Command::new(bin("chaosctl"))
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::from(write))
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    (
        out.status,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_closed_stdout_ends_chaosctl_quietly() {
    for args in [
        &["config", "--preset", "paper"][..],
        &["simulate", "--duration", "0.5"][..],
    ] {
        let (status, err) = into_a_closed_pipe(args);
        assert_ne!(
            status.code(),
            Some(101),
            "chaosctl {args:?} panicked: {err}"
        );
        assert!(!err.contains("panicked"), "chaosctl {args:?}: {err}");
        // Like any Unix filter: SIGPIPE ends it (the shell's 141), or it exits by itself.
        assert!(
            status.signal() == Some(libc::SIGPIPE) || status.success(),
            "chaosctl {args:?}: {status:?}: {err}"
        );
    }
}
