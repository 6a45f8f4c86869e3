//! The chaos monitor in the daemon: the reporter feeds it, status, watch, metrics, the log and
//! the summary show it.
//!
//! The monitor ([`control::monitor`]) costs a few hundred microseconds once per period (the 0–1
//! test over its window), too much for the tick and nothing for the reporter, which already sees
//! every state the law ran on. So it runs here, off the loop's core, and the loop pays only the
//! null-space residual (a few flops in the law). Its window starts again whenever the system
//! changes under it: a parameter edit, or the arm coming back to RUN from a hold or a fault,
//! since returns from before the change belong to another system.

use crate::controller::Applied;
use crate::telemetry::{ChaosSummary, TickRecord};
use control::monitor::{ChaosMonitor, Edge, Evidence, MonitorSettings};
use protocol::Mode;

/// Verdict changes kept for the summary (the first ones: how the run settled).
pub const HISTORY: usize = 32;

/// The monitor and what it has said.
pub struct ChaosWatch {
    monitor: ChaosMonitor,
    n: usize,
    running: bool,
    /// μ on the newest tick (it moves with `feedback.mu = "auto"`).
    mu: f64,
    /// Verdict changes so far, and the first [`HISTORY`] of them.
    pub edges: u64,
    pub history: Vec<Edge>,
    /// The next parameter block only hands over the gain the model chose (`crate::gains`):
    /// the same system at another gain, as `mu = "auto"` moves it anyway, so the window goes on.
    gain_only: bool,
}

impl ChaosWatch {
    pub fn new(settings: MonitorSettings, tau: f64, n: usize) -> Self {
        Self {
            monitor: ChaosMonitor::new(settings, tau),
            n,
            running: false,
            mu: 0.0,
            edges: 0,
            history: Vec::with_capacity(HISTORY),
            gain_only: false,
        }
    }

    /// One tick's record (see the module docs for when the window restarts); the verdict's
    /// change, if it changed.
    pub fn observe(&mut self, r: &TickRecord, mu_auto: bool) -> Option<Edge> {
        let run = r.mode == Mode::Run;
        let mut edited = matches!(r.applied, Some(Applied::Params));
        if edited && self.gain_only {
            (edited, self.gain_only) = (false, false);
        }
        if (run && !self.running) || edited {
            self.monitor.restart(r.t, r.tau);
        }
        self.running = run;
        self.mu = r.mu;
        let s = r.state.as_ref().filter(|_| run && r.ran_law)?;
        let (q, qd) = (&s.q[..self.n], &s.qd[..self.n]);
        let e = self
            .monitor
            .push(r.t, q, qd, r.period_residual, r.null_residual)?;
        self.edges += 1;
        if self.history.len() < HISTORY {
            self.history.push(e);
        }
        let auto = if mu_auto { " (auto)" } else { "" };
        tracing::info!(
            "chaos: {} → {} at t = {:.1} s: {}; μ = {}{auto}",
            e.from.name(),
            e.to.name(),
            e.t,
            describe(&e.evidence),
            crate::number::short(r.mu)
        );
        Some(e)
    }

    /// The next parameter block is the model's gain only (see the field).
    pub fn gain_only(&mut self) {
        self.gain_only = true;
    }

    pub fn evidence(&self) -> &Evidence {
        self.monitor.evidence()
    }

    /// `status --json`'s `chaos` object.
    pub fn to_json(&self, mu_auto: bool) -> serde_json::Value {
        let e = self.evidence();
        serde_json::json!({
            "verdict": e.verdict.name(),
            "since": e.since,
            "periods": e.periods,
            "window": e.window,
            "residual": e.residual,
            "null_residual": e.null_residual,
            "residual_trend": e.residual_trend,
            "lyapunov": e.lambda,
            "k": e.k,
            "edges": self.edges,
            "mu_auto": mu_auto,
            "settings": self.monitor.settings(),
        })
    }

    /// The telemetry sample's chaos fields.
    pub fn fill(&self, t: &mut protocol::TelemetrySample, mu_auto: bool) {
        let e = self.evidence();
        t.chaos = e.verdict.code();
        t.mu_auto = u32::from(mu_auto);
        t.lyapunov = e.lambda.unwrap_or(f64::NAN);
        t.k01 = e.k.unwrap_or(f64::NAN);
    }

    pub fn summary(&self) -> ChaosSummary {
        ChaosSummary {
            evidence: *self.evidence(),
            mu: self.mu,
            edges: self.edges,
            history: self.history.clone(),
            model_gain: None,
            target: None,
        }
    }
}

/// `λ = +0.31/s, K = 0.98, residual 4.2e0 rad/s (×1.02 a period), 64 periods`.
pub fn describe(e: &Evidence) -> String {
    let opt = |v: Option<f64>, f: &dyn Fn(f64) -> String| v.map_or("n/a".to_string(), f);
    format!(
        "λ = {}, K = {}, residual {:.1e} rad/s ({} a period), {} periods",
        opt(e.lambda, &|l| format!("{l:+.3}/s")),
        opt(e.k, &|k| format!("{k:.2}")),
        e.residual,
        opt(e.residual_trend, &|r| format!("×{r:.3}")),
        e.periods
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::monitor::Verdict;
    use protocol::StateSample;

    fn record(t: f64, q: f64, residual: f64, mode: Mode) -> TickRecord {
        let mut s = StateSample::default();
        s.q[0] = q;
        TickRecord {
            t,
            mode,
            ran_law: true,
            period_residual: residual,
            null_residual: residual,
            tau: 1.0,
            state: Some(s),
            ..TickRecord::blank()
        }
    }

    #[test]
    fn a_converging_arm_is_said_in_the_log_the_summary_and_telemetry() {
        let mut w = ChaosWatch::new(MonitorSettings::default(), 1.0, 3);
        let mut r = 1.0;
        for k in 0..40 {
            w.observe(&record(k as f64, 0.5 + r, r, Mode::Run), true);
            r *= 0.6;
        }
        assert_eq!(w.evidence().verdict, Verdict::Periodic);
        let s = w.summary();
        let seen: Vec<Verdict> = s.history.iter().map(|e| e.to).collect();
        assert_eq!(seen, [Verdict::Converging, Verdict::Periodic]);
        let mut t = protocol::TelemetrySample::default();
        w.fill(&mut t, true);
        assert_eq!(
            (Verdict::from_code(t.chaos), t.mu_auto),
            (Verdict::Periodic, 1)
        );
        assert_eq!(w.to_json(true)["verdict"], "periodic");
        assert_eq!(Verdict::from_code(99), Verdict::Unknown);
    }

    #[test]
    fn a_hold_or_an_edit_restarts_the_window() {
        let mut w = ChaosWatch::new(MonitorSettings::default(), 1.0, 3);
        for k in 0..10 {
            w.observe(&record(k as f64, k as f64, 1.0, Mode::Run), false);
        }
        assert_eq!(w.evidence().periods, 9);
        w.observe(&record(10.0, 0.0, 1.0, Mode::Hold), false);
        w.observe(&record(11.0, 0.0, 1.0, Mode::Run), false);
        assert_eq!(w.evidence().periods, 0);
        for k in 12..15 {
            w.observe(&record(k as f64, 0.0, 1.0, Mode::Run), false);
        }
        let mut edit = record(15.0, 0.0, 1.0, Mode::Run);
        edit.applied = Some(Applied::Params);
        w.observe(&edit, false);
        assert_eq!(w.evidence().periods, 0);
    }
}
