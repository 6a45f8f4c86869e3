//! The `[plant]` table. The plant validates it at start-up and names a bad field, as the daemon
//! does with `[daemon]`.

use control::basics::ConfigError;
use rt::{Trigger, WaitStrategy};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlantConfig {
    /// Must equal the daemon's namespace.
    pub namespace: String,
    /// Plant rate (Hz): one integration period and one published state per tick.
    pub rate_hz: f64,
    /// RK4 substeps per period.
    pub substeps: u32,
    pub wait: WaitStrategy,
    pub spin_us: f64,
    pub core: Option<usize>,
    pub priority: u8,
    pub lock_memory: bool,
    /// Without a command for this long (ms) the plant brakes to rest.
    pub command_timeout_ms: f64,
    /// Braking deceleration gain: q̈ = −gain · q̇ (1/s).
    pub brake_gain: f64,
    pub output_dir: PathBuf,
    /// "clock": apply the newest command at the next cycle (free-running, the default).
    /// "state": after publishing a state, wait for the command answering it, up to
    /// `answer_deadline_us`, and apply it in the same cycle. Must match `daemon.trigger`.
    pub trigger: Trigger,
    /// State trigger: how long after the state is published the answer may come (µs), and never
    /// past the end of the cycle; later is a late cycle. Default: half the period. Must be below
    /// the period.
    pub answer_deadline_us: Option<f64>,
    /// State trigger: this many late cycles in a row make the plant brake (Franka FCI stops
    /// after 20 at 1 kHz). It follows commands again as soon as an answer comes in time.
    pub max_late_cycles: u32,
    /// State trigger: also write each state to, and take answers from, an iceoryx2 blackboard
    /// (`protocol::board`), the latest-value fast lane; pub-sub still carries every sample. Off,
    /// or if the lane cannot be opened, pub-sub alone carries them. Ignored with the clock trigger.
    pub fast_lane: bool,
    /// "kinematic": the commanded motion is the motion (q̈ integrated, a position reached, no
    /// masses). "rigid-body": the arm's dynamics (`[plant.rigid_body]`: friction, payload,
    /// sensors, the joint servo of position and velocity modes). Torque commands need it.
    pub dynamics: Dynamics,
    /// The rigid-body arm's physics.
    pub rigid_body: control::rigid_body::RigidBodyConfig,
    /// `dynamics = "mujoco"`: the model MuJoCo simulates ([`MujocoConfig`]).
    #[serde(skip_serializing_if = "MujocoConfig::is_default")]
    pub mujoco: MujocoConfig,
}

/// `[plant.mujoco]`: the arm MuJoCo simulates (`chaosd-plant-mujoco`, docs/mujoco.md).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MujocoConfig {
    /// A URDF or MJCF file (MuJoCo compiles both). Default: the set-up's own robot, which for
    /// a built-in robot has no collision geometry (MuJoCo then judges no contact).
    pub model: Option<PathBuf>,
    /// Where a URDF's `package://NAME/` mesh paths point, by package name. Default: the
    /// nearest folder above the URDF that is named NAME (how example-robot-data is laid out).
    pub packages: std::collections::BTreeMap<String, PathBuf>,
}

impl MujocoConfig {
    fn is_default(&self) -> bool {
        *self == Self::default()
    }
}

/// How the simulated arm moves.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Dynamics {
    #[default]
    Kinematic,
    RigidBody,
    /// MuJoCo's physics of the `[plant.mujoco]` model (`chaosd-plant-mujoco`).
    Mujoco,
}

impl Dynamics {
    /// The name a file and `--engine` use.
    pub fn name(self) -> &'static str {
        match self {
            Self::Kinematic => "kinematic",
            Self::RigidBody => "rigid-body",
            Self::Mujoco => "mujoco",
        }
    }
}

impl Default for PlantConfig {
    fn default() -> Self {
        Self {
            namespace: protocol::DEFAULT_NAMESPACE.to_string(),
            rate_hz: 1000.0,
            substeps: 4,
            wait: WaitStrategy::Hybrid,
            spin_us: 50.0,
            core: Some(0),
            priority: 50,
            lock_memory: true,
            command_timeout_ms: 50.0,
            brake_gain: 20.0,
            output_dir: PathBuf::from("out/chaosd"),
            trigger: Trigger::Clock,
            answer_deadline_us: None,
            max_late_cycles: 20,
            fast_lane: true,
            dynamics: Dynamics::Kinematic,
            rigid_body: Default::default(),
            mujoco: MujocoConfig::default(),
        }
    }
}

fn invalid(field: &str, value: impl std::fmt::Debug, expected: &str) -> ConfigError {
    ConfigError::Invalid {
        field: format!("plant.{field}"),
        value: format!("{value:?}"),
        expected: expected.into(),
    }
}

impl PlantConfig {
    pub fn from_table(t: Option<&toml::Table>) -> Result<Self, ConfigError> {
        let c: Self = match t {
            Some(t) => t
                .clone()
                .try_into()
                .map_err(|e: toml::de::Error| ConfigError::Parse(format!("in [plant]: {e}")))?,
            None => Self::default(),
        };
        c.validate()?;
        Ok(c)
    }

    pub fn validate(&self) -> Result<(), ConfigError> {
        protocol::validate_namespace(&self.namespace)
            .map_err(|e| invalid("namespace", &self.namespace, &e.to_string()))?;
        rt::setup::check_loop(
            self.rate_hz,
            (100.0, 20_000.0),
            self.spin_us,
            self.priority,
            self.core,
        )
        .map_err(|e| ConfigError::Invalid {
            field: format!("plant.{}", e.field),
            value: e.value,
            expected: e.expected,
        })?;
        if !(1..=100).contains(&self.substeps) {
            return Err(invalid(
                "substeps",
                self.substeps,
                "must be between 1 and 100",
            ));
        }
        if !(self.command_timeout_ms.is_finite()
            && self.command_timeout_ms >= 1.0
            && self.command_timeout_ms <= 60_000.0)
        {
            return Err(invalid(
                "command_timeout_ms",
                self.command_timeout_ms,
                "must be between 1 and 60000 ms",
            ));
        }
        if !(self.brake_gain.is_finite() && self.brake_gain > 0.0 && self.brake_gain <= 1e4) {
            return Err(invalid(
                "brake_gain",
                self.brake_gain,
                "must be > 0 and ≤ 10000 1/s",
            ));
        }
        if let Some(m) = &self.mujoco.model {
            if m.as_os_str().is_empty() {
                return Err(invalid("mujoco.model", m, "a URDF or MJCF file's path"));
            }
        }
        if self.output_dir.as_os_str().is_empty() {
            return Err(invalid("output_dir", &self.output_dir, "must not be empty"));
        }
        let period_us = 1e6 / self.rate_hz;
        if let Some(a) = self.answer_deadline_us {
            if !(a.is_finite() && a >= 1.0 && a < period_us) {
                return Err(invalid(
                    "answer_deadline_us",
                    a,
                    &format!("must be at least 1 µs and below the period ({period_us} µs)"),
                ));
            }
        }
        if !(1..=100_000).contains(&self.max_late_cycles) {
            return Err(invalid(
                "max_late_cycles",
                self.max_late_cycles,
                "must be between 1 and 100000",
            ));
        }
        Ok(())
    }

    pub fn period_ns(&self) -> u64 {
        (1e9 / self.rate_hz).round() as u64
    }

    /// State trigger: the answer deadline after the state is published (ns).
    pub fn answer_deadline_ns(&self) -> u64 {
        match self.answer_deadline_us {
            Some(us) => (us * 1e3) as u64,
            None => self.period_ns() / 2,
        }
    }

    /// State trigger: when the answer to a state published at `published_ns` is due: the answer
    /// deadline after it, but never past the end of the cycle it was published in, where this
    /// process owns the clock (`cycle_end_ns`: the nominal end, one period after the deadline the
    /// cycle was due at).
    ///
    /// A state published after its cycle's nominal end means this process woke more than a
    /// period late. It skips the periods it missed (its overruns, see `Schedule::advance`), so
    /// the cycle it runs in ends at the next period boundary, and the controller is held to that
    /// one, not to a boundary already past.
    pub fn answer_due_ns(&self, published_ns: u64, cycle_end_ns: Option<u64>) -> u64 {
        let due = published_ns.saturating_add(self.answer_deadline_ns());
        let Some(end) = cycle_end_ns else {
            return due;
        };
        let p = self.period_ns().max(1);
        let end = if published_ns >= end {
            end + p * ((published_ns - end) / p + 1)
        } else {
            end
        };
        due.min(end)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_answer_is_due_half_a_period_after_the_state_and_within_the_cycle() {
        // 1 kHz: half a period is 500 µs. On time: 500 µs after the publication.
        let c = PlantConfig::default();
        assert_eq!(c.answer_due_ns(1_000_000, Some(2_000_000)), 1_500_000);
        // The plant woke 300 µs late: the controller still has its 500 µs, not 200.
        assert_eq!(c.answer_due_ns(1_300_000, Some(2_000_000)), 1_800_000);
        // 700 µs late: the answer must still come within the cycle.
        assert_eq!(c.answer_due_ns(1_700_000, Some(2_000_000)), 2_000_000);
        // A device-clocked plant: the device ends the cycle.
        assert_eq!(c.answer_due_ns(1_700_000, None), 2_200_000);
        // Woke 1.3 ms late (a held vCPU): the periods it skipped are its overruns; the cycle it
        // publishes in ends at 3 ms, and the answer is due by then, not by the 2 ms already past.
        assert_eq!(c.answer_due_ns(2_300_000, Some(2_000_000)), 2_800_000);
        assert_eq!(c.answer_due_ns(2_700_000, Some(2_000_000)), 3_000_000);
        assert_eq!(c.answer_due_ns(2_000_000, Some(2_000_000)), 2_500_000);
        // Whenever the state goes out, its answer is due no later than the deadline the
        // schedule resumes at after that cycle (so a cycle never runs into the next one), and
        // exactly then when the cycle's end is what caps it.
        for published in (1_000_000..6_000_000).step_by(37_000) {
            let due = c.answer_due_ns(published, Some(2_000_000));
            let mut s = rt::clock::Schedule::new(1_000_000, 0);
            assert_eq!(s.deadline(), 1_000_000);
            s.advance(published);
            let next = s.deadline();
            assert!(due <= next, "published {published}: due {due} after {next}");
            assert!(due > published, "published {published}: due {due}");
            if published + 500_000 > next {
                assert_eq!(due, next, "published {published}");
            }
        }
    }

    #[test]
    fn validation_names_the_field() {
        assert!(PlantConfig::from_table(None).is_ok());
        let t: toml::Table = toml::from_str("rate_hz = 5").unwrap();
        assert!(PlantConfig::from_table(Some(&t))
            .unwrap_err()
            .to_string()
            .contains("plant.rate_hz"));
        let t: toml::Table = toml::from_str("command_timeout_ms = -1").unwrap();
        assert!(PlantConfig::from_table(Some(&t))
            .unwrap_err()
            .to_string()
            .contains("plant.command_timeout_ms"));
        for bad in [
            "answer_deadline_us = 1000",
            "answer_deadline_us = -3",
            "max_late_cycles = 0",
        ] {
            let t: toml::Table = toml::from_str(bad).unwrap();
            let e = PlantConfig::from_table(Some(&t)).unwrap_err().to_string();
            assert!(e.contains(bad.split(' ').next().unwrap()), "{bad}: {e}");
        }
        let t: toml::Table = toml::from_str("trigger = \"bell\"").unwrap();
        assert!(PlantConfig::from_table(Some(&t))
            .unwrap_err()
            .to_string()
            .contains("bell"));
        let t: toml::Table = toml::from_str("typo = 1").unwrap();
        assert!(PlantConfig::from_table(Some(&t))
            .unwrap_err()
            .to_string()
            .contains("typo"));
    }
}
