//! chaosd: the controller service (`run`), the one-command demonstration (`demo`) and a config
//! checker. `main` maps errors to exit codes; all input is validated before any process starts.

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};

use daemon::config::DaemonSetup;
use daemon::telemetry::DaemonSummary;
use rt::WaitStrategy;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

/// `println!` that ignores a closed stdout: `chaosd demo | head -2` must not panic on the broken
/// pipe, and the demo must still stop its plant and write its files.
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

#[derive(Parser)]
#[command(
    name = "chaosd",
    version,
    about = "Real-time chaos-control daemon for a redundant arm (the paper's planar arm or a URDF robot)"
)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Run the controller service until SIGINT/SIGTERM (or --duration).
    Run {
        #[command(flatten)]
        common: Common,
        /// Stop after this many seconds.
        #[arg(long)]
        duration: Option<f64>,
        /// Start from the config file alone: ignore (and delete) the live state a previous run
        /// saved in the output directory (changes made with chaosctl, controller time, a FAULT).
        #[arg(long)]
        fresh: bool,
        /// Write a replay recording of every tick to NAME in the output directory (for
        /// `chaosctl replay`): MCAP, with every channel of `chaosctl record` beside the replay's
        /// (it opens in Foxglove), or the text format alone when NAME ends in `.replay`.
        #[arg(long, value_name = "NAME")]
        record: Option<String>,
    },
    /// Start a plant process and the daemon, run a while with the delayed feedback switched on
    /// part-way, and print a report.
    Demo {
        #[command(flatten)]
        common: Common,
        /// Seconds to run (default 25 for the planar arm, 60 for the Panda).
        #[arg(long)]
        duration: Option<f64>,
        /// Pyragas gain switched on part-way, or `auto` (it adapts; give the run a few minutes)
        /// (default: the config's, or 0.2 if that is 0).
        #[arg(long)]
        mu: Option<control::adapt::MuSetting>,
        /// When the feedback switches on (default: the config's t_on if it falls inside the run,
        /// else a third of the way in).
        #[arg(long = "t-on")]
        t_on: Option<f64>,
        /// What starts a tick: clock (free-running, the default) or state (each state is
        /// answered in the same cycle). Sets daemon.trigger and plant.trigger.
        #[arg(long)]
        trigger: Option<rt::Trigger>,
        /// Drive the arm through a hardware bridge instead of the simulator: `udp` runs
        /// chaosd-fakebot (a device emulator that owns the clock) and chaosd-bridge over UDP on
        /// the loopback, with the state trigger.
        #[arg(long, value_enum)]
        bridge: Option<BridgeKind>,
        /// The command interface (a robot set-up only): acceleration, velocity, position or
        /// torque. Velocity, position and torque run the rigid-body plant (its joint servo, its
        /// masses) unless the config's [plant] names the dynamics.
        #[arg(long, value_parser = control::command::CommandMode::parse)]
        mode: Option<control::command::CommandMode>,
        /// Send the commands as the law asks, without the limiter: to see what it prevents
        /// (through --bridge udp, the device's reflex stops).
        #[arg(long = "no-limiter")]
        no_limiter: bool,
    },
    /// Validate a config file and print the effective settings.
    CheckConfig {
        #[command(flatten)]
        common: Common,
    },
}

/// The plant side of a demo, when it is not the simulator.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum BridgeKind {
    /// chaosd-fakebot + chaosd-bridge over UDP on 127.0.0.1.
    Udp,
}

#[derive(Args, Clone)]
struct Common {
    /// TOML config file.
    #[arg(long, conflicts_with = "preset")]
    config: Option<PathBuf>,
    /// A built-in set-up (paper, paper-eq11, paper-obstacle, paper-floating, demo; panda for
    /// the 7-joint Panda).
    #[arg(long, conflicts_with = "robot")]
    preset: Option<String>,
    /// A built-in robot's set-up: `panda` (the Panda study's working set-up, the same as
    /// `--preset panda`), or `planar` (the paper's 3-link arm: the `demo` preset in `demo`,
    /// `paper` elsewhere). A URDF robot of your own is named in a config's [robot] table.
    #[arg(long, conflicts_with = "config")]
    robot: Option<String>,
    /// Overrides daemon.namespace.
    #[arg(long)]
    namespace: Option<String>,
    /// Overrides daemon.output_dir.
    #[arg(long)]
    output: Option<PathBuf>,
    /// Overrides daemon.rate_hz (in `demo` with the state trigger, plant.rate_hz too: the
    /// plant sets the pace).
    #[arg(long)]
    rate: Option<f64>,
    /// Overrides daemon.wait (sleep, hybrid, spin).
    #[arg(long)]
    wait: Option<WaitStrategy>,
    /// Serve the live view for Foxglove on ADDR, e.g. 127.0.0.1:8765 (overrides
    /// daemon.foxglove; in Foxglove: Open connection → Foxglove WebSocket → ws://ADDR).
    #[arg(long, value_name = "ADDR")]
    foxglove: Option<String>,
}

impl Common {
    /// The preset a `--robot` name stands for (`planar`: `planar_preset`).
    fn robot_preset(&self, planar_preset: &str) -> Result<Option<String>> {
        Ok(match self.robot.as_deref() {
            None => None,
            Some("planar") => Some(planar_preset.into()),
            Some("panda") => Some("panda".into()),
            Some(other) => bail!(
                "--robot {other:?}: the built-in robots are panda and planar; for a URDF of your own, name it in a config's [robot] table (docs/your-robot.md) and pass --config"
            ),
        })
    }

    fn setup(&self) -> Result<DaemonSetup> {
        let preset = match self.robot_preset("paper")? {
            Some(p) => Some(p),
            None => self.preset.clone(),
        };
        let mut s = match (&self.config, &preset) {
            (Some(p), _) => DaemonSetup::load(p)?,
            (None, Some(name)) => DaemonSetup::from_system(rt::robot::preset(name)?)?,
            (None, None) => DaemonSetup::from_system(rt::robot::preset("paper")?)?,
        };
        if let Some(ns) = &self.namespace {
            s.daemon.namespace = ns.clone();
        }
        if let Some(o) = &self.output {
            s.daemon.output_dir = o.clone();
        }
        if let Some(r) = self.rate {
            s.daemon.rate_hz = r;
        }
        if let Some(w) = self.wait {
            s.daemon.wait = w;
        }
        if let Some(a) = &self.foxglove {
            s.daemon.foxglove = Some(a.clone());
        }
        s.validate()?;
        Ok(s)
    }
}

fn check_duration(d: f64) -> Result<()> {
    if !(d.is_finite() && d > 0.0 && d <= 1e7) {
        bail!("--duration {d}: must be a finite number of seconds > 0");
    }
    Ok(())
}

/// A status line to stdout; a closed stdout (`chaosd run | head`) must not stop the daemon.
fn print_line(line: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stdout(), "{line}");
}

/// Stops the child when dropped, on every exit path: SIGTERM first, so it writes its
/// histograms and leaves its iceoryx2 node cleanly, then SIGKILL.
struct ChildGuard(Option<Child>);

impl ChildGuard {
    /// SIGTERM, then up to `grace` for a clean exit, then SIGKILL.
    fn stop(&mut self, grace: Duration) -> Option<std::process::ExitStatus> {
        let mut child = self.0.take()?;
        // SAFETY: plain kill(2) on our own child's pid.
        unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
        let until = Instant::now() + grace;
        while Instant::now() < until {
            if let Ok(Some(st)) = child.try_wait() {
                return Some(st);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = child.kill();
        child.wait().ok()
    }
}

impl Drop for ChildGuard {
    fn drop(&mut self) {
        self.stop(Duration::from_secs(3));
    }
}

/// The file chaosd-plant writes at exit (the daemon reads it as JSON and does not link the plant).
const PLANT_SUMMARY: &str = "plant-summary.json";

/// The plant process dies with us, even if we are SIGKILLed.
fn plant_command(exe: PathBuf) -> Command {
    use std::os::unix::process::CommandExt;
    let mut c = Command::new(exe);
    // SAFETY: prctl is async-signal-safe; it only asks for SIGKILL when the parent dies.
    unsafe {
        c.pre_exec(|| {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
            Ok(())
        });
    }
    c
}

fn plant_exe() -> Result<PathBuf> {
    sibling_exe("chaosd-plant")
}

fn sibling_exe(name: &str) -> Result<PathBuf> {
    let me = std::env::current_exe().context("cannot locate the chaosd executable")?;
    let p = me.with_file_name(name);
    if !p.exists() {
        bail!(
            "{} not found: build both programs with `cargo build --release --bins`",
            p.display()
        );
    }
    Ok(p)
}

/// Two free UDP ports on the loopback (bound, read, released: the children bind them next).
fn free_udp_ports() -> Result<(u16, u16)> {
    let a = std::net::UdpSocket::bind("127.0.0.1:0").context("no free UDP port")?;
    let b = std::net::UdpSocket::bind("127.0.0.1:0").context("no free UDP port")?;
    Ok((a.local_addr()?.port(), b.local_addr()?.port()))
}

/// Starts `exe args…` with its output in `log`, as a child that dies with us.
fn spawn_logged(exe: PathBuf, args: &[String], log: &Path) -> Result<ChildGuard> {
    let f = rt::files::create(log)?;
    let name = exe.display().to_string();
    let child = plant_command(exe)
        .args(args)
        .stdin(Stdio::null())
        .stdout(f.try_clone()?)
        .stderr(f)
        .spawn()
        .with_context(|| format!("cannot start {name}"))?;
    Ok(ChildGuard(Some(child)))
}

/// The plant side of a demo: chaosd-plant, or chaosd-fakebot and chaosd-bridge. Returns the
/// plant process (the simulator or the bridge) and the device process (none for the simulator).
fn spawn_plant_side(
    bridge: Option<BridgeKind>,
    cfg_path: &Path,
    out: &Path,
    duration: f64,
) -> Result<(ChildGuard, ChildGuard)> {
    let cfg = cfg_path.display().to_string();
    let until = format!("{}", duration + 10.0);
    let common = ["--config".to_string(), cfg, "--duration".into(), until];
    let Some(BridgeKind::Udp) = bridge else {
        let plant = spawn_logged(plant_exe()?, &common, &out.join("plant.log"))?;
        return Ok((plant, ChildGuard(None)));
    };
    let (dev, br) = free_udp_ports()?;
    let (dev, br) = (format!("127.0.0.1:{dev}"), format!("127.0.0.1:{br}"));
    let summary = out.join(FAKEBOT_SUMMARY).display().to_string();
    let _ = std::fs::remove_file(&summary);
    let mut args = common.to_vec();
    args.extend(["--listen".into(), dev.clone(), "--peer".into(), br.clone()]);
    args.extend(["--summary".into(), summary]);
    // On the bridge's core above it: see plant::udp::fakebot::Placement.
    args.push("--beside-plant".into());
    let device = spawn_logged(
        sibling_exe("chaosd-fakebot")?,
        &args,
        &out.join("fakebot.log"),
    )?;
    let mut args = common.to_vec();
    args.extend(["--device".into(), dev, "--bind".into(), br]);
    let plant = spawn_logged(sibling_exe("chaosd-bridge")?, &args, &out.join("plant.log"))?;
    Ok((plant, device))
}

/// The file chaosd-fakebot writes at exit in a `--bridge udp` demo.
const FAKEBOT_SUMMARY: &str = "fakebot-summary.json";

/// The device's side of a `--bridge udp` demo: its round trip and its missed cycles.
fn print_device(out: &Path) {
    let text = std::fs::read_to_string(out.join(FAKEBOT_SUMMARY)).unwrap_or_default();
    let Ok(v) = serde_json::from_str::<serde_json::Value>(&text) else {
        say!("device (UDP)          n/a (chaosd-fakebot wrote no summary; see fakebot.log)");
        return;
    };
    let c = &v["counters"];
    let n = |k: &str| c[k].as_u64().unwrap_or(0);
    say!(
        "device round trip     {}  (fakebot: state sent over UDP → answer received)",
        pct(&v, "round_trip")
    );
    say!(
        "device cycles         {} cycles, {} answered in time, {} missed, {} late answers, {} brakes; {} states and {} commands lost (injected)",
        n("cycles"), n("answered_in_time"), n("missed"), n("late_answers"), n("brakes"), n("states_lost"), n("commands_lost")
    );
    say!(
        "device reflexes       {} reflex stops{}",
        n("reflex_stops"),
        v["first_reflex"]
            .as_str()
            .map_or(String::new(), |f| format!("; the first {f}"))
    );
}

/// `--mode` and whether the limiter is on (`--no-limiter`).
type CommandChoice = (Option<control::command::CommandMode>, bool);

fn demo(
    common: &Common,
    duration: Option<f64>,
    (mu, t_on): (Option<control::adapt::MuSetting>, Option<f64>),
    trigger: Option<rt::Trigger>,
    bridge: Option<BridgeKind>,
    (mode, limiter): CommandChoice,
) -> Result<()> {
    if bridge == Some(BridgeKind::Udp) && trigger == Some(rt::Trigger::Clock) {
        bail!(
            "--bridge udp needs --trigger state: the device expects each answer within its cycle"
        );
    }
    let trigger = if bridge.is_some() {
        Some(rt::Trigger::State)
    } else {
        trigger
    };
    let mut s = if common.config.is_none() && common.preset.is_none() {
        Common {
            preset: Some(common.robot_preset("demo")?.unwrap_or("demo".into())),
            robot: None,
            ..common.clone()
        }
        .setup()?
    } else {
        common.setup()?
    };
    // The Panda's self-motion settles over tens of periods (docs/panda-study.md): a planar
    // demo's 25 s would end before the feedback had shown anything.
    let duration = duration.unwrap_or(match s.system {
        control::System::Planar(_) => 25.0,
        control::System::Spatial(_) => 60.0,
    });
    check_duration(duration)?;
    if common.namespace.is_none() {
        s.daemon.namespace = format!("demo-{}", std::process::id());
    }
    if common.output.is_none() {
        s.daemon.output_dir = PathBuf::from("out/demo");
    }
    let fb = s.system.feedback();
    use control::adapt::MuSetting;
    let mu = mu.unwrap_or(match (fb.auto, fb.mu) {
        (Some(_), _) => MuSetting::Auto,
        (None, m) if m > 0.0 => MuSetting::Fixed(m),
        _ => MuSetting::Fixed(0.2),
    });
    let t_on = t_on.unwrap_or(if fb.t_on > 0.0 && fb.t_on < duration {
        fb.t_on
    } else {
        duration / 3.0
    });
    s.system.schedule_feedback(mu, t_on);
    // The plant reads the same file: give it our namespace and output directory.
    let mut plant = s.system.tables().1.clone().unwrap_or_default();
    choose_command(&mut s.system, &mut plant, mode, limiter)?;
    if let Some(t) = trigger {
        s.daemon.trigger = t;
        plant.insert("trigger".into(), t.name().into());
    }
    // State-triggered there is one clock, the plant's: --rate sets it too.
    if let (Some(r), rt::Trigger::State) = (common.rate, s.daemon.trigger) {
        plant.insert("rate_hz".into(), r.into());
    }
    servo_substeps(&mut plant);
    plant.insert("namespace".into(), s.daemon.namespace.clone().into());
    plant.insert(
        "output_dir".into(),
        s.daemon.output_dir.display().to_string().into(),
    );
    *s.system.tables_mut().1 = Some(plant);
    s.validate()?;
    let out = s.daemon.output_dir.clone();
    rt::files::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let cfg_path = out.join("config.toml");
    rt::files::write(&cfg_path, s.to_toml())?;
    let _ = std::fs::remove_file(out.join(PLANT_SUMMARY));
    // A demo always starts from its configuration.
    daemon::persist::clear(&out)?;

    // Handle SIGINT/SIGTERM from here on, so an interrupt during start-up still stops cleanly.
    rt::signal::install();
    let log_path = out.join("plant.log");
    let (mut guard, mut device) = spawn_plant_side(bridge, &cfg_path, &out, duration)?;
    let fb = s.system.feedback();
    say!(
        "chaosd demo: {}, {} Hz, plant pid {}, namespace {:?}; μ = {}{} from t = {:.1} s; {duration} s",
        s.system.describe_arm(),
        s.daemon.rate_hz,
        guard.0.as_ref().map_or(0, |c| c.id()),
        s.daemon.namespace,
        fb.mu,
        if fb.auto.is_some() { " (auto)" } else { "" },
        fb.t_on
    );
    if let Some(d) = &device.0 {
        say!(
            "chaosd demo: over UDP on the loopback: chaosd-fakebot (device pid {}) ⇄ chaosd-bridge ⇄ chaosd, state trigger",
            d.id()
        );
    }
    std::thread::sleep(Duration::from_millis(300));
    if let Some(Ok(Some(st))) = device.0.as_mut().map(|c| c.try_wait()) {
        let log = std::fs::read_to_string(out.join("fakebot.log")).unwrap_or_default();
        bail!("chaosd-fakebot exited at start ({st}):\n{log}");
    }
    if let Some(Ok(Some(st))) = guard.0.as_mut().map(|c| c.try_wait()) {
        let log = std::fs::read_to_string(&log_path).unwrap_or_default();
        bail!("the plant process exited at start ({st}):\n{log}");
    }
    let summary = daemon::service::run(&s, Some(duration), print_line)?;
    let status = guard.stop(Duration::from_secs(5));
    device.stop(Duration::from_secs(5));
    let plant_json = std::fs::read_to_string(out.join(PLANT_SUMMARY)).ok();
    let plant_summary: Option<serde_json::Value> = plant_json
        .as_deref()
        .and_then(|t| serde_json::from_str(t).ok());
    print_report(&s, &summary, plant_summary.as_ref(), &out);
    if bridge.is_some() {
        print_device(&out);
    }
    if !status.is_some_and(|s| s.success()) {
        // The report above stands, but the run did not: say so in the exit code too.
        bail!(
            "the plant did not exit cleanly ({}); see {}",
            status.map_or("no status".into(), |s| s.to_string()),
            log_path.display()
        );
    }
    Ok(())
}

/// Applies `--mode` and `--no-limiter` to the set-up, and gives a non-acceleration mode the
/// rigid-body plant unless `[plant]` already names the dynamics.
fn choose_command(
    system: &mut control::System,
    plant: &mut toml::Table,
    mode: Option<control::command::CommandMode>,
    limiter: bool,
) -> Result<()> {
    use control::command::CommandMode;
    let control::System::Spatial(sp) = system else {
        if let Some(m) = mode.filter(|&m| m != CommandMode::Acceleration) {
            bail!("--mode {m}: the paper's planar arm has no mass model and takes accelerations only; try --robot panda");
        }
        if !limiter {
            bail!(
                "--no-limiter: the paper's planar arm has no limits to enforce; try --robot panda"
            );
        }
        return Ok(());
    };
    if let Some(m) = mode {
        sp.config.command.mode = m;
    }
    sp.config.command.limiter = limiter;
    if sp.config.command.mode != CommandMode::Acceleration && !plant.contains_key("dynamics") {
        plant.insert("dynamics".into(), "rigid-body".into());
    }
    Ok(())
}

/// The rigid-body arm's joint servo runs at the physics substep, like a robot's own joint
/// controllers, which run far above the command rate: at a slower plant rate (a UR's 500 Hz)
/// the demo takes more substeps, so the servo keeps at least 4 kHz, unless `[plant]` names them.
fn servo_substeps(plant: &mut toml::Table) {
    const SERVO_HZ: f64 = 4000.0;
    if plant.get("dynamics").and_then(|d| d.as_str()) != Some("rigid-body")
        || plant.contains_key("substeps")
    {
        return;
    }
    let rate = plant
        .get("rate_hz")
        .and_then(|r| r.as_float().or_else(|| r.as_integer().map(|i| i as f64)))
        .unwrap_or(1000.0);
    if rate.is_finite() && rate > 0.0 {
        let n = (SERVO_HZ / rate).ceil().clamp(4.0, 100.0) as i64;
        plant.insert("substeps".into(), n.into());
    }
}

fn pct(v: &serde_json::Value, key: &str) -> String {
    let g = |k: &str| v[key][k].as_f64().unwrap_or(f64::NAN);
    format!(
        "p50 {:.1} µs, p99 {:.1} µs, p99.9 {:.1} µs, max {:.1} µs",
        g("p50_us"),
        g("p99_us"),
        g("p999_us"),
        g("max_us")
    )
}

/// The state trigger's figures from the plant's summary: answered in time, late, braked.
fn print_answers(s: &DaemonSetup, p: &serde_json::Value) {
    let c = &p["counters"];
    let n = |k: &str| c[k].as_u64().unwrap_or(0);
    say!(
        "trigger               {}{}",
        s.daemon.trigger.name(),
        match s.daemon.trigger {
            rt::Trigger::State => ": a tick per state, the answer applied in the same cycle",
            rt::Trigger::Clock =>
                ": free-running loops, each applies the newest sample at its tick",
        }
    );
    if let Some(share) = p["in_time_share"].as_f64() {
        say!(
            "answered in time      {:.3} % of {} cycles; {} late cycles, {} late answers dropped, {} brakes after too many late cycles, {} cycles with no controller answering",
            share * 100.0,
            n("answered_in_time") + n("late_cycles"),
            n("late_cycles"),
            n("late_answers"),
            n("late_brakes"),
            n("silent_cycles")
        );
    }
}

/// State trigger: how often the daemon's core was gone while it waited for states, so that late
/// cycles can be told apart from a slow law (see `rt::gaps`).
fn print_core_gone(s: &DaemonSetup, c: &daemon::controller::Counters) {
    if s.daemon.trigger != rt::Trigger::State {
        return;
    }
    say!(
        "core gone             {}",
        rt::gaps::describe(&c.wait_gaps, &c.late_wakes, s.daemon.period_ns())
    );
}

/// The chaos monitor's verdict at the end and how it got there (`chaotic at 13 s → …`).
fn print_chaos(d: &DaemonSummary) {
    let c = &d.chaos;
    let path: Vec<String> = c
        .history
        .iter()
        .map(|e| format!("{} at {:.0} s", e.to.name(), e.t))
        .collect();
    say!(
        "chaos monitor         {} ({}){}",
        c.evidence.verdict.name(),
        daemon::chaos::describe(&c.evidence),
        if path.is_empty() {
            String::new()
        } else {
            format!("; {}", path.join(" → "))
        }
    );
}

fn print_report(s: &DaemonSetup, d: &DaemonSummary, plant: Option<&serde_json::Value>, out: &Path) {
    let c = &d.counters;
    say!("\n== chaosd demo report ==");
    match d.tracking_rms_m {
        Some(t) => say!("tracking error        RMS {t:.2e} m (after the first 2 s)"),
        None => say!("tracking error        n/a (no states received)"),
    }
    match (d.period_residual_before, d.period_residual_after) {
        (Some(b), Some(a)) => say!(
            "period residual       mean |q̇(t) − q̇(t−τ)|: {b:.3} rad/s before feedback → {a:.3} rad/s over the last 5 s with μ = {}{} ({})",
            d.chaos.mu,
            if s.system.feedback().auto.is_some() { " (auto)" } else { "" },
            if a == 0.0 { "periodic to rounding".to_string() } else if a <= b { format!("{:.1}× smaller", b / a) } else { format!("{:.1}× LARGER: not settled on a period-T orbit", a / b) }
        ),
        (b, a) => {
            let show = |v: Option<f64>| v.map_or("n/a".to_string(), |x| format!("{x:.3} rad/s"));
            say!(
                "period residual       mean |q̇(t) − q̇(t−τ)|: {} before feedback, {} with it (the run stopped before t_on + 5 s: nothing to compare)",
                show(b),
                show(a)
            )
        }
    }
    print_chaos(d);
    say!("wake-up lateness      {}", d.lateness.one_line());
    say!(
        "overruns              {} skipped periods in {} ticks",
        c.overruns,
        c.ticks
    );
    say!("compute per tick      {}", d.compute.one_line());
    say!("state age at tick     {}", d.state_age.one_line());
    if let Some(p) = plant {
        say!("state → command       {}", pct(p, "state_to_command"));
        say!(
            "command round trip    {}  (state published → command received by the plant{})",
            pct(p, "round_trip"),
            if s.daemon.trigger == rt::Trigger::State {
                ", same cycle"
            } else {
                ", at its next tick"
            }
        );
        print_answers(s, p);
        print_core_gone(s, c);
    } else {
        say!("command round trip    n/a (the plant wrote no summary)");
    }
    say!(
        "faults                {} samples rejected ({} invalid, {} stale, {} out of order, {} from the future, {} flagged faulty by the plant); {} holds; {} plant restarts; {} telemetry records dropped",
        c.rejected(), c.rejected_invalid, c.rejected_stale, c.rejected_out_of_order, c.rejected_future, c.plant_faults, c.holds_entered, c.plant_restarts, c.telemetry_dropped
    );
    if c.track_lost + c.out_of_reach + c.nonfinite > 0 {
        say!(
            "tracking loss         error above control.track_loss = {} m on {} ticks, the start-up transient included ({} near-singular, {} with the target out of reach, {} non-finite results)",
            s.system.safety().track_loss, c.track_lost, c.singular, c.out_of_reach, c.nonfinite
        );
    }
    let sf = s.system.safety();
    say!(
        "safety                filter {}: acted on {} ticks, left the null space on {} (tracking gave way), {} without a command meeting every limit; {} runaway-guard faults{}",
        if sf.enabled { "on" } else { "OFF" },
        c.safety_active, c.safety_left_null_space, c.safety_infeasible, c.faults,
        d.min_clearance_m.map_or(String::new(), |m| format!("; min clearance {m:.3} m (required {} m)", sf.clearance))
    );
    if let Some(line) = d.joint_limits.one_line() {
        say!("joint limits          {line}");
    }
    if let control::System::Spatial(_) = s.system {
        say!(
            "command               {} mode; {}",
            d.command.mode,
            d.command.one_line()
        );
        say!(
            "device                {} reflex stops{}",
            d.device_stops,
            d.first_device_stop
                .as_ref()
                .map_or(String::new(), |f| format!("; the first {f}"))
        );
    }
    say!("real-time set-up      {}", d.realtime.one_line());
    // Only the files that were written: a plant that died writes none of its own.
    let listed = |names: &[&str]| {
        names
            .iter()
            .filter(|n| out.join(n).exists())
            .copied()
            .collect::<Vec<_>>()
            .join(", ")
    };
    say!(
        "histograms            {}/{}",
        out.display(),
        listed(&[
            "daemon-lateness.hgrm",
            "daemon-compute.hgrm",
            "daemon-state-age.hgrm",
            "daemon.hlog",
            "plant-round-trip.hgrm",
            "plant-state-to-command.hgrm",
            "plant-lateness.hgrm",
        ])
    );
    say!(
        "summaries             {}/{}",
        out.display(),
        listed(&["daemon-summary.json", "plant-summary.json"])
    );
}

/// Adopts the live state a previous run left in the output directory, unless `fresh`.
fn resume_live_state(s: &mut DaemonSetup, fresh: bool) -> Result<()> {
    let dir = s.daemon.output_dir.clone();
    if fresh {
        return daemon::persist::clear(&dir)
            .with_context(|| format!("cannot remove {}", daemon::persist::path(&dir).display()));
    }
    let Some(saved) = daemon::persist::load(&dir, s.system.n())? else {
        return Ok(());
    };
    let (live, edited) = daemon::persist::adopt(saved, &s.system);
    if let Some(why) = edited {
        tracing::warn!("{why}");
    }
    let (t, fault) = (live.t, live.fault.clone());
    s.resume_from(live).map_err(|e| {
        anyhow::anyhow!("{}: the saved state does not fit this configuration: {e} (start with --fresh to ignore it)", daemon::persist::path(&dir).display())
    })?;
    tracing::info!(
        "resuming the live state saved in {}: controller time {t:.3} s, μ = {}, {} obstacles{} (--fresh starts from the file)",
        daemon::persist::path(&dir).display(),
        s.system.feedback().mu,
        s.system.safety().obstacles,
        fault.map_or(String::new(), |f| format!(", in FAULT ({f}): `chaosctl resume` to control again"))
    );
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    rt::log::init();
    let result = match cli.command {
        Cmd::Run {
            common,
            duration,
            fresh,
            record,
        } => (|| {
            if let Some(d) = duration {
                check_duration(d)?;
            }
            let mut s = common.setup()?;
            resume_live_state(&mut s, fresh)?;
            s.record = record;
            let summary = daemon::service::run(&s, duration, print_line)?;
            say!(
                "chaosd: stopped after {:.1} s; lateness {}; files in {}",
                summary.duration_s,
                summary.lateness.one_line(),
                s.daemon.output_dir.display()
            );
            Ok(())
        })(),
        Cmd::Demo {
            common,
            duration,
            mu,
            t_on,
            trigger,
            bridge,
            mode,
            no_limiter,
        } => demo(
            &common,
            duration,
            (mu, t_on),
            trigger,
            bridge,
            (mode, !no_limiter),
        ),
        Cmd::CheckConfig { common } => common.setup().map(|s| print!("{}", s.to_toml())),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            rt::log::fatal("chaosd", &format!("{e:#}"));
            ExitCode::from(2)
        }
    }
}
