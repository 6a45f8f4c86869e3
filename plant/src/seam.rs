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
    /// Apply q̈(s) = `qdd` + `qddd`·s (rad/s², rad/s³, one entry per joint) from now until the
    /// next write, where s starts at `since`: the time (s) the plant has advanced since the state
    /// this command answers. A bridge that cannot ramp may apply `qdd + qddd·since` as a
    /// constant.
    Accelerate {
        qdd: &'a [f64],
        qddd: &'a [f64],
        since: f64,
    },
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
    /// and fills `phi`, `q`, `qd` of `out`. The loop stamps, numbers and publishes it. Until the
    /// first command arrives the loop passes `dt = 0`: a simulator then holds its initial state,
    /// so a run starts when the controller does (a bridge just reads its sensors).
    fn read(&mut self, dt: f64, out: &mut StateSample) -> Result<(), PlantError>;
    /// Called once when the loop stops (brake, disable drives, ...).
    fn deactivate(&mut self);

    /// The stamp for a state read at the tick whose deadline was `nominal_ns`, at `now_ns`.
    /// A bridge stamps the measurement instant (the default, `now_ns`); a simulator, whose
    /// physics advances on the nominal grid, stamps `nominal_ns`, free of wake-up jitter.
    fn stamp(&self, nominal_ns: u64, now_ns: u64) -> u64 {
        let _ = nominal_ns;
        now_ns
    }
}
