//! chaosctl: the command-line tool for chaosd.
//!
//! `main` only maps errors to exit codes; each subcommand lives in its own module and validates
//! all of its input before doing any work.

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
    /// Print a preset as a TOML config file to start from.
    Config {
        #[arg(long, default_value = "paper")]
        preset: String,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Simulate(a) => simulate::run(a),
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
