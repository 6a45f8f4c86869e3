//! chaosd's pure-math core.
//!
//! **Architecture invariant:** this crate does no I/O, spawns no threads, reads no clock and knows
//! nothing of iceoryx2. It is the single implementation of the arm models and the control law that
//! the offline tools, the real-time daemon and the simulated plant all share, so an offline result
//! and a live run can never disagree because of duplicated math. The step paths (`law::evaluate`,
//! `Simulation::step`, `DelayLine::push/sample`) never allocate; `tests/no_alloc.rs` proves it.

// Index loops mirror the subscripts of the equations (q_j, l_j, column k of J) and are kept.
#![allow(clippy::needless_range_loop)]

pub mod adapt;
pub mod analysis;
pub mod arm;
pub mod basics;
pub mod command;
pub mod commanded;
pub mod config;
pub mod delay;
pub mod dual;
pub mod hold;
pub mod law;
pub mod model;
pub mod monitor;
pub mod plan;
pub mod resolve;
pub mod rigid_body;
pub mod safety;
pub mod secondary;
pub mod sim;
pub mod steer;
pub mod system;
pub mod target;
pub mod task;
pub mod tick_law;
pub mod tune;

pub use arm::{ArmModel, FixedArm, FloatingArm, Jac, Kinematics, Vec2, VecN};
pub use basics::{ConfigError, MAX_JOINTS, MIN_JOINTS};
pub use config::Config;
pub use delay::DelayLine;
pub use law::{LawParams, Secondary};
pub use resolve::ControlOutput;
pub use sim::{ArmState, RunStats, Simulation, Summary};
pub use system::System;
pub use task::Path;
