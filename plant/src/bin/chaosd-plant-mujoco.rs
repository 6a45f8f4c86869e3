//! chaosd-plant-mujoco: the arm simulated by MuJoCo, served over iceoryx2 like chaosd-plant
//! (`[plant] dynamics = "mujoco"`; chaosd-plant hands such a set-up over to this program).
//!
//! Built only with the `mujoco` feature, against the MuJoCo library (docs/mujoco.md).

use clap::Parser;
use plant::app::{self, PlantArgs};
use plant::mujoco::MujocoPlant;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "chaosd-plant-mujoco",
    version,
    about = "The chaosd plant process with MuJoCo's physics: the robot's URDF or MJCF, its meshes judging contact"
)]
struct Args {
    #[command(flatten)]
    plant: PlantArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    app::serve("chaosd-plant-mujoco", &args.plant, |l| {
        MujocoPlant::from_launch(&l.system, &l.plant)
    })
}
