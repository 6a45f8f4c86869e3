//! How often the limiter shaped the commands, per joint and kind of limit: what tells a person
//! whether the arm is being driven at its limits (and which one), in `status`, the demo report,
//! the summary and the metrics.
//!
//! The loop only marks each tick's clamps in its record (`TickRecord::limiter_hits`); the
//! reporter thread counts them here.

use control::command::{CommandMode, LimitKind, LIMIT_KINDS};
use protocol::MAX_JOINTS;
use serde::Serialize;

/// Ticks on which each joint's command was clamped, per [`LimitKind`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SaturationTable {
    /// The command interface the daemon sends.
    pub mode: CommandMode,
    /// Whether the limiter is on.
    pub limiter: bool,
    pub n: usize,
    /// `counts[joint][kind]`, kinds in `LimitKind::ALL` order.
    pub counts: [[u64; LIMIT_KINDS]; MAX_JOINTS],
}

impl SaturationTable {
    pub fn new(mode: CommandMode, limiter: bool, n: usize) -> Self {
        Self {
            mode,
            limiter,
            n: n.min(MAX_JOINTS),
            counts: [[0; LIMIT_KINDS]; MAX_JOINTS],
        }
    }

    /// Counts one tick's clamps.
    pub fn observe(&mut self, hits: &[u8; MAX_JOINTS]) {
        for (row, &h) in self.counts.iter_mut().zip(hits).take(self.n) {
            for (k, c) in row.iter_mut().enumerate() {
                *c += u64::from(h >> k & 1);
            }
        }
    }

    pub fn total(&self, kind: LimitKind) -> u64 {
        self.counts.iter().map(|r| r[kind as usize]).sum()
    }

    /// `{"jerk": {"total": 12, "per_joint": [..]}, ...}` for `status --json` and the summary.
    pub fn to_json(&self) -> serde_json::Value {
        let mut kinds = serde_json::Map::new();
        for kind in LimitKind::ALL {
            let per: Vec<u64> = self.counts[..self.n]
                .iter()
                .map(|r| r[kind as usize])
                .collect();
            kinds.insert(
                kind.name().into(),
                serde_json::json!({ "total": self.total(kind), "per_joint": per }),
            );
        }
        serde_json::json!({
            "mode": self.mode.name(),
            "limiter": self.limiter,
            "saturations": kinds,
        })
    }

    /// One line for the report: the totals that are not zero, and the joint that saturated
    /// most for each.
    pub fn one_line(&self) -> String {
        if !self.limiter {
            return "limiter OFF: commands sent as the law asked".into();
        }
        let parts: Vec<String> = LimitKind::ALL
            .iter()
            .filter(|&&k| self.total(k) > 0)
            .map(|&k| {
                let (j, _) = self.counts[..self.n]
                    .iter()
                    .enumerate()
                    .max_by_key(|(_, r)| r[k as usize])
                    .unwrap_or((0, &[0; LIMIT_KINDS]));
                format!("{} {} (most on joint {})", k.name(), self.total(k), j + 1)
            })
            .collect();
        if parts.is_empty() {
            "no command needed limiting".into()
        } else {
            format!("joint-ticks limited: {}", parts.join(", "))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_per_joint_and_kind() {
        let mut t = SaturationTable::new(CommandMode::Position, true, 3);
        let mut hits = [0u8; MAX_JOINTS];
        hits[1] = 1 << LimitKind::Jerk as u8 | 1 << LimitKind::Velocity as u8;
        hits[5] = 0xff; // beyond n: ignored
        t.observe(&hits);
        t.observe(&hits);
        assert_eq!(t.total(LimitKind::Jerk), 2);
        assert_eq!(t.total(LimitKind::Velocity), 2);
        assert_eq!(t.total(LimitKind::Torque), 0);
        assert!(
            t.one_line().contains("jerk 2 (most on joint 2)"),
            "{}",
            t.one_line()
        );
        assert_eq!(t.to_json()["saturations"]["jerk"]["per_joint"][1], 2);
        let quiet = SaturationTable::new(CommandMode::Torque, true, 7);
        assert_eq!(quiet.one_line(), "no command needed limiting");
    }
}
