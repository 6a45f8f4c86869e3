//! What starts a cycle, and waiting for a sample to arrive.
//!
//! A free-running loop ([`Trigger::Clock`]) wakes on its own deadlines. A state-triggered one
//! ([`Trigger::State`]) runs when the peer's sample arrives, the way a device-clocked robot
//! interface (Franka FCI, KUKA RSI) works: the device sends its state, and the answer must come
//! back within the same cycle. [`poll_until`] is that wait, with the same three strategies as
//! [`crate::wait_until`], so the daemon and the plant wait for each other exactly alike.

use crate::gaps::GapMeter;
use crate::{monotonic_ns, WaitStrategy};
use serde::{Deserialize, Serialize};

/// What starts a cycle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Trigger {
    /// A fixed-rate loop on its own absolute deadlines.
    #[default]
    Clock,
    /// A cycle runs when a new state arrives; its answer goes out at once.
    State,
}

impl Trigger {
    pub fn name(self) -> &'static str {
        match self {
            Trigger::Clock => "clock",
            Trigger::State => "state",
        }
    }
}

impl std::str::FromStr for Trigger {
    type Err = crate::word::UnknownWord;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "clock" => Ok(Trigger::Clock),
            "state" => Ok(Trigger::State),
            _ => Err(crate::word::UnknownWord {
                value: s.to_string(),
                what: "a trigger",
                expected: "clock or state",
            }),
        }
    }
}

/// With [`WaitStrategy::Sleep`], how long each sleep between two polls lasts.
pub const SLEEP_POLL_NS: u64 = 20_000;

/// Polls `poll` until it yields a value or `deadline_ns` passes (then `None`).
///
/// `expected_ns` is when the value is expected. `Spin` polls throughout; `Hybrid` sleeps until
/// `spin_ns` before `expected_ns`, polls without sleeping until `spin_ns` after it, and from
/// then on (the value is overdue: a stalled or dead peer) polls every [`SLEEP_POLL_NS`], so a
/// missing peer does not cost a spinning core; `Sleep` sleeps until `expected_ns`, then polls
/// every [`SLEEP_POLL_NS`]. `poll` must not allocate; this function does not either.
///
/// ```
/// use rt::{monotonic_ns, trigger::poll_until, WaitStrategy};
/// let start = monotonic_ns();
/// let mut calls = 0;
/// // Ready on the third poll.
/// let got = poll_until(start, start + 1_000_000_000, WaitStrategy::Spin, 0, || {
///     calls += 1;
///     (calls == 3).then_some(42)
/// });
/// assert_eq!(got, Some(42));
/// // Never ready: gives up at the deadline.
/// let d = monotonic_ns() + 200_000;
/// assert_eq!(poll_until(d, d, WaitStrategy::Hybrid, 50_000, || None::<u8>), None);
/// assert!(monotonic_ns() >= d);
/// ```
#[inline]
pub fn poll_until<T>(
    expected_ns: u64,
    deadline_ns: u64,
    strategy: WaitStrategy,
    spin_ns: u64,
    poll: impl FnMut() -> Option<T>,
) -> Option<T> {
    poll_until_warm(expected_ns, deadline_ns, strategy, spin_ns, poll, || {})
}

/// When a wait polls without sleeping: from `from_ns` (inclusive) to `to_ns` (exclusive).
///
/// Before the window a wait sleeps (once, until it opens); inside it polls in a tight loop;
/// after it the value is overdue (a stalled or dead peer) and the wait goes back to sleeping
/// between polls, so a missing peer does not cost a spinning core.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    pub from_ns: u64,
    pub to_ns: u64,
}

impl Window {
    /// Always poll (a core given to the wait).
    pub const ALWAYS: Window = Window {
        from_ns: 0,
        to_ns: u64::MAX,
    };

    /// The window a strategy gives around `expected_ns`: `Spin` always polls, `Hybrid` polls
    /// within `spin_ns` either side of it, `Sleep` never (it sleeps until `expected_ns`, then
    /// between polls).
    ///
    /// ```
    /// use rt::{trigger::Window, WaitStrategy};
    /// let w = Window::around(WaitStrategy::Hybrid, 1_000_000, 50_000);
    /// assert_eq!((w.from_ns, w.to_ns), (950_000, 1_050_000));
    /// assert_eq!(Window::around(WaitStrategy::Spin, 7, 0), Window::ALWAYS);
    /// assert!(Window::around(WaitStrategy::Sleep, 7, 50).is_empty());
    /// ```
    pub fn around(strategy: WaitStrategy, expected_ns: u64, spin_ns: u64) -> Window {
        match strategy {
            WaitStrategy::Spin => Window::ALWAYS,
            WaitStrategy::Hybrid => Window {
                from_ns: expected_ns.saturating_sub(spin_ns),
                to_ns: expected_ns.saturating_add(spin_ns),
            },
            WaitStrategy::Sleep => Window {
                from_ns: expected_ns,
                to_ns: expected_ns,
            },
        }
    }

    /// The same window, kept open until at least `to_ns` (a non-empty window only: `Sleep`
    /// stays a sleeping wait).
    pub fn open_until(self, to_ns: u64) -> Window {
        if self.is_empty() {
            return self;
        }
        Window {
            to_ns: self.to_ns.max(to_ns),
            ..self
        }
    }

    pub fn is_empty(&self) -> bool {
        self.from_ns >= self.to_ns
    }
}

/// [`poll_until`], calling `warm` after each sleep that `poll` finds nothing after.
///
/// Why: a core that slept has lost the waiting code's caches, and the first use after a wake-up
/// costs several times a warm one. `warm` is where the caller rehearses what it will do with the
/// value (the daemon runs its law on the previous state), so that the real work runs warm.
/// `Spin` never sleeps and so never calls it. `warm` must not allocate either.
#[inline]
pub fn poll_until_warm<T>(
    expected_ns: u64,
    deadline_ns: u64,
    strategy: WaitStrategy,
    spin_ns: u64,
    poll: impl FnMut() -> Option<T>,
    warm: impl FnMut(),
) -> Option<T> {
    let window = Window::around(strategy, expected_ns, spin_ns);
    poll_within(window, deadline_ns, poll, warm)
}

/// Polls `poll` until it yields or `deadline_ns` passes: sleeping until `window` opens, polling
/// without sleeping inside it, and every [`SLEEP_POLL_NS`] after it; `warm` runs after each
/// sleep that `poll` finds nothing after (see [`poll_until_warm`]). Allocates nothing.
#[inline]
pub fn poll_within<T>(
    window: Window,
    deadline_ns: u64,
    poll: impl FnMut() -> Option<T>,
    warm: impl FnMut(),
) -> Option<T> {
    poll_within_metered(window, deadline_ns, &mut GapMeter::default(), poll, warm)
}

/// [`poll_within`], counting in `meter` the stretches its core was taken while it polled
/// without sleeping, and how late each sleep ended (see [`crate::gaps`]). The meter's run goes on
/// from the caller's last read before the call, and is still open on return: the caller's next
/// read through the meter (`GapMeter::read_at`) counts a stretch that ended inside the successful
/// poll, without a clock read on the path.
#[inline]
pub fn poll_within_metered<T>(
    window: Window,
    deadline_ns: u64,
    meter: &mut GapMeter,
    mut poll: impl FnMut() -> Option<T>,
    mut warm: impl FnMut(),
) -> Option<T> {
    if let Some(v) = poll() {
        return Some(v);
    }
    let wake = window.from_ns.min(deadline_ns);
    // Through the meter: the stretch since the caller's last read ends here, not in the sleep.
    let mut slept = wake > meter.read();
    if slept {
        nap(meter, wake);
    }
    loop {
        if let Some(v) = poll() {
            return Some(v);
        }
        if slept {
            slept = false;
            warm();
            continue;
        }
        let now = meter.read();
        if now >= deadline_ns {
            return None;
        }
        if now >= window.to_ns {
            nap(meter, (now + SLEEP_POLL_NS).min(deadline_ns));
            slept = true;
        } else {
            core::hint::spin_loop();
        }
    }
}

/// A sleep the wait takes on purpose: not a stretch without the core, but counted if it ends late.
#[inline]
fn nap(meter: &mut GapMeter, until_ns: u64) {
    meter.forget();
    crate::clock::sleep_until(until_ns);
    meter.woke(until_ns, monotonic_ns());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_strategy_returns_at_the_deadline_or_with_the_value() {
        for w in WaitStrategy::ALL {
            let d = monotonic_ns() + 300_000;
            assert_eq!(poll_until(d - 100_000, d, w, 50_000, || None::<()>), None);
            assert!(monotonic_ns() >= d, "{w:?} gave up early");
            let ready = monotonic_ns() + 200_000;
            let got = poll_until(ready, ready + 1_000_000_000, w, 50_000, || {
                (monotonic_ns() >= ready).then_some(())
            });
            assert_eq!(got, Some(()), "{w:?}");
        }
        assert_eq!("state".parse::<Trigger>(), Ok(Trigger::State));
        assert!("tick"
            .parse::<Trigger>()
            .unwrap_err()
            .to_string()
            .contains("clock or state"));
    }

    #[test]
    fn a_window_kept_open_polls_until_the_value_comes() {
        // The value comes 50 ms after the hybrid window (±50 µs) closed. Kept open, the wait
        // spins until then: at most the one sleep before the window, so at most one rehearsal.
        // Not kept open, it sleeps between polls, rehearsing after each sleep.
        let run = |keep_open: bool| {
            let t = monotonic_ns() + 200_000;
            let ready = t + 50_000_000;
            let mut w = Window::around(WaitStrategy::Hybrid, t, 50_000);
            if keep_open {
                w = w.open_until(ready + 1_000_000);
            }
            let mut warmed = 0;
            let got = poll_within(
                w,
                ready + 1_000_000_000,
                || (monotonic_ns() >= ready).then_some(()),
                || warmed += 1,
            );
            assert_eq!(got, Some(()));
            warmed
        };
        assert!(run(true) <= 1);
        assert!(run(false) >= 2);
        let sleep = Window::around(WaitStrategy::Sleep, 7, 50_000);
        assert_eq!(sleep.open_until(u64::MAX), sleep);
    }

    #[test]
    fn the_meter_counts_polls_that_lost_the_core_and_never_sleeps() {
        // The successful poll keeps the core for 300 µs, as a host stall at that moment would:
        // the wait returns with its run open, and the caller's close counts the stretch.
        let mut m = GapMeter::default();
        let mut n = 0;
        let got = poll_within_metered(
            Window::ALWAYS,
            monotonic_ns() + 1_000_000_000,
            &mut m,
            || {
                n += 1;
                if n < 200 {
                    return None;
                }
                let t = monotonic_ns();
                while monotonic_ns() < t + 300_000 {}
                Some(())
            },
            || {},
        );
        m.close_at(monotonic_ns());
        assert_eq!(got, Some(()));
        assert!(
            m.gaps.count >= 1 && m.gaps.max_ns >= 300_000,
            "{:?}",
            m.gaps
        );
        // A sleeping wait: 5 ms of sleeps between polls, none of them a gap.
        let mut m = GapMeter::default();
        let now = monotonic_ns();
        let w = Window::around(WaitStrategy::Sleep, now, 0);
        let got = poll_within_metered(w, now + 5_000_000, &mut m, || None::<()>, || {});
        m.close_at(monotonic_ns());
        assert_eq!(got, None);
        assert!(m.gaps.total_ns < 2_000_000, "sleeps counted: {:?}", m.gaps);
    }

    #[test]
    fn a_stretch_before_the_first_sleep_is_counted_not_forgotten() {
        // The caller's last read was 300 µs ago (a stall after it); the wait then sleeps until
        // its window opens. The stretch ends at the wait's first read, before the sleep.
        let mut m = GapMeter::default();
        let now = monotonic_ns();
        m.read_at(now - 300_000);
        let w = Window::around(WaitStrategy::Hybrid, now + 2_000_000, 50_000);
        let got = poll_within_metered(w, now + 2_000_000, &mut m, || None::<()>, || {});
        assert_eq!(got, None);
        assert!(m.gaps.max_ns >= 300_000, "{:?}", m.gaps);
    }

    #[test]
    fn warm_runs_after_each_sleep_and_never_while_spinning() {
        let mut warmed = 0;
        let d = monotonic_ns() + 300_000;
        let got = poll_until_warm(
            d,
            d,
            WaitStrategy::Hybrid,
            50_000,
            || None::<()>,
            || warmed += 1,
        );
        assert_eq!(got, None);
        // At most the one sleep before the spin window (none if this thread was preempted past
        // it); never a rehearsal while spinning.
        assert!(warmed <= 1, "{warmed}");
        let mut warmed = 0;
        let d = monotonic_ns() + 200_000;
        poll_until_warm(d, d, WaitStrategy::Spin, 0, || None::<()>, || warmed += 1);
        assert_eq!(warmed, 0);
        // A value already there: no sleep, no rehearsal.
        let mut warmed = 0;
        let far = monotonic_ns() + 1_000_000_000;
        let got = poll_until_warm(
            far,
            far,
            WaitStrategy::Hybrid,
            0,
            || Some(1),
            || warmed += 1,
        );
        assert_eq!((got, warmed), (Some(1), 0));
    }
}
