//! The ground floor: what every layer of `control` names and none of them owns.
//!
//! Joint counts, the flag bits of an evaluation, the refusal type with its helpers, and angle
//! wrapping import nothing of the crate, so any layer above may use them without tying itself
//! to another (ARCHITECTURE.md, "Layers").

pub mod angle;
pub mod dof;
pub mod error;
pub mod flags;
pub mod number;
pub mod rng;

pub use angle::wrap_angle;
pub use dof::{MAX_JOINTS, MIN_JOINTS};
pub use error::{
    excerpt, invalid, live_number, range, ConfigError, LiveError, PhysicsError, MAX_CONFIG_BYTES,
    MAX_QUOTE,
};
