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
//! The caller reads the clock through the meter at each step of its loop (the wait's polls, the
//! tick's start and end), so every stretch between two steps is watched. Only the sleeps the wait
//! takes on purpose are not: the meter forgets its last read before each. A sleep that ends late
//! is counted apart ([`GapMeter::late_wakes`]), by how far past the time it asked for it woke.
//! On a VM that is tens of microseconds when nothing is wrong, and far more when the host does
//! not run the vCPU when its timer fires.

use crate::monotonic_ns;
use serde::{Deserialize, Serialize};

/// Stretches of at least [`GapMeter::MIN_NS`] between two clock reads of a loop (or, for
/// [`GapMeter::late_wakes`], sleeps that ended that late).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
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

    /// How many were at least `ns` long (`ns` one of [`Gaps::BOUNDS_NS`], else the next bound
    /// above it).
    pub fn at_least(&self, ns: u64) -> u64 {
        let from = Self::BOUNDS_NS.partition_point(|&lo| lo < ns);
        self.by_length[from..].iter().sum()
    }
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

    /// Ends the polling run at `now_ns`, the caller's first read after it.
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
