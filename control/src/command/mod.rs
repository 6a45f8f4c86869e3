//! From the law's joint acceleration to what a real arm accepts (docs/science.md, "Commanding real arms").
//!
//! The law speaks q̈; robots take positions, velocities or torques at a fixed rate and stop with a
//! reflex error when the stream implies motion beyond their limits. This module turns one into
//! the other, the way a robot's motion generator does, and keeps the stream inside the limits:
//!
//! * [`CommandMode`]: which interface the daemon sends (ros2_control's names);
//! * [`JointLimits`]: the limits, from the description and the maker's table, tightened by the
//!   set-up but never loosened;
//! * [`Limiter`]: jerk, then acceleration, then velocity, then position, as libfranka limits a
//!   motion generator's stream, with saturations counted per joint and kind;
//! * [`MotionGenerator`]: the reference (q_r, q̇_r) the q̈ stream integrates into, and the
//!   command for the mode (computed torque plus a joint PD for torque).
//!
//! Everything here runs on the daemon's loop: fixed-size, no allocation.

mod generator;
mod limiter;
mod limits;
mod mode;

pub use generator::{Command, CommandGains, MotionGenerator, Pull, Stream};
pub use limiter::{LimitKind, Limiter, MotionState, Saturations, LIMIT_KINDS};
pub use limits::{
    JointLimits, LimitOverrides, MakerTable, DEFAULT_JERK_PER_QDD, DEFAULT_QDD_MAX, PANDA,
    PANDA_QDD_MAX,
};
pub use mode::CommandMode;
