//! One `[[obstacles]]` entry for every arm: a disc in the planar arm's plane (`D = 2`) or a
//! sphere in a robot's space (`D = 3`). A file, a live `obstacle add` and a command-line
//! `--obstacle` all go through its one check, and the law gets the one runtime
//! [`Ball`] from it.

use crate::basics::{range, ConfigError};
use crate::secondary::balls::Ball;
use nalgebra::SVector;
use serde::{Deserialize, Serialize};

/// An obstacle as a file writes it: centre (m), radius (m) and the potential's margin (m).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(
    deny_unknown_fields,
    bound(
        serialize = "[f64; D]: Serialize",
        deserialize = "[f64; D]: Deserialize<'de>"
    )
)]
pub struct ObstacleEntry<const D: usize> {
    pub center: [f64; D],
    pub radius: f64,
    #[serde(default = "default_margin")]
    pub margin: f64,
}

/// A planar arm's disc.
pub type ObstacleConfig = ObstacleEntry<2>;
/// A robot's sphere.
pub type SphereEntry = ObstacleEntry<3>;

/// The potential's margin when an entry gives none (m).
pub const OBSTACLE_MARGIN: f64 = 0.1;

fn default_margin() -> f64 {
    OBSTACLE_MARGIN
}

/// The largest radius and margin an entry may give (m).
const MAX_SIZE: f64 = 100.0;

impl<const D: usize> ObstacleEntry<D> {
    /// An obstacle at `center` of radius `radius` with the default margin.
    ///
    /// ```
    /// use control::config::ObstacleEntry;
    /// let s = ObstacleEntry::new([0.3, 0.0, 0.5], 0.05);
    /// assert!(s.validate("obstacles[0]").is_ok());
    /// let e = ObstacleEntry::new([0.3, f64::NAN], 0.05).validate("obstacles[1]");
    /// assert!(e.unwrap_err().to_string().contains("obstacles[1].center[1]"));
    /// ```
    pub fn new(center: [f64; D], radius: f64) -> Self {
        Self {
            center,
            radius,
            margin: default_margin(),
        }
    }

    /// Checks the entry: a finite centre, a radius in (0, 100] m, a margin in [0, 100] m;
    /// `field` names it in the refusal (`obstacles[2]`, `obstacle`, `--obstacle #1`).
    pub fn validate(&self, field: &str) -> Result<(), ConfigError> {
        if let Some(i) = self.center.iter().position(|x| !x.is_finite()) {
            return Err(crate::basics::invalid(
                &format!("{field}.center[{i}]"),
                self.center[i],
                "must be finite",
            ));
        }
        if !(self.radius.is_finite() && self.radius > 0.0 && self.radius <= MAX_SIZE) {
            return Err(crate::basics::invalid(
                &format!("{field}.radius"),
                self.radius,
                &format!("must be a finite number > 0 and ≤ {MAX_SIZE}"),
            ));
        }
        range(&format!("{field}.margin"), self.margin, 0.0, MAX_SIZE)
    }

    /// The obstacle as the law and the filter hold it.
    pub fn to_ball(&self) -> Ball<D> {
        Ball {
            center: SVector::from(self.center),
            radius: self.radius,
            margin: self.margin,
        }
    }
}

impl ObstacleEntry<2> {
    /// A disc at (x, y) of radius r (m), with the potential's default margin.
    pub fn disc(x: f64, y: f64, r: f64) -> Self {
        Self::new([x, y], r)
    }
}

impl ObstacleEntry<3> {
    /// A sphere `[x, y, z, radius]` (m) with the default margin, as a file's `[[obstacles]]`
    /// entry without `margin` reads.
    pub fn of([x, y, z, radius]: [f64; 4]) -> Self {
        Self::new([x, y, z], radius)
    }
}
