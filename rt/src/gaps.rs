//! Time a polling wait lost its core.
//!
//! Why: a state-triggered loop has no deadline of its own to be late for, so when its vCPU is
//! taken away while it waits (the host stalls it, an interrupt runs, something preempts it), the
//! only trace would be an answer the plant counts as late. A polling wait reads the clock every
//! few hundred nanoseconds, and a tick takes a few microseconds, so a stretch between two reads
//! much longer than that is time the loop did not run (or, rarely, one of its steps was slow).
//! Counting those stretches costs a subtraction per read, no system call, and tells an operator
//! whether late answers were the controller's doing or the machine's.
//!
//! The caller reads the clock through the meter at each step of its loop: each poll, and the end
//! of its tick. So every stretch of the loop is watched (its waits, the rehearsal after a sleep,
//! its bookkeeping after the send, a few microseconds each) except two: the tick itself, which
//! the caller times on its own so that a slow law never passes for a missing core, and the sleeps
//! the wait takes on purpose (the meter forgets its last read before each). A sleep that ends late
//! is counted apart ([`GapMeter::late_wakes`]), by how far past the time it asked for it woke.
//! On a VM that is tens of microseconds when nothing is wrong, and far more when the host does
//! not run the vCPU when its timer fires.

use crate::monotonic_ns;
use serde::{Deserialize, Serialize};

/// Stretches of at least [`GapMeter::MIN_NS`] between two clock reads of a loop (or, for
/// [`GapMeter::late_wakes`], sleeps that ended that late).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct Gaps {
    pub count: u64,
    pub total_ns: u64,
    pub max_ns: u64,
    /// How many were at least each of [`Gaps::BOUNDS_NS`] long and shorter than the next.
    pub by_length: [u64; 8],
}

impl Gaps {
    /// The lower bounds of `by_length`'s buckets: 10, 20, 50, 100, 200 and 500 µs, 1 and 2 ms.
    pub const BOUNDS_NS: [u64; 8] = [
        10_000, 20_000, 50_000, 100_000, 200_000, 500_000, 1_000_000, 2_000_000,
    ];

    /// Adds one stretch of `ns` (at least the first bound).
    pub fn add(&mut self, ns: u64) {
        self.count += 1;
        self.total_ns = self.total_ns.saturating_add(ns);
        self.max_ns = self.max_ns.max(ns);
        let b = Self::BOUNDS_NS
            .iter()
            .rposition(|&lo| ns >= lo)
            .unwrap_or(0);
        self.by_length[b] += 1;
    }

    /// The bound [`Gaps::at_least`] counts from for `ns`: the first of [`Gaps::BOUNDS_NS`] at or
    /// above it, or the last one (2 ms) for anything longer.
    ///
    /// ```
    /// use rt::gaps::Gaps;
    /// assert_eq!(Gaps::bound_for(50_000), 50_000); // half a period at 10 kHz
    /// assert_eq!(Gaps::bound_for(250_000), 500_000); // at 2 kHz
    /// assert_eq!(Gaps::bound_for(5_000_000), 2_000_000); // at 100 Hz
    /// ```
    pub fn bound_for(ns: u64) -> u64 {
        let last = Self::BOUNDS_NS[Self::BOUNDS_NS.len() - 1];
        Self::BOUNDS_NS
            .into_iter()
            .find(|&b| b >= ns)
            .unwrap_or(last)
    }

    /// How many were at least [`Gaps::bound_for`]`(ns)` long.
    pub fn at_least(&self, ns: u64) -> u64 {
        let bound = Self::bound_for(ns);
        let from = Self::BOUNDS_NS.partition_point(|&lo| lo < bound);
        self.by_length[from..].iter().sum()
    }
}

/// One line on a loop with period `period_ns`: its stretches without the core (`gaps`) and
/// how many of them, and of its late wake-ups (`late_wakes`), reached half a period (counted
/// from [`Gaps::bound_for`] it). The daemon's report and `chaosctl status` both print it.
///
/// ```
/// use rt::gaps::{describe, Gaps};
/// let mut g = Gaps::default();
/// g.add(900_000);
/// let line = describe(&g, &Gaps::default(), 1_000_000);
/// assert!(line.starts_with("1 stretches of ≥ 10 µs"), "{line}");
/// assert!(line.contains("1 of them, and 0 sleeps woke ≥ 500 µs late"), "{line}");
/// ```
pub fn describe(gaps: &Gaps, late_wakes: &Gaps, period_ns: u64) -> String {
    let half = period_ns / 2;
    let bound = Gaps::bound_for(half);
    format!(
        "{} stretches of ≥ 10 µs between two clock reads of the loop, outside its tick ({:.1} ms in all, longest {:.0} µs); {} of them, and {} sleeps woke ≥ {} µs late (half a period: {} µs; the latest woke {:.0} µs late)",
        gaps.count,
        gaps.total_ns as f64 / 1e6,
        gaps.max_ns as f64 / 1e3,
        gaps.at_least(bound),
        late_wakes.at_least(bound),
        bound / 1000,
        half / 1000,
        late_wakes.max_ns as f64 / 1e3,
    )
}

/// The clock reads of a polling wait, and the [`Gaps`] between them.
///
/// ```
/// use rt::gaps::GapMeter;
/// let mut m = GapMeter::default();
/// m.read_at(1_000);
/// m.read_at(1_400); // one poll: not a gap
/// m.read_at(251_400); // 250 µs without a read: the core was elsewhere
/// m.forget(); // the wait slept on purpose
/// m.read_at(900_000);
/// m.close_at(900_300);
/// assert_eq!((m.gaps.count, m.gaps.total_ns, m.gaps.max_ns), (1, 250_000, 250_000));
/// assert_eq!((m.gaps.at_least(200_000), m.gaps.at_least(500_000)), (1, 0));
/// ```
#[derive(Clone, Copy, Debug, Default)]
pub struct GapMeter {
    /// Stretches between two reads of a polling run.
    pub gaps: Gaps,
    /// Sleeps that ended at least [`GapMeter::MIN_NS`] after the time they asked for, by how
    /// much.
    pub late_wakes: Gaps,
    /// The last read of the current polling run; 0 when not polling.
    last_ns: u64,
}

impl GapMeter {
    /// The shortest stretch counted: far longer than one poll (well under 1 µs), and short
    /// enough to catch anything that costs a 10 kHz loop a good share of its answer window.
    pub const MIN_NS: u64 = Gaps::BOUNDS_NS[0];

    /// Reads the clock as the next poll of the current run, and returns the time.
    #[inline]
    pub fn read(&mut self) -> u64 {
        let now = monotonic_ns();
        self.read_at(now);
        now
    }

    /// [`GapMeter::read`] with a time the caller already read.
    #[inline]
    pub fn read_at(&mut self, now_ns: u64) {
        self.note(now_ns);
        self.last_ns = now_ns;
    }

    /// Ends the run at `now_ns`, the caller's first read after it; nothing counts until the next
    /// read opens another.
    #[inline]
    pub fn close_at(&mut self, now_ns: u64) {
        self.note(now_ns);
        self.last_ns = 0;
    }

    /// A sleep that asked to end at `asked_ns` ended at `now_ns`; a polling run starts there.
    ///
    /// ```
    /// use rt::gaps::GapMeter;
    /// let mut m = GapMeter::default();
    /// m.woke(1_000_000, 1_004_000); // 4 µs late: a normal wake-up
    /// m.woke(2_000_000, 2_900_000); // 900 µs late
    /// assert_eq!((m.late_wakes.count, m.late_wakes.max_ns, m.gaps.count), (1, 900_000, 0));
    /// ```
    #[inline]
    pub fn woke(&mut self, asked_ns: u64, now_ns: u64) {
        let d = now_ns.saturating_sub(asked_ns);
        if d >= Self::MIN_NS {
            self.late_wakes.add(d);
        }
        self.last_ns = now_ns;
    }

    /// Ends the polling run without counting anything since its last read (a sleep follows or
    /// came before).
    #[inline]
    pub fn forget(&mut self) {
        self.last_ns = 0;
    }

    #[inline]
    fn note(&mut self, now_ns: u64) {
        if self.last_ns == 0 {
            return;
        }
        let d = now_ns.saturating_sub(self.last_ns);
        if d >= Self::MIN_NS {
            self.gaps.add(d);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stretches_land_in_the_bucket_of_their_bound() {
        let mut g = Gaps::default();
        for ns in [10_000, 19_999, 20_000, 1_999_999, 2_000_000, u64::MAX] {
            g.add(ns);
        }
        assert_eq!(g.by_length, [2, 1, 0, 0, 0, 0, 1, 2]);
        assert_eq!((g.count, g.max_ns, g.total_ns), (6, u64::MAX, u64::MAX));
        assert_eq!(g.at_least(10_000), 6);
        assert_eq!(g.at_least(20_000), 4);
        // Between bounds: from the bound above. Past the last: from the last.
        assert_eq!(g.at_least(15_000), 4);
        assert_eq!(g.at_least(50_000_000), 2);
    }
}
