//! Telling a trap from a transient: the same watch in the daemon and in `chaosctl simulate`.
//!
//! A steady trap holds the arm off its path: tracking lost while the filter acts, or the
//! filter outside the null space, most of the time. [`TrapWatch`] sees it after `trap_time`.
//!
//! A recurring trap lets the arm go now and then: the posture swings past a sphere once round
//! the path, the filter leaves the null space for a few percent of the ticks of that period, and
//! the hand is off by millimetres to centimetres, never long enough, or far enough, for the first
//! watch (measured on the Panda beside two spheres: 1.5–35 % of the ticks of a period, errors
//! 1 mm–3 cm below `track_loss`, tracking clean again for up to 15 periods in between).
//! [`Recurrence`] counts the task periods in which the filter cost tracking; a host stall that
//! knocks the arm once does not add up to a trap.
//!
//! [`TrapDetector`] puts the two together with what rules a start's transient out (the filter
//! must have had a part in it). What to do about a trap (steer, or say `Blocked`) is the
//! caller's.

use crate::basics::flags;
use crate::system::SafetySummary;

/// How much of the recent past was trapped: a level that rises towards 1 on trapped ticks and
/// falls towards 0 on good ones, halving every `trap_time`. It crosses ½ after `trap_time` of
/// a steady trap, and also when the arm keeps slipping in and out of one (tracking regained
/// for a moment once round the circle is still a trap).
#[derive(Clone, Copy, Debug, Default)]
pub struct TrapWatch {
    level: f64,
    last_t: Option<f64>,
    fired: bool,
}

/// The level below which a trap that fired counts as over.
const TRAP_OVER: f64 = 0.1;

impl TrapWatch {
    /// One tick on which the law ran: true once per trap, when the level first reaches ½.
    pub fn observe(&mut self, t: f64, bad: bool, trap_time: f64) -> bool {
        let dt = self.last_t.map_or(0.0, |l| (t - l).max(0.0));
        self.last_t = Some(t);
        let keep = (-dt * std::f64::consts::LN_2 / trap_time).exp();
        self.level = keep * self.level + (1.0 - keep) * f64::from(u8::from(bad));
        if self.fired {
            self.fired = self.level >= TRAP_OVER;
            return false;
        }
        if self.level >= 0.5 {
            self.fired = true;
            return true;
        }
        false
    }

    /// Still inside a trap (or one building up).
    pub fn trapped(&self) -> bool {
        self.level > TRAP_OVER
    }
}

/// Task periods in which the filter must cost tracking before they make a recurring trap; two
/// next to each other count once (one graze across a period's end).
pub const RECUR_PERIODS: usize = 2;
/// ... within this many task periods, the newest included.
pub const RECUR_WINDOW: i64 = 16;
/// A period costs tracking when the filter left the null space in it and the hand was this far
/// off its path (m) after that: the live target for tracking after an edit.
pub const RECUR_ERROR: f64 = 1e-3;
/// One period in which the filter left the null space and the hand went this far off its path
/// (m) is a trap at once: a chaotic self-motion may graze an obstacle only every 10-20
/// periods, but each graze costs centimetres.
pub const SEVERE_ERROR: f64 = 1e-2;

/// The task periods, by index `⌊t / period⌋`, in which the filter cost tracking.
#[derive(Clone, Copy, Debug, Default)]
pub struct Recurrence {
    /// The newest counted periods, oldest first; `len` of them are valid.
    hits: [i64; RECUR_PERIODS],
    len: usize,
    /// The period in which the filter last left the null space.
    left_in: Option<i64>,
    /// It fired on one period's cost alone ([`SEVERE_ERROR`]).
    pub severe: bool,
    /// One costly period is not enough, however costly: the answer to a trap (a pull onto a
    /// new cycle from wherever the arm was) may graze once on its way.
    pub patient: bool,
}

impl Recurrence {
    /// One tick on which the law ran, at controller time `t` with the task's `period` (s):
    /// true when this tick makes the [`RECUR_PERIODS`]th costly period within
    /// [`RECUR_WINDOW`], or one period costs more than [`SEVERE_ERROR`]. The caller starts a
    /// new watch after it fires.
    ///
    /// ```
    /// use control::plan::trap::Recurrence;
    /// let mut r = Recurrence::default();
    /// // The filter leaves the null space once a period, and the hand is then 2 mm off.
    /// let fired = (0..10_000).map(|k| k as f64 * 1e-3).find(|&t| {
    ///     let left = t % 2.0 < 0.1;
    ///     r.observe(t, 2.0, left, if t % 2.0 < 0.3 { 2e-3 } else { 0.0 })
    /// });
    /// assert_eq!(fired, Some(4.0));
    /// ```
    pub fn observe(&mut self, t: f64, period: f64, left: bool, tracking_error: f64) -> bool {
        if !(t / period).is_finite() {
            return false;
        }
        let k = (t / period).floor() as i64;
        if left {
            self.left_in = Some(k);
        }
        let costly = self.left_in == Some(k) && tracking_error > RECUR_ERROR;
        if costly && tracking_error > SEVERE_ERROR && !self.patient {
            self.severe = true;
            return true;
        }
        if !costly || self.counted(k) {
            return false;
        }
        self.push(k);
        self.len == RECUR_PERIODS
    }

    /// How many costly periods lie within the window ending at the newest one.
    pub fn count(&self) -> usize {
        self.len
    }

    /// Period `k` is counted already, or is next to the newest counted one.
    fn counted(&self, k: i64) -> bool {
        self.len > 0 && k - self.hits[self.len - 1] <= 1
    }

    /// Adds period `k`, forgetting the periods that fell out of the window and, when full,
    /// the oldest.
    fn push(&mut self, k: i64) {
        let mut kept = [0; RECUR_PERIODS];
        let mut n = 0;
        for &h in self.hits[..self.len]
            .iter()
            .filter(|&&h| k - h < RECUR_WINDOW)
        {
            kept[n] = h;
            n += 1;
        }
        if n == RECUR_PERIODS {
            kept.rotate_left(1);
            n -= 1;
        }
        kept[n] = k;
        self.hits = kept;
        self.len = n + 1;
    }
}

/// Lost tracking is the filter's doing if the filter changed a command this recently (s).
pub const FILTER_RECENT_S: f64 = 1.0;

/// Which watch saw the trap.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrapKind {
    /// Tracking lost, or the filter outside the null space, for `trap_time`.
    Steady,
    /// The filter cost tracking in [`RECUR_PERIODS`] task periods out of [`RECUR_WINDOW`].
    Recurring,
    /// The filter cost more than [`SEVERE_ERROR`] of tracking in one task period.
    Severe,
}

/// A trap, with what was seen during it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trap {
    pub kind: TrapKind,
    /// The worst tracking error (m) while it built up.
    pub error: f64,
    /// The filter left the null space during it (else it held the arm).
    pub left_null_space: bool,
}

impl Trap {
    /// What happened, in words: `tracking error up to 0.210 m for 2 s, the safety filter
    /// holding the arm`.
    pub fn words(&self, trap_time: f64) -> String {
        if self.kind == TrapKind::Severe {
            return format!(
                "the safety filter left the null space and cost {:.3} m of tracking (more than \
                 {SEVERE_ERROR} m at once)",
                self.error
            );
        }
        if self.kind == TrapKind::Recurring {
            return format!(
                "the safety filter left the null space and cost more than {RECUR_ERROR} m of \
                 tracking in {RECUR_PERIODS} separate task periods out of {RECUR_WINDOW}, error \
                 up to {:.3} m",
                self.error
            );
        }
        let filter = if self.left_null_space {
            "the safety filter acting outside the null space"
        } else {
            "the safety filter holding the arm"
        };
        format!(
            "tracking error up to {:.3} m for {trap_time} s, {filter}",
            self.error
        )
    }
}

/// How long after a trap the recurrence is not counted: the steering's pull onto the new cycle
/// may graze on the way (seen offline: two grazes within 2.2 s of the answer on the Panda,
/// which then tracked to 1e-12 m).
pub fn settle_time(s: &SafetySummary) -> f64 {
    s.trap_time.max(SETTLE_PERIODS * s.task_period)
}

/// Task periods of [`settle_time`].
pub const SETTLE_PERIODS: f64 = 2.0;

/// Both watches, fed one tick at a time by whoever runs the law.
#[derive(Clone, Copy, Debug, Default)]
pub struct TrapDetector {
    trap: TrapWatch,
    recur: Recurrence,
    /// Controller time the filter last changed a command.
    filter_acted: Option<f64>,
    error: f64,
    left_null_space: bool,
    /// No recurrence is counted before this time (s): the answer to a trap, steering onto a new
    /// cycle, may graze on its way there.
    settle_until: f64,
}

impl TrapDetector {
    /// One tick on which the law ran, with its output's `law_flags` and tracking error, under
    /// the arm's safety settings: the trap, once, when a watch fires. The watches start
    /// afresh after it (the answer gets a watch of its own), and during a detour (tracking is
    /// paused by design).
    ///
    /// ```
    /// use control::basics::flags;
    /// use control::plan::trap::{TrapDetector, TrapKind};
    /// use control::System;
    /// let s = System::Planar(control::Config::default()).safety();
    /// let mut d = TrapDetector::default();
    /// // The filter acting, the hand 0.2 m off its path: trapped after `trap_time` (2 s).
    /// let trap = (0..3000)
    ///     .find_map(|k| d.observe(k as f64 * 1e-3, flags::SAFETY_ACTIVE, 0.2, &s))
    ///     .unwrap();
    /// assert_eq!(trap.kind, TrapKind::Steady);
    /// assert!(trap.words(s.trap_time).starts_with("tracking error up to 0.200 m for 2 s"));
    /// ```
    pub fn observe(
        &mut self,
        t: f64,
        law_flags: u32,
        tracking_error: f64,
        s: &SafetySummary,
    ) -> Option<Trap> {
        if law_flags & flags::DETOUR != 0 {
            *self = Self::default();
            return None;
        }
        // The filter's trap, not a start's transient: tracking lost while the filter acts (it
        // need not change every command to hold the arm off its path).
        if law_flags & flags::SAFETY_ACTIVE != 0 {
            self.filter_acted = Some(t);
        }
        let filter_near = self.filter_acted.is_some_and(|a| t - a <= FILTER_RECENT_S);
        let left = law_flags & flags::SAFETY_LEFT_NULL_SPACE != 0;
        let lost = tracking_error > s.track_loss && filter_near;
        let steady = self.trap.observe(t, lost || left, s.trap_time);
        let recurred =
            t >= self.settle_until && self.recur.observe(t, s.task_period, left, tracking_error);
        if lost || left || recurred || (filter_near && self.recur.count() > 0) {
            self.error = self.error.max(tracking_error);
            self.left_null_space |= left;
        }
        if !steady && !recurred {
            if !self.trap.trapped() && self.recur.count() == 0 {
                self.error = 0.0;
                self.left_null_space = false;
            }
            return None;
        }
        let trap = Trap {
            kind: if steady {
                TrapKind::Steady
            } else if self.recur.severe {
                TrapKind::Severe
            } else {
                TrapKind::Recurring
            },
            error: self.error,
            left_null_space: self.left_null_space,
        };
        self.afresh();
        self.recur.patient = true;
        self.settle_until = t + settle_time(s);
        Some(trap)
    }

    /// A watch from the start of a run at time 0: the recurrence is not counted for
    /// [`settle_time`], as a start inside the filter's margin is pushed out at a cost.
    pub fn starting(s: &SafetySummary) -> Self {
        Self {
            settle_until: settle_time(s),
            ..Self::default()
        }
    }

    /// Both watches start again, and the recurrence is not counted for [`settle_time`]: after
    /// an edit, whose plan the arm may be pulled onto.
    pub fn settle_from(&mut self, t: f64, s: &SafetySummary) {
        self.afresh();
        self.settle_until = t + settle_time(s);
    }

    /// Something other than the filter knocked the arm (a hold, a stalled tick): the periods
    /// counted so far are forgotten, and none is counted until the arm has had
    /// [`settle_time`] to recover. The steady watch goes on: a trap that holds the arm is
    /// still seen on a machine that stalls now and then.
    pub fn disturbed(&mut self, t: f64, s: &SafetySummary) {
        self.recur = Recurrence::default();
        self.settle_until = self.settle_until.max(t + settle_time(s));
    }

    /// Both watches start again (after a block that ended); the filter's last action is kept.
    pub fn afresh(&mut self) {
        self.trap = TrapWatch::default();
        self.recur = Recurrence::default();
        self.error = 0.0;
        self.left_null_space = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_trap_fires_once_after_trap_time_and_good_tracking_ends_it() {
        let dt = 0.001;
        let mut w = TrapWatch::default();
        let fired: Vec<usize> = (0..=4000)
            .filter(|&k| w.observe(k as f64 * dt, true, 2.0))
            .collect();
        assert_eq!(fired, vec![2000], "once, after 2 s of a steady trap");
        let (t, level) = (4.0, w.level);
        assert!((level - 0.75).abs() < 1e-3, "{level}");
        let over = (1..=20_000)
            .find(|&k| {
                w.observe(t + k as f64 * dt, false, 2.0);
                !w.fired
            })
            .unwrap();
        // From ¾ down to 0.1: log2(7.5) trap times.
        assert!(
            (over as f64 * dt - 2.0 * 7.5f64.log2()).abs() < 0.01,
            "{over}"
        );
    }

    #[test]
    fn slipping_in_and_out_of_a_trap_is_a_trap() {
        // Tracking regained for 1 s in every 6 s (the arm swinging past its path once round).
        let mut w = TrapWatch::default();
        let first = (0..30_000).find(|&k| {
            let t = k as f64 * 0.001;
            w.observe(t, t % 6.0 < 5.0, 2.0)
        });
        assert!(first.is_some_and(|k| k < 6000), "{first:?}");
    }

    /// Feeds `r` one costly tick (left, 2 mm off) in each of `periods` (period 2 s), and says
    /// which one fired.
    fn costly_in(r: &mut Recurrence, periods: &[i64]) -> Option<i64> {
        periods
            .iter()
            .copied()
            .find(|&k| r.observe(k as f64 * 2.0 + 0.5, 2.0, true, 2e-3))
    }

    #[test]
    fn the_second_separate_costly_period_within_the_window_fires() {
        // Every other period (a period-2 cycle that grazes a sphere once in two rounds).
        assert_eq!(costly_in(&mut Recurrence::default(), &[3, 5, 7]), Some(5));
        // Two within 16 periods, however spread.
        assert_eq!(costly_in(&mut Recurrence::default(), &[0, 15]), Some(15));
        // Next to each other: one graze across a period's end, not two.
        assert_eq!(costly_in(&mut Recurrence::default(), &[4, 5]), None);
        assert_eq!(costly_in(&mut Recurrence::default(), &[4, 5, 6]), Some(6));
        // Older ones fall out: 0 is 16 and more before 16.
        let mut r = Recurrence::default();
        assert_eq!(costly_in(&mut r, &[0, 16]), None);
        assert_eq!(r.count(), 1);
        assert_eq!(costly_in(&mut r, &[30]), Some(30));
    }

    #[test]
    fn a_period_counts_once_and_only_when_the_filter_cost_tracking() {
        let mut r = Recurrence::default();
        // Many costly ticks in one period are one period.
        for j in 0..1000 {
            assert!(!r.observe(j as f64 * 1e-3, 2.0, true, 5e-3));
        }
        assert_eq!(r.count(), 1);
        // The filter leaving the null space without costing 1 mm: not counted; nor an error
        // the filter had no part in (a start's transient, a host stall).
        assert!(!r.observe(2.5, 2.0, true, 5e-4));
        assert!(!r.observe(4.5, 2.0, false, 5e-2));
        assert_eq!(r.count(), 1);
        // The error after the filter left, later in the same period, counts (and fires).
        assert!(!r.observe(6.1, 2.0, true, 0.0));
        assert!(r.observe(6.4, 2.0, false, 3e-3));
        assert_eq!(r.count(), 2);
    }

    fn summary(task_period: f64) -> SafetySummary {
        let mut s = crate::system::System::Planar(crate::config::Config::default()).safety();
        s.task_period = task_period;
        s
    }

    #[test]
    fn one_graze_that_costs_centimetres_is_a_trap_at_once_but_not_at_the_start() {
        let s = summary(2.0);
        // The filter leaves the null space for 50 ms at 0.1 s and 10.1 s; the hand is 3 cm off
        // for 0.3 s each time (once only: the chaos grazes rarely).
        let run = |d: &mut TrapDetector| {
            (0..20_000).find_map(|k| {
                let t = k as f64 * 1e-3;
                let at = |t0: f64| (t0..t0 + 0.05).contains(&t);
                let f = if at(0.1) || at(10.1) {
                    flags::SAFETY_ACTIVE | flags::SAFETY_LEFT_NULL_SPACE
                } else {
                    0
                };
                let near = |t0: f64| (t0..t0 + 0.3).contains(&t);
                let e = if near(0.1) || near(10.1) { 3e-2 } else { 1e-9 };
                d.observe(t, f, e, &s).map(|trap| (t, trap))
            })
        };
        // From a start, the first one is the start's transient (a start inside the margin
        // pushed out): the second is the trap.
        let (t, trap) = run(&mut TrapDetector::starting(&s)).unwrap();
        assert!((10.1..10.2).contains(&t), "{t}");
        assert_eq!(trap.kind, TrapKind::Severe);
        assert!(
            trap.words(s.trap_time)
                .contains("cost 0.030 m of tracking (more than 0.01 m at once)"),
            "{}",
            trap.words(s.trap_time)
        );
        // A watch without the start's settling fires on the first; after that trap (its answer
        // may graze once on its way onto a new cycle) one graze is not enough.
        let mut d = TrapDetector::default();
        let (t, _) = run(&mut d).unwrap();
        assert!(t < 0.2, "{t}");
        assert!(run(&mut d).is_none());
        // An edit makes it quick again.
        d.settle_from(0.0, &s);
        assert!(run(&mut d).is_some_and(|(t, _)| t > 10.0));
        // Millimetres once are no trap.
        let mut r = Recurrence::default();
        assert!(!r.observe(0.1, 2.0, true, 9e-3));
        assert!(!r.severe);
    }

    #[test]
    fn a_start_far_from_the_path_is_no_trap_without_the_filter() {
        let s = summary(2.0);
        let mut d = TrapDetector::default();
        assert!((0..10_000).all(|k| d.observe(k as f64 * 1e-3, 0, 0.5, &s).is_none()));
    }

    #[test]
    fn a_recurring_trap_is_told_apart_and_said_in_words() {
        let s = summary(2.0);
        let mut d = TrapDetector::default();
        // Once a period the filter leaves the null space for 60 ms and the hand is 4 mm off.
        let tick = |t: f64| {
            let graze = t % 2.0 < 0.06;
            let f = if graze {
                flags::SAFETY_ACTIVE | flags::SAFETY_LEFT_NULL_SPACE
            } else {
                0
            };
            (f, if t % 2.0 < 0.3 { 4e-3 } else { 1e-9 })
        };
        let first_from = |d: &mut TrapDetector, k0: usize| {
            (k0..20_000).find_map(|k| {
                let t = k as f64 * 1e-3;
                let (f, e) = tick(t);
                d.observe(t, f, e, &s).map(|trap| (t, trap))
            })
        };
        let (t, trap) = first_from(&mut d, 0).unwrap();
        assert!((4.0..4.1).contains(&t), "{t}");
        assert_eq!(trap.kind, TrapKind::Recurring);
        assert!(trap.left_null_space);
        let words = trap.words(s.trap_time);
        assert!(
            words.contains("in 2 separate task periods out of 16, error up to 0.004 m"),
            "{words}"
        );
        // It starts afresh after firing, counting from the settle time on (4 s: two periods):
        // the grazes at 8 and 12 s (the one at 10 s lies next to the first).
        let (t, _) = first_from(&mut d, 4100).unwrap();
        assert!((12.0..12.1).contains(&t), "{t}");
        // A detour starts it afresh at once: 14 and 18 s.
        assert!(d.observe(12.5, flags::DETOUR, 0.3, &s).is_none());
        let (t, _) = first_from(&mut d, 12_600).unwrap();
        assert!((18.0..18.1).contains(&t), "{t}");
    }

    #[test]
    fn a_knock_between_two_grazes_is_not_the_filters_doing() {
        let s = summary(2.0);
        // Once a period the filter leaves the null space for 60 ms and the hand is 4 mm off.
        let first = |knock: Option<f64>| {
            let mut d = TrapDetector::default();
            (0..20_000).find_map(|k| {
                let t = k as f64 * 1e-3;
                if knock == Some(t) {
                    d.disturbed(t, &s); // a hold, or a tick 20 ms late
                }
                let graze = t % 2.0 < 0.06;
                let f = if graze {
                    flags::SAFETY_ACTIVE | flags::SAFETY_LEFT_NULL_SPACE
                } else {
                    0
                };
                let e = if graze { 4e-3 } else { 1e-9 };
                d.observe(t, f, e, &s).map(|_| t)
            })
        };
        assert_eq!(first(None), Some(4.0));
        // The graze at 0 s is forgotten, and none counts for 4 s: 8 and 12 s (10 s lies next
        // to 8 s).
        assert_eq!(first(Some(3.0)), Some(12.0));
    }

    #[test]
    fn a_nan_time_or_error_never_fires() {
        let mut r = Recurrence::default();
        for k in 0..40 {
            assert!(!r.observe(f64::NAN, 2.0, true, 1.0));
            assert!(!r.observe(k as f64 * 2.0, 2.0, true, f64::NAN));
        }
    }
}
