//! chaosd-fakebot: a device emulator for chaosd-bridge. It owns the clock, integrates the arm,
//! speaks the UDP protocol of `plant::udp`, and injects faults on request.

use anyhow::{ensure, Context, Result};
use clap::Parser;
use control::with_dof;
use plant::app::{self, PlantArgs};
use plant::config::PlantConfig;
use plant::udp::fakebot::{self, AnswerWait, FakebotConfig, FakebotSummary, Placement};
use plant::SimPlant;
use rt::WaitStrategy;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "chaosd-fakebot",
    version,
    about = "A robot emulator on the chaosd UDP device protocol, with fault injection"
)]
struct Args {
    /// --config / --preset give the arm, its start and [plant] rate_hz, substeps, brake_gain.
    #[command(flatten)]
    plant: PlantArgs,
    /// Where the device receives commands.
    #[arg(long, default_value = "127.0.0.1:47000")]
    listen: SocketAddr,
    /// Where the states go (the bridge's --bind).
    #[arg(long, default_value = "127.0.0.1:47001")]
    peer: SocketAddr,
    /// Missed answers in a row before the device brakes.
    #[arg(long = "max-missed", default_value_t = 20)]
    max_missed: u32,
    /// Missed answers in a row after which the device stops with a reflex error, as FCI does
    /// (`communication_constraints_violation`; cleared by a HOLD, `chaosctl recover`), instead
    /// of braking and resuming by itself. Off by default: this VM stalls now and then.
    #[arg(long = "stop-after-missed")]
    stop_after_missed: Option<u32>,
    /// Probability (0..=0.5) of losing each packet, in either direction.
    #[arg(long, default_value_t = 0.0)]
    loss: f64,
    /// Every this many seconds, delay the answers in transit by --spike-ms (a network spike).
    #[arg(long = "spike-every")]
    spike_every: Option<f64>,
    #[arg(long = "spike-ms", default_value_t = 5.0)]
    spike_ms: f64,
    /// Restart (new session, initial state) every this many seconds.
    #[arg(long = "restart-every")]
    restart_every: Option<f64>,
    #[arg(long = "restart-pause-ms", default_value_t = 200.0)]
    restart_pause_ms: f64,
    /// Seed of the loss injector.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Write the counters here as JSON at exit.
    #[arg(long)]
    summary: Option<PathBuf>,
    /// Run where a device with a clock of its own sits on a machine it shares with the loops:
    /// on [plant] core, 10 SCHED_FIFO steps above [plant] priority (at most 99), sleeping until
    /// each cycle and blocking for each answer, so the bridge keeps the core whenever the device
    /// is not working. What e2e and the demo use.
    #[arg(long = "beside-plant", conflicts_with_all = ["core", "priority", "answer_wait"])]
    beside_plant: bool,
    /// Pin the device to this core.
    #[arg(long)]
    core: Option<usize>,
    /// SCHED_FIFO priority 1..=99 of the device, or 0 for the normal scheduler.
    #[arg(long)]
    priority: Option<u8>,
    /// How the device waits for its next cycle: sleep, hybrid or spin [default: [plant] wait].
    #[arg(long)]
    wait: Option<rt::WaitStrategy>,
    /// How it waits for each answer: poll (while answers come; for a device with a core of its
    /// own) or block (in ppoll) [default: block with a --priority above 0, else poll].
    #[arg(long = "answer-wait")]
    answer_wait: Option<AnswerWait>,
    /// The command interfaces the device takes, comma-separated (acceleration, velocity,
    /// position, torque; torque needs [plant] dynamics = "rigid-body") [default: all it can].
    #[arg(long, value_delimiter = ',')]
    interfaces: Vec<String>,
    /// Follow every command as sent, without the arm's rules (no reflex stops): to see what a
    /// limiter-less stream would do to an arm that did not protect itself.
    #[arg(long = "no-reflexes")]
    no_reflexes: bool,
}

/// The `wire::takes` flags of `--interfaces`; the default is every interface this arm can
/// follow (torque only with rigid-body dynamics).
fn interfaces(a: &Args, p: &PlantConfig) -> Result<u32> {
    ensure!(
        p.dynamics != plant::config::Dynamics::Mujoco,
        "plant.dynamics = \"mujoco\": the fakebot simulates kinematic or rigid-body arms; MuJoCo \
         is chaosd-plant-mujoco's (docs/mujoco.md)"
    );
    let rigid = p.dynamics == plant::config::Dynamics::RigidBody;
    if a.interfaces.is_empty() {
        let all: &[u32] = if rigid { &[0, 1, 2, 3] } else { &[0, 1, 2] };
        return Ok(plant::udp::wire::takes(all));
    }
    let mut codes = Vec::new();
    for name in &a.interfaces {
        let mode = control::command::CommandMode::parse(name)
            .map_err(|e| anyhow::anyhow!("--interfaces: {e}"))?;
        ensure!(
            rigid || mode != control::command::CommandMode::Torque,
            "--interfaces torque: a kinematic arm has no masses to apply torques to; set [plant] dynamics = \"rigid-body\""
        );
        codes.push(mode.code());
    }
    Ok(plant::udp::wire::takes(&codes))
}

fn validate(a: &Args) -> Result<()> {
    ensure!(
        (1..=100_000).contains(&a.max_missed),
        "--max-missed {}: must be between 1 and 100000",
        a.max_missed
    );
    if let Some(n) = a.stop_after_missed {
        ensure!(
            (1..=100_000).contains(&n),
            "--stop-after-missed {n}: must be between 1 and 100000"
        );
    }
    ensure!(
        a.loss.is_finite() && (0.0..=0.5).contains(&a.loss),
        "--loss {}: must be between 0 and 0.5",
        a.loss
    );
    for (name, v) in [
        ("spike-every", a.spike_every),
        ("restart-every", a.restart_every),
    ] {
        if let Some(v) = v {
            ensure!(
                v.is_finite() && (0.01..=1e6).contains(&v),
                "--{name} {v}: must be between 0.01 and 1e6 s"
            );
        }
    }
    for (name, v) in [
        ("spike-ms", a.spike_ms),
        ("restart-pause-ms", a.restart_pause_ms),
    ] {
        ensure!(
            v.is_finite() && (0.0..=60_000.0).contains(&v),
            "--{name} {v}: must be between 0 and 60000 ms"
        );
    }
    if let Some(p) = a.priority {
        ensure!(
            p <= 99,
            "--priority {p}: must be 0 (normal scheduler) or a SCHED_FIFO priority 1..=99"
        );
    }
    if let Some(c) = a.core {
        ensure!(c < 1024, "--core {c}: must be a CPU index below 1024");
    }
    ensure!(
        a.listen != a.peer,
        "--listen and --peer are both {}",
        a.listen
    );
    Ok(())
}

/// Where the device runs and how it waits: `--beside-plant` or the flags one by one. A device
/// that shares a core (`--beside-plant`) or runs at SCHED_FIFO blocks for its answers unless
/// told otherwise; one that polls at SCHED_FIFO is warned about.
fn placement(a: &Args, p: &PlantConfig) -> (Placement, WaitStrategy, AnswerWait) {
    let (placement, wait) = if a.beside_plant {
        (
            Placement::beside(p.core, p.priority),
            a.wait.unwrap_or(WaitStrategy::Sleep),
        )
    } else {
        let placement = Placement {
            core: a.core,
            priority: a.priority.unwrap_or(0),
        };
        (placement, a.wait.unwrap_or(p.wait))
    };
    let realtime = placement.priority > 0;
    let answer_wait = a.answer_wait.unwrap_or(if a.beside_plant || realtime {
        AnswerWait::Block
    } else {
        AnswerWait::Poll
    });
    if realtime && (answer_wait == AnswerWait::Poll || wait == WaitStrategy::Spin) {
        eprintln!(
            "chaosd-fakebot: warning: at SCHED_FIFO {} a polling device keeps every lower-priority \
             thread off its core while it polls (the bridge too, if it shares the core)",
            placement.priority
        );
    }
    (placement, wait, answer_wait)
}

fn run(a: &Args) -> Result<FakebotSummary> {
    validate(a)?;
    let l = app::load(&a.plant)?;
    let p = &l.plant;
    let (placement, wait, answer_wait) = placement(a, p);
    let cfg = FakebotConfig {
        listen: a.listen,
        peer: a.peer,
        rate_hz: p.rate_hz,
        max_missed: a.max_missed,
        stop_after_missed: a.stop_after_missed,
        loss: a.loss,
        spike_every_s: a.spike_every,
        spike_ms: a.spike_ms,
        restart_every_s: a.restart_every,
        restart_pause_ms: a.restart_pause_ms,
        seed: a.seed,
        wait,
        spin_us: p.spin_us,
        answer_wait,
        placement,
        takes: interfaces(a, p)?,
        enforce: !a.no_reflexes,
    };
    let s = &l.system;
    let c = with_dof!(s.n(), N => {
        // Built once here so a bad [plant] is one error at start-up, then again on each restart.
        SimPlant::<N>::from_config(s, p)?;
        let limits = s.device_limits::<N>()?;
        // A robot powers up at rest; chaosd's own acceleration-level emulator keeps the
        // set-up's q̇0, as every planar result was measured with it.
        let rest = s.command_mode() != control::command::CommandMode::Acceleration;
        let make = || {
            let sim = SimPlant::<N>::from_config(s, p).expect("checked at start-up");
            if rest { sim.at_rest() } else { sim }
        };
        fakebot::run::<N>(&cfg, make, limits, l.duration)
    })?;
    if let Some(path) = &a.summary {
        rt::files::write(path, serde_json::to_string_pretty(&c)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(c)
}

/// " (at 5.112 s)", " (first at 5.112 s, last at 57.020 s)", or nothing without brakes.
fn brake_times(s: &FakebotSummary) -> String {
    match (s.first_brake_s, s.last_brake_s) {
        (Some(a), Some(b)) if a == b => format!(" (at {a:.3} s)"),
        (Some(a), Some(b)) => format!(" (first at {a:.3} s, last at {b:.3} s)"),
        _ => String::new(),
    }
}

fn main() -> ExitCode {
    let args = Args::parse();
    match run(&args) {
        Ok(s) => {
            let c = &s.counters;
            eprintln!(
                "chaosd-fakebot: round trip (state sent → answer received) {}",
                s.round_trip.one_line()
            );
            eprintln!(
                "chaosd-fakebot: {} cycles ({} skipped by its own lateness), {} answered in time, {} missed, {} late answers, {} malformed, {} stale; lost {} states and {} commands; {} brakes{}, {} spikes, {} restarts; {} reflex stops{}",
                c.cycles, c.skipped, c.answered_in_time, c.missed, c.late_answers, c.malformed, c.stale_session, c.states_lost, c.commands_lost, c.brakes, brake_times(&s), c.spikes, c.restarts,
                c.reflex_stops, s.first_reflex.as_ref().map_or(String::new(), |f| format!(", the first {f}"))
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("chaosd-fakebot: error: {e:#}");
            ExitCode::from(2)
        }
    }
}
