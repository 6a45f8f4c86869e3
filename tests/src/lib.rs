//! Harness for tests that run the real binaries as separate processes.
//!
//! iceoryx2 resources are global on the machine, so every test gets its own namespace. Every
//! child is owned by a [`Proc`] guard that SIGKILLs it when dropped, so a failing assertion never
//! leaves a process behind; children also get `PR_SET_PDEATHSIG`, so even a test binary that is
//! killed takes them along. Waits are bounded and fail with what was seen, never hang. Tests that
//! spawn processes take [`serial`] so two 2-process systems never compete for the 2 cores.

pub mod deadline;
pub mod foxglove_check;
pub mod live;

use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ipc;
use protocol::{CommandSample, ServiceNames, StateSample};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

static SERIAL: Mutex<()> = Mutex::new(());

/// Serialises process-spawning tests (poisoning from a failed test is ignored).
pub fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

/// A namespace no other test, run or machine user shares.
pub fn unique_namespace(test: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
    format!(
        "t-{}-{}-{}",
        test.replace('_', "-").chars().take(24).collect::<String>(),
        std::process::id(),
        nanos
    )
}

/// The directory holding the built binaries (next to this test executable's `deps/`).
pub fn bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("current exe");
    let dir = exe.parent().and_then(Path::parent).expect("target dir");
    let p = dir.join(name);
    assert!(
        p.exists(),
        "{} is missing: run `cargo build --release --bins` before `cargo test --release`",
        p.display()
    );
    p
}

/// A scratch directory for one test, removed at the end.
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(ns: &str) -> Self {
        let p = std::env::temp_dir().join(format!("chaosd-{ns}"));
        std::fs::create_dir_all(&p).expect("temp dir");
        Self(p)
    }
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// A child process that is stopped when dropped (SIGTERM, then SIGKILL).
pub struct Proc {
    pub name: String,
    child: Option<Child>,
    log: PathBuf,
}

impl Proc {
    /// Starts `exe args…` with stdout and stderr going to `<dir>/<name>.log`.
    pub fn spawn(name: &str, exe: &Path, args: &[&str], dir: &Path) -> Self {
        Self::spawn_env(name, exe, args, &[], dir)
    }

    /// [`Proc::spawn`] with extra environment variables.
    pub fn spawn_env(
        name: &str,
        exe: &Path,
        args: &[&str],
        env: &[(&str, &str)],
        dir: &Path,
    ) -> Self {
        let log = dir.join(format!("{name}.log"));
        let f = std::fs::File::create(&log).expect("log file");
        let mut cmd = Command::new(exe);
        cmd.args(args)
            .envs(env.iter().copied())
            .stdin(Stdio::null())
            .stdout(f.try_clone().unwrap())
            .stderr(f);
        // SAFETY: prctl is async-signal-safe; it only asks for SIGKILL when the parent dies.
        unsafe {
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
                Ok(())
            });
        }
        let child = cmd
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {}: {e}", exe.display()));
        Self {
            name: name.into(),
            child: Some(child),
            log,
        }
    }

    pub fn pid(&self) -> u32 {
        self.child.as_ref().map_or(0, |c| c.id())
    }

    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Sends `sig` (SIGSTOP, SIGCONT, ...) to the running process.
    pub fn signal(&self, sig: i32) {
        if let Some(c) = &self.child {
            // SAFETY: kill(2) on our own child.
            unsafe { libc::kill(c.id() as i32, sig) };
        }
    }

    /// SIGKILL, like a crash.
    pub fn kill9(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    /// SIGTERM and wait for the exit (SIGKILL after `grace`, which fails the test).
    pub fn terminate(&mut self, grace: Duration) -> ExitStatus {
        let mut c = self.child.take().expect("process already gone");
        // SAFETY: kill(2) on our own child.
        unsafe { libc::kill(c.id() as i32, libc::SIGTERM) };
        let until = Instant::now() + grace;
        loop {
            if let Ok(Some(st)) = c.try_wait() {
                return st;
            }
            if Instant::now() > until {
                let _ = c.kill();
                let _ = c.wait();
                panic!(
                    "{} ignored SIGTERM for {grace:?}; log:\n{}",
                    self.name,
                    self.log()
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Waits for the process to exit by itself.
    pub fn wait_exit(&mut self, limit: Duration) -> ExitStatus {
        let until = Instant::now() + limit;
        let c = self.child.as_mut().expect("process already gone");
        loop {
            if let Ok(Some(st)) = c.try_wait() {
                self.child = None;
                return st;
            }
            assert!(
                Instant::now() < until,
                "{} still running after {limit:?}; log:\n{}",
                self.name,
                self.log()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Proc {
    /// SIGTERM first, so the process releases its iceoryx2 node and services as it does on a
    /// clean stop (a SIGKILL leaves them on the machine until another node sweeps them up);
    /// SIGKILL after a grace of [`DROP_GRACE`]. Never panics: it runs when a test has failed.
    fn drop(&mut self) {
        if let Some(c) = self.child.as_mut() {
            if let Ok(None) = c.try_wait() {
                // SAFETY: kill(2) on our own child, which has not been reaped.
                unsafe { libc::kill(c.id() as i32, libc::SIGTERM) };
                let until = Instant::now() + DROP_GRACE;
                while Instant::now() < until && matches!(c.try_wait(), Ok(None)) {
                    std::thread::sleep(Duration::from_millis(20));
                }
            }
        }
        self.kill9();
    }
}

/// How long a dropped [`Proc`] has to stop cleanly after its SIGTERM.
pub const DROP_GRACE: Duration = Duration::from_secs(3);

/// A config file for a test system: namespaced, writing into the test's directory, sleeping
/// waits (never a spin: the test and its peers share 2 cores) at SCHED_FIFO 40 where permitted,
/// as the daemon is meant to run, so builds or other load on the machine do not starve the loops
/// (without the privilege both fall back to the normal scheduler with a warning).
pub fn write_config(dir: &Path, ns: &str, extra_daemon: &str, extra_top: &str) -> PathBuf {
    write_config_with(dir, ns, extra_daemon, "", extra_top)
}

/// [`write_config`] with extra `[plant]` lines too.
pub fn write_config_with(
    dir: &Path,
    ns: &str,
    extra_daemon: &str,
    extra_plant: &str,
    extra_top: &str,
) -> PathBuf {
    let out = dir.join("out");
    let text = format!(
        "{extra_top}\n[daemon]\nnamespace = \"{ns}\"\noutput_dir = \"{out}\"\nwait = \"sleep\"\npriority = 40\nlock_memory = false\nreport_every_s = 0.5\n{extra_daemon}\n\
         [plant]\nnamespace = \"{ns}\"\noutput_dir = \"{out}\"\nwait = \"sleep\"\npriority = 40\nlock_memory = false\n{extra_plant}\n",
        out = out.display()
    );
    let p = dir.join("config.toml");
    std::fs::write(&p, text).unwrap();
    p
}

/// Watches a namespace's state and command streams from the test process.
pub struct Monitor {
    _node: iceoryx2::node::Node<ipc::Service>,
    states: Subscriber<ipc::Service, StateSample, ()>,
    commands: Subscriber<ipc::Service, CommandSample, ()>,
    pub seen_states: Vec<StateSample>,
    pub seen_commands: Vec<CommandSample>,
}

/// Creates a quiet iceoryx2 node for the test process.
pub fn node() -> iceoryx2::node::Node<ipc::Service> {
    protocol::node("chaosd-test").expect("iceoryx2 node")
}

impl Monitor {
    pub fn new(ns: &str) -> Self {
        let node = node();
        let names = ServiceNames::new(ns).unwrap();
        let s = protocol::open_state_service(&node, &names).expect("state service");
        let c = protocol::open_command_service(&node, &names).expect("command service");
        let states = s.subscriber_builder().create().expect("state subscriber");
        let commands = c.subscriber_builder().create().expect("command subscriber");
        Self {
            _node: node,
            states,
            commands,
            seen_states: Vec::new(),
            seen_commands: Vec::new(),
        }
    }

    /// Drains both streams into `seen_*`.
    pub fn poll(&mut self) {
        while let Ok(Some(s)) = self.states.receive() {
            self.seen_states.push(*s);
        }
        while let Ok(Some(c)) = self.commands.receive() {
            self.seen_commands.push(*c);
        }
    }

    /// Polls until `cond` holds, or fails after `limit` with `what`.
    pub fn wait_for(
        &mut self,
        what: &str,
        limit: Duration,
        mut cond: impl FnMut(&Monitor) -> bool,
    ) {
        let until = Instant::now() + limit;
        loop {
            self.poll();
            if cond(self) {
                return;
            }
            assert!(
                Instant::now() < until,
                "timed out after {limit:?} waiting for {what}; saw {} states (last {:?}) and {} commands (last {:?})",
                self.seen_states.len(),
                self.seen_states.last(),
                self.seen_commands.len(),
                self.seen_commands.last()
            );
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    pub fn clear(&mut self) {
        self.poll();
        self.seen_states.clear();
        self.seen_commands.clear();
    }
}

/// Reads a JSON summary written by a process.
pub fn read_json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{} is not JSON: {e}", path.display()))
}

/// Lateness p99 (µs) above which a live run counts as disturbed by the host.
const DISTURBED_P99_US: f64 = 1000.0;

/// A wake-up this late, or a wait for a state this long (ns), is a host stall that costs
/// tracking.
const STALL_NS: u64 = 5_000_000;

/// Whether the host disturbed a run, from the summaries its processes wrote (the daemon's,
/// the plant's): more than 1 % of one's wake-ups over a period late, one stall of
/// [`STALL_NS`] (a wake-up that late, or the daemon waiting that long for a state), or a
/// plant whose states stopped coming (the daemon dropped one as stale or went to HOLD: it
/// does so only when the plant's process misses its periods, which a stalled vCPU does
/// without the daemon's own clock showing it).
pub fn disturbed(summaries: &[&serde_json::Value]) -> bool {
    summaries.iter().any(|s| {
        let c = &s["counters"];
        let plant_stalled = ["holds_entered", "rejected_stale"]
            .iter()
            .any(|k| c[k].as_u64().unwrap_or(0) > 0);
        let late = &s["lateness"];
        let longest = ["late_wakes", "wait_gaps"]
            .map(|k| s["counters"][k]["max_ns"].as_u64().unwrap_or(0))
            .into_iter()
            .chain([(late["max_us"].as_f64().unwrap_or(0.0) * 1e3) as u64])
            .max()
            .unwrap_or(0);
        plant_stalled
            || late["p99_us"].as_f64().unwrap_or(0.0) > DISTURBED_P99_US
            || longest >= STALL_NS
    })
}

/// Seconds before a run's end in which an arm brake (`counters.arm_brakes`) leaves the last
/// 5 s measuring the recovery from it: the Panda's self-motion closes in at −0.75 /s, so a kick
/// of 0.25 rad/s needs about 10 s to be back under 1e-2 and 5 more to leave the window.
pub const BRAKE_RECOVERY_S: f64 = 15.0;

/// Asserts that the daemon summary `s`'s period residual fell from `start` to its last 5 s'
/// (`period_residual_after`) by `factor` and to under `max`. A host stall of 20 ms (a HOLD,
/// a device braking on missed answers) knocks the arm off its cycle; when the newest came in
/// the last [`BRAKE_RECOVERY_S`] s, the window measures the recovery, which must have begun
/// (below `start`), and the test says so.
pub fn assert_residual_falls(s: &serde_json::Value, start: f64, factor: f64, max: f64) {
    let after = s["period_residual_after"].as_f64().unwrap_or(f64::NAN);
    let end = s["duration_s"].as_f64().unwrap_or(f64::NAN);
    let late_brake = s["last_arm_brake_s"]
        .as_f64()
        .filter(|&t| t > end - BRAKE_RECOVERY_S);
    match late_brake {
        None => assert!(
            after * factor <= start && after < max,
            "residual {start} → {after} (asked: {factor}× smaller, under {max}): {s}"
        ),
        Some(t) => {
            eprintln!("the arm braked at t = {t:.1} s of {end:.1}: residual {start} → {after}");
            assert!(
                after < start,
                "residual {start} → {after} after a brake at t = {t}: {s}"
            );
        }
    }
}

/// Asserts that a live run tracked its path to `bound` (m).
///
/// A loop that the host stalls for 10-20 ms leaves the plant running on its last command, and
/// the arm leaves its path by up to millimetres until the law pulls it back (a time constant of
/// 1/√kp, 0.16 s on the Panda): physics, not a fault, and a shared VM does it in bursts
/// (injected 15 ms stalls every 0.2 s give an RMS of 0.9 mm and a median of 0.4 mm where a
/// quiet run has 6 µm). So a run the host [`disturbed`] must keep its median within `bound` and
/// its RMS within `10 · bound`; a quiet one its RMS within `bound`.
///
/// `summaries` are the daemon's summary and, when the run has one, the plant's.
pub fn assert_tracks(summaries: &[&serde_json::Value], bound: f64) {
    let s = summaries[0];
    let rms = s["tracking_rms_m"].as_f64().unwrap_or(f64::NAN);
    let p99_late = s["lateness"]["p99_us"].as_f64().unwrap_or(0.0);
    if !disturbed(summaries) {
        assert!(rms < bound, "tracking RMS {rms} m over {bound} m: {s}");
        return;
    }
    let median = s["tracking"]["p50_m"].as_f64().unwrap_or(f64::NAN);
    eprintln!(
        "disturbed run (lateness p99 {p99_late} µs): tracking RMS {rms} m, median {median} m"
    );
    assert!(
        median < bound && rms < 10.0 * bound,
        "a disturbed run (lateness p99 {p99_late} µs) must keep the median tracking error under \
         {bound} m and the RMS under {} m: {s}",
        10.0 * bound
    );
}

/// The Panda study set-up that the filter traps only now and then: μ = 1.8 from the start and
/// two spheres over the circle (offline, the filter leaves the null space and costs millimetres
/// of tracking in a few task periods, never 5 cm, never 2 s on end). `plan` is `plan` (`"auto"` steers, as there are spheres; `false`
/// leaves the arm to the trap watch).
pub fn panda_grazing_two_spheres(plan: &str) -> String {
    let cfg = control::config::spatial::PANDA_PAPER
        .replace("mu = 1.0\nt_on = 60.0", "mu = 1.8\nt_on = 0.0")
        .replace(
            "[safety]\nenabled = true\n",
            &format!("[safety]\nenabled = true\nplan = {plan}\n"),
        )
        .replace(
            "[sim]",
            "[[obstacles]]\ncenter = [0.145, -0.233, 0.675]\nradius = 0.072\n\n\
             [[obstacles]]\ncenter = [0.282, -0.167, 0.606]\nradius = 0.068\n\n[sim]",
        );
    assert!(
        cfg.contains("mu = 1.8") && cfg.contains("[[obstacles]]") && cfg.contains("plan = "),
        "the preset moved"
    );
    cfg
}
