//! Status bits of one evaluation of the law: what the law, the filter and the planner report
//! about a tick, in one `u32` that crosses the wire unchanged.
/// Damped least squares was active (σ_min below the threshold).
pub const SINGULAR: u32 = 1 << 0;
/// The target is outside the annular workspace around joint 1.
pub const OUT_OF_REACH: u32 = 1 << 1;
/// Tracking error above the configured limit.
pub const TRACK_LOST: u32 = 1 << 2;
/// Some link is inside an obstacle's safety zone.
pub const IN_SAFETY_ZONE: u32 = 1 << 3;
/// The delayed feedback term was applied.
pub const FEEDBACK_ACTIVE: u32 = 1 << 4;
/// The raw command was not finite and was replaced by zero acceleration.
pub const NONFINITE: u32 = 1 << 5;
/// The safety filter changed the command (some limit or clearance was binding).
pub const SAFETY_ACTIVE: u32 = 1 << 6;
/// The null space could not keep every limit: the filter changed the task motion too, so
/// tracking gave way to safety.
pub const SAFETY_LEFT_NULL_SPACE: u32 = 1 << 7;
/// No acceleration within the limits meets every barrier condition; the closest one found
/// was used (and the acceleration limits were applied).
pub const SAFETY_INFEASIBLE: u32 = 1 << 8;
/// A joint-space detour onto a planned cycle runs: tracking is paused by design.
pub const DETOUR: u32 = 1 << 9;
