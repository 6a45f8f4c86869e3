//! chaosd-plant: serves the simulated arm over iceoryx2 until SIGINT/SIGTERM.
//!
//! All of `main` is [`plant::app`]; only the size dispatch (the simulator is generic over the
//! joint count) is here.

use clap::Parser;
use control::with_dof;
use plant::app::{self, PlantArgs};
use plant::SimPlant;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "chaosd-plant",
    version,
    about = "The chaosd plant process: a simulated arm served over iceoryx2"
)]
struct Args {
    #[command(flatten)]
    plant: PlantArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    app::main_with("chaosd-plant", &args.plant, |l| {
        let (system, cfg) = (&l.system, &l.plant);
        with_dof!(system.n(), N => {
            let mut sim = SimPlant::<N>::from_config(system, cfg)?;
            let summary = plant::run::run(&mut sim, cfg, &l.arm(), l.duration);
            if sim.time_jumps() > 0 {
                tracing::warn!("{} stalls longer than {} s were skipped, not simulated", sim.time_jumps(), plant::sim::MAX_CATCH_UP_S);
            }
            summary
        })
    })
}
