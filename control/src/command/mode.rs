//! The command interfaces, by ros2_control's names.

use serde::{Deserialize, Serialize};

/// What the daemon sends the arm each tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CommandMode {
    /// q̈ and its rate: chaosd's own plant and emulator (the paper's level).
    #[default]
    Acceleration,
    /// The reference velocity q̇_r (Franka's joint-velocity generator, a UR `speedj`).
    Velocity,
    /// The reference position q_r (Franka's joint-position generator, a UR `servoJ`).
    Position,
    /// Computed torque τ = M(q)q̈ + C(q,q̇)q̇ + g(q) plus a joint PD on the reference error.
    Torque,
}

impl CommandMode {
    pub const ALL: [CommandMode; 4] = [
        CommandMode::Acceleration,
        CommandMode::Velocity,
        CommandMode::Position,
        CommandMode::Torque,
    ];

    /// The name in config files, on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            CommandMode::Acceleration => "acceleration",
            CommandMode::Velocity => "velocity",
            CommandMode::Position => "position",
            CommandMode::Torque => "torque",
        }
    }

    /// Parses a name; the error lists the valid ones.
    ///
    /// ```
    /// use control::command::CommandMode;
    /// assert_eq!(CommandMode::parse("torque"), Ok(CommandMode::Torque));
    /// assert!(CommandMode::parse("effort").unwrap_err().to_string().contains("position"));
    /// ```
    pub fn parse(name: &str) -> Result<Self, crate::basics::LiveError> {
        Self::ALL
            .into_iter()
            .find(|m| m.name() == name)
            .ok_or_else(|| crate::basics::LiveError::CommandMode(name.into()))
    }

    /// The code on the wire (`protocol::interface`): 0, 1, 2, 3 in the order above.
    pub fn code(self) -> u32 {
        self as u32
    }

    pub fn from_code(code: u32) -> Option<Self> {
        Self::ALL.get(code as usize).copied()
    }
}

impl std::fmt::Display for CommandMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
