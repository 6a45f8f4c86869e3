//! The obstacles of either arm's set-up as a client edits and lists them (the daemon's
//! `obstacle add|rm|ls`): a disc in the plane or a sphere in space, numbered from 1 everywhere.
//!
//! The daemon parses a request once for every arm and asks here how many numbers place a
//! centre; which list of which file the obstacle goes into is this file's business.

use super::System;
use crate::basics::ConfigError;
use crate::config::spatial::SphereEntry;
use crate::config::{ObstacleConfig, Robot};

/// One obstacle as listed: its centre (2 or 3 numbers), radius and margin (m).
#[derive(Clone, Debug, PartialEq)]
pub struct ObstacleRow {
    pub center: Vec<f64>,
    pub radius: f64,
    pub margin: f64,
}

impl System {
    /// How many numbers place an obstacle's centre: 2 (a disc in the plane) or 3 (a sphere).
    pub fn obstacle_dims(&self) -> usize {
        match self.config().robot {
            Robot::Planar(_) => 2,
            Robot::Spatial(_) => 3,
        }
    }

    /// The obstacles in the order `obstacle rm N` counts them (from 1).
    pub fn obstacle_rows(&self) -> Vec<ObstacleRow> {
        let row = |center: &[f64], radius, margin| ObstacleRow {
            center: center.to_vec(),
            radius,
            margin,
        };
        match &self.config().robot {
            Robot::Planar(p) => p
                .obstacles
                .iter()
                .map(|o| row(&o.center, o.radius, o.margin))
                .collect(),
            Robot::Spatial(s) => s
                .obstacles
                .iter()
                .map(|o| row(&o.center, o.radius, o.margin))
                .collect(),
        }
    }

    /// Adds an obstacle whose centre has [`Self::obstacle_dims`] numbers; the caller validates
    /// the whole set-up after.
    ///
    /// ```
    /// let mut s = control::System::preset("demo", &control::system::builtin_robot).unwrap();
    /// s.add_obstacle(&[0.0, 1.6], 0.25, 0.1).unwrap();
    /// assert_eq!(s.obstacle_rows()[0].center, vec![0.0, 1.6]);
    /// assert!(s.add_obstacle(&[0.0, 1.6, 0.2], 0.25, 0.1).is_err());
    /// // A robot's sphere meets the same check as a file's entry, named as the request says it.
    /// let mut p = control::System::preset("panda", &control::system::builtin_robot).unwrap();
    /// let e = p.add_obstacle(&[0.3, 0.0, 0.5], -0.1, 0.1).unwrap_err();
    /// assert!(e.to_string().contains("obstacle.radius"), "{e}");
    /// ```
    pub fn add_obstacle(
        &mut self,
        center: &[f64],
        radius: f64,
        margin: f64,
    ) -> Result<(), ConfigError> {
        let dims = self.obstacle_dims();
        if center.len() != dims {
            return Err(crate::basics::invalid(
                "obstacle.center",
                center,
                &format!("{dims} numbers on this arm"),
            ));
        }
        match &mut self.config_mut().robot {
            Robot::Planar(p) => {
                let o = ObstacleConfig {
                    center: [center[0], center[1]],
                    radius,
                    margin,
                };
                o.validate("obstacle")?;
                p.obstacles.push(o);
            }
            Robot::Spatial(s) => {
                let o = SphereEntry {
                    center: [center[0], center[1], center[2]],
                    radius,
                    margin,
                };
                o.validate("obstacle")?;
                s.obstacles.push(o);
            }
        }
        Ok(())
    }

    /// Removes every obstacle (a client's `--obstacle` flags replace the file's).
    pub fn clear_obstacles(&mut self) {
        match &mut self.config_mut().robot {
            Robot::Planar(p) => p.obstacles.clear(),
            Robot::Spatial(s) => s.obstacles.clear(),
        }
    }

    /// Removes the obstacle at `index` (0-based; the caller has checked it against
    /// [`Self::obstacle_rows`]).
    pub fn remove_obstacle(&mut self, index: usize) {
        match &mut self.config_mut().robot {
            Robot::Planar(p) => {
                p.obstacles.remove(index);
            }
            Robot::Spatial(s) => {
                s.obstacles.remove(index);
            }
        }
    }
}
