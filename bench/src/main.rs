//! chaosd-bench: answers "how fast is this on my machine, and against what?" in one command.
//!
//! Every subcommand measures chaosd next to its alternatives in the same run, on pinned cores,
//! and reports ratios: absolute times on a shared VM are noisy, ratios measured side by side are
//! not. Nothing here asserts a speed; the tests only check the harness itself.

mod compute;
mod naive;
mod stats;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "chaosd-bench", version, about = "chaosd latency, jitter and compute benchmarks")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Control-law evaluation, RK4 step and a 300 s simulation, next to a naive implementation.
    Compute {
        /// Fewer repetitions, for a smoke test.
        #[arg(long)]
        quick: bool,
        /// Core to pin to.
        #[arg(long, default_value_t = 0)]
        core: usize,
    },
}

fn pin(core: usize) {
    let ids = core_affinity::get_core_ids().unwrap_or_default();
    match ids.into_iter().find(|c| c.id == core) {
        Some(id) if core_affinity::set_for_current(id) => {}
        _ => eprintln!("chaosd-bench: warning: could not pin to core {core}; timings will be noisier"),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Compute { quick, core } => {
            pin(core);
            compute::run(quick).map(|s| print!("{s}"))
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("chaosd-bench: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
