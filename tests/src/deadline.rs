//! Deadlines that a host stall pushes back.
//!
//! The live tests give the daemon a time to answer an edit ("tracking again within 5 s",
//! "Blocked within 1 s"). On a shared VM the host now and then takes a vCPU away for 10-30 ms,
//! from the loop or from the plant; the arm runs on its last command meanwhile, leaves its path
//! by millimetres, and needs about a second to settle again. That is physics, not a slow
//! daemon, so the time allowed counts from the later of the edit and the last stall the
//! daemon's own counters show (periods it overran, ticks without a fresh state), and never
//! runs past three times the time allowed, nor more than 30 s past it. On a quiet host it is
//! the plain deadline.

use std::time::{Duration, Instant};

/// Overruns or missing states between two reads, beyond twice the run's usual rate, that count
/// as a stall.
const STALL_TICKS: u64 = 3;

/// How far past the time allowed stalls may push the deadline: twice the time allowed, and
/// never more than [`MAX_EXTRA`] (a long wait already has room for a few stalls).
const MAX_STRETCH: u32 = 2;
const MAX_EXTRA: Duration = Duration::from_secs(30);

/// A deadline of `within`, restarted by host stalls (up to `within` + min(2 · `within`, 30 s)).
pub struct Deadline {
    start: Instant,
    from: Instant,
    within: Duration,
    seen: Option<(u64, Instant)>,
    /// The first count read, and when: the run's usual rate of missed ticks.
    first: Option<(u64, Instant)>,
    stalls: u32,
}

impl Deadline {
    pub fn new(within: Duration) -> Self {
        Self::starting(within, Instant::now())
    }

    fn starting(within: Duration, now: Instant) -> Self {
        Self {
            start: now,
            from: now,
            within,
            seen: None,
            first: None,
            stalls: 0,
        }
    }

    /// Reads the stall counters of a `status --json` answer (null while the daemon does not
    /// answer yet: no news).
    pub fn observe(&mut self, status: &serde_json::Value) {
        self.observe_at(status, Instant::now());
    }

    fn observe_at(&mut self, status: &serde_json::Value, at: Instant) {
        let Some(count) = missed_ticks(status) else {
            return;
        };
        let judged = self
            .seen
            .zip(self.first)
            .filter(|(seen, first)| seen.1 > first.1);
        if let Some(((before, then), (first, since))) = judged {
            // Some set-ups miss ticks steadily (a plant whose phase drifts against the loop's):
            // a stall is a burst well above the run's own rate.
            let rate = (before - first) as f64 / then.duration_since(since).as_secs_f64().max(1e-3);
            let usual = rate * at.duration_since(then).as_secs_f64();
            if count as f64 >= before as f64 + 2.0 * usual + STALL_TICKS as f64 {
                self.from = at;
                self.stalls += 1;
            }
        }
        self.first.get_or_insert((count, at));
        self.seen = Some((count, at));
    }

    /// The time counted against the deadline: since the start, or since the last stall.
    pub fn took(&self) -> Duration {
        self.from.elapsed()
    }

    pub fn passed(&self) -> bool {
        self.passed_at(Instant::now())
    }

    fn passed_at(&self, now: Instant) -> bool {
        let extra = (self.within * MAX_STRETCH).min(MAX_EXTRA);
        now.duration_since(self.from) > self.within
            || now.duration_since(self.start) > self.within + extra
    }

    /// Stalls seen so far, for a failure's message.
    pub fn stalls(&self) -> u32 {
        self.stalls
    }
}

/// Periods the daemon overran, plus its ticks without a fresh state.
fn missed_ticks(v: &serde_json::Value) -> Option<u64> {
    let c = &v["counters"];
    let n = |k: &str| c[k].as_u64();
    Some(n("overruns")? + n("ticks")?.saturating_sub(n("fresh_states")?))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn counters(overruns: u64, ticks: u64, fresh: u64) -> serde_json::Value {
        serde_json::json!({"counters": {"overruns": overruns, "ticks": ticks, "fresh_states": fresh}})
    }

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn a_stall_restarts_the_time_allowed_and_a_quiet_run_does_not() {
        let t0 = Instant::now();
        let mut d = Deadline::starting(80 * MS, t0);
        d.observe_at(&counters(0, 100, 100), t0);
        d.observe_at(&serde_json::Value::Null, t0 + 10 * MS);
        d.observe_at(&counters(1, 150, 149), t0 + 50 * MS); // one overrun, one state late
        assert_eq!((d.stalls(), d.from), (0, t0));
        d.observe_at(&counters(3, 200, 197), t0 + 60 * MS); // two overruns, two states missing
        assert_eq!((d.stalls(), d.from), (1, t0 + 60 * MS));
        assert!(
            !d.passed_at(t0 + 110 * MS),
            "50 ms after the stall, of 80 allowed"
        );
        assert!(d.passed_at(t0 + 150 * MS));
    }

    #[test]
    fn stalls_push_the_deadline_three_times_at_most() {
        let t0 = Instant::now();
        let mut d = Deadline::starting(30 * MS, t0);
        for k in 0..=12u32 {
            d.observe_at(
                &counters(100 * u64::from(k / 3), 1000, 1000),
                t0 + k * 10 * MS,
            );
        }
        assert_eq!((d.stalls(), d.from), (4, t0 + 120 * MS));
        assert!(!d.passed_at(t0 + 89 * MS));
        assert!(d.passed_at(t0 + 121 * MS), "past 3 × 30 ms");
    }

    #[test]
    fn a_long_wait_is_stretched_30_s_at_most() {
        let t0 = Instant::now();
        let mut d = Deadline::starting(Duration::from_secs(60), t0);
        d.observe_at(&counters(0, 1000, 1000), t0);
        d.observe_at(&counters(0, 1000, 1000), t0 + Duration::from_secs(1));
        d.observe_at(&counters(50, 1000, 1000), t0 + Duration::from_secs(80));
        assert_eq!(d.stalls(), 1);
        assert!(!d.passed_at(t0 + Duration::from_secs(89)));
        assert!(d.passed_at(t0 + Duration::from_secs(91)));
    }

    #[test]
    fn a_steady_rate_of_missed_ticks_is_no_stall() {
        let t0 = Instant::now();
        let mut d = Deadline::starting(Duration::from_secs(10), t0);
        for k in 0..10u32 {
            d.observe_at(
                &counters(0, 1000 + 100 * u64::from(k), 1000 + 90 * u64::from(k)),
                t0 + k * 10 * MS,
            );
        }
        assert_eq!(d.stalls(), 0);
    }
}
