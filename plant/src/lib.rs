//! The plant process: the other end of chaosd's loop.
//!
//! [`seam::Plant`] is the seam a hardware bridge implements to replace the simulator without any
//! change to the daemon: the daemon only ever sees state samples arrive and commands leave.
//! [`sim::SimPlant`] is the simulated arm (the same kinematic model the offline tools integrate),
//! [`run::run`] the loop that serves any `Plant` over iceoryx2, and [`app`] the process's `main`
//! as a function, so that a bridge's `main` is a few lines (`plant/examples/bridge_template.rs`).

pub mod app;
pub mod config;
pub mod handshake;
pub mod intake;
#[cfg(feature = "mujoco")]
pub mod mujoco;
pub mod report;
pub mod run;
pub mod seam;
pub mod sim;
pub mod udp;

pub use config::PlantConfig;
pub use report::{PlantCounters, PlantSummary};
pub use seam::{Actuation, Plant, PlantError};
pub use sim::SimPlant;
