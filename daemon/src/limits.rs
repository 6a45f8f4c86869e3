//! How close the arm came to its joint limits over a run: what a person asks first of a demo on
//! a real robot ("did it ever leave its limits?").
//!
//! The reporter thread watches every state the law used and every command sent, against the
//! limits the running law obeys (`SafetyParams`: the URDF's, tightened by the config). It keeps
//! the smallest position margin, the peak speed and the peak commanded acceleration as
//! fractions of their limits, and counts the ticks outside any. The loop does none of this.

use control::safety::SafetyParams;
use protocol::{CommandSample, StateSample};
use serde::Serialize;

/// Relative slack before a value counts as outside its limit (rounding of the filter's own
/// solution sits at about 1e-12).
const SLACK: f64 = 1e-9;

/// What the run showed, for the summary and the demo report.
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
    /// States outside a position or speed limit, and commands beyond an acceleration limit.
    pub states_outside: u64,
    pub commands_outside: u64,
}

/// The running watch.
#[derive(Clone, Debug)]
pub struct LimitWatch {
    limits: SafetyParams,
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

impl LimitWatch {
    pub fn new(limits: SafetyParams, n: usize) -> Self {
        Self {
            limits,
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
        let (seen, mut outside) = (&mut self.seen, false);
        for i in 0..self.n.min(s.q.len()) {
            let margin = (s.q[i] - l.q_min[i]).min(l.q_max[i] - s.q[i]);
            if margin.is_finite() && seen.min_position_margin.is_none_or(|m| margin < m) {
                seen.min_position_margin = Some(margin);
                seen.min_position_joint = i + 1;
            }
            let speed = s.qd[i].abs() / l.qd_max[i];
            if l.qd_max[i].is_finite() {
                peak(
                    &mut seen.peak_speed_fraction,
                    &mut seen.peak_speed_joint,
                    speed,
                    i,
                );
            }
            outside |= margin < -SLACK || speed > 1.0 + SLACK;
        }
        seen.states_outside += u64::from(outside);
    }

    pub fn observe_command(&mut self, c: &CommandSample) {
        let l = &self.limits;
        let (seen, mut outside) = (&mut self.seen, false);
        for i in 0..self.n.min(c.qdd.len()) {
            let a = c.qdd[i].abs() / l.qdd_max[i];
            if l.qdd_max[i].is_finite() {
                let slot = &mut seen.peak_acceleration_fraction;
                peak(slot, &mut seen.peak_acceleration_joint, a, i);
            }
            outside |= a > 1.0 + SLACK;
        }
        seen.commands_outside += u64::from(outside);
    }

    pub fn seen(&self) -> LimitsSeen {
        self.seen
    }
}

impl LimitsSeen {
    /// One line for a report, or None when no limit is finite.
    pub fn one_line(&self) -> Option<String> {
        let mut parts = Vec::new();
        if let Some(m) = self.min_position_margin {
            parts.push(format!(
                "closest to a position limit {m:.3} rad (joint {})",
                self.min_position_joint
            ));
        }
        if let Some(f) = self.peak_speed_fraction {
            parts.push(format!(
                "peak speed {:.0} % of its limit (joint {})",
                f * 100.0,
                self.peak_speed_joint
            ));
        }
        if let Some(f) = self.peak_acceleration_fraction {
            parts.push(format!(
                "peak commanded q̈ {:.0} % of its limit (joint {})",
                f * 100.0,
                self.peak_acceleration_joint
            ));
        }
        if parts.is_empty() {
            return None;
        }
        Some(format!(
            "{}; {} states outside a position or speed limit, {} commands beyond an acceleration limit",
            parts.join(", "),
            self.states_outside,
            self.commands_outside
        ))
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
        let mut w = LimitWatch::new(l, 2);
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
        let none = LimitWatch::new(SafetyParams::off(), 2);
        assert_eq!(none.seen().one_line(), None);
    }
}
