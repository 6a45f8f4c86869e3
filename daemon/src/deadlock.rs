//! Safety without deadlock: the daemon never runs on silently with the arm trapped.
//!
//! The safety filter is local. It keeps clearance now, but it can hold the arm off its path
//! for good, and the loop alone cannot tell a trap from a transient. This module, on the
//! reporter thread, does three things:
//!
//! - **Plans.** At start and on every committed edit it asks the planner thread
//!   ([`crate::planner`]) whether a clean cycle exists (filter on; the planar fixed-base arm
//!   or any spatial one).
//! - **Watches for traps.** Tracking lost while the filter acts, or the filter acting outside
//!   the null space, for `safety.trap_time` makes a trap (a start far from the path loses
//!   tracking too, but the filter plays no part in it); so does the filter costing tracking in
//!   a few task periods out of a window ([`control::plan::trap`], which `chaosctl simulate`
//!   runs too). The first trap of an edit is answered by steering onto a cycle planned from
//!   where the arm is. A second one, or one on an arm without a planner, means the arm cannot
//!   get round.
//! - **Says `Blocked`.** When there is no clean cycle, or steering did not help, the daemon
//!   enters `Blocked` with the reason in words, and holds the posture (tracking paused) or runs
//!   on best-effort, as `safety.when_blocked` says. The next edit ends it once a clean cycle
//!   exists again.
//!
//! What reaches the loop is a `Copy` request through the same bounded channel as every other
//! change: a steering table ([`crate::telemetry::LoopRequest::Steer`]) or the hold switch. No
//! lock, no allocation on the loop.

use crate::planner::{Done, Job, Planner, Why};
use crate::replay::ReplayLog;
use crate::targeting::{Ended, Targeting};
use crate::telemetry::{LoopRequest, TickRecord};
use control::plan::trap::TrapDetector;
use control::plan::{has_planner, plan_asked, steering_of, PlanOutcome};
use control::safety::policy::WhenBlocked;
use control::steer::Steering;
use control::target::Target;
use control::System;
use crossbeam::channel::Sender;

/// Why the arm is blocked, since when, and what the daemon does about it.
#[derive(Clone, Debug, PartialEq)]
pub struct BlockedState {
    pub reason: String,
    /// Controller time (s) it began.
    pub since: f64,
    pub action: WhenBlocked,
    /// The planner's best clearance (m), and the obstacle and link that set it (1-based).
    pub best_clearance: Option<f64>,
    pub obstacle: Option<usize>,
    pub link: Option<usize>,
}

impl BlockedState {
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "reason": self.reason,
            "since": self.since,
            "action": self.action.name(),
            "best_clearance": self.best_clearance,
            "obstacle": self.obstacle,
            "link": self.link,
        })
    }
}

/// The newest plan the planner returned.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanInfo {
    pub generation: u64,
    pub why: Why,
    pub found: bool,
    pub took_ms: f64,
    pub min_clearance: Option<f64>,
    /// Only the physical limits admitted the cycle (the default margins found none).
    pub limits_only: bool,
}

/// What a plan is made round (the obstacles and the task, as their config sections read):
/// an edit that changes neither forces no detour.
#[derive(Clone, Debug, Default, PartialEq)]
struct Layout {
    obstacles: Option<String>,
    task: String,
}

impl Layout {
    fn of(system: &System) -> Self {
        let rows = system.obstacle_rows();
        Self {
            obstacles: (!rows.is_empty()).then(|| format!("{rows:?}")),
            task: system.task_key(),
        }
    }
}

/// A tick this late (ns) knocks the arm: the plant ran on the previous command for 5 ticks.
const STALL_NS: u64 = 5_000_000;

/// The reporter's side of safety without deadlock.
pub struct Deadlock {
    planner: Option<Planner>,
    generation: u64,
    trap: TrapDetector,
    /// Traps seen since the last edit.
    traps: u32,
    steering_wanted: bool,
    /// A trap asked for steering: it outlives later edits.
    trap_steered: bool,
    /// The obstacles and task planned round, and whether an edit changed them since the last
    /// plan came back.
    layout: Layout,
    layout_edited: bool,
    pub blocked: Option<BlockedState>,
    pub plan: Option<PlanInfo>,
    planner_error: Option<String>,
    /// Requests not yet taken by the loop's channel (retried on the next poll).
    send_steer: Option<Option<Steering>>,
    send_hold: Option<bool>,
    /// What the loop was last sent.
    steering: bool,
    following: Option<Steering>,
    detour: Option<(f64, f64)>,
    holding: bool,
    /// Times the daemon became blocked, and the first reason.
    pub entered: u64,
    pub first: Option<String>,
    /// `mu = "auto"`: the steering onto the model's cycle, which any planner steering ends.
    pub target: Targeting,
}

impl Deadlock {
    /// Starts the planner for an arm that has one (not the planar floating base, nor other
    /// planar link counts) and plans the start.
    pub fn new(system: &System, loop_core: Option<usize>) -> Self {
        let planner = has_planner(system)
            .then(|| {
                crate::planner::spawn(loop_core)
                    .map_err(|e| tracing::warn!("cannot start the cycle planner: {e}"))
                    .ok()
            })
            .flatten();
        let steering_wanted = plan_asked(system).0;
        let mut d = Self {
            planner,
            generation: 0,
            trap: TrapDetector::starting(&system.safety()),
            traps: 0,
            steering_wanted,
            trap_steered: false,
            layout: Layout::of(system),
            layout_edited: false,
            blocked: None,
            plan: None,
            planner_error: None,
            send_steer: None,
            send_hold: None,
            steering: false,
            following: None,
            detour: None,
            holding: false,
            entered: 0,
            first: None,
            target: Targeting::default(),
        };
        let q0 =
            control::with_dof!(system.n(), N => system.initial_state::<N>().q.as_slice().to_vec());
        d.submit(system, Why::Start, 0.0, Some(q0));
        d
    }

    fn submit(&mut self, system: &System, why: Why, t0: f64, q_now: Option<Vec<f64>>) {
        let Some(p) = &self.planner else {
            return;
        };
        if system.safety().enabled {
            p.submit(Job {
                generation: self.generation,
                why,
                system: system.clone(),
                t0,
                q_now,
                following: self.following,
            });
        }
    }

    /// A committed change: plan it; an arm without a planner is unblocked (a trap that
    /// remains is seen again after `trap_time`).
    pub fn edited(&mut self, system: &System, t: f64, q_now: Option<Vec<f64>>) {
        self.generation += 1;
        // The model's cycle was the set-up's before the edit: its own comes with its gain.
        self.target.edited();
        if self.target.active() {
            self.target.end(t, Ended::Edited);
            self.send_steer = Some(None);
        }
        let layout = Layout::of(system);
        // Until a plan for it comes back: a μ edit right after an obstacle edit drops the
        // obstacle's plan (stale), and its own plan is then the one for the new layout.
        self.layout_edited |= layout != self.layout;
        self.layout = layout;
        // `set safety.plan on|off` steers, or stops; a trap's steering stays.
        self.steering_wanted = plan_asked(system).0 || self.trap_steered;
        self.trap.settle_from(t, &system.safety());
        self.traps = 0;
        let plans = self.planner.is_some() && system.safety().enabled;
        if plans {
            self.submit(system, Why::Edit, t, q_now);
        } else {
            if self.steering {
                self.send_steer = Some(None);
            }
            self.unblock(t, "the edit");
        }
    }

    /// One tick record: watches for a trap while the law runs.
    pub fn observe(&mut self, r: &TickRecord, system: &System) {
        if r.ran_law
            && self
                .target
                .observe(r.t, r.period_residual, r.feedback_active)
        {
            self.send_steer = Some(None);
        }
        let s = system.safety();
        // A hold or a stalled tick knocks the arm on its own (a loaded machine: holds and 20-50
        // ms stalls, the filter then acting on the way back): not a recurring trap.
        if r.mode != protocol::Mode::Run || r.lateness_ns > STALL_NS {
            self.trap.disturbed(r.t, &s);
        }
        if !r.ran_law || r.mode != protocol::Mode::Run {
            return;
        }
        if !s.enabled || self.blocked.is_some() {
            return;
        }
        // A detour pauses tracking by design: the watch starts afresh when it hands over.
        let Some(trap) = self.trap.observe(r.t, r.law_flags, r.tracking_error, &s) else {
            return;
        };
        self.traps += 1;
        let q_now = r.state.map(|st| st.q[..system.n()].to_vec());
        let plans = self.planner.is_some() && self.planner_error.is_none();
        if plans && self.traps == 1 {
            tracing::warn!(
                "trapped at t = {:.3} s ({}): planning a clean cycle from the arm's posture",
                r.t,
                trap.words(s.trap_time)
            );
            self.steering_wanted = true;
            self.trap_steered = true;
            self.submit(system, Why::Trap, r.t, q_now);
            return;
        }
        let reason = if plans {
            format!(
                "trapped: steering onto the planned clean cycle did not get the arm round ({}); \
                 edit the obstacles or the task",
                trap.words(s.trap_time)
            )
        } else {
            format!(
                "trapped: {}, and this arm has no cycle planner to find a way round; edit the \
                 obstacles or the task",
                trap.words(s.trap_time)
            )
        };
        self.block(
            r.t,
            BlockedState {
                reason,
                since: r.t,
                action: s.when_blocked,
                best_clearance: r.clearance.is_finite().then_some(r.clearance),
                obstacle: None,
                link: None,
            },
        );
    }

    /// Takes what the planner finished and sends the loop what changed (never blocks).
    pub fn poll(
        &mut self,
        system: &System,
        t: f64,
        tx: &Sender<LoopRequest>,
        replay: Option<&mut ReplayLog>,
    ) {
        while let Some(done) = self.planner.as_ref().and_then(Planner::try_done) {
            self.take(done, system, t);
        }
        self.flush(tx, replay);
    }

    fn take(&mut self, done: Done, system: &System, t: f64) {
        if done.generation != self.generation {
            return; // an edit came after it: its own plan is on the way
        }
        let layout_edited = std::mem::take(&mut self.layout_edited);
        let planned = match done.result {
            Ok(p) => p,
            Err(e) => {
                if self.planner_error.is_none() {
                    tracing::warn!("the cycle planner cannot plan for this set-up: {e}");
                }
                self.planner_error = Some(e.to_string());
                return;
            }
        };
        let took_ms = done.took.as_secs_f64() * 1e3;
        match planned.outcome {
            PlanOutcome::Found(c) => {
                self.plan = Some(PlanInfo {
                    generation: done.generation,
                    why: done.why,
                    found: true,
                    took_ms,
                    min_clearance: c.min_clearance.is_finite().then_some(c.min_clearance),
                    limits_only: planned.limits_only,
                });
                self.unblock(t, "a clean cycle exists");
                let wanted =
                    self.steering_wanted || self.detour_forced(&c, done.why, layout_edited);
                match steering_of(system, &c) {
                    Ok(steer) if wanted => {
                        self.target.end(t, Ended::Planner);
                        if let Some(d) = &c.detour {
                            tracing::warn!(
                                "taking a joint-space detour onto the planned cycle: tracking \
                                 paused for {:.2} s ({})",
                                d.t_arrive - d.t_start,
                                c.unreachable.as_ref().map_or("", |b| b.reason.as_str())
                            );
                        }
                        self.send_steer = Some(Some(steer));
                    }
                    Ok(_) => {
                        if self.steering && !self.target.active() {
                            self.send_steer = Some(None);
                        }
                    }
                    Err(e) => tracing::warn!("cannot hand the planned cycle to the loop: {e}"),
                }
            }
            PlanOutcome::Blocked(b) => {
                self.target.end(t, Ended::Planner);
                self.plan = Some(PlanInfo {
                    generation: done.generation,
                    why: done.why,
                    found: false,
                    took_ms,
                    min_clearance: None,
                    limits_only: planned.limits_only,
                });
                if self.steering {
                    self.send_steer = Some(None);
                }
                let action = system.safety().when_blocked;
                self.block(
                    t,
                    BlockedState {
                        reason: format!("no clean cycle the arm can follow: {}", b.reason),
                        since: t,
                        action,
                        best_clearance: b.best_clearance.is_finite().then_some(b.best_clearance),
                        obstacle: b.obstacle.map(|o| o + 1),
                        link: b.link.map(|l| l + 1),
                    },
                );
            }
        }
    }

    fn block(&mut self, t: f64, state: BlockedState) {
        let what = match state.action {
            WhenBlocked::Hold => "holding the posture, tracking paused",
            WhenBlocked::BestEffort => "running on best-effort",
        };
        tracing::warn!("BLOCKED at t = {t:.3} s: {} ({what})", state.reason);
        self.entered += 1;
        self.first
            .get_or_insert_with(|| format!("at t = {t:.3} s: {}", state.reason));
        if state.action == WhenBlocked::Hold {
            self.send_hold = Some(true);
        }
        self.blocked = Some(state);
    }

    fn unblock(&mut self, t: f64, why: &str) {
        if let Some(b) = self.blocked.take() {
            tracing::info!(
                "no longer blocked at t = {t:.3} s ({why}; blocked for {:.1} s)",
                t - b.since
            );
            self.trap.afresh();
        }
        if self.holding || self.send_hold == Some(true) {
            self.send_hold = Some(false);
        }
    }

    /// A detour is the only way out for an arm on its path that an obstacle keeps from every
    /// clean cycle: it is taken whether or not steering was asked for, at start, after a trap,
    /// or when an edit moved the obstacles or the task. Not for an arm off its path (a start's
    /// transient: a trap after it plans again), nor without obstacles, nor after an edit of the
    /// law alone: near a fold of its self-motion the grid can miss a way the arm has within the
    /// rate bound, and an arm no obstacle was put in the way of is not trapped.
    fn detour_forced(&self, c: &control::steer::Cycle, why: Why, layout_edited: bool) -> bool {
        c.detour.is_some()
            && !c.arm_off_path
            && self.layout.obstacles.is_some()
            && (why != Why::Edit || layout_edited)
    }

    /// Sends what the loop has not been sent yet; a full channel is retried on the next poll.
    fn flush(&mut self, tx: &Sender<LoopRequest>, replay: Option<&mut ReplayLog>) {
        if let Some(s) = self.send_steer {
            if tx.try_send(LoopRequest::Steer(s)).is_ok() {
                if let Some(log) = replay {
                    log.steered(s.as_ref());
                }
                let planar = s.and_then(|s| match s {
                    Steering::Planar(p) => Some(p),
                    Steering::Spatial(_) => None,
                });
                self.steering = s.is_some();
                // The planner plans from the cycle it steers onto, not from the model's.
                self.following = s.filter(|_| !self.target.active());
                self.detour = planar
                    .and_then(|s| s.detour)
                    .map(|d| (d.t_start, d.t_arrive));
                self.send_steer = None;
            }
        }
        if let Some(h) = self.send_hold {
            if h == self.holding {
                self.send_hold = None;
            } else if tx.try_send(LoopRequest::BlockedHold(h)).is_ok() {
                self.holding = h;
                self.send_hold = None;
            }
        }
    }

    /// `mu = "auto"`: steers the arm onto the model's cycle (its gain was just handed to the
    /// loop at controller time `now`), unless a planner's steering has the arm, wants it, or
    /// the daemon is blocked.
    pub fn target(&mut self, target: &Target, now: f64, period: f64) {
        let planner_has_it = self.steering && !self.target.active();
        if self.steering_wanted || planner_has_it || self.blocked.is_some() {
            return;
        }
        self.send_steer = Some(Some(target.steering));
        self.target.start(target, now, period);
    }

    /// The loop is steering onto a planned cycle.
    pub fn steering(&self) -> bool {
        self.steering
    }

    /// `status`'s `plan` field.
    pub fn plan_json(&self) -> serde_json::Value {
        serde_json::json!({
            "planner": self.planner.is_some(),
            "error": self.planner_error,
            "steering": self.steering,
            // The joint-space detour the loop was last sent, tracking paused from start to
            // arrive (controller time, s).
            "detour": self.detour.map(|(start, arrive)| serde_json::json!({
                "start": start, "arrive": arrive,
            })),
            "newest": self.plan.as_ref().map(|p| serde_json::json!({
                "generation": p.generation,
                "why": format!("{:?}", p.why).to_lowercase(),
                "found": p.found,
                "took_ms": p.took_ms,
                "min_clearance": p.min_clearance,
                "limits_only": p.limits_only,
            })),
        })
    }

    /// The wire code of the blocked state (`TelemetrySample::blocked`).
    pub fn code(&self) -> u32 {
        self.blocked.as_ref().map_or(0, |b| b.action.code())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Edits `d` to each of `systems` in turn, at once, at task time `t` with the arm at `q`,
    /// and takes the plan; returns whether the loop was sent a steering table.
    fn steered_after_edits(d: &mut Deadlock, systems: &[System], t: f64, q: [f64; 3]) -> bool {
        let (tx, rx) = crossbeam::channel::bounded(16);
        for system in systems {
            d.edited(system, t, Some(q.to_vec()));
        }
        let system = systems.last().expect("an edit");
        for _ in 0..2000 {
            d.poll(system, t, &tx, None);
            if d.plan
                .as_ref()
                .is_some_and(|p| p.generation == d.generation)
            {
                return rx
                    .try_iter()
                    .any(|r| matches!(r, LoopRequest::Steer(Some(_))));
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        panic!("the planner did not answer in 10 s");
    }

    #[test]
    fn only_an_edit_of_the_obstacles_or_the_task_forces_a_detour() {
        // A posture of the default arm's chaotic self-motion (at t = 4.5 s) from which the grid
        // links no cycle within its rate bound: the planner offers a detour, though no
        // obstacle is in the way.
        let (t, q) = (
            4.5,
            [0.6390814869980641, 0.37407687103733667, 1.5400306742489358],
        );
        let mut cfg = control::Config::default();
        // Steering not asked for: only a forced detour steers.
        cfg.safety.plan = control::safety::policy::PlanMode::Off;
        let offered = |cfg: &control::Config| {
            let planned = control::plan::plan_config(cfg, t, Some(q)).unwrap();
            let PlanOutcome::Found(c) = planned.outcome else {
                panic!("no cycle");
            };
            c.detour.is_some() && !c.arm_off_path
        };
        assert!(offered(&cfg), "the case is gone");
        let mut d = Deadlock::new(&System::Planar(cfg.clone()), None);
        let open = System::Planar(cfg.clone());
        cfg.feedback.mu = 0.3;
        let mu = System::Planar(cfg.clone());
        assert!(!steered_after_edits(&mut d, &[mu], t, q));
        // An obstacle added (out of the arm's way: the grid's answer is the same): the edit
        // moved the layout, so the daemon cannot tell the arm is free, and takes the detour.
        cfg.planar_mut()
            .unwrap()
            .obstacles
            .push(control::config::ObstacleConfig::disc(-1.5, -1.5, 0.1));
        assert!(offered(&cfg), "the case is gone");
        let with_obstacle = System::Planar(cfg.clone());
        assert!(steered_after_edits(
            &mut d,
            std::slice::from_ref(&with_obstacle),
            t,
            q
        ));
        // A law edit with the obstacle in place: not forced again.
        cfg.feedback.mu = 0.1;
        let mu_again = System::Planar(cfg.clone());
        assert!(!steered_after_edits(
            &mut d,
            std::slice::from_ref(&mu_again),
            t,
            q
        ));
        // An obstacle edit at once followed by a law edit: the first plan is dropped as stale,
        // and the second one is still made for a new layout.
        let d = &mut Deadlock::new(&open, None);
        assert!(steered_after_edits(d, &[with_obstacle, mu_again], t, q));
    }

    #[test]
    fn by_default_an_obstacle_starts_the_steering_and_removing_the_last_one_ends_it() {
        // The paper's arm on its circle, well inside its rate bound.
        let mut cfg = control::Config::default();
        let q = [0.2, 1.3, 1.1];
        let free = System::Planar(cfg.clone());
        let mut d = Deadlock::new(&free, None);
        assert!(!steered_after_edits(
            &mut d,
            std::slice::from_ref(&free),
            0.0,
            q
        ));
        cfg.planar_mut()
            .unwrap()
            .obstacles
            .push(control::config::ObstacleConfig::disc(-1.5, -1.5, 0.1));
        let one = System::Planar(cfg.clone());
        assert!(steered_after_edits(
            &mut d,
            std::slice::from_ref(&one),
            0.0,
            q
        ));
        assert!(d.steering());
        let (tx, rx) = crossbeam::channel::bounded(16);
        d.edited(&free, 0.0, Some(q.to_vec()));
        for _ in 0..2000 {
            d.poll(&free, 0.0, &tx, None);
            if !d.steering() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        assert!(!d.steering(), "still steering without an obstacle");
        assert!(rx.try_iter().any(|r| matches!(r, LoopRequest::Steer(None))));
    }
}
