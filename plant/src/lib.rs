//! The plant process: the other end of chaosd's loop.
//!
//! [`seam::Plant`] is the seam a hardware bridge implements to replace the simulator without any
//! change to the daemon: the daemon only ever sees state samples arrive and commands leave.
//! [`sim::SimPlant`] is the simulated arm (the same kinematic model the offline tools integrate),
//! and [`run::run`] the loop that serves any `Plant` over iceoryx2.

pub mod config;
pub mod run;
pub mod seam;
pub mod sim;

pub use config::PlantConfig;
pub use seam::{Actuation, Plant, PlantError};
pub use sim::SimPlant;
