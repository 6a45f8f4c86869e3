//! chaosctl: the command-line tool for chaosd.
//!
//! `main` only maps errors to exit codes; each subcommand lives in its own module and validates
//! all of its input before doing any work.

mod analysis;
mod online;
mod plot;
mod setup;
mod simulate;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "chaosctl",
    version,
    about = "Watch and steer chaosd, and analyse the arm's self-motion offline"
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
    /// Which starts end on a stabilised orbit and which stay chaotic, over starts × μ.
    Basins(analysis::basins::BasinsCmd),
    /// Time courses, phase portraits, Poincaré sections of one run as PNG + SVG (Figs. 2-4, 7-9).
    Figures(analysis::figures::FiguresCmd),
    /// Obstacle avoidance over starts × μ: the paper's potential vs the safety filter (contact,
    /// clearance, tracking, Poincaré class), CSV + plot.
    Obstacles(analysis::obstacles::ObstaclesCmd),
    /// The arm itself at several instants of one period, filter off and on side by side, with
    /// the circle, the obstacles and their clearance rings (PNG + SVG).
    ArmFigure(analysis::arm_figure::ArmFigureCmd),
    #[command(flatten)]
    Online(online::Online),
    /// Replay a recording (`chaosd run --record NAME`) through the daemon's controller and
    /// compare every command bit for bit. Exit 0: all identical; 1: a mismatch; 2: a bad file.
    Replay {
        /// The recording file.
        recording: std::path::PathBuf,
    },
    /// Print a preset as a TOML config file to start from.
    Config {
        #[arg(long, default_value = "paper")]
        preset: String,
    },
}

fn main() -> ExitCode {
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
        Command::Basins(a) => analysis::basins::run(a),
        Command::Figures(a) => analysis::figures::run(a),
        Command::Obstacles(a) => analysis::obstacles::run(a),
        Command::ArmFigure(a) => analysis::arm_figure::run(a),
        Command::Config { preset } => control::Config::preset(&preset)
            .map(|c| print!("{}", c.to_toml_string()))
            .map_err(Into::into),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("chaosctl: error: {e:#}");
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
