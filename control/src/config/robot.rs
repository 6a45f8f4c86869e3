//! What differs between the arms' files, in one enum: the paper's planar arm (closed-form
//! kinematics, discs in its plane) or a URDF chain (a robot section, a 3-D task, spheres and a
//! command interface). Everything else in a [`Config`] (law, feedback, safety, sim, the
//! processes' tables) is written once and means the same on every arm.
//!
//! Why an enum and not two config types: a section shared by both arms is then one field, so
//! a feature added to it lands on every arm, and the one place that asks which arm a file
//! describes is a `match` on [`Config::robot`].

use super::command::CommandSection;
use super::{ArmConfig, Config, ObstacleConfig, SphereEntry, TaskConfig};
use crate::task::Shape;
use serde::{Deserialize, Serialize};

/// The arm a config describes and what belongs to that arm alone.
#[derive(Clone, Debug, PartialEq)]
pub enum Robot {
    Planar(PlanarRobot),
    Spatial(Box<SpatialRobot>),
}

/// The paper's planar arm: `[robot] description = "planar"` (or the older `[arm]`).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct PlanarRobot {
    pub arm: ArmConfig,
    pub task: TaskConfig,
    /// `[[obstacles]]`: discs in the arm's plane.
    pub obstacles: Vec<ObstacleConfig>,
}

/// A URDF chain: `[robot]` names it (a built-in name or a file), `[task]` is a path in space.
#[derive(Clone, Debug, PartialEq)]
pub struct SpatialRobot {
    pub robot: RobotSection,
    pub task: TaskSection,
    /// `[[obstacles]]`: spheres in the base frame.
    pub obstacles: Vec<SphereEntry>,
    /// The interface the daemon sends and its limiter (docs/science.md, "Commanding real arms").
    pub command: CommandSection,
}

impl Config {
    /// The planar arm's own part, or None for a robot.
    pub fn planar(&self) -> Option<&PlanarRobot> {
        match &self.robot {
            Robot::Planar(p) => Some(p),
            Robot::Spatial(_) => None,
        }
    }

    pub fn planar_mut(&mut self) -> Option<&mut PlanarRobot> {
        match &mut self.robot {
            Robot::Planar(p) => Some(p),
            Robot::Spatial(_) => None,
        }
    }

    /// A robot's own part, or None for the planar arm.
    pub fn spatial(&self) -> Option<&SpatialRobot> {
        match &self.robot {
            Robot::Spatial(s) => Some(s),
            Robot::Planar(_) => None,
        }
    }

    pub fn spatial_mut(&mut self) -> Option<&mut SpatialRobot> {
        match &mut self.robot {
            Robot::Spatial(s) => Some(s),
            Robot::Planar(_) => None,
        }
    }

    /// The planar arm's part, for the methods that only the planar arm has (its closed-form
    /// model, its law's parameters).
    ///
    /// # Panics
    /// On a robot's config: a caller that holds one asks [`crate::System`], which never calls a
    /// planar method on it.
    pub fn planar_part(&self) -> &PlanarRobot {
        self.planar()
            .expect("a planar arm's method called on a robot's config")
    }

    /// A robot's part, for the methods that only a chain has.
    ///
    /// # Panics
    /// On the planar arm's config (see [`Self::planar_part`]).
    pub fn spatial_part(&self) -> &SpatialRobot {
        self.spatial()
            .expect("a robot's method called on the planar arm's config")
    }

    /// The task's period T (s), on every arm.
    pub fn period(&self) -> f64 {
        match &self.robot {
            Robot::Planar(p) => p.task.period,
            Robot::Spatial(s) => s.task.period,
        }
    }

    /// The task's radius and period (m, s), to change in place.
    pub fn task_circle_mut(&mut self) -> (&mut f64, &mut f64) {
        match &mut self.robot {
            Robot::Planar(p) => (&mut p.task.radius, &mut p.task.period),
            Robot::Spatial(s) => (&mut s.task.radius, &mut s.task.period),
        }
    }

    /// How long the path takes to come up to speed from rest (s), to change in place.
    pub fn task_ramp_mut(&mut self) -> &mut f64 {
        match &mut self.robot {
            Robot::Planar(p) => &mut p.task.ramp,
            Robot::Spatial(s) => &mut s.task.ramp,
        }
    }

    /// The task as text: two set-ups with the same key follow the same path.
    pub fn task_key(&self) -> String {
        match &self.robot {
            Robot::Planar(p) => format!("{:?}", p.task),
            Robot::Spatial(s) => format!("{:?}", s.task),
        }
    }

    /// How many obstacles the set-up has (discs or spheres).
    pub fn obstacle_count(&self) -> usize {
        match &self.robot {
            Robot::Planar(p) => p.obstacles.len(),
            Robot::Spatial(s) => s.obstacles.len(),
        }
    }

    /// Whether the law steers onto a planned clean cycle: the filter on, an arm with a
    /// planner, and `safety.plan` on (or `auto` with an obstacle).
    pub fn steers_onto_plan(&self) -> bool {
        self.safety.enabled
            && self.has_planner()
            && self.safety.plan.steers(self.obstacle_count() > 0)
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSection {
    /// A built-in robot's name (`chaosctl robot show panda`) or a URDF file's path.
    pub description: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tip: Option<String>,
    /// The tool point in the tip link's frame (m).
    #[serde(default)]
    pub tool: [f64; 3],
    /// Capsule radius per link (m); default 0.05 each.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_radii: Option<Vec<f64>>,
    /// Capsules with end points of their own, one per link in order, instead of `link_radii`'s
    /// about the joint origins (`chaosctl robot fit-radii --capsules` fits them to a model's
    /// meshes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub capsules: Option<Vec<CapsuleEntry>>,
}

/// One link's capsule: the segment from `a` to `b` in the link's own frame (the URDF frame of
/// the joint's child link), and its radius.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CapsuleEntry {
    pub a: [f64; 3],
    pub b: [f64; 3],
    pub radius: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskSection {
    /// "position" (m = 3) or "pose" (m = 6).
    pub kind: String,
    /// The path's shape, as on every arm.
    pub path: Shape,
    /// Centre (m, base frame); default: where the tool starts, so the path's start point
    /// (c + r·u) is one radius above it along u.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub center: Option<[f64; 3]>,
    pub normal: [f64; 3],
    pub radius: f64,
    pub period: f64,
    /// Pose task: the tool orientation as roll, pitch, yaw (rad); default: the start's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orientation_rpy: Option<[f64; 3]>,
    /// Seconds over which the path speeds up from rest ([`crate::task::ramp`]); 0: full speed.
    #[serde(default, skip_serializing_if = "crate::config::is_zero")]
    pub ramp: f64,
}
