//! What the chaos monitor costs the reporter thread (issue 27): it runs there, off the loop's
//! core, on every state the law ran on, and once per period does its real work (Rosenstein's λ
//! over the newest returns, the 0–1 test over the window).
//!
//! The states are a chaotic 300 s run of the paper's arm at 1 kHz (μ = 0: the window fills with
//! returns that differ, the worst case for both estimates); each `push` is timed alone.

use crate::stats::{fmt_ns, histogram, summary, Table};
use anyhow::Result;
use control::monitor::{ChaosMonitor, MonitorSettings};
use control::{Config, Simulation};
use std::time::Instant;

pub fn table(quick: bool) -> Result<String> {
    let cfg = Config::preset("paper")?;
    let seconds = if quick { 60.0 } else { 300.0 };
    let mut sim = Simulation::new(
        cfg.model::<3>(),
        cfg.law_params(),
        1e-3,
        cfg.initial_state(),
        2.0,
    );
    let mut monitor = ChaosMonitor::new(MonitorSettings::default(), cfg.tau());
    let (mut ticks, mut returns) = (histogram(), histogram());
    let mut total_ns = 0u64;
    let steps = (seconds / 1e-3) as u64;
    for _ in 0..steps {
        let t = sim.time();
        let x = *sim.state();
        let out = sim.step();
        let periods = monitor.evidence().periods;
        let start = Instant::now();
        std::hint::black_box(monitor.push(
            t,
            x.q.as_slice(),
            x.qd.as_slice(),
            out.period_residual,
            out.null_residual,
        ));
        let ns = start.elapsed().as_nanos() as u64;
        total_ns += ns;
        let h = if monitor.evidence().periods != periods {
            &mut returns
        } else {
            &mut ticks
        };
        h.saturating_record(ns.max(1));
    }
    let mut t = Table::new(&[
        "chaos monitor on the reporter thread (paper arm, μ = 0, 1 kHz)",
        "n",
        "p50",
        "p99",
        "max",
    ]);
    for (name, h) in [
        ("a tick within a period (sums the residual)", &ticks),
        (
            "a period's end (λ over 32 returns, K over up to 256)",
            &returns,
        ),
    ] {
        let s = summary(h);
        t.row(vec![
            name.into(),
            h.len().to_string(),
            fmt_ns(s[0] as f64),
            fmt_ns(s[2] as f64),
            fmt_ns(s[4] as f64),
        ]);
    }
    Ok(format!(
        "{}\nIn all: {:.3} % of one core over the {seconds:.0} s run ({} per simulated second), none of it on the loop's core.\n",
        t.render(),
        total_ns as f64 / (seconds * 1e9) * 100.0,
        fmt_ns(total_ns as f64 / seconds)
    ))
}
