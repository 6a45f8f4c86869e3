//! The metrics window: latency distributions over the last complete 10 s, for monitoring.
//!
//! Telemetry goes out 10-50 times a second; a p99.9 over one such interval (20-100 ticks) would
//! be its maximum. A scraper (`chaosctl exporter`) instead wants a distribution over enough ticks
//! for its tail to mean something, and one that forgets (a summary since start says nothing about
//! this hour after a month). So the reporter thread keeps three HdrHistograms (wake-up lateness,
//! compute per tick, state age), and every [`WINDOW`] it takes their percentiles and starts them
//! afresh. Each telemetry sample carries the last complete window's figures. The loop does no
//! extra work: the records are the ones it already sends.

use crate::controller::Counters;
use crate::telemetry::TickRecord;
use hdrhistogram::Histogram;
use protocol::TelemetrySample;
use rt::hist::{self, Percentiles};
use std::time::{Duration, Instant};

/// How long one window lasts.
pub const WINDOW: Duration = Duration::from_secs(10);

pub struct MetricsWindow {
    hist: [Histogram<u64>; 3],
    started: Instant,
    every: Duration,
    /// The last complete window: percentiles of each histogram, its length (s) and ticks.
    done: Option<([Percentiles; 3], f64, u64)>,
}

impl Default for MetricsWindow {
    fn default() -> Self {
        Self::new(WINDOW)
    }
}

impl MetricsWindow {
    pub fn new(every: Duration) -> Self {
        Self {
            hist: [hist::new_ns(), hist::new_ns(), hist::new_ns()],
            started: Instant::now(),
            every,
            done: None,
        }
    }

    pub fn record(&mut self, r: &TickRecord) {
        self.hist[0].saturating_record(r.lateness_ns.max(1));
        self.hist[1].saturating_record(r.compute_ns.max(1));
        if let Some(a) = r.state_age_ns {
            self.hist[2].saturating_record(a.max(1));
        }
    }

    fn current(&self) -> ([Percentiles; 3], f64, u64) {
        (
            [
                Percentiles::of(&self.hist[0]),
                Percentiles::of(&self.hist[1]),
                Percentiles::of(&self.hist[2]),
            ],
            self.started.elapsed().as_secs_f64(),
            self.hist[0].len(),
        )
    }

    /// Closes the window if it is due, then writes the newest complete window's figures and the
    /// counters that are not in the sample yet.
    pub fn fill(&mut self, t: &mut TelemetrySample, c: &Counters) {
        self.fill_at(t, c, Instant::now());
    }

    fn fill_at(&mut self, t: &mut TelemetrySample, c: &Counters, now: Instant) {
        if now.duration_since(self.started) >= self.every {
            self.done = Some(self.current());
            for h in &mut self.hist {
                h.reset();
            }
            self.started = now;
        }
        let (p, len, ticks) = self.done.unwrap_or_else(|| self.current());
        let q = |p: &Percentiles| {
            if p.count == 0 {
                [f64::NAN; 4]
            } else {
                [p.p50_us, p.p99_us, p.p999_us, p.max_us]
            }
        };
        t.window_s = len;
        t.window_ticks = ticks;
        t.lateness_us = q(&p[0]);
        t.compute_us = q(&p[1]);
        t.state_age_us = q(&p[2]);
        t.faults = c.faults;
        t.plant_restarts = c.plant_restarts;
        t.safety_active = c.safety_active;
        t.track_lost = c.track_lost;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(late_us: u64) -> TickRecord {
        TickRecord {
            lateness_ns: late_us * 1000,
            compute_ns: 10_000,
            ..TickRecord::blank()
        }
    }

    #[test]
    fn each_window_reports_its_own_ticks_and_then_forgets_them() {
        let t0 = Instant::now();
        let mut w = MetricsWindow::new(Duration::from_secs(10));
        let mut t = TelemetrySample::default();
        let c = Counters {
            faults: 2,
            ..Default::default()
        };
        for i in 1..=1000 {
            w.record(&rec(i));
        }
        // Before the first window closes: the one under way.
        w.fill_at(&mut t, &c, t0);
        assert_eq!(t.window_ticks, 1000);
        assert!(
            (t.lateness_us[1] - 990.0).abs() < 10.0,
            "{:?}",
            t.lateness_us
        );
        assert!((t.lateness_us[3] - 1000.0).abs() < 10.0);
        assert!(t.state_age_us[0].is_nan(), "no states: no figure");
        assert_eq!(t.faults, 2);
        // The window closes; the next one has only fast ticks, but the figures stay those of the
        // last complete window until it closes too.
        w.fill_at(&mut t, &c, t0 + Duration::from_secs(11));
        for _ in 0..500 {
            w.record(&rec(2));
        }
        w.fill_at(&mut t, &c, t0 + Duration::from_secs(12));
        assert_eq!(t.window_ticks, 1000);
        w.fill_at(&mut t, &c, t0 + Duration::from_secs(22));
        assert_eq!(t.window_ticks, 500);
        assert!(t.lateness_us[3] < 3.0, "{:?}", t.lateness_us);
    }
}
