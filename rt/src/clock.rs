//! Waiting for an absolute CLOCK_MONOTONIC deadline.
//!
//! Deadlines are absolute so that lateness never accumulates: each period's deadline is the
//! previous one plus the period, whatever happened in between. Three strategies trade CPU for
//! precision: `Sleep` hands the core back (wake-up lateness is the kernel's timer latency, tens of
//! µs here), `Spin` burns the core and wakes within the clock read's resolution, and `Hybrid`
//! sleeps until shortly before the deadline and spins the rest.

use crate::monotonic_ns;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WaitStrategy {
    Sleep,
    Hybrid,
    Spin,
}

impl WaitStrategy {
    pub const ALL: [WaitStrategy; 3] = [
        WaitStrategy::Sleep,
        WaitStrategy::Hybrid,
        WaitStrategy::Spin,
    ];

    pub fn name(self) -> &'static str {
        match self {
            WaitStrategy::Sleep => "sleep",
            WaitStrategy::Hybrid => "hybrid",
            WaitStrategy::Spin => "spin",
        }
    }
}

impl std::str::FromStr for WaitStrategy {
    type Err = crate::word::UnknownWord;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "sleep" => Ok(WaitStrategy::Sleep),
            "hybrid" => Ok(WaitStrategy::Hybrid),
            "spin" => Ok(WaitStrategy::Spin),
            _ => Err(crate::word::UnknownWord {
                value: s.to_string(),
                what: "a wait strategy",
                expected: "sleep, hybrid or spin",
            }),
        }
    }
}

/// Sleeps until the absolute CLOCK_MONOTONIC time `deadline_ns` (a no-op if it has passed).
pub fn sleep_until(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: `ts` is a valid timespec; a null remainder is allowed with TIMER_ABSTIME.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if rc != libc::EINTR {
            return;
        }
    }
}

/// Waits until `deadline_ns` with the given strategy; `spin_ns` is the hybrid's spin window.
/// Returns the wake-up time.
#[inline]
pub fn wait_until(deadline_ns: u64, strategy: WaitStrategy, spin_ns: u64) -> u64 {
    wait_until_warm(deadline_ns, strategy, spin_ns, || {})
}

/// [`wait_until`], calling `warm` once after the hybrid's sleep, before it spins (see
/// [`crate::trigger::poll_until_warm`] for why). `Sleep` wakes at the deadline and `Spin` never
/// sleeps, so neither calls it; nor does a hybrid whose deadline came during the sleep.
#[inline]
pub fn wait_until_warm(
    deadline_ns: u64,
    strategy: WaitStrategy,
    spin_ns: u64,
    warm: impl FnOnce(),
) -> u64 {
    match strategy {
        WaitStrategy::Sleep => sleep_until(deadline_ns),
        WaitStrategy::Hybrid => {
            if deadline_ns > spin_ns {
                sleep_until(deadline_ns - spin_ns);
            }
            if monotonic_ns() < deadline_ns {
                warm();
            }
            while monotonic_ns() < deadline_ns {
                core::hint::spin_loop();
            }
        }
        WaitStrategy::Spin => {
            while monotonic_ns() < deadline_ns {
                core::hint::spin_loop();
            }
        }
    }
    monotonic_ns()
}

/// The schedule of a fixed-rate loop: absolute deadlines, with missed periods skipped.
#[derive(Clone, Copy, Debug)]
pub struct Schedule {
    period_ns: u64,
    next_ns: u64,
    /// Periods skipped because the loop woke after the following deadline had already passed.
    pub overruns: u64,
}

impl Schedule {
    /// A schedule whose first deadline is one period from `start_ns`.
    pub fn new(period_ns: u64, start_ns: u64) -> Self {
        Self {
            period_ns,
            next_ns: start_ns + period_ns,
            overruns: 0,
        }
    }

    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }

    /// The next deadline.
    pub fn deadline(&self) -> u64 {
        self.next_ns
    }

    /// Moves the next deadline (a phase lock re-aligning the loop). Lateness stays measured
    /// against the moved deadline.
    pub fn set_deadline(&mut self, next_ns: u64) {
        self.next_ns = next_ns;
    }

    /// Advances past a tick that woke at `now_ns`. If whole periods were missed they are
    /// skipped (counted as overruns) rather than run back to back. Returns the periods skipped.
    pub fn advance(&mut self, now_ns: u64) -> u64 {
        self.next_ns += self.period_ns;
        if now_ns >= self.next_ns {
            let missed = (now_ns - self.next_ns) / self.period_ns + 1;
            self.next_ns += missed * self.period_ns;
            self.overruns += missed;
            return missed;
        }
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedule_skips_missed_periods() {
        let mut s = Schedule::new(1000, 0);
        assert_eq!(s.deadline(), 1000);
        assert_eq!(s.advance(1010), 0);
        assert_eq!(s.deadline(), 2000);
        // Woke 3.5 periods late: the deadlines at 3000, 4000 and 5000 have passed.
        assert_eq!(s.advance(5500), 3);
        assert_eq!(s.deadline(), 6000);
        assert_eq!(s.overruns, 3);
    }

    #[test]
    fn waits_reach_the_deadline() {
        for w in WaitStrategy::ALL {
            let d = monotonic_ns() + 200_000;
            let woke = wait_until(d, w, 50_000);
            assert!(woke >= d, "{w:?} woke early");
        }
        assert_eq!("hybrid".parse::<WaitStrategy>(), Ok(WaitStrategy::Hybrid));
        assert!("fast"
            .parse::<WaitStrategy>()
            .unwrap_err()
            .to_string()
            .contains("sleep, hybrid or spin"));
    }
}
