//! The Plant seam: what the plant loop needs from whatever moves the arm.
//!
//! Modelled on ros2_control's `SystemInterface`: a lifecycle (`activate` / `deactivate`), `write`
//! to hand over the actuation, `read` to get the measured state, and both may fail. The loop, the
//! transport and the timing are the same for every implementation ([`crate::run::run`]), so a
//! hardware bridge replaces the simulator by implementing this trait, and the daemon never knows
//! the difference.
//!
//! ## The contract, in one place
//!
//! * **Lifecycle.** `activate` once, then cycles, then `deactivate` once (also after an error).
//! * **One cycle.** Each cycle the loop calls `read` exactly once and publishes what it filled
//!   in, and `write`s at most once per received command. `read` never replays missed time on the
//!   loop's behalf: `elapsed` says how much time passed since the previous `read`, and a
//!   simulator decides itself how much of a long stall to integrate (bounded).
//! * **Who owns the clock.** By default the loop does: it waits for its own deadline and then
//!   calls `read`. A device that sends its state on its own clock (FCI, RSI, the UDP bridge)
//!   returns `true` from [`Plant::device_clocked`]; the loop then does not wait, and `read`
//!   blocks until the device's next state arrives (or returns [`PlantError::Unavailable`]).
//! * **What the modes mean.** [`Actuation::Accelerate`], [`Actuation::Position`],
//!   [`Actuation::Velocity`] and [`Actuation::Torque`] follow the daemon's command in the
//!   interface the set-up names (`[command] mode`); a plant that does not take one refuses it at
//!   the handshake, before any command.
//!   [`Actuation::Hold`] (protocol `Mode::Hold`, sent by the daemon when it lacks fresh states)
//!   means: bring the joints to rest with the plant's own deceleration and keep them there,
//!   ready to follow the next `Accelerate` at once. [`Actuation::Brake`] (`Mode::Brake`,
//!   `Mode::Fault`, a command timeout, too many late cycles, shutdown) means: stop and stay
//!   stopped; a real arm engages its brakes.
//! * **Errors.** [`PlantError::Unavailable`] is a missed cycle: the loop counts it, publishes
//!   nothing (so the daemon's watchdog sees the silence and holds) and carries on.
//!   [`PlantError::Fault`] and [`PlantError::Activation`] stop the loop. Errors keep their
//!   source, so the exit message says what the device or the OS said.
//! * **No allocation** in `write` or `read`: both work on preallocated buffers.

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
        /// The `seq` of the published state this command answers (a device protocol that
        /// echoes its own cycle counter maps it back; `read` saw that number in `out.seq`).
        answers: u64,
    },
    /// Follow the reference position `q` (and its rate `qd`), to be reached one period after
    /// the answered state, `since` seconds ago (a position interface: Franka's joint positions,
    /// a UR `servoJ`). `qd` may be used as velocity feed-forward.
    Position {
        q: &'a [f64],
        qd: &'a [f64],
        since: f64,
        answers: u64,
    },
    /// Follow the reference velocity `qd` (a velocity interface).
    Velocity {
        qd: &'a [f64],
        since: f64,
        answers: u64,
    },
    /// Apply the joint torques `tau` (N·m) until the next write (an effort interface).
    Torque {
        tau: &'a [f64],
        since: f64,
        answers: u64,
    },
    /// Come to rest with the plant's own deceleration and hold the position, ready to resume.
    Hold,
    /// Stop and stay stopped (a real arm engages its brakes).
    Brake,
}

/// The error source a plant keeps (an `io::Error`, a driver's error type, ...).
pub type Source = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Why a plant call failed. The source is kept, not flattened into a string.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlantError {
    /// `activate` failed: the run does not start.
    #[error("plant could not be activated: {what}")]
    Activation {
        what: &'static str,
        #[source]
        source: Source,
    },
    /// No state or no delivery this cycle (a lost device, a dropped packet); the loop counts it
    /// and carries on.
    #[error("plant unavailable this cycle: {what}")]
    Unavailable {
        what: &'static str,
        #[source]
        source: Option<Source>,
    },
    /// The plant cannot go on (a non-finite simulated state, a drive fault): the loop stops.
    #[error("plant fault: {what}")]
    Fault {
        what: &'static str,
        #[source]
        source: Option<Source>,
    },
}

/// A thing that has joints: the simulated arm, or a bridge to a real one.
///
/// A minimal implementation, driven the way the loop drives it (see `plant/examples/` for a
/// complete bridge):
///
/// ```
/// use plant::{Actuation, Plant, PlantError};
/// use protocol::StateSample;
///
/// /// Two joints that integrate the commanded acceleration exactly (q̈ constant per cycle).
/// struct TwoJoints { q: [f64; 2], qd: [f64; 2], qdd: [f64; 2] }
///
/// impl Plant for TwoJoints {
///     fn n(&self) -> usize { 2 }
///     fn flags(&self) -> u32 { protocol::flags::SIMULATED }
///     fn activate(&mut self) -> Result<(), PlantError> { Ok(()) }
///     fn write(&mut self, a: Actuation<'_>) -> Result<(), PlantError> {
///         self.qdd = match a {
///             Actuation::Accelerate { qdd, qddd, since, .. } => {
///                 [qdd[0] + qddd[0] * since, qdd[1] + qddd[1] * since]
///             }
///             // This arm takes accelerations only (its handshake says so).
///             _ => [-self.qd[0] * 20.0, -self.qd[1] * 20.0],
///         };
///         Ok(())
///     }
///     fn read(&mut self, elapsed: f64, out: &mut StateSample) -> Result<(), PlantError> {
///         for j in 0..2 {
///             self.q[j] += self.qd[j] * elapsed + 0.5 * self.qdd[j] * elapsed * elapsed;
///             self.qd[j] += self.qdd[j] * elapsed;
///         }
///         out.n = 2;
///         out.q[..2].copy_from_slice(&self.q);
///         out.qd[..2].copy_from_slice(&self.qd);
///         Ok(())
///     }
///     fn deactivate(&mut self) {}
/// }
///
/// let mut arm = TwoJoints { q: [0.0; 2], qd: [0.0; 2], qdd: [0.0; 2] };
/// let mut s = StateSample::default();
/// arm.activate()?;
/// arm.write(Actuation::Accelerate { qdd: &[1.0, -1.0], qddd: &[0.0; 2], since: 0.0, answers: 0 })?;
/// for _ in 0..1000 {
///     arm.read(1e-3, &mut s)?; // one cycle per call
/// }
/// assert!((s.qd[0] - 1.0).abs() < 1e-9 && (s.qd[1] + 1.0).abs() < 1e-9);
/// arm.deactivate();
/// # Ok::<(), PlantError>(())
/// ```
pub trait Plant {
    /// Number of joints.
    fn n(&self) -> usize;
    /// `protocol::flags` describing this plant (SIMULATED, FLOATING_BASE, BRAKING, ...).
    fn flags(&self) -> u32;
    /// Called once before the first `write`/`read` (power up, enable drives, open a socket, ...).
    fn activate(&mut self) -> Result<(), PlantError>;
    /// Hands over the actuation for the coming cycle (a bridge sends it to the device now).
    fn write(&mut self, actuation: Actuation<'_>) -> Result<(), PlantError>;
    /// Reads one cycle and fills `phi`, `q`, `qd` of `out` (`n` too); the loop has already set
    /// `out.seq` to the number this state will be published with, and stamps and publishes it. `elapsed` is the time (s) since the previous `read` as the loop counts
    /// it: one period, more after a stall, and 0 until the first command arrives (a simulator
    /// then holds its initial state, so a run starts when the controller does). A simulator
    /// integrates it (and bounds a long catch-up itself); a bridge reads its sensors, and if
    /// [`Plant::device_clocked`], first waits for the device's next state, and sets
    /// `out.device_time_ns` to the device's own cycle clock when it has one (the daemon then
    /// advances its command stream by exactly the device's time; 0 falls back on the stamps).
    fn read(&mut self, elapsed: f64, out: &mut StateSample) -> Result<(), PlantError>;
    /// Called once when the loop stops (brake, disable drives, ...).
    fn deactivate(&mut self);

    /// The stamp for a state read at the cycle whose deadline was `nominal_ns`, at `now_ns`.
    /// A bridge stamps the measurement instant (the default, `now_ns`); a simulator, whose
    /// physics advances on the nominal grid, stamps `nominal_ns`, free of wake-up jitter.
    fn stamp(&self, nominal_ns: u64, now_ns: u64) -> u64 {
        let _ = nominal_ns;
        now_ns
    }

    /// Whether the device owns the clock: `read` then blocks until the device's next state, and
    /// the loop does not wait for its own deadlines.
    fn device_clocked(&self) -> bool {
        false
    }

    /// Substeps in which the arm could not apply a torque it was asked for and clamped it at
    /// the joint's effort limit while following a command (a simulator knows; a bridge whose
    /// device does not say, 0). A brake to rest uses every newton-metre the motors have by
    /// design and is not counted. Reported at exit, so that a run that asked for more than the
    /// motors have says so.
    fn effort_clamps(&self) -> u64 {
        0
    }

    /// What the plant saw of contact on its own geometry (MuJoCo's meshes), read at exit; None
    /// for a plant that does not judge it.
    fn contacts(&self) -> Option<crate::report::ContactReport> {
        None
    }
}

/// The actuation a RUN command asks for, in its interface (`since`: how long ago the answered
/// state was published, in plant time).
pub fn actuation(cmd: &protocol::CommandSample, since: f64) -> Actuation<'_> {
    let n = (cmd.n as usize).min(protocol::MAX_JOINTS);
    let answers = cmd.state_seq;
    match cmd.interface {
        protocol::interface::POSITION => Actuation::Position {
            q: &cmd.q[..n],
            qd: &cmd.qd[..n],
            since,
            answers,
        },
        protocol::interface::VELOCITY => Actuation::Velocity {
            qd: &cmd.qd[..n],
            since,
            answers,
        },
        protocol::interface::TORQUE => Actuation::Torque {
            tau: &cmd.tau[..n],
            since,
            answers,
        },
        _ => Actuation::Accelerate {
            qdd: &cmd.qdd[..n],
            qddd: &cmd.qddd[..n],
            since,
            answers,
        },
    }
}
