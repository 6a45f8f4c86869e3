//! chaosd's command line: the controller service (`run`), the one-command demonstration (`demo`)
//! and a config checker. It lives in the library so that a program of your own (one that
//! registers custom secondary tasks, say: examples/custom-task) is the whole of chaosd with two
//! lines of its own. [`main`] maps errors to exit codes; all input is validated before any
//! process starts.

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};

use crate::config::DaemonSetup;
use crate::demo_report;
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
    /// part-way, and print a report: by default the 7-joint Panda (`--robot planar` for the
    /// paper's arm), each state answered in the same cycle.
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
        /// What starts a tick: state (each state is answered in the same cycle; the default)
        /// or clock (free-running loops). A --config file's daemon.trigger or plant.trigger is
        /// kept unless this is given. Sets daemon.trigger and plant.trigger.
        #[arg(long)]
        trigger: Option<rt::Trigger>,
        /// Drive the arm through a hardware bridge instead of the simulator: `udp` runs
        /// chaosd-fakebot (a device emulator that owns the clock) and chaosd-bridge over UDP on
        /// the loopback, with the state trigger.
        #[arg(long, value_enum, conflicts_with = "plant")]
        bridge: Option<BridgeKind>,
        /// The plant's physics: `mujoco` runs chaosd-plant-mujoco (MuJoCo's model of the robot,
        /// its meshes judging contact; built by scripts/mujoco-setup, docs/mujoco.md).
        #[arg(long, value_enum)]
        plant: Option<PlantKind>,
        /// With --plant mujoco: the robot's URDF or MJCF for MuJoCo (default: the set-up's own
        /// robot, which for a built-in robot has no collision geometry).
        #[arg(long = "mujoco-model", requires = "plant")]
        mujoco_model: Option<PathBuf>,
        /// The command interface (a robot set-up only): acceleration, velocity, position or
        /// torque. Velocity, position and torque run the rigid-body plant (its joint servo, its
        /// masses) unless the config's [plant] names the dynamics.
        #[arg(long, value_parser = control::command::CommandMode::parse)]
        mode: Option<control::command::CommandMode>,
        /// Send the commands as the law asks, without the limiter: to see what it prevents
        /// (through --bridge udp, the device's reflex stops).
        #[arg(long = "no-limiter")]
        no_limiter: bool,
        /// Print every line of the report (lateness, state age, the trigger's counts, faults
        /// by kind, joint limits, files), not only the one-screen summary. The full report is
        /// always written to report.txt in the output directory.
        #[arg(long)]
        details: bool,
    },
    /// Validate a config file and print the effective settings.
    CheckConfig {
        #[command(flatten)]
        common: Common,
    },
}

/// The physics of a demo's plant, when it is not chaosd's own.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum PlantKind {
    /// MuJoCo (chaosd-plant-mujoco).
    Mujoco,
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
    /// the 7-joint Panda, panda-paper for it with the paper's recipe: chaotic first, slow).
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
    let summary = out
        .join(crate::demo_report::FAKEBOT_SUMMARY)
        .display()
        .to_string();
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

/// `--mode` and whether the limiter is on (`--no-limiter`).
type CommandChoice = (Option<control::command::CommandMode>, bool);

fn demo(
    common: &Common,
    duration: Option<f64>,
    (mu, t_on): (Option<control::adapt::MuSetting>, Option<f64>),
    trigger: Option<rt::Trigger>,
    (bridge, mujoco): (Option<BridgeKind>, Option<Option<PathBuf>>),
    (mode, limiter): CommandChoice,
    details: bool,
) -> Result<()> {
    if bridge == Some(BridgeKind::Udp) && trigger == Some(rt::Trigger::Clock) {
        bail!(
            "--bridge udp needs --trigger state: the device expects each answer within its cycle"
        );
    }
    let built_in = common.config.is_none();
    let mut s = if built_in && common.preset.is_none() {
        Common {
            preset: Some(common.robot_preset("demo")?.unwrap_or("panda".into())),
            robot: None,
            ..common.clone()
        }
        .setup()?
    } else {
        common.setup()?
    };
    // The Panda's self-motion settles over tens of periods (docs/panda-study.md): a planar
    // demo's 25 s would end before the feedback had shown anything.
    let duration = duration.unwrap_or(if s.system.robot().is_some() {
        60.0
    } else {
        25.0
    });
    check_duration(duration)?;
    // Same-cycle is the better default wherever the set-up does not say otherwise (a built-in
    // set-up, or a file of one's own without daemon.trigger or plant.trigger): the answer
    // reaches the plant microseconds after its state, not a period later (docs/service.md).
    let (daemon_table, plant_table) = s.system.tables();
    let says = |t: &Option<toml::Table>| t.as_ref().is_some_and(|t| t.contains_key("trigger"));
    let file_says = says(daemon_table) || says(plant_table);
    let trigger = if bridge.is_some() || (trigger.is_none() && !file_says) {
        Some(rt::Trigger::State)
    } else {
        trigger
    };
    if built_in {
        // About a dozen status lines, whatever the length: the run fits one screen.
        s.daemon.report_every_s = (duration / 12.0).round().clamp(2.0, 60.0);
    }
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
    // The file's switch-on time (0 for the `panda` preset: its feedback is part of the law
    // from the start), unless the run ends before it.
    let t_on = t_on.unwrap_or(if fb.t_on < duration {
        fb.t_on
    } else {
        duration / 3.0
    });
    s.system.schedule_feedback(mu, t_on);
    // The plant reads the same file: give it our namespace and output directory.
    let mut plant = s.system.tables().1.clone().unwrap_or_default();
    if let Some(model) = mujoco {
        use_mujoco(&s.system, &mut plant, model)?;
    }
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
    crate::persist::clear(&out)?;

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
    let summary = crate::service::run(&s, Some(duration), print_line)?;
    let status = guard.stop(Duration::from_secs(5));
    device.stop(Duration::from_secs(5));
    let plant_summary = read_json(&out.join(PLANT_SUMMARY));
    let device = bridge.and_then(|_| read_json(&out.join(demo_report::FAKEBOT_SUMMARY)));
    let run = demo_report::Run {
        setup: &s,
        daemon: &summary,
        plant: plant_summary.as_ref(),
        bridge: bridge.is_some(),
        device: device.as_ref(),
        out: &out,
    };
    print_report(&run, details)?;
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

/// `--plant mujoco [--mujoco-model FILE]`: `[plant] dynamics = "mujoco"` and the model.
fn use_mujoco(
    system: &control::System,
    plant: &mut toml::Table,
    model: Option<PathBuf>,
) -> Result<()> {
    if system.robot().is_none() {
        bail!("--plant mujoco simulates a robot's URDF; the paper's planar arm has no mass model: try --robot panda");
    }
    plant.insert("dynamics".into(), "mujoco".into());
    if let Some(m) = model {
        // The plant reads the config from the output directory: the path must not depend on
        // where it was given from.
        let abs = m
            .canonicalize()
            .with_context(|| format!("--mujoco-model {}", m.display()))?;
        let mut t = toml::Table::new();
        t.insert("model".into(), abs.display().to_string().into());
        plant.insert("mujoco".into(), t.into());
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
    let Some(r) = system.robot_mut() else {
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
    let command = &mut r.own_mut().command;
    if let Some(m) = mode {
        command.mode = m;
    }
    command.limiter = limiter;
    if command.mode != CommandMode::Acceleration && !plant.contains_key("dynamics") {
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

/// A summary a child process wrote at exit, if it did.
fn read_json(path: &Path) -> Option<serde_json::Value> {
    let text = std::fs::read_to_string(path).ok()?;
    serde_json::from_str(&text).ok()
}

/// The short report (or every line with `--details`); the full one goes to `report.txt`.
fn print_report(run: &demo_report::Run, details: bool) -> Result<()> {
    let all = demo_report::lines(run);
    let file = run.out.join("report.txt");
    let mut text = format!("{}\n", demo_report::HEADING);
    for l in &all {
        text += &format!("{l}\n");
    }
    rt::files::write(&file, text)?;
    let shown = if details {
        all
    } else {
        demo_report::brief(&all, &file)
    };
    say!("\n{}", demo_report::HEADING);
    for l in shown {
        say!("{l}");
    }
    Ok(())
}

/// Adopts the live state a previous run left in the output directory, unless `fresh`.
fn resume_live_state(s: &mut DaemonSetup, fresh: bool) -> Result<()> {
    let dir = s.daemon.output_dir.clone();
    if fresh {
        return crate::persist::clear(&dir)
            .with_context(|| format!("cannot remove {}", crate::persist::path(&dir).display()));
    }
    let Some(saved) = crate::persist::load(&dir, s.system.n())? else {
        return Ok(());
    };
    let (live, edited) = crate::persist::adopt(saved, &s.system).map_err(|e| {
        anyhow::anyhow!(
            "{}: {e} (start with --fresh to ignore it)",
            crate::persist::path(&dir).display()
        )
    })?;
    if let Some(why) = edited {
        tracing::warn!("{why}");
    }
    let (t, fault) = (live.t, live.fault.clone());
    s.resume_from(live).map_err(|e| {
        anyhow::anyhow!("{}: the saved state does not fit this configuration: {e} (start with --fresh to ignore it)", crate::persist::path(&dir).display())
    })?;
    tracing::info!(
        "resuming the live state saved in {}: controller time {t:.3} s, μ = {}, {} obstacles{} (--fresh starts from the file)",
        crate::persist::path(&dir).display(),
        crate::number::short(s.system.feedback().mu),
        s.system.safety().obstacles,
        fault.map_or(String::new(), |f| format!(", in FAULT ({f}): `chaosctl resume` to control again"))
    );
    Ok(())
}

/// chaosd's `main`: parses the command line, runs it, and maps an error to exit code 2.
pub fn main() -> ExitCode {
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
            let summary = crate::service::run(&s, duration, print_line)?;
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
            plant,
            mujoco_model,
            mode,
            no_limiter,
            details,
        } => demo(
            &common,
            duration,
            (mu, t_on),
            trigger,
            (bridge, plant.map(|_| mujoco_model)),
            (mode, !no_limiter),
            details,
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
