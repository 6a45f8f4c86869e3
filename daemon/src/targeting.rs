//! `mu = "auto"`: the arm steered onto the model's cycle, then handed to the feedback
//! ([`control::target`]).
//!
//! The deadlock watch owns what the loop steers by ([`crate::deadlock::Deadlock::target`]):
//! a planner's steering (obstacles, a trap) has the arm before this one, and an edit ends it.
//! This keeps the steering's story: when it began, how closely the steered law follows the
//! cycle, and when and why the pull went (`status`'s `gains.target`).

use control::target::{Release, Released, Target};
use serde::Serialize;

/// How a steering onto the model's cycle ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Ended {
    /// Handed to the feedback ([`Released`]).
    Released(Released),
    /// An edit: the cycle was the set-up's before it.
    Edited,
    /// The planner steers the arm now (a trap, or `Blocked`).
    Planner,
}

/// One steering onto the model's cycle.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TargetInfo {
    /// Controller time it began (s).
    pub since: f64,
    /// The steered law's miss of the cycle (rad).
    pub miss: f64,
    pub ended_at: Option<f64>,
    pub ended: Option<Ended>,
}

/// The steering onto the model's cycle under way, and the newest one's story.
#[derive(Debug, Default)]
pub struct Targeting {
    under_way: Option<Release>,
    pub last: Option<TargetInfo>,
    /// Steerings back onto the cycle since the last edit.
    retargets: u32,
}

impl Targeting {
    /// Whether the arm may be steered back onto the cycle once more (counts it).
    pub fn may_retarget(&mut self) -> bool {
        self.retargets += 1;
        self.retargets <= control::target::MAX_RETARGETS
    }

    /// An edit: the count starts again.
    pub fn edited(&mut self) {
        self.retargets = 0;
    }

    pub fn active(&self) -> bool {
        self.under_way.is_some()
    }

    /// The loop was sent `target`'s steering at controller time `now`.
    pub fn start(&mut self, target: &Target, now: f64, period: f64) {
        tracing::info!(
            "mu = \"auto\": steering the arm onto the model's cycle at t = {now:.3} s (the steered \
             law follows it to {:.1e} rad); the feedback takes it once it repeats itself",
            target.miss
        );
        self.under_way = Some(Release::new(now, period));
        self.last = Some(TargetInfo {
            since: now,
            miss: target.miss,
            ended_at: None,
            ended: None,
        });
    }

    /// One tick the law ran on, at controller time `t`, with its period residual (rad/s) and
    /// the feedback on or not yet: true when the pull should go now (the arm is on the cycle,
    /// or it took too long).
    pub fn observe(&mut self, t: f64, residual: f64, feedback: bool) -> bool {
        let Some(release) = self.under_way.as_mut() else {
            return false;
        };
        let Some(why) = release.observe(t, residual, feedback) else {
            return false;
        };
        match why {
            Released::OnTheCycle => tracing::info!(
                "mu = \"auto\": the arm is on the model's cycle at t = {t:.3} s: the pull goes, \
                 the feedback holds it"
            ),
            Released::TimedOut => tracing::warn!(
                "mu = \"auto\": the steered arm did not settle on the model's cycle by t = {t:.3} s \
                 (a plant unlike the model, or the filter): the pull goes, the feedback alone \
                 catches it"
            ),
        }
        self.end(t, Ended::Released(why));
        true
    }

    /// The steering ended at `now` for `why`.
    pub fn end(&mut self, now: f64, why: Ended) {
        if self.under_way.take().is_some() {
            if let Some(info) = self.last.as_mut() {
                (info.ended_at, info.ended) = (Some(now), Some(why));
            }
        }
    }

    /// `status`'s `gains.target`.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "steering": self.active(),
            "last": self.last,
        })
    }
}
