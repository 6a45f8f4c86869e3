//! The reporter thread: everything the tick must not do.
//!
//! The loop hands one small `Copy` record per tick to this thread through a bounded crossbeam
//! channel with `try_send`, and counts a drop if the queue is full: it never waits. Here the
//! records become HdrHistograms (wake-up lateness, compute time, state age), per-second windows of
//! tracking error and period residual, live status lines and, at exit, the files a person or a
//! tool reads: `.hgrm` percentile text, a V2 `.hlog` and `daemon-summary.json`.

use crate::controller::Counters;
use hdrhistogram::Histogram;
use protocol::Mode;
use rt::hist::{self, Percentiles};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

/// One tick, as the loop saw it.
#[derive(Clone, Copy, Debug)]
pub struct TickRecord {
    /// Controller time (s).
    pub t: f64,
    pub lateness_ns: u64,
    pub compute_ns: u64,
    pub state_age_ns: Option<u64>,
    pub mode: Mode,
    /// Whether the law ran (a fresh state arrived).
    pub ran_law: bool,
    pub law_flags: u32,
    pub tracking_error: f64,
    pub period_residual: f64,
    pub clearance: f64,
    pub mu: f64,
    pub feedback_active: bool,
    pub counters: Counters,
}

/// What the reporter learnt over the run.
#[derive(Clone, Debug, Serialize)]
pub struct DaemonSummary {
    pub namespace: String,
    pub rate_hz: f64,
    pub wait: String,
    pub realtime: rt::setup::RtReport,
    pub duration_s: f64,
    pub counters: Counters,
    pub lateness: Percentiles,
    pub compute: Percentiles,
    pub state_age: Percentiles,
    /// RMS tracking error over ticks after the first 2 s (m).
    pub tracking_rms_m: Option<f64>,
    /// Mean |q̇(t) − q̇(t − τ)| while the feedback was off (after the first 2 s).
    pub period_residual_before: Option<f64>,
    /// The same over the last 5 s with the feedback on.
    pub period_residual_after: Option<f64>,
    pub feedback_on_at_s: Option<f64>,
    pub min_clearance_m: Option<f64>,
    pub time_in_safety_zone_s: f64,
    pub files: Vec<PathBuf>,
}

/// Per-second accumulator.
#[derive(Clone, Copy, Default)]
struct Second {
    resid: f64,
    n: u64,
    feedback: bool,
}

pub struct Reporter {
    namespace: String,
    rate_hz: f64,
    wait: String,
    out_dir: PathBuf,
    report_every: Option<Duration>,
    realtime: rt::setup::RtReport,
    lateness: Histogram<u64>,
    compute: Histogram<u64>,
    state_age: Histogram<u64>,
    window_lateness: Histogram<u64>,
    seconds: Vec<Second>,
    sq_track: f64,
    n_track: u64,
    feedback_on_at: Option<f64>,
    min_clearance: f64,
    safety_ticks: u64,
    last: Option<TickRecord>,
    window_track: (f64, u64),
    window_resid: (f64, u64),
}

impl Reporter {
    pub fn new(
        namespace: &str,
        rate_hz: f64,
        wait: &str,
        out_dir: &Path,
        report_every_s: f64,
        realtime: rt::setup::RtReport,
    ) -> Self {
        Self {
            namespace: namespace.into(),
            rate_hz,
            wait: wait.into(),
            out_dir: out_dir.into(),
            report_every: (report_every_s > 0.0).then(|| Duration::from_secs_f64(report_every_s)),
            realtime,
            lateness: hist::new_ns(),
            compute: hist::new_ns(),
            state_age: hist::new_ns(),
            window_lateness: hist::new_ns(),
            seconds: Vec::new(),
            sq_track: 0.0,
            n_track: 0,
            feedback_on_at: None,
            min_clearance: f64::INFINITY,
            safety_ticks: 0,
            last: None,
            window_track: (0.0, 0),
            window_resid: (0.0, 0),
        }
    }

    fn record(&mut self, r: &TickRecord) {
        self.lateness.saturating_record(r.lateness_ns.max(1));
        self.window_lateness.saturating_record(r.lateness_ns.max(1));
        self.compute.saturating_record(r.compute_ns.max(1));
        if let Some(a) = r.state_age_ns {
            self.state_age.saturating_record(a.max(1));
        }
        if r.ran_law {
            let sec = r.t.max(0.0) as usize;
            if self.seconds.len() <= sec {
                self.seconds.resize(sec + 1, Second::default());
            }
            let s = &mut self.seconds[sec];
            s.resid += r.period_residual;
            s.n += 1;
            s.feedback |= r.feedback_active;
            if r.feedback_active && self.feedback_on_at.is_none() {
                self.feedback_on_at = Some(r.t);
            }
            if r.t >= 2.0 {
                self.sq_track += r.tracking_error * r.tracking_error;
                self.n_track += 1;
            }
            self.window_track.0 += r.tracking_error * r.tracking_error;
            self.window_track.1 += 1;
            self.window_resid.0 += r.period_residual;
            self.window_resid.1 += 1;
            if r.clearance.is_finite() {
                self.min_clearance = self.min_clearance.min(r.clearance);
            }
            if r.law_flags & control::law::flags::IN_SAFETY_ZONE != 0 {
                self.safety_ticks += 1;
            }
        }
        self.last = Some(*r);
    }

    fn status_line(&mut self) -> Option<String> {
        let r = self.last?;
        let c = &r.counters;
        let p = Percentiles::of(&self.window_lateness);
        let track = if self.window_track.1 > 0 {
            (self.window_track.0 / self.window_track.1 as f64).sqrt()
        } else {
            f64::NAN
        };
        let resid = if self.window_resid.1 > 0 {
            self.window_resid.0 / self.window_resid.1 as f64
        } else {
            f64::NAN
        };
        self.window_lateness.reset();
        self.window_track = (0.0, 0);
        self.window_resid = (0.0, 0);
        let mode = match r.mode {
            Mode::Run => "RUN ",
            Mode::Hold => "HOLD",
            Mode::Brake => "BRAKE",
        };
        Some(format!(
            "[{:7.1} s] {mode} μ={:.2} feedback {}  track {:.1e} m  residual {:.2e} rad/s  late p99 {:.1} µs max {:.1} µs  overruns {}  rejected {}  holds {}  drops {}",
            r.t,
            r.mu,
            if r.feedback_active { "on " } else { "off" },
            track,
            resid,
            p.p99_us,
            p.max_us,
            c.overruns,
            c.rejected_invalid + c.rejected_stale + c.rejected_out_of_order,
            c.holds_entered,
            c.telemetry_dropped
        ))
    }

    /// Drains records until the loop closes the channel, then writes the files.
    pub fn run(
        mut self,
        rx: crossbeam::channel::Receiver<TickRecord>,
        mut on_line: impl FnMut(&str),
    ) -> anyhow::Result<DaemonSummary> {
        let start = Instant::now();
        let wall_start = SystemTime::now();
        let mut next_report = self.report_every.map(|d| start + d);
        loop {
            match rx.recv_timeout(Duration::from_millis(100)) {
                Ok(r) => {
                    self.record(&r);
                    while let Ok(r) = rx.try_recv() {
                        self.record(&r);
                    }
                }
                Err(crossbeam::channel::RecvTimeoutError::Timeout) => {}
                Err(crossbeam::channel::RecvTimeoutError::Disconnected) => break,
            }
            if let (Some(at), Some(every)) = (next_report, self.report_every) {
                if Instant::now() >= at {
                    if let Some(line) = self.status_line() {
                        on_line(&line);
                    }
                    next_report = Some(at + every);
                }
            }
        }
        self.finish(start.elapsed(), wall_start)
    }

    fn finish(self, elapsed: Duration, wall_start: SystemTime) -> anyhow::Result<DaemonSummary> {
        std::fs::create_dir_all(&self.out_dir).map_err(|e| {
            anyhow::anyhow!(
                "cannot create output directory {}: {e}",
                self.out_dir.display()
            )
        })?;
        let mut files = Vec::new();
        for (name, h) in [
            ("lateness", &self.lateness),
            ("compute", &self.compute),
            ("state-age", &self.state_age),
        ] {
            let p = self.out_dir.join(format!("daemon-{name}.hgrm"));
            hist::save_hgrm(h, &p)
                .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", p.display()))?;
            files.push(p);
        }
        let hlog = self.out_dir.join("daemon.hlog");
        hist::save_hlog(
            &[
                ("lateness", &self.lateness),
                ("compute", &self.compute),
                ("state-age", &self.state_age),
            ],
            wall_start,
            elapsed,
            &hlog,
        )
        .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", hlog.display()))?;
        files.push(hlog);

        let mean = |secs: &[Second]| {
            let (s, n) = secs
                .iter()
                .fold((0.0, 0u64), |(s, n), x| (s + x.resid, n + x.n));
            (n > 0).then(|| s / n as f64)
        };
        let before: Vec<Second> = self
            .seconds
            .iter()
            .enumerate()
            .filter(|(i, s)| *i >= 2 && !s.feedback)
            .map(|(_, s)| *s)
            .collect();
        let on: Vec<Second> = self
            .seconds
            .iter()
            .copied()
            .filter(|s| s.feedback)
            .collect();
        let after_from = on.len().saturating_sub(5);
        let counters = self.last.map(|r| r.counters).unwrap_or_default();
        let summary = DaemonSummary {
            namespace: self.namespace.clone(),
            rate_hz: self.rate_hz,
            wait: self.wait.clone(),
            realtime: self.realtime.clone(),
            duration_s: elapsed.as_secs_f64(),
            counters,
            lateness: Percentiles::of(&self.lateness),
            compute: Percentiles::of(&self.compute),
            state_age: Percentiles::of(&self.state_age),
            tracking_rms_m: (self.n_track > 0)
                .then(|| (self.sq_track / self.n_track as f64).sqrt()),
            period_residual_before: mean(&before),
            period_residual_after: mean(&on[after_from..]),
            feedback_on_at_s: self.feedback_on_at,
            min_clearance_m: self.min_clearance.is_finite().then_some(self.min_clearance),
            time_in_safety_zone_s: self.safety_ticks as f64 / self.rate_hz,
            files: Vec::new(),
        };
        files.push(self.out_dir.join(SUMMARY_FILE));
        Ok(DaemonSummary { files, ..summary })
    }
}

/// Name of the JSON summary in the output directory.
pub const SUMMARY_FILE: &str = "daemon-summary.json";

/// Writes the summary once the loop has added what only it knows (the real-time set-up).
pub fn write_summary(summary: &DaemonSummary, dir: &Path) -> anyhow::Result<()> {
    let json = dir.join(SUMMARY_FILE);
    std::fs::write(&json, serde_json::to_string_pretty(summary)?)
        .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", json.display()))
}
