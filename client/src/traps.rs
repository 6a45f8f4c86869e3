//! What `chaosctl simulate` does about a trap: what the daemon does ([`control::plan::trap`]),
//! on simulated time.
//!
//! The first trap is answered by steering onto a cycle planned from where the arm is; a second
//! one, a trap with no clean cycle, or one on an arm without a planner, is `Blocked`. Offline
//! nothing needs holding, so a blocked run goes on best-effort and says so: the report shows
//! what a daemon would have said, and when.

use control::plan::trap::TrapDetector;
use control::plan::{has_planner, plan_arm, steering_of, PlanOutcome};
use control::steer::Steering;
use control::System;
use serde::Serialize;

/// One thing the watch said.
#[derive(Clone, Debug, Serialize)]
pub struct TrapEvent {
    /// Simulated time (s).
    pub t: f64,
    /// `"steered"` or `"blocked"`.
    pub answer: &'static str,
    pub what: String,
}

/// The trap watch over one offline run.
pub struct OfflineTraps {
    system: System,
    detector: TrapDetector,
    /// The run follows this steering (the start's plan, or a trap's).
    following: Option<Steering>,
    traps: u32,
    blocked: bool,
    pub events: Vec<TrapEvent>,
}

impl OfflineTraps {
    /// A watch for `system`, which starts steered by `following` (its `safety.plan`) or not.
    pub fn new(system: System, following: Option<Steering>) -> Self {
        Self {
            detector: TrapDetector::starting(&system.safety()),
            system,
            following,
            traps: 0,
            blocked: false,
            events: Vec::new(),
        }
    }

    /// One step's output at time `t` with the arm at `q`: the steering to hand the law when a
    /// trap is answered by one.
    pub fn observe(
        &mut self,
        t: f64,
        law_flags: u32,
        tracking_error: f64,
        q: &[f64],
    ) -> Option<Steering> {
        let s = self.system.safety();
        if !s.enabled || self.blocked {
            return None;
        }
        let trap = self.detector.observe(t, law_flags, tracking_error, &s)?;
        self.traps += 1;
        let words = trap.words(s.trap_time);
        if self.traps > 1 || !has_planner(&self.system) {
            let why = if self.traps > 1 {
                "steering onto the planned clean cycle did not get the arm round"
            } else {
                "this arm has no cycle planner to find a way round"
            };
            self.block(t, format!("trapped ({words}): {why}"));
            return None;
        }
        match plan_arm(&self.system, t, Some(q), self.following.as_ref()) {
            Ok(p) => match p.outcome {
                PlanOutcome::Found(c) => match steering_of(&self.system, &c) {
                    Ok(steer) => {
                        self.events.push(TrapEvent {
                            t,
                            answer: "steered",
                            what: format!(
                                "{words}: steering onto a clean cycle planned from the arm's \
                                 posture"
                            ),
                        });
                        self.following = Some(steer);
                        Some(steer)
                    }
                    Err(e) => {
                        self.block(t, format!("trapped ({words}); the planned cycle: {e}"));
                        None
                    }
                },
                PlanOutcome::Blocked(b) => {
                    self.block(
                        t,
                        format!(
                            "trapped ({words}); no clean cycle the arm can follow: {}",
                            b.reason
                        ),
                    );
                    None
                }
            },
            Err(e) => {
                self.block(
                    t,
                    format!("trapped ({words}); the planner cannot plan: {e}"),
                );
                None
            }
        }
    }

    /// The start's plan found no clean cycle: the daemon would say `Blocked` at once.
    pub fn blocked_at_start(&mut self, b: &control::steer::Blocked) {
        self.block(
            0.0,
            format!("no clean cycle the arm can follow: {}", b.reason),
        );
    }

    fn block(&mut self, t: f64, what: String) {
        self.blocked = true;
        self.events.push(TrapEvent {
            t,
            answer: "blocked",
            what: format!("{what} (offline: the run goes on best-effort)"),
        });
    }
}

/// The events as the human report's lines (none when nothing was trapped).
pub fn print(events: &[TrapEvent]) {
    for e in events {
        let label = if e.answer == "blocked" {
            "BLOCKED"
        } else {
            "trapped"
        };
        println!("  {label:<16} at t = {:.3} s: {}", e.t, e.what);
    }
}
