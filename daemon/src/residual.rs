//! The period residual before and after the feedback, in constant memory.
//!
//! The demo report compares the mean |q̇(t) − q̇(t − τ)| while the feedback was off with its mean
//! over the last 5 s with it on. A set-up whose feedback acts from the start (the `panda`
//! preset) has no "before": its report compares the first 5 s after the start-up transient
//! with the last 5 s. A daemon runs for months, so nothing here may grow with its
//! lifetime: whole seconds are folded into a running "before" sum as they complete, and only the
//! last few seconds with the feedback on are kept.

use std::collections::VecDeque;

/// Seconds with the feedback on that the "after" mean covers.
pub const AFTER_S: usize = 5;
/// Seconds at the start left out of the "before" mean (the start-up transient).
pub const SKIP_S: u64 = 2;

/// One second's sum of residuals.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Second {
    index: u64,
    resid: f64,
    n: u64,
    feedback: bool,
}

/// Accumulates residuals second by second.
#[derive(Debug)]
pub struct Residuals {
    cur: Option<Second>,
    before: (f64, u64),
    /// Seconds [`SKIP_S`] to [`SKIP_S`] + [`AFTER_S`], feedback or not.
    start: (f64, u64),
    last_on: VecDeque<Second>,
}

impl Default for Residuals {
    fn default() -> Self {
        Self {
            cur: None,
            before: (0.0, 0),
            start: (0.0, 0),
            last_on: VecDeque::with_capacity(AFTER_S + 1),
        }
    }
}

impl Residuals {
    /// Adds one tick's residual at controller time `t` (s, non-decreasing).
    pub fn add(&mut self, t: f64, resid: f64, feedback: bool) {
        let index = t.max(0.0) as u64;
        if self.cur.is_some_and(|c| c.index != index) {
            self.fold();
        }
        let c = self.cur.get_or_insert(Second {
            index,
            ..Second::default()
        });
        c.resid += resid;
        c.n += 1;
        c.feedback |= feedback;
    }

    /// Moves the current second into the running sums.
    fn fold(&mut self) {
        let Some(c) = self.cur.take() else { return };
        if (SKIP_S..SKIP_S + AFTER_S as u64).contains(&c.index) {
            self.start.0 += c.resid;
            self.start.1 += c.n;
        }
        if c.feedback {
            if self.last_on.len() == AFTER_S {
                self.last_on.pop_front();
            }
            self.last_on.push_back(c);
        } else if c.index >= SKIP_S {
            self.before.0 += c.resid;
            self.before.1 += c.n;
        }
    }

    /// (mean before the feedback, mean over the last [`AFTER_S`] s with it), the current
    /// second included.
    pub fn means(&self) -> (Option<f64>, Option<f64>) {
        let (before, _, after) = self.all_means();
        (before, after)
    }

    /// (before the feedback, the first [`AFTER_S`] s after the start-up transient, the last
    /// [`AFTER_S`] s with the feedback on).
    pub fn all_means(&self) -> (Option<f64>, Option<f64>, Option<f64>) {
        let mut copy = Self {
            cur: self.cur,
            before: self.before,
            start: self.start,
            last_on: self.last_on.clone(),
        };
        copy.fold();
        let mean = |(s, n): (f64, u64)| (n > 0).then(|| s / n as f64);
        let after = copy
            .last_on
            .iter()
            .fold((0.0, 0), |(s, n), c| (s + c.resid, n + c.n));
        (mean(copy.before), mean(copy.start), mean(after))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn means_match_the_definition_and_memory_stays_flat() {
        let mut r = Residuals::default();
        // 10 s off at residual 4, then a week on, falling to 0.05 in the last 5 s.
        let week = 7 * 86_400;
        for k in 0..(10 + week) * 10 {
            let t = k as f64 * 0.1;
            let on = t >= 10.0;
            let resid = if !on {
                4.0
            } else if t >= (10 + week - 5) as f64 {
                0.05
            } else {
                1.0
            };
            r.add(t, resid, on);
            assert!(r.last_on.len() <= AFTER_S);
        }
        let (b, a) = r.means();
        assert_eq!(b, Some(4.0));
        assert!((a.unwrap() - 0.05).abs() < 1e-12, "{a:?}");
        // Never switched on: no "after".
        let mut r = Residuals::default();
        for k in 0..100 {
            r.add(k as f64 * 0.1, 1.0, false);
        }
        assert_eq!(r.means(), (Some(1.0), None));
        // On from the start: no "before"; the start's mean covers seconds 2-7.
        let mut r = Residuals::default();
        for k in 0..200 {
            let t = k as f64 * 0.1;
            r.add(t, if t < 7.0 { 3.0 } else { 0.5 }, true);
        }
        assert_eq!(r.all_means(), (None, Some(3.0), Some(0.5)));
    }
}
