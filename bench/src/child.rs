//! Child processes the benchmarks start: the latency peer, cyclictest, the daemon and the plant.
//!
//! A benchmark that hangs, or leaves a spinning process pinned to a core, is worse than one that
//! fails, so every child is supervised the same way:
//! * it is owned by a [`Child`] guard that SIGKILLs and reaps it when dropped, on every exit path
//!   (errors, panics, early returns);
//! * it gets `PR_SET_PDEATHSIG = SIGKILL`, so it dies with us even if we are SIGKILLed and no
//!   destructor runs (and it exits at once if we were already gone when it started);
//! * every wait has a limit. Waiting for a line, for an exit, or for a peer's answer ends with an
//!   error that says what was expected, the child's exit status if it has one, and the tail of its
//!   log, never with a hang.
//!
//! A child that talks to us does so by lines on its stdout, read by a thread into a channel so
//! that a wait can time out; its stderr goes to a log file.

use anyhow::{anyhow, bail, Context, Result};
use crossbeam::channel::{Receiver, RecvTimeoutError};
use std::io::{BufRead, BufReader, Write};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{ChildStdin, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// A supervised child process.
pub struct Child {
    name: String,
    child: Option<std::process::Child>,
    log: PathBuf,
    stdin: Option<ChildStdin>,
    lines: Option<Receiver<String>>,
    status: Option<ExitStatus>,
}

/// Whether the child's stdout is a line channel to us or goes to its log.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stdout {
    Lines,
    Log,
}

/// Makes `cmd` die with this thread's process, start on any core and with a 1 ns timer slack.
///
/// A child inherits its parent thread's CPU affinity; a benchmark thread is usually pinned to
/// one core, so the child's mask is reset to every core and it pins itself where it is told.
/// The 1 ns timer slack survives exec, so a SCHED_OTHER child sleeps as precisely as our own
/// loops do (they set it with `rt::setup::apply`). But a child that calls sched_setscheduler()
/// gets its *default* slack back, and that default is the slack of the thread that forked it:
/// spawn such children (cyclictest) from a thread whose own slack is 1 ns ([`with_fine_slack`]).
/// SCHED_FIFO threads ignore the slack.
pub fn harden(cmd: &mut Command) {
    // SAFETY: getpid is async-signal-safe; it is read before the fork.
    let parent = unsafe { libc::getpid() };
    // SAFETY: only async-signal-safe calls (prctl, getppid, _exit) run between fork and exec.
    unsafe {
        cmd.pre_exec(move || {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
            if libc::getppid() != parent {
                libc::_exit(1); // the parent died before the prctl: do not run orphaned
            }
            let mut all: libc::cpu_set_t = std::mem::zeroed();
            for cpu in 0..libc::CPU_SETSIZE as usize {
                libc::CPU_SET(cpu, &mut all);
            }
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &all);
            libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0);
            Ok(())
        });
    }
}

/// Runs `f` on a fresh thread whose timer slack is 1 ns, so children it forks inherit 1 ns as
/// their default slack (see [`harden`]). The thread lives until `f` returns, as
/// PR_SET_PDEATHSIG requires of a child's spawner.
pub fn with_fine_slack<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    std::thread::scope(|s| {
        s.spawn(|| {
            // SAFETY: PR_SET_TIMERSLACK takes an unsigned long and affects this thread only.
            unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) };
            f()
        })
        .join()
        .unwrap_or_else(|p| std::panic::resume_unwind(p))
    })
}

impl Child {
    /// Starts `cmd` with stderr (and, for [`Stdout::Log`], stdout) appended to `log`.
    ///
    /// PR_SET_PDEATHSIG fires when the *thread* that forked exits, so spawn from a thread that
    /// outlives the child (the main thread, or the test's thread).
    pub fn spawn(name: &str, mut cmd: Command, log: &Path, stdout: Stdout) -> Result<Self> {
        if let Some(dir) = log.parent() {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
        }
        let f = std::fs::File::create(log)
            .with_context(|| format!("cannot create {}", log.display()))?;
        harden(&mut cmd);
        cmd.stderr(f.try_clone()?);
        match stdout {
            Stdout::Lines => cmd.stdin(Stdio::piped()).stdout(Stdio::piped()),
            Stdout::Log => cmd.stdin(Stdio::null()).stdout(f),
        };
        let program = cmd.get_program().to_string_lossy().into_owned();
        let mut child = cmd
            .spawn()
            .with_context(|| format!("cannot start {name} ({program})"))?;
        let stdin = child.stdin.take();
        let lines = child.stdout.take().map(|out| {
            let (tx, rx) = crossbeam::channel::unbounded();
            std::thread::spawn(move || {
                for line in BufReader::new(out).lines() {
                    let Ok(l) = line else { break };
                    if tx.send(l).is_err() {
                        break;
                    }
                }
            });
            rx
        });
        Ok(Self {
            name: name.into(),
            child: Some(child),
            log: log.into(),
            stdin,
            lines,
            status: None,
        })
    }

    pub fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(|c| c.id())
    }

    /// The last `n` lines of the log.
    pub fn log_tail(&self, n: usize) -> String {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        lines[lines.len().saturating_sub(n)..].join("\n")
    }

    /// The exit status, if the child has exited (reaps it).
    pub fn poll_exit(&mut self) -> Option<ExitStatus> {
        if self.status.is_none() {
            if let Some(c) = self.child.as_mut() {
                if let Ok(Some(st)) = c.try_wait() {
                    self.status = Some(st);
                    self.child = None;
                }
            }
        }
        self.status
    }

    /// An error about this child: what went wrong, its state, and its log's tail.
    pub fn failure(&mut self, what: &str) -> anyhow::Error {
        let state = match self.poll_exit() {
            Some(st) => format!("it exited with {st}"),
            None => "it is still running".into(),
        };
        let tail = self.log_tail(15);
        let log = if tail.trim().is_empty() {
            format!("its log {} is empty", self.log.display())
        } else {
            format!("last lines of {}:\n{tail}", self.log.display())
        };
        anyhow!("{}: {what}; {state}; {log}", self.name)
    }

    /// Sends one line to the child's stdin.
    pub fn send(&mut self, line: &str) -> Result<()> {
        let r = match self.stdin.as_mut() {
            Some(s) => writeln!(s, "{line}").and_then(|_| s.flush()),
            None => return Err(self.failure("it has no stdin to send to")),
        };
        r.map_err(|e| self.failure(&format!("cannot send {line:?} ({e})")))
    }

    /// Waits up to `limit` for a line starting with `prefix` and returns the rest of it.
    /// A line `error <message>` from the child, its exit, or the limit end the wait with an
    /// error; on the limit the child is killed, since it is wedged.
    pub fn expect(&mut self, prefix: &str, limit: Duration) -> Result<String> {
        let Some(rx) = self.lines.clone() else {
            return Err(self.failure("it has no stdout to read from"));
        };
        let until = Instant::now() + limit;
        loop {
            let left = until.saturating_duration_since(Instant::now());
            if left.is_zero() {
                self.kill();
                return Err(self.failure(&format!(
                    "no `{prefix}` line within {limit:?}, so it was killed"
                )));
            }
            match rx.recv_timeout(left.min(Duration::from_millis(50))) {
                Ok(line) => {
                    if let Some(rest) = line.strip_prefix(prefix) {
                        return Ok(rest.trim().to_string());
                    }
                    if let Some(msg) = line.strip_prefix("error") {
                        let msg = msg.trim().to_string();
                        return Err(self.failure(&format!(
                            "it reported an error while we waited for `{prefix}`: {msg}"
                        )));
                    }
                    // Anything else is chatter; keep waiting.
                }
                Err(RecvTimeoutError::Timeout) => {
                    // The output may close before the exit is visible: only an exit ends the wait.
                    if self.poll_exit().is_some() && rx.is_empty() {
                        return Err(self.failure(&format!("it exited before sending `{prefix}`")));
                    }
                }
                Err(RecvTimeoutError::Disconnected) => {
                    std::thread::sleep(Duration::from_millis(20));
                    if self.poll_exit().is_some() {
                        return Err(self.failure(&format!("it exited before sending `{prefix}`")));
                    }
                }
            }
        }
    }

    /// Waits up to `limit` for the child to exit by itself; kills it and fails after that.
    pub fn wait(&mut self, limit: Duration) -> Result<ExitStatus> {
        let until = Instant::now() + limit;
        loop {
            if let Some(st) = self.poll_exit() {
                return Ok(st);
            }
            if Instant::now() >= until {
                self.kill();
                bail!(self.failure(&format!("did not exit within {limit:?}, so it was killed")));
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Waits for a successful exit; any other status is an error with the log's tail.
    pub fn wait_success(&mut self, limit: Duration) -> Result<()> {
        let st = self.wait(limit)?;
        if st.success() {
            Ok(())
        } else {
            Err(self.failure("it failed"))
        }
    }

    /// SIGTERM, then up to `grace` for a clean exit, then SIGKILL (an error).
    pub fn terminate(&mut self, grace: Duration) -> Result<ExitStatus> {
        if let Some(pid) = self.pid() {
            // SAFETY: kill(2) on our own, not yet reaped, child.
            unsafe { libc::kill(pid as i32, libc::SIGTERM) };
        }
        self.wait(grace)
    }

    /// SIGKILL and reap (no-op if already gone).
    pub fn kill(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            if let Ok(st) = c.wait() {
                self.status = Some(st);
            }
        }
    }
}

impl Drop for Child {
    fn drop(&mut self) {
        self.stdin = None;
        self.kill();
    }
}

/// Clock ticks of user + system CPU time a process has used (all its threads), from
/// `/proc/<pid>/stat`.
pub fn cpu_ticks(pid: u32) -> Result<u64> {
    let text = std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .with_context(|| format!("cannot read /proc/{pid}/stat"))?;
    parse_stat_cpu(&text)
}

/// utime + stime from the text of `/proc/<pid>/stat`. The command name (field 2) is in
/// parentheses and may itself hold spaces and parentheses, so fields are counted after the last
/// `)`: state is field 3, utime field 14, stime field 15.
pub fn parse_stat_cpu(text: &str) -> Result<u64> {
    let rest = text
        .rsplit_once(')')
        .map(|(_, r)| r)
        .ok_or_else(|| anyhow!("no ')' in /proc stat line"))?;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let field = |n: usize| -> Result<u64> {
        f.get(n - 3)
            .ok_or_else(|| anyhow!("/proc stat line has no field {n}"))?
            .parse::<u64>()
            .with_context(|| format!("field {n} of the /proc stat line is not a number"))
    };
    Ok(field(14)? + field(15)?)
}

/// Clock ticks each CPU has been stolen so far, indexed by CPU number: time the hypervisor ran
/// something else while that vCPU wanted to run (`steal`, the 8th value of `/proc/stat`'s
/// `cpuN` lines).
pub fn steal_ticks() -> Result<Vec<u64>> {
    let text = std::fs::read_to_string("/proc/stat").context("cannot read /proc/stat")?;
    parse_steal(&text)
}

/// The `steal` column of each `cpuN` line of `/proc/stat`'s text, indexed by N.
pub fn parse_steal(text: &str) -> Result<Vec<u64>> {
    let mut out = Vec::new();
    for line in text.lines() {
        let mut f = line.split_whitespace();
        let Some(n) = f.next().and_then(|c| c.strip_prefix("cpu")) else {
            continue;
        };
        let Ok(n) = n.parse::<usize>() else {
            continue; // the "cpu" total line
        };
        let steal = f
            .nth(7)
            .ok_or_else(|| anyhow!("/proc/stat line cpu{n} has no steal column"))?
            .parse::<u64>()
            .with_context(|| format!("steal of cpu{n} in /proc/stat is not a number"))?;
        if out.len() <= n {
            out.resize(n + 1, 0);
        }
        out[n] = steal;
    }
    Ok(out)
}

/// Clock ticks per second for [`cpu_ticks`] and [`steal_ticks`].
pub fn clock_ticks_per_s() -> f64 {
    // SAFETY: sysconf has no preconditions.
    let t = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if t > 0 {
        t as f64
    } else {
        100.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steal_is_read_per_cpu() {
        let text = "cpu  7574338 0 501643 6676893 23070 0 23546 35248 0 0\n\
                    cpu0 3770448 0 260449 3350124 7126 0 7515 17906 0 0\n\
                    cpu1 3803889 0 241194 3326769 15943 0 16031 17341 0 0\n\
                    intr 1 2 3\n";
        assert_eq!(parse_steal(text).unwrap(), vec![17906, 17341]);
        let short = "cpu0 1 2 3\n";
        assert!(parse_steal(short).unwrap_err().to_string().contains("cpu0"));
        // This machine's own: one entry per CPU.
        assert!(!steal_ticks().unwrap().is_empty());
    }

    fn dir(test: &str) -> PathBuf {
        let d =
            std::env::temp_dir().join(format!("chaosd-bench-child-{test}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn sh(script: &str) -> Command {
        let mut c = Command::new("sh");
        c.args(["-c", script]);
        c
    }

    fn alive(pid: u32) -> bool {
        // A reaped child's pid no longer exists (kill with signal 0 fails with ESRCH).
        // SAFETY: signal 0 only checks for existence.
        unsafe { libc::kill(pid as i32, 0) == 0 }
    }

    #[test]
    fn a_child_that_fails_is_reported_with_its_status_and_log() {
        let d = dir("fails");
        let mut c = Child::spawn(
            "peer",
            sh("echo 'cannot map shared memory' >&2; exit 3"),
            &d.join("peer.log"),
            Stdout::Lines,
        )
        .unwrap();
        let e = c
            .expect("ready", Duration::from_secs(30))
            .unwrap_err()
            .to_string();
        assert!(e.contains("exited before sending `ready`"), "{e}");
        assert!(e.contains("exit status: 3"), "{e}");
        assert!(e.contains("cannot map shared memory"), "{e}");
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn a_hung_child_is_timed_out_and_killed() {
        let d = dir("hung");
        let mut c = Child::spawn(
            "peer",
            sh("echo starting >&2; exec sleep 600"),
            &d.join("peer.log"),
            Stdout::Lines,
        )
        .unwrap();
        let pid = c.pid().unwrap();
        let t0 = Instant::now();
        let e = c
            .expect("ready", Duration::from_millis(300))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no `ready` line within 300ms, so it was killed"),
            "{e}"
        );
        assert!(e.contains("signal: 9"), "{e}");
        assert!(e.contains("starting"), "{e}");
        assert!(!alive(pid), "the hung child must be gone");
        // The limit, not the child's 600 s sleep, ended the wait.
        assert!(t0.elapsed() < Duration::from_secs(300));
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn a_child_that_reports_an_error_line_fails_the_wait() {
        let d = dir("errline");
        let mut c = Child::spawn(
            "peer",
            sh("read cmd; echo \"error unknown command $cmd\"; sleep 600"),
            &d.join("peer.log"),
            Stdout::Lines,
        )
        .unwrap();
        c.send("run bogus 10").unwrap();
        let e = c
            .expect("done", Duration::from_secs(30))
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown command run bogus 10"), "{e}");
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn lines_exits_and_drop() {
        let d = dir("lines");
        let mut c = Child::spawn(
            "echo",
            sh("read x; echo noise; echo \"ready $x\"; exit 0"),
            &d.join("e.log"),
            Stdout::Lines,
        )
        .unwrap();
        c.send("udp=1234").unwrap();
        assert_eq!(
            c.expect("ready", Duration::from_secs(30)).unwrap(),
            "udp=1234"
        );
        c.wait_success(Duration::from_secs(30)).unwrap();

        let mut c = Child::spawn("bad", sh("exit 4"), &d.join("b.log"), Stdout::Log).unwrap();
        let e = c
            .wait_success(Duration::from_secs(30))
            .unwrap_err()
            .to_string();
        assert!(e.contains("exit status: 4"), "{e}");

        // A process that ignores SIGTERM is killed after the grace period, with an error.
        let mut c = Child::spawn(
            "stubborn",
            sh("trap '' TERM; exec sleep 600"),
            &d.join("s.log"),
            Stdout::Log,
        )
        .unwrap();
        std::thread::sleep(Duration::from_millis(100));
        assert!(c.terminate(Duration::from_millis(200)).is_err());

        let c = Child::spawn(
            "sleeper",
            sh("exec sleep 600"),
            &d.join("z.log"),
            Stdout::Log,
        )
        .unwrap();
        let pid = c.pid().unwrap();
        drop(c);
        assert!(!alive(pid), "dropping the guard kills the child");
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn proc_stat_cpu_fields() {
        // comm with spaces and a ')' inside; utime = 1500, stime = 250.
        let line = "4242 (my (odd) proc) S 1 4242 4242 0 -1 4194560 100 0 0 0 1500 250 0 0 20 0 3 0 12345 1000000 200 18446744073709551615";
        assert_eq!(parse_stat_cpu(line).unwrap(), 1750);
        assert!(parse_stat_cpu("4242 (x) S 1 2").is_err());
        assert!(parse_stat_cpu("garbage").is_err());
        let me = cpu_ticks(std::process::id()).unwrap();
        assert!(me < u64::MAX);
        assert!(clock_ticks_per_s() > 0.0);
    }
}
