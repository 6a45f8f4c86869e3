//! The robot model a set-up may have: a URDF chain with masses, a command interface and the
//! maker's limits. The paper's planar arm has none of these (it is kinematic and takes
//! accelerations only), so a caller asks [`System::robot`] and, when it answers `None`, states
//! that physical reason, instead of asking which kind of arm it holds. A planar arm written as
//! a chain (`robots/planar3.urdf`) is a robot like any other.

use super::{SpatialSystem, System};
use crate::arm::{ArmModel, FixedArm};
use crate::basics::ConfigError;
use crate::command::JointLimits;

impl System {
    /// The robot model (the file and the chain its `[robot]` names); `None` for the paper's
    /// planar arm, which has no masses, no command interface and no limits.
    ///
    /// ```
    /// let panda = control::System::preset("panda", &control::system::builtin_robot).unwrap();
    /// assert_eq!(panda.robot().unwrap().chain.dof(), 7);
    /// assert!(control::System::Planar(control::Config::default()).robot().is_none());
    /// ```
    pub fn robot(&self) -> Option<&SpatialSystem> {
        match self {
            System::Planar(_) => None,
            System::Spatial(s) => Some(s),
        }
    }

    /// [`System::robot`], to change its file's sections.
    pub fn robot_mut(&mut self) -> Option<&mut SpatialSystem> {
        match self {
            System::Planar(_) => None,
            System::Spatial(s) => Some(s),
        }
    }

    /// The limits a device of this set-up enforces (the description's, tightened by the maker's
    /// table and `[command.limits]`); none for an arm without a robot model.
    pub fn device_limits<const N: usize>(&self) -> Result<JointLimits<N>, ConfigError> {
        match self.robot() {
            Some(s) => s
                .own()
                .command
                .limits::<N>(&s.chain, &s.own().robot.description),
            None => Ok(JointLimits::NONE),
        }
    }

    /// The arm a kinematic plant integrates: the planar arm's model (a floating base turns),
    /// or a robot's fixed base (it integrates q̈ alone: φ̇ = 0 and no link length is read).
    /// `N` must be [`System::n`].
    pub fn kinematic_model<const N: usize>(&self) -> ArmModel<N> {
        match self {
            System::Planar(c) => c.model::<N>(),
            System::Spatial(_) => ArmModel::Fixed(FixedArm::new([0.0; N])),
        }
    }
}
