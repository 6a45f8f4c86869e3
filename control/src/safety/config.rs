//! `[safety]`: one section for every arm's file: clearance, limits, barrier gains, the runaway
//! guard and what to do when trapped.
//!
//! Most keys mean the same on every arm. The joint limits differ by where they come from: the
//! planar arm's are the file's (`q_min`, `q_max`, `qd_max`, `qdd_max`), a robot's position and
//! rate limits are its URDF's (a robot's file refuses `q_min`, `q_max` and `qd_max` by name and
//! scales the rates with `velocity_scale`), its acceleration limits the maker's unless
//! `qdd_max` is given. Where the two forms' older files had different defaults (`enabled`,
//! `clearance`, the limits, `k0`/`k1`), a key a planar file leaves out gets the planar default
//! ([`SafetySection::fill_planar_defaults`]).
//!
//! The planar defaults turn the filter on with limits a little above what the demo's motion
//! uses (|q̇| ≤ 15 rad/s, |q̈| ≤ 290 rad/s²). The `paper*` presets turn it off, for a faithful
//! reproduction, and widen the limits beyond the paper's own free motion (|q̇| up to 49 rad/s,
//! |q̈| up to 3 400 rad/s² at μ = 0), so `--safety on` there only adds the obstacle clearance.

use super::SafetyParams;
use crate::basics::ConfigError;
use crate::basics::MAX_JOINTS;
use serde::{Deserialize, Serialize};

/// One limit for every joint, or one per joint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Limit {
    All(f64),
    Each(Vec<f64>),
}

impl Limit {
    pub fn resolve(&self, n: usize) -> [f64; MAX_JOINTS] {
        let mut out = [f64::INFINITY; MAX_JOINTS];
        for (i, v) in out.iter_mut().enumerate().take(n) {
            *v = match self {
                Limit::All(x) => *x,
                Limit::Each(xs) => xs.get(i).copied().unwrap_or(f64::NAN),
            };
        }
        out
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SafetySection {
    /// Filter the law's q̈ (null space first). The daemon's runaway guard runs either way.
    pub enabled: bool,
    /// Required distance (m) from every link to every obstacle's surface (its radius; the
    /// obstacle's `margin` belongs to the paper's potential, not to the filter).
    pub clearance: f64,
    /// The planar arm's lower joint limits (rad), one per joint; `-inf` for an unlimited joint.
    /// Default: none. (A robot's come from its URDF.)
    #[serde(skip_serializing_if = "Option::is_none")]
    pub q_min: Option<Vec<f64>>,
    /// The planar arm's upper joint limits (rad), one per joint; `inf` for an unlimited joint.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub q_max: Option<Vec<f64>>,
    /// The planar arm's joint rate limit (rad/s): one number for all joints, or a list. (A
    /// robot's come from its URDF, scaled by `velocity_scale`.)
    #[serde(skip_serializing_if = "Option::is_none")]
    pub qd_max: Option<Limit>,
    /// Joint acceleration limit (rad/s²): one number for all joints, or a list. A robot's
    /// default: its maker's published limits (the Panda) or 10.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub qdd_max: Option<Limit>,
    /// Scales every rate limit (≤ 1: only tighter).
    #[serde(skip_serializing_if = "is_one")]
    pub velocity_scale: f64,
    /// Position barriers ḧ + k1 ḣ + k0 h ≥ 0; k1² ≥ 4 k0 (real roots: no overshoot). The
    /// planar default, a double root at −20/s, lets a link close in at up to 20 m/s per metre
    /// of clearance left: the demo's hand runs its circle at π m/s, and a slower barrier (−10/s)
    /// braked the hand itself off its path wherever the path passes within 0.3 m of an
    /// obstacle, whatever the posture (docs/analysis.md). A robot's default is −10/s.
    pub k0: f64,
    pub k1: f64,
    /// The fastest a link is pushed out of an obstacle's clearance (m/s): a link that starts
    /// inside, or that an obstacle appears on, leaves at no more than this speed.
    pub push_out_speed: f64,
    /// Rate barriers ḣ + k_rate h ≥ 0 (1/s).
    pub k_rate: f64,
    /// Daemon: a joint rate or the law's acceleration beyond its limit for this long (s) → FAULT.
    pub guard_time: f64,
    /// Daemon: a tracking error above this (m) that keeps growing for `guard_growth_time` → FAULT.
    pub guard_tracking_error: f64,
    /// Daemon: how long (s) the tracking error must keep growing above `guard_tracking_error`.
    /// (A start far from the circle grows the error for ~0.1 s while the arm gets going.)
    pub guard_growth_time: f64,
    /// Steer the self-motion onto a planned clean cycle (`chaosctl plan` shows it), so the
    /// filter cannot hold the arm off its path: `auto` (the default) while there is an
    /// obstacle, `true` always, `false` never before a trap.
    pub plan: crate::safety::policy::PlanMode,
    /// The pull's natural frequency (Hz), critically damped.
    pub plan_hz: f64,
    /// Daemon: tracking lost, or the filter acting outside the null space, for this long (s)
    /// → the arm is trapped: the daemon steers onto a planned cycle, or says `Blocked`.
    pub trap_time: f64,
    /// Daemon: what to do while blocked (no clean cycle): `hold` or `best-effort`.
    pub when_blocked: crate::safety::policy::WhenBlocked,
}

fn is_one(v: &f64) -> bool {
    *v == 1.0
}

/// A robot's defaults: the filter off until asked for, the limits from the robot.
impl Default for SafetySection {
    fn default() -> Self {
        Self {
            enabled: false,
            clearance: 0.02,
            q_min: None,
            q_max: None,
            qd_max: None,
            qdd_max: None,
            velocity_scale: 1.0,
            k0: 100.0,
            k1: 20.0,
            push_out_speed: 0.1,
            k_rate: 50.0,
            guard_time: 0.02,
            guard_tracking_error: 1.0,
            guard_growth_time: 0.5,
            plan: crate::safety::policy::PlanMode::Auto,
            plan_hz: 1.0,
            trap_time: crate::safety::policy::DEFAULT_TRAP_TIME,
            when_blocked: crate::safety::policy::WhenBlocked::Hold,
        }
    }
}

/// [`crate::basics::invalid`] for a key of the `[safety]` table.
fn invalid(field: &str, value: impl std::fmt::Debug, expected: &str) -> ConfigError {
    crate::basics::invalid(&format!("safety.{field}"), value, expected)
}

fn in_range(field: &str, v: f64, lo: f64, hi: f64, open_lo: bool) -> Result<(), ConfigError> {
    let ok = v.is_finite() && v <= hi && if open_lo { v > lo } else { v >= lo };
    if ok {
        Ok(())
    } else {
        let lo_s = if open_lo { ">" } else { "≥" };
        Err(invalid(
            field,
            v,
            &format!("must be a finite number {lo_s} {lo} and ≤ {hi}"),
        ))
    }
}

impl SafetySection {
    /// The planar arm's defaults: the filter on, limits a little above the demo's motion.
    pub fn planar() -> Self {
        Self {
            enabled: true,
            clearance: 0.05,
            qd_max: Some(Limit::All(20.0)),
            qdd_max: Some(Limit::All(1000.0)),
            k0: 400.0,
            k1: 40.0,
            ..Self::default()
        }
    }

    /// The paper presets: filter off, limits wider than the paper's own free motion.
    pub fn paper() -> Self {
        Self {
            enabled: false,
            qd_max: Some(Limit::All(100.0)),
            qdd_max: Some(Limit::All(10_000.0)),
            ..Self::planar()
        }
    }

    /// Gives the keys a planar file's `[safety]` (`given`) leaves out their planar defaults.
    pub fn fill_planar_defaults(&mut self, given: Option<&toml::Table>) {
        let has = |k: &str| given.is_some_and(|t| t.contains_key(k));
        let planar = Self::planar();
        if !has("enabled") {
            self.enabled = planar.enabled;
        }
        if !has("clearance") {
            self.clearance = planar.clearance;
        }
        if !has("qd_max") {
            self.qd_max = planar.qd_max;
        }
        if !has("qdd_max") {
            self.qdd_max = planar.qdd_max;
        }
        if !has("k0") {
            self.k0 = planar.k0;
        }
        if !has("k1") {
            self.k1 = planar.k1;
        }
    }

    /// Refuses the planar arm's own limits in a robot's file.
    pub fn check_robot(&self) -> Result<(), ConfigError> {
        const WHY: &str = "the planar arm's key: a robot's position and rate limits come from its URDF (scale the rates with safety.velocity_scale)";
        for (key, v) in [("q_min", &self.q_min), ("q_max", &self.q_max)] {
            if let Some(v) = v {
                return Err(invalid(key, v, WHY));
            }
        }
        match &self.qd_max {
            Some(Limit::All(x)) => Err(invalid("qd_max", x, WHY)),
            Some(Limit::Each(v)) => Err(invalid("qd_max", v, WHY)),
            None => Ok(()),
        }
    }

    /// Checks the keys that do not depend on the joint count.
    pub fn validate_gains(&self) -> Result<(), ConfigError> {
        in_range("clearance", self.clearance, 0.0, 10.0, false)?;
        in_range("velocity_scale", self.velocity_scale, 0.0, 1.0, true)?;
        in_range("plan_hz", self.plan_hz, 0.0, 20.0, true)?;
        crate::safety::policy::check_trap_time(self.trap_time)?;
        in_range("k0", self.k0, 0.0, 1e6, true)?;
        in_range("k1", self.k1, 0.0, 1e4, true)?;
        if self.k1 * self.k1 < 4.0 * self.k0 {
            return Err(invalid(
                "k1",
                self.k1,
                &format!("must satisfy k1² ≥ 4·k0 = {} so that s² + k1·s + k0 has real roots (no overshoot of a limit)", 4.0 * self.k0),
            ));
        }
        in_range("push_out_speed", self.push_out_speed, 0.0, 100.0, true)?;
        in_range("k_rate", self.k_rate, 0.0, 1e4, true)?;
        in_range("guard_time", self.guard_time, 0.0, 10.0, false)?;
        in_range(
            "guard_tracking_error",
            self.guard_tracking_error,
            0.0,
            1e3,
            true,
        )
    }

    /// Checks every field for an arm of `n` joints.
    pub fn validate(&self, n: usize) -> Result<(), ConfigError> {
        self.validate_gains()?;
        for (name, lim, hi) in [
            ("qd_max", &self.qd_max, 1e4),
            ("qdd_max", &self.qdd_max, 1e6),
        ] {
            let Some(lim) = lim else { continue };
            if let Limit::Each(v) = lim {
                if v.len() != n {
                    return Err(invalid(
                        name,
                        v,
                        &format!("must have {n} entries, one per joint, or be one number"),
                    ));
                }
            }
            for (i, x) in lim.resolve(n).iter().take(n).enumerate() {
                in_range(&format!("{name}[{i}]"), *x, 0.0, hi, true)?;
            }
        }
        let (lo, hi) = (self.q_min(n), self.q_max(n));
        for (name, v) in [("q_min", &self.q_min), ("q_max", &self.q_max)] {
            if let Some(v) = v {
                if v.len() != n {
                    return Err(invalid(
                        name,
                        v,
                        &format!(
                            "must have {n} entries, one per joint (use inf for an unlimited joint)"
                        ),
                    ));
                }
                if let Some(i) = v.iter().position(|x| x.is_nan()) {
                    return Err(invalid(
                        &format!("{name}[{i}]"),
                        v[i],
                        "must be a number (inf: unlimited)",
                    ));
                }
            }
        }
        match (0..n).find(|&i| lo[i] >= hi[i]) {
            Some(i) => Err(invalid(
                &format!("q_min[{i}]"),
                lo[i],
                &format!("must be below safety.q_max[{i}] = {}", hi[i]),
            )),
            None => Ok(()),
        }
    }

    fn q_min(&self, n: usize) -> [f64; MAX_JOINTS] {
        let mut out = [f64::NEG_INFINITY; MAX_JOINTS];
        if let Some(v) = &self.q_min {
            out[..n.min(v.len())].copy_from_slice(&v[..n.min(v.len())]);
        }
        out
    }

    fn q_max(&self, n: usize) -> [f64; MAX_JOINTS] {
        let mut out = [f64::INFINITY; MAX_JOINTS];
        if let Some(v) = &self.q_max {
            out[..n.min(v.len())].copy_from_slice(&v[..n.min(v.len())]);
        }
        out
    }

    /// A limit per joint; +∞ where the file gives none.
    fn limit(&self, l: &Option<Limit>, n: usize) -> [f64; MAX_JOINTS] {
        l.as_ref()
            .map_or([f64::INFINITY; MAX_JOINTS], |l| l.resolve(n))
    }

    /// The filter's parameter block for an arm of `n` joints with the file's limits (the
    /// config must be valid); a robot's limits are then its chain's ([`crate::config::spatial`]).
    pub fn params(&self, n: usize) -> SafetyParams {
        SafetyParams {
            enabled: self.enabled,
            clearance: self.clearance,
            q_min: self.q_min(n),
            q_max: self.q_max(n),
            qd_max: self.limit(&self.qd_max, n).map(|v| v * self.velocity_scale),
            qdd_max: self.limit(&self.qdd_max, n),
            // The planar arm's model publishes no jerk limit; a robot's are set from its maker's.
            jerk_max: [f64::INFINITY; MAX_JOINTS],
            k0: self.k0,
            k1: self.k1,
            push_out_speed: self.push_out_speed,
            k_rate: self.k_rate,
            guard_time: self.guard_time,
            guard_tracking_error: self.guard_tracking_error,
            guard_growth_time: self.guard_growth_time,
        }
    }
}
