//! The arm as a device: it takes a command in its interface and turns it into what its motors
//! do, as a robot's own controller does.
//!
//! * torque: applied as sent (clamped to the torque limits by [`RigidBody`]);
//! * position: the joint servo follows the commanded position, reached at the end of the period
//!   (the set-point moves on from the previous one at the commanded rate);
//! * velocity: the device integrates the commanded rate into its own set-point and the servo
//!   follows that, so the daemon's reference position never reaches it;
//! * acceleration: the arm's own inverse dynamics turns q̈ (ramped) into torque.
//!
//! Shared by the plant process and the offline loop, so both run the same device. It takes the
//! daemon's own [`Command`] (the fields its mode does not use are ignored).

use super::{Drive, Measured, RigidBody, Sensor};
use crate::arm::VecN;
use crate::command::{Command, CommandMode};

/// The simulated robot: its physics, its sensors and its command handling.
#[derive(Debug, Clone)]
pub struct Device<const N: usize> {
    pub arm: RigidBody<N>,
    pub sensor: Sensor<N>,
    drive: Drive<N>,
    /// Where the drive's reference is at the start of the current period, relative to the
    /// period's start (position mode: the command is for the period's end).
    offset: f64,
    /// Velocity mode's own set-point.
    set_point: Option<VecN<N>>,
}

impl<const N: usize> Device<N> {
    pub fn new(arm: RigidBody<N>, sensor: Sensor<N>) -> Self {
        Self {
            arm,
            sensor,
            drive: Drive::Hold,
            offset: 0.0,
            set_point: None,
        }
    }

    /// Takes the command for the next period of `dt` seconds, which answers a state measured
    /// `since` seconds ago (0 when it arrives at the period's start).
    pub fn command(&mut self, c: &Command<N>, dt: f64, since: f64) {
        if c.mode != CommandMode::Velocity {
            self.set_point = None;
        }
        let since = since.max(0.0);
        self.offset = since;
        self.drive = match c.mode {
            CommandMode::Torque => Drive::Torque(c.tau),
            CommandMode::Acceleration => Drive::Ramp {
                qdd: c.qdd,
                qddd: c.qddd,
            },
            CommandMode::Position => {
                // Reached one period after the answered state: the reference runs from dt
                // before that.
                self.offset = since - dt;
                Drive::Track {
                    q: c.q,
                    qd: c.qd,
                    qdd: VecN::<N>::zeros(),
                }
            }
            CommandMode::Velocity => {
                // The set-point moves on from where it is now, by what `advance` integrates.
                self.offset = 0.0;
                let from = *self.set_point.get_or_insert(self.arm.state.q);
                Drive::Track {
                    q: from,
                    qd: c.qd,
                    qdd: VecN::<N>::zeros(),
                }
            }
        };
    }

    /// No command to follow: come to rest and hold (a brake on a real arm).
    pub fn hold(&mut self) {
        self.drive = Drive::Hold;
        self.set_point = None;
    }

    /// Advances one period of `dt` in `substeps`.
    pub fn advance(&mut self, dt: f64, substeps: u32) {
        self.arm.advance(&self.drive, self.offset, dt, substeps);
        // Velocity mode's set-point keeps integrating the last rate over a late period, as the
        // drive's reference does (it once stood still there, and each late command was a step).
        if let (Some(sp), Drive::Track { qd, .. }) = (&mut self.set_point, &self.drive) {
            *sp += qd * dt;
        }
        // A command is for one period; a late one keeps its reference moving on.
        self.offset += dt;
    }

    /// What the sensors read now (and the torque applied over the last substep).
    pub fn measure(&mut self) -> Measured<N> {
        self.sensor.measure(&self.arm.state, &self.arm.applied)
    }
}
