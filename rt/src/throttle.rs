//! The kernel's real-time throttling, and the loops it would stop.
//!
//! Why: by default Linux lets SCHED_FIFO threads use only `kernel.sched_rt_runtime_us` of every
//! `kernel.sched_rt_period_us` (950 ms of each second) on a CPU, and then stops them for the
//! rest. A loop that polls through its whole period at SCHED_FIFO (`wait = "spin"`, or a hybrid
//! window as long as the period) is stopped for 50 ms every second: at 10 kHz that is 500 cycles
//! in a row, every second (docs/performance.md, "RT throttling", has the measurement). The hybrid wait
//! sleeps part of each period, stays under the limit, and is not stopped.
//!
//! chaosd does not change this system-wide setting itself; it says so when a loop would be
//! stopped, and how to lift the limit.

use crate::WaitStrategy;

/// The RT bandwidth limit: `runtime_us` of every `period_us` (µs); `runtime_us < 0` = none.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RtLimit {
    pub runtime_us: i64,
    pub period_us: i64,
}

impl RtLimit {
    /// Reads `/proc/sys/kernel/sched_rt_{runtime,period}_us`; `None` if unreadable.
    pub fn read() -> Option<Self> {
        let get = |name: &str| std::fs::read_to_string(format!("/proc/sys/kernel/{name}")).ok();
        Self::parse(&get("sched_rt_runtime_us")?, &get("sched_rt_period_us")?)
    }

    /// The limit from the two files' text; `None` unless both are numbers.
    ///
    /// ```
    /// use rt::throttle::RtLimit;
    /// assert_eq!(
    ///     RtLimit::parse("950000\n", "1000000\n"),
    ///     Some(RtLimit { runtime_us: 950_000, period_us: 1_000_000 })
    /// );
    /// assert_eq!(RtLimit::parse("-1\n", "1000000\n").map(|l| l.is_off()), Some(true));
    /// assert_eq!(RtLimit::parse("", "1000000"), None);
    /// ```
    pub fn parse(runtime: &str, period: &str) -> Option<Self> {
        Some(Self {
            runtime_us: runtime.trim().parse().ok()?,
            period_us: period.trim().parse().ok()?,
        })
    }

    /// No limit: `-1`, or a runtime that fills the whole period (the kernel does not throttle
    /// then).
    pub fn is_off(&self) -> bool {
        self.runtime_us < 0 || self.period_us <= 0 || self.runtime_us >= self.period_us
    }

    /// Whether a SCHED_FIFO loop that polls `busy_share` of each period (0..=1) comes within
    /// [`RtLimit::MARGIN`] of the limit, and so is stopped once its ticks are added.
    ///
    /// ```
    /// use rt::throttle::RtLimit;
    /// let default = RtLimit { runtime_us: 950_000, period_us: 1_000_000 };
    /// assert!(default.stops(1.0));
    /// assert!(default.stops(0.92)); // with its ticks, past 95 %
    /// assert!(!default.stops(0.55)); // the hybrid wait at 10 kHz
    /// assert!(!RtLimit { runtime_us: -1, period_us: 1_000_000 }.stops(1.0));
    /// assert!(!RtLimit { runtime_us: 1_000_000, period_us: 1_000_000 }.stops(1.0));
    /// ```
    pub fn stops(&self, busy_share: f64) -> bool {
        !self.is_off()
            && busy_share + Self::MARGIN >= self.runtime_us as f64 / self.period_us as f64
    }

    /// The share of a period a loop's ticks and sleeps' wake-ups may add to its polling.
    pub const MARGIN: f64 = 0.05;

    /// "950000 of 1000000 µs", or "off".
    pub fn describe(&self) -> String {
        if self.is_off() {
            format!(
                "off (sched_rt_runtime_us = {} of {} µs)",
                self.runtime_us, self.period_us
            )
        } else {
            format!(
                "sched_rt_runtime_us = {} of {} µs",
                self.runtime_us, self.period_us
            )
        }
    }
}

/// The share of each period a loop with this wait polls without sleeping, at most: `Spin` all
/// of it, `Hybrid` its window before the expected time (`spin_ns`), `Sleep` none.
pub fn busy_share(wait: WaitStrategy, spin_ns: u64, period_ns: u64) -> f64 {
    match wait {
        WaitStrategy::Spin => 1.0,
        WaitStrategy::Hybrid => (spin_ns as f64 / period_ns.max(1) as f64).min(1.0),
        WaitStrategy::Sleep => 0.0,
    }
}

/// The warning for a SCHED_FIFO loop (`sched_fifo`) that `limit` would stop, if any.
pub fn warning(
    limit: Option<RtLimit>,
    sched_fifo: bool,
    wait: WaitStrategy,
    spin_ns: u64,
    period_ns: u64,
) -> Option<String> {
    let limit = limit?;
    if !sched_fifo || !limit.stops(busy_share(wait, spin_ns, period_ns)) {
        return None;
    }
    let stopped_ms = (limit.period_us - limit.runtime_us) as f64 / 1e3;
    Some(format!(
        "this loop polls through (nearly) its whole period at SCHED_FIFO, and the kernel's RT \
         throttling ({}) will stop it for {stopped_ms:.0} ms every {:.0} ms; lift it with \
         `sysctl kernel.sched_rt_runtime_us=-1`, or use the hybrid wait with spin_us well below \
         the period",
        limit.describe(),
        limit.period_us as f64 / 1e3
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_fifo_loops_that_poll_past_the_limit_are_warned() {
        let lim = Some(RtLimit {
            runtime_us: 950_000,
            period_us: 1_000_000,
        });
        let w = warning(lim, true, WaitStrategy::Spin, 0, 100_000).unwrap();
        assert!(w.contains("50 ms every 1000 ms"), "{w}");
        assert!(w.contains("sched_rt_runtime_us = 950000 of 1000000"), "{w}");
        // 10 kHz: a 100 µs window is the whole period; the default 50 µs is half of it.
        assert!(warning(lim, true, WaitStrategy::Hybrid, 100_000, 100_000).is_some());
        assert!(warning(lim, true, WaitStrategy::Hybrid, 50_000, 100_000).is_none());
        assert!(warning(lim, false, WaitStrategy::Spin, 0, 100_000).is_none());
        assert!(warning(lim, true, WaitStrategy::Sleep, 0, 100_000).is_none());
        assert!(warning(None, true, WaitStrategy::Spin, 0, 100_000).is_none());
        let off = RtLimit {
            runtime_us: -1,
            period_us: 1_000_000,
        };
        assert!(warning(Some(off), true, WaitStrategy::Spin, 0, 100_000).is_none());
        assert!(off.describe().starts_with("off"));
        // Within the margin of the limit: a 92 µs window at 10 kHz.
        assert!(warning(lim, true, WaitStrategy::Hybrid, 92_000, 100_000).is_some());
    }
}
