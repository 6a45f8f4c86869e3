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

/// `dynamics = "mujoco"`: this process becomes chaosd-plant-mujoco, beside it, with the same
/// arguments (a parent's death signal and the pid stay, so a demo's clean-up still holds).
/// Returns only if it cannot.
fn hand_over_to_mujoco() -> anyhow::Error {
    use std::os::unix::process::CommandExt;
    let Ok(me) = std::env::current_exe() else {
        return anyhow::anyhow!("cannot locate chaosd-plant to find chaosd-plant-mujoco beside it");
    };
    let exe = me.with_file_name("chaosd-plant-mujoco");
    if !exe.exists() {
        return anyhow::anyhow!(
            "plant.dynamics = \"mujoco\" needs {}, which is not built: \
             scripts/mujoco-setup installs MuJoCo and builds it (docs/mujoco.md)",
            exe.display()
        );
    }
    let err = std::process::Command::new(&exe)
        .args(std::env::args_os().skip(1))
        .exec();
    anyhow::anyhow!("cannot start {}: {err}", exe.display())
}

fn main() -> ExitCode {
    let args = Args::parse();
    app::main_with("chaosd-plant", &args.plant, |l| {
        let (system, cfg) = (&l.system, &l.plant);
        if cfg.dynamics == plant::config::Dynamics::Mujoco {
            return Err(hand_over_to_mujoco());
        }
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
