//! The Plant seam: what the plant loop needs from whatever moves the arm.
//!
//! Modelled on ros2_control's `SystemInterface`: a lifecycle (`activate` / `deactivate`), `write`
//! to hand over the actuation, `read` to get the measured state. The loop, the transport and the
//! timing are the same for every implementation, so a hardware bridge replaces the simulator by
//! implementing this trait, and the daemon never knows the difference. Both calls work on
//! preallocated buffers; implementations must not allocate in `write` or `read`.

use protocol::StateSample;

/// What the loop asks the plant to do until the next `write`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Actuation<'a> {
    /// Apply these joint accelerations (rad/s², one per joint), held until the next write.
    Accelerate(&'a [f64]),
    /// Bring the joints to rest and keep them there.
    Brake,
}

#[derive(Debug, thiserror::Error)]
pub enum PlantError {
    #[error("plant could not be activated: {0}")]
    Activation(String),
    #[error("plant fault: {0}")]
    Fault(String),
}

/// A thing that has joints: the simulated arm, or a bridge to a real one.
pub trait Plant {
    /// Number of joints.
    fn n(&self) -> usize;
    /// `protocol::flags` describing this plant (SIMULATED, FLOATING_BASE, ...).
    fn flags(&self) -> u32;
    /// Called once before the first `write`/`read` (power up, enable drives, ...).
    fn activate(&mut self) -> Result<(), PlantError>;
    /// Hands over the actuation for the coming period.
    fn write(&mut self, actuation: Actuation<'_>);
    /// Advances one period of `dt` seconds (a simulator integrates; a bridge reads its sensors)
    /// and fills `phi`, `q`, `qd` of `out`. The loop stamps, numbers and publishes it.
    fn read(&mut self, dt: f64, out: &mut StateSample) -> Result<(), PlantError>;
    /// Called once when the loop stops (brake, disable drives, ...).
    fn deactivate(&mut self);
}
