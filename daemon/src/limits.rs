//! How close the arm came to its joint limits over a run: what a person asks first of a demo on
//! a real robot ("did it ever leave its limits?").
//!
//! The reporter thread watches every state the law used and every command sent, against the
//! limits the running law obeys (`SafetyParams`: the URDF's, tightened by the config). It keeps
//! the smallest position margin, the peak speed and the peak commanded acceleration as
//! fractions of their limits, and counts the ticks outside any. The loop does none of this.

use control::basics::MAX_JOINTS;
use control::safety::SafetyParams;
use protocol::{CommandSample, StateSample};
use serde::Serialize;

/// Relative slack before a value counts as outside its limit (rounding of the filter's own
/// solution sits at about 1e-12).
const SLACK: f64 = 1e-9;

/// What the run showed, for the summary, status and the demo report.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct LimitsSeen {
    /// Smallest distance to a finite position limit (rad or m), and its joint (1-based).
    pub min_position_margin: Option<f64>,
    pub min_position_joint: usize,
    /// Peak |q̇_i| / q̇_max,i over the states, and its joint.
    pub peak_speed_fraction: Option<f64>,
    pub peak_speed_joint: usize,
    /// Peak |q̈_i| / q̈_max,i over the commands sent, and its joint.
    pub peak_acceleration_fraction: Option<f64>,
    pub peak_acceleration_joint: usize,
    /// Peak |q⃛_i| / q⃛_max,i over the commands sent (the rate each command's q̈ ramps at).
    pub peak_jerk_fraction: Option<f64>,
    pub peak_jerk_joint: usize,
    /// Peak |τ_i| / τ_max,i over the torques sent (torque mode), and its joint.
    pub peak_effort_fraction: Option<f64>,
    pub peak_effort_joint: usize,
    /// States outside a position or speed limit, and commands beyond an acceleration, jerk or
    /// effort limit.
    pub states_outside: u64,
    pub commands_outside: u64,
    /// The same, per kind of limit (a state or command may count under two).
    pub position_outside: u64,
    pub speed_outside: u64,
    pub acceleration_outside: u64,
    pub jerk_outside: u64,
    pub effort_outside: u64,
}

/// The running watch.
#[derive(Clone, Debug)]
pub struct LimitWatch {
    limits: SafetyParams,
    /// Effort limits (N·m or N), ∞ where there is none.
    effort: [f64; MAX_JOINTS],
    n: usize,
    seen: LimitsSeen,
}

/// Folds `value` (for `joint`) into a running maximum.
fn peak(slot: &mut Option<f64>, at: &mut usize, value: f64, joint: usize) {
    if value.is_finite() && slot.is_none_or(|p| value > p) {
        *slot = Some(value);
        *at = joint + 1;
    }
}

/// Folds `|value| / limit` into a peak and says whether it is beyond the limit (never for an
/// infinite limit).
fn against(slot: &mut Option<f64>, at: &mut usize, value: f64, limit: f64, joint: usize) -> bool {
    if !limit.is_finite() {
        return false;
    }
    let f = value.abs() / limit;
    peak(slot, at, f, joint);
    f > 1.0 + SLACK
}

impl LimitWatch {
    pub fn new(limits: SafetyParams, effort: [f64; MAX_JOINTS], n: usize) -> Self {
        Self {
            limits,
            effort,
            n,
            seen: LimitsSeen::default(),
        }
    }

    /// The limits changed (a live `set`): later ticks are judged by the new ones.
    pub fn set_limits(&mut self, limits: SafetyParams) {
        self.limits = limits;
    }

    pub fn observe_state(&mut self, s: &StateSample) {
        let l = &self.limits;
        let seen = &mut self.seen;
        let (mut position, mut speed) = (false, false);
        for i in 0..self.n.min(s.q.len()) {
            let margin = (s.q[i] - l.q_min[i]).min(l.q_max[i] - s.q[i]);
            if margin.is_finite() && seen.min_position_margin.is_none_or(|m| margin < m) {
                seen.min_position_margin = Some(margin);
                seen.min_position_joint = i + 1;
            }
            position |= margin < -SLACK;
            let slot = &mut seen.peak_speed_fraction;
            speed |= against(slot, &mut seen.peak_speed_joint, s.qd[i], l.qd_max[i], i);
        }
        seen.position_outside += u64::from(position);
        seen.speed_outside += u64::from(speed);
        seen.states_outside += u64::from(position || speed);
    }

    pub fn observe_command(&mut self, c: &CommandSample) {
        let l = &self.limits;
        let seen = &mut self.seen;
        let (mut acceleration, mut jerk, mut effort) = (false, false, false);
        for i in 0..self.n.min(c.qdd.len()) {
            let (slot, at) = (
                &mut seen.peak_acceleration_fraction,
                &mut seen.peak_acceleration_joint,
            );
            acceleration |= against(slot, at, c.qdd[i], l.qdd_max[i], i);
            let (slot, at) = (&mut seen.peak_jerk_fraction, &mut seen.peak_jerk_joint);
            jerk |= against(slot, at, c.qddd[i], l.jerk_max[i], i);
            if c.interface == protocol::interface::TORQUE {
                let (slot, at) = (&mut seen.peak_effort_fraction, &mut seen.peak_effort_joint);
                effort |= against(slot, at, c.tau[i], self.effort[i], i);
            }
        }
        seen.acceleration_outside += u64::from(acceleration);
        seen.jerk_outside += u64::from(jerk);
        seen.effort_outside += u64::from(effort);
        seen.commands_outside += u64::from(acceleration || jerk || effort);
    }

    pub fn seen(&self) -> LimitsSeen {
        self.seen
    }
}

impl LimitsSeen {
    /// The breach counts in the order of [`protocol::LIMIT_BREACH_KINDS`] (the telemetry's
    /// `limit_breaches`).
    pub fn by_kind(&self) -> [u64; 5] {
        [
            self.position_outside,
            self.speed_outside,
            self.acceleration_outside,
            self.jerk_outside,
            self.effort_outside,
        ]
    }

    /// One line for a report, or None when no limit is finite.
    pub fn one_line(&self) -> Option<String> {
        let mut parts = Vec::new();
        if let Some(m) = self.min_position_margin {
            parts.push(format!(
                "closest to a position limit {m:.3} rad (joint {})",
                self.min_position_joint
            ));
        }
        let fractions = [
            (
                "peak speed",
                self.peak_speed_fraction,
                self.peak_speed_joint,
            ),
            (
                "peak commanded q̈",
                self.peak_acceleration_fraction,
                self.peak_acceleration_joint,
            ),
            (
                "peak commanded jerk",
                self.peak_jerk_fraction,
                self.peak_jerk_joint,
            ),
            (
                "peak torque",
                self.peak_effort_fraction,
                self.peak_effort_joint,
            ),
        ];
        for (what, f, joint) in fractions {
            if let Some(f) = f {
                parts.push(format!(
                    "{what} {:.0} % of its limit (joint {joint})",
                    f * 100.0
                ));
            }
        }
        if parts.is_empty() {
            return None;
        }
        Some(format!(
            "{}; {} states outside a position or speed limit, {} commands beyond an acceleration, jerk or effort limit",
            parts.join(", "),
            self.states_outside,
            self.commands_outside
        ))
    }

    /// Every kind of limit the run broke, with the count and the worst joint: what the one-screen
    /// report's problems line must never leave out.
    pub fn breaches(&self) -> Vec<String> {
        let percent = |f: Option<f64>| f.map_or(String::new(), |f| format!(", {:.0} %", f * 100.0));
        let mut out = Vec::new();
        if self.position_outside > 0 {
            out.push(format!(
                "{} states past a position limit (worst joint {}, {:.3} past)",
                self.position_outside,
                self.min_position_joint,
                -self.min_position_margin.unwrap_or(0.0)
            ));
        }
        let rows = [
            (
                self.speed_outside,
                "states above a speed limit",
                self.peak_speed_joint,
                self.peak_speed_fraction,
            ),
            (
                self.acceleration_outside,
                "commands above an acceleration limit",
                self.peak_acceleration_joint,
                self.peak_acceleration_fraction,
            ),
            (
                self.jerk_outside,
                "commands above a jerk limit",
                self.peak_jerk_joint,
                self.peak_jerk_fraction,
            ),
            (
                self.effort_outside,
                "torques above an effort limit",
                self.peak_effort_joint,
                self.peak_effort_fraction,
            ),
        ];
        for (n, what, joint, f) in rows {
            if n > 0 {
                out.push(format!("{n} {what} (worst joint {joint}{})", percent(f)));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn margins_peaks_and_breaches_are_seen() {
        let mut l = SafetyParams::off();
        l.q_min[0] = -1.0;
        l.q_max[0] = 1.0;
        l.qd_max[0] = 2.0;
        l.qdd_max[0] = 10.0;
        let mut w = LimitWatch::new(l, [f64::INFINITY; MAX_JOINTS], 2);
        let mut s = StateSample {
            n: 2,
            ..Default::default()
        };
        s.q[0] = 0.75;
        s.qd[0] = 1.0;
        w.observe_state(&s);
        s.q[0] = 1.25;
        w.observe_state(&s);
        let mut c = CommandSample::default();
        c.qdd[0] = -5.0;
        w.observe_command(&c);
        let seen = w.seen();
        assert_eq!(seen.min_position_margin, Some(-0.25));
        assert_eq!(
            (seen.peak_speed_fraction, seen.peak_acceleration_fraction),
            (Some(0.5), Some(0.5))
        );
        assert_eq!((seen.states_outside, seen.commands_outside), (1, 0));
        assert!(seen.one_line().unwrap().contains("1 states outside"));
        assert_eq!(
            seen.breaches(),
            ["1 states past a position limit (worst joint 1, 0.250 past)"]
        );
        c.qdd[0] = 0.0;
        c.qddd[0] = 3.0;
        c.tau[0] = 30.0;
        c.interface = protocol::interface::TORQUE;
        let mut effort = [f64::INFINITY; MAX_JOINTS];
        effort[0] = 20.0;
        l.jerk_max[0] = 2.0;
        let mut w = LimitWatch::new(l, effort, 2);
        w.observe_command(&c);
        assert_eq!(
            w.seen().breaches(),
            [
                "1 commands above a jerk limit (worst joint 1, 150 %)",
                "1 torques above an effort limit (worst joint 1, 150 %)"
            ]
        );
        let none = LimitWatch::new(SafetyParams::off(), [f64::INFINITY; MAX_JOINTS], 2);
        assert_eq!(none.seen().one_line(), None);
    }
}
