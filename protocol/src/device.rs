//! What a command means and what the device said about it: the command interface codes
//! ([`interface`]) and the device's status ([`DeviceStatus`]) on the wire.
//!
//! A real arm stops with a reflex error when a command breaks one of its rules; the state
//! sample carries that reason (and the joint) back, so the daemon can name it in its FAULT.
//! Both travel as plain `u32`, validated on receipt, like `mode` and `flags`.

use core::fmt;

/// The command interfaces, by ros2_control's names: which field of a command the device
/// follows.
pub mod interface {
    /// `qdd` (and its ramp `qddd`): chaosd's own plant.
    pub const ACCELERATION: u32 = 0;
    /// `qd`: the reference joint velocity.
    pub const VELOCITY: u32 = 1;
    /// `q`: the reference joint position.
    pub const POSITION: u32 = 2;
    /// `tau`: joint torques.
    pub const TORQUE: u32 = 3;

    /// The interface's name, or `None` for an unknown code.
    pub fn name(code: u32) -> Option<&'static str> {
        ["acceleration", "velocity", "position", "torque"]
            .get(code as usize)
            .copied()
    }
}

/// Why a device stopped, as the state sample reports it (0: it did not).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum DeviceStatus {
    Ok = 0,
    /// The commanded stream implies a joint velocity beyond the limit.
    VelocityLimit = 1,
    /// ... an acceleration beyond the limit.
    AccelerationLimit = 2,
    /// ... a jerk beyond the limit.
    JerkLimit = 3,
    /// A commanded position outside the joint's range.
    PositionLimit = 4,
    /// The first command does not continue the arm's own state (a jump).
    Discontinuity = 5,
    /// A commanded torque beyond the limit.
    TorqueLimit = 6,
    /// A torque rate beyond the limit.
    TorqueRateLimit = 7,
    /// Too many commands in a row did not arrive.
    LostPackets = 8,
    /// The command used an interface this device does not take.
    InterfaceUnsupported = 9,
}

impl DeviceStatus {
    pub const ALL: [DeviceStatus; 10] = [
        DeviceStatus::Ok,
        DeviceStatus::VelocityLimit,
        DeviceStatus::AccelerationLimit,
        DeviceStatus::JerkLimit,
        DeviceStatus::PositionLimit,
        DeviceStatus::Discontinuity,
        DeviceStatus::TorqueLimit,
        DeviceStatus::TorqueRateLimit,
        DeviceStatus::LostPackets,
        DeviceStatus::InterfaceUnsupported,
    ];

    /// Decodes a wire code.
    pub fn from_code(code: u32) -> Option<Self> {
        Self::ALL.get(code as usize).copied()
    }

    /// libfranka's name for the same reflex, where there is one.
    pub fn name(self) -> &'static str {
        match self {
            DeviceStatus::Ok => "ok",
            DeviceStatus::VelocityLimit => "joint_motion_generator_velocity_limits_violation",
            DeviceStatus::AccelerationLimit => {
                "joint_motion_generator_acceleration_limits_violation"
            }
            DeviceStatus::JerkLimit => "joint_motion_generator_jerk_limits_violation",
            DeviceStatus::PositionLimit => "joint_position_limits_violation",
            DeviceStatus::Discontinuity => "joint_motion_generator_start_pose_invalid",
            DeviceStatus::TorqueLimit => "joint_torque_limits_violation",
            DeviceStatus::TorqueRateLimit => "joint_torque_rate_limits_violation",
            DeviceStatus::LostPackets => "communication_constraints_violation",
            DeviceStatus::InterfaceUnsupported => "command_interface_not_supported",
        }
    }

    /// In words, for a person.
    pub fn reason(self) -> &'static str {
        match self {
            DeviceStatus::Ok => "no error",
            DeviceStatus::VelocityLimit => "velocity limit",
            DeviceStatus::AccelerationLimit => "acceleration limit",
            DeviceStatus::JerkLimit => "jerk limit",
            DeviceStatus::PositionLimit => "position limit",
            DeviceStatus::Discontinuity => "discontinuity",
            DeviceStatus::TorqueLimit => "torque limit",
            DeviceStatus::TorqueRateLimit => "torque rate limit",
            DeviceStatus::LostPackets => "lost packets",
            DeviceStatus::InterfaceUnsupported => "unsupported command interface",
        }
    }
}

impl fmt::Display for DeviceStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.reason(), self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_unknown_ones_are_none() {
        for s in DeviceStatus::ALL {
            assert_eq!(DeviceStatus::from_code(s as u32), Some(s));
        }
        assert_eq!(DeviceStatus::from_code(10), None);
        assert_eq!(interface::name(interface::TORQUE), Some("torque"));
        assert_eq!(interface::name(4), None);
        assert!(DeviceStatus::JerkLimit.to_string().contains("jerk"));
    }
}
