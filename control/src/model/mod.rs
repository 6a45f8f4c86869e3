//! Robot models from URDF: serial chains, their kinematics and rigid-body dynamics.
//!
//! pinocchio's split, in Rust: a [`Chain`] is built once from a description (names, limits,
//! bodies); [`Chain::model`] turns it into a fixed-size [`Model`] whose algorithms, one file
//! each ([`Model::tip_kinematics`], [`Model::rnea`], [`Model::mass_matrix`], [`Model::aba`]),
//! run per tick on the stack and never allocate. Golden data from pinocchio checks them
//! (`control/tests/model_pinocchio.rs`).

mod aba;
mod builtin;
mod chain;
mod crba;
mod error;
mod eval;
mod fixed;
mod kinematics;
mod physics;
mod pose;
mod rnea;
pub mod spatial;
pub mod urdf;

pub use builtin::{builtin, BUILTIN};
pub use chain::{Body, Chain, ChainJoint, JointKind, STANDARD_GRAVITY};
pub use error::{ModelError, RobotError};
pub use eval::{Evaluation, LengthError};
pub use fixed::{Frames, Model};
pub use kinematics::TipKinematics;
pub use pose::{z_onto, Pose};
pub use urdf::{Limits, MAX_URDF_BYTES};
