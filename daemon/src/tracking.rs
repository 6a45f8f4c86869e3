//! The run's tracking error, as an RMS and as a distribution.
//!
//! An RMS alone cannot tell a run that tracks to micrometres but lost the path for 15 ms when
//! the host stalled the loop's vCPU from a run that tracks badly throughout: both can read a
//! millimetre. The median and the tail say which, so the summary and the demo report show them
//! side by side. Errors are kept in nanometres; the first 2 s (the start-up transient) are left
//! out, as for the residual.

use hdrhistogram::Histogram;
use serde::Serialize;

/// Ticks before this time (s) are the start-up transient.
pub const SETTLE_S: f64 = 2.0;

/// The largest error the histogram holds (nm): 1 km, far past any arm.
const MAX_NM: u64 = 1_000_000_000_000;

/// The tracking error over a run: after [`SETTLE_S`], and over the whole run (what a report
/// shows of a run that ended, by a FAULT say, inside its start-up transient).
#[derive(Default)]
pub struct TrackingStats {
    settled: Errors,
    whole: Errors,
}

/// One accumulation of errors.
struct Errors {
    sum_sq: f64,
    n: u64,
    nm: Histogram<u64>,
}

/// The distribution of the tracking error (m).
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub struct TrackingSpread {
    pub p50_m: f64,
    pub p99_m: f64,
    pub max_m: f64,
}

impl Default for Errors {
    fn default() -> Self {
        Self {
            sum_sq: 0.0,
            n: 0,
            nm: Histogram::new_with_bounds(1, MAX_NM, 3).expect("static bounds are valid"),
        }
    }
}

impl Errors {
    fn observe(&mut self, e: f64) {
        self.sum_sq += e * e;
        self.n += 1;
        self.nm.saturating_record(((e.abs() * 1e9) as u64).max(1));
    }

    fn rms(&self) -> Option<f64> {
        (self.n > 0).then(|| (self.sum_sq / self.n as f64).sqrt())
    }

    fn spread(&self) -> Option<TrackingSpread> {
        let m = |nm: u64| nm as f64 * 1e-9;
        (self.n > 0).then(|| TrackingSpread {
            p50_m: m(self.nm.value_at_quantile(0.5)),
            p99_m: m(self.nm.value_at_quantile(0.99)),
            max_m: m(self.nm.max()),
        })
    }
}

impl TrackingStats {
    /// Counts one tick's error `e` (m) at time `t` (s); a non-finite error is the nonfinite
    /// counter's business, not this one's.
    pub fn observe(&mut self, t: f64, e: f64) {
        if !e.is_finite() {
            return;
        }
        self.whole.observe(e);
        if t >= SETTLE_S {
            self.settled.observe(e);
        }
    }

    /// After the start-up transient.
    pub fn rms(&self) -> Option<f64> {
        self.settled.rms()
    }

    /// After the start-up transient.
    pub fn spread(&self) -> Option<TrackingSpread> {
        self.settled.spread()
    }

    /// Over every tick, the transient included.
    pub fn whole_rms(&self) -> Option<f64> {
        self.whole.rms()
    }

    /// Over every tick, the transient included.
    pub fn whole_spread(&self) -> Option<TrackingSpread> {
        self.whole.spread()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_short_excursion_moves_the_rms_and_the_tail_but_not_the_median() {
        let mut s = TrackingStats::default();
        s.observe(1.0, 1.0); // transient: left out
        for i in 0..1000 {
            s.observe(2.0 + i as f64 * 1e-3, if i < 15 { 1e-2 } else { 1e-6 });
        }
        s.observe(3.0, f64::NAN);
        let rms = s.rms().unwrap();
        let expected = ((15.0 * 1e-4 + 985.0 * 1e-12) / 1000.0_f64).sqrt();
        assert!((rms - expected).abs() < 1e-12, "{rms} vs {expected}");
        let sp = s.spread().unwrap();
        assert!((sp.p50_m - 1e-6).abs() < 1e-8, "{sp:?}");
        assert!((sp.max_m - 1e-2).abs() < 1e-4, "{sp:?}");
        assert!(sp.p99_m > 1e-3, "{sp:?}");
    }

    #[test]
    fn nothing_observed_says_nothing() {
        assert_eq!(TrackingStats::default().rms(), None);
        assert_eq!(TrackingStats::default().spread(), None);
        assert_eq!(TrackingStats::default().whole_rms(), None);
    }

    #[test]
    fn a_run_that_ends_in_its_transient_still_has_its_whole_run() {
        let mut s = TrackingStats::default();
        s.observe(0.5, 3e-3);
        s.observe(0.9, 4e-3);
        assert_eq!(s.rms(), None);
        assert!((s.whole_rms().unwrap() - (12.5e-6f64).sqrt()).abs() < 1e-12);
        assert!((s.whole_spread().unwrap().max_m - 4e-3).abs() < 1e-5);
    }
}
