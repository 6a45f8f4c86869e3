//! chaosctl: the command-line tool for chaosd.
//!
//! `main` only maps errors to exit codes; each subcommand lives in its own module and validates
//! all of its input before doing any work.

mod analysis;
mod export;
mod exporter;
mod plan;
mod plan_map;
mod plot;
mod robot;
mod robot_fit;
mod setup;
mod simulate;
mod subject;
mod traps;

use anyhow::Context;
use clap::{Parser, Subcommand};
use client::online;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "chaosctl",
    version,
    about = "Watch and steer chaosd, and analyse the arm's self-motion offline",
    after_help = "Across hosts (Zenoh): `chaosctl gateway --namespace NS [--listen EP] [--connect EP] \
                  [--allow-changes]`, `chaosctl fleet --remote EP` and `chaosctl --remote EP \
                  status|get|set|watch …` run chaosd-gateway, which is built on its own: \
                  cargo build --release -p gateway"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run one deterministic closed-loop simulation and summarise it.
    Simulate(simulate::SimulateArgs),
    /// Largest Lyapunov exponent of one run (Benettin), with its standard error.
    Lyapunov(analysis::lyapunov::LyapunovCmd),
    /// λ_max and Poincaré class over a μ range and several starts, in parallel (the paper's Fig. 6).
    Sweep(analysis::sweep::SweepCmd),
    /// Stroboscopic Poincaré section at t = kT: classify (period-p, quasi-periodic, irregular) and plot.
    Poincare(analysis::poincare::PoincareCmd),
    /// Period-T orbits by Newton's method, Floquet multipliers, and their stability against μ.
    Orbits(analysis::orbits::OrbitsCmd),
    /// The Pyragas gain the daemon chooses from its model for mu = "auto": the cycle, the delayed
    /// loop's leading Floquet multiplier at every gain tried, the fastest, and the smallest gain
    /// with 80 % of its rate, the choice (--json).
    Tune(analysis::tune::TuneCmd),
    /// Which starts end on a stabilised orbit and which stay chaotic, over starts × μ.
    Basins(analysis::basins_map::BasinsCmd),
    /// From how many random starts (near the set-up's start, or across the joint box) the arm
    /// becomes periodic inside every position, speed, acceleration and jerk limit, and the first
    /// rule each other start broke (CSV, JSON; sharded like sweep).
    Starts(analysis::starts::StartsCmd),
    /// The daemon's chaos monitor against the offline λ_max over starts × μ (a confusion table
    /// and its detection delay), and mu = "auto" against fixed μ and after edits (JSON, CSV, plot).
    Monitor(analysis::monitor::MonitorCmd),
    /// Time courses, phase portraits, Poincaré sections of one run as PNG + SVG (Figs. 2-4, 7-9).
    Figures(analysis::figures::FiguresCmd),
    /// Obstacle avoidance over starts × μ: the paper's potential vs the safety filter (contact,
    /// clearance, tracking, Poincaré class), CSV + plot.
    Obstacles(analysis::obstacles::ObstaclesCmd),
    /// The arm itself at several instants of one period (from above, or in space from the side
    /// and the front) with its path, the obstacles and their clearance rings, and its joint
    /// angles over its last periods; filter off and on where there are obstacles (PNG + SVG).
    ArmFigure(analysis::arm_figure::ArmFigureCmd),
    /// Whether a clean periodic posture cycle exists for a set-up (the planar arm: a grid search;
    /// a URDF robot: cycles relaxed from several starts): its smallest clearance and the planning
    /// time, or why there is none (--json, --csv).
    Plan(plan::PlanCmd),
    /// Put the shard files of one sharded sweep, basins, obstacles or starts run back together: checks
    /// that every grid point is there exactly once (naming any missing one) and writes exactly
    /// the unsharded result.
    Merge(MergeArgs),
    #[command(flatten)]
    Online(online::Online),
    /// Serve the daemons' telemetry as Prometheus metrics on http://LISTEN/metrics.
    Exporter(exporter::ExporterArgs),
    /// Replay a recording (`chaosd run --record NAME`, MCAP or `.replay` text) through the
    /// daemon's controller and compare every command bit for bit. Exit 0: all identical; 1: a
    /// mismatch; 2: a bad file.
    Replay {
        /// The recording file.
        recording: std::path::PathBuf,
    },
    /// What an MCAP recording holds; with --csv, its per-tick rows as CSV.
    Export(export::ExportArgs),
    /// Robot models from URDF: `robot show ROBOT`, `robot eval ROBOT --q …`, `robot fit-radii`.
    Robot(robot::RobotCmd),
    /// Print a preset as a TOML config file to start from, or a file of yours checked and
    /// written in today's form (a planar file in the older `[arm]`/`[control]` form comes out
    /// with `[robot] description = "planar"`).
    Config {
        #[arg(long, default_value = "paper", conflicts_with = "config")]
        preset: String,
        /// A config file to check and print in today's form.
        #[arg(long)]
        config: Option<std::path::PathBuf>,
    },
}

#[derive(clap::Args, Debug)]
struct MergeArgs {
    /// The shard files (PREFIX.shard-I-of-N.json), all N of them, in any order.
    #[arg(required = true)]
    files: Vec<std::path::PathBuf>,
    /// Output prefix: writes OUT.csv, OUT.png and OUT.svg (OUT.csv may be given as OUT).
    #[arg(long)]
    out: std::path::PathBuf,
}

/// `chaosctl merge`: parses the arguments the shards recorded, as the shards did, and hands the
/// command's own merge the files (see `analysis::shard`).
fn merge(m: MergeArgs) -> anyhow::Result<()> {
    let files = analysis::shard::load(&m.files)?;
    let first = files[0].path.display().to_string();
    let argv = std::iter::once("chaosctl".to_string()).chain(files[0].args.iter().cloned());
    let cli = Cli::try_parse_from(argv).map_err(|e| {
        anyhow::anyhow!(
            "{first}: the arguments it recorded do not parse with this chaosctl: {}",
            e.to_string().lines().next().unwrap_or("")
        )
    })?;
    let out = if m.out.extension().is_some_and(|e| e == "csv") {
        m.out.with_extension("")
    } else {
        m.out
    };
    match cli.command {
        Command::Sweep(mut a) => {
            (a.shard, a.output) = (None, out);
            analysis::sweep::merge(a, files)
        }
        Command::Basins(mut a) => {
            (a.shard, a.output) = (None, out);
            analysis::basins::merge(a, files)
        }
        Command::Obstacles(mut a) => {
            (a.shard, a.output) = (None, out);
            analysis::obstacles::merge(a, files)
        }
        Command::Starts(mut a) => {
            (a.shard, a.output) = (None, out);
            analysis::starts::merge(a, files)
        }
        _ => anyhow::bail!("{first}: its recorded command has no shards"),
    }
}

/// `chaosctl gateway …` (= `chaosd-gateway serve …`), `chaosctl fleet …` and `chaosctl --remote
/// ENDPOINT …` run `chaosd-gateway`: Zenoh stays out of chaosctl's own build. `None`: not one of
/// those, parse as usual.
fn gateway_command() -> Option<ExitCode> {
    use std::os::unix::process::CommandExt;
    let args: Vec<std::ffi::OsString> = std::env::args_os().skip(1).collect();
    let remote = args
        .iter()
        .any(|a| a == "--remote" || a.to_str().is_some_and(|s| s.starts_with("--remote=")));
    let mut forwarded = args.clone();
    match args.first().and_then(|a| a.to_str()) {
        Some("gateway") => forwarded[0] = "serve".into(),
        Some("fleet") => {}
        _ if remote => {}
        _ => return None,
    }
    let beside = std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(|d| d.join("chaosd-gateway")))
        .filter(|p| p.exists());
    let exe = beside.unwrap_or_else(|| "chaosd-gateway".into());
    let err = std::process::Command::new(&exe).args(forwarded).exec();
    eprintln!(
        "chaosctl: error: cannot run {} ({err}): the Zenoh gateway is built on its own, with \
         `cargo build --release -p gateway`",
        exe.display()
    );
    Some(ExitCode::from(3))
}

fn main() -> ExitCode {
    if let Some(code) = gateway_command() {
        return code;
    }
    // Like any Unix filter: when the reader of our output goes away (`chaosctl ... | head`),
    // end quietly instead of panicking on the failed write.
    // SAFETY: restoring the default disposition of SIGPIPE before any thread is started.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Online(c) => return online::run(c),
        Command::Replay { recording } => return replay(&recording),
        Command::Simulate(a) => simulate::run(a),
        Command::Lyapunov(a) => analysis::lyapunov::run(a),
        Command::Sweep(a) => analysis::sweep::run(a),
        Command::Poincare(a) => analysis::poincare::run(a),
        Command::Orbits(a) => analysis::orbits::run(a),
        Command::Tune(a) => analysis::tune::run(a),
        Command::Basins(a) => analysis::basins::run(a),
        Command::Starts(a) => analysis::starts::run(a),
        Command::Monitor(a) => analysis::monitor::run(a),
        Command::Figures(a) => analysis::figures::run(a),
        Command::Obstacles(a) => analysis::obstacles::run(a),
        Command::ArmFigure(a) => analysis::arm_figure::run(a),
        Command::Merge(m) => merge(m),
        Command::Plan(a) => plan::run(&a),
        Command::Exporter(a) => exporter::run(a),
        Command::Robot(a) => robot::run(a),
        Command::Export(a) => export::run(a),
        Command::Config {
            config: Some(path), ..
        } => std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read config file {}", path.display()))
            .and_then(|text| {
                rt::robot::parse(&text).with_context(|| format!("in {}", path.display()))
            })
            .map(|s| print!("{}", s.to_toml())),
        Command::Config { preset, .. } => rt::robot::preset(&preset)
            .map(|s| print!("{}", s.to_toml()))
            .map_err(Into::into),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            rt::log::fatal("chaosctl", &format!("{e:#}"));
            ExitCode::from(2)
        }
    }
}

/// `chaosctl replay`: prints how many ticks matched and the first mismatch, if any.
fn replay(path: &std::path::Path) -> ExitCode {
    match daemon::replay::replay(path) {
        Ok(r) => {
            println!("{r}");
            if r.all_matched() {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(1)
            }
        }
        Err(e) => {
            eprintln!("chaosctl: replay: {e:#}");
            ExitCode::from(2)
        }
    }
}
