//! The daemon's tick (`daemon::controller::Controller::tick`, the real one) warm, cold, and
//! cold but rehearsed: why the loop rehearses while it waits.
//!
//! A loop at 1 kHz sleeps most of each period, and what runs meanwhile (the kernel, the other
//! process, the host) evicts the tick's code and data. "Cold" here evicts them on purpose by
//! writing a buffer larger than the last-level cache before each tick; "rehearsed" does the same
//! and then calls `Controller::rehearse` on the previous state, as the loop does after its sleep.
//! Each tick is timed alone (one clock read costs about 20 ns here, small next to a tick).

use crate::stats::{fmt_ns, histogram, summary, Table};
use anyhow::Result;
use control::{Config, Simulation};
use daemon::controller::{Controller, ControllerSettings};
use hdrhistogram::Histogram;
use protocol::StateSample;
use std::hint::black_box;
use std::time::Instant;

/// Bytes written to evict the caches (larger than this machine's L3 share).
const EVICT_BYTES: usize = 64 << 20;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Before {
    Nothing,
    Eviction,
    EvictionThenRehearsal,
}

fn controller(cfg: &Config) -> Controller<3> {
    let settings = ControllerSettings {
        rate_hz: 1000.0,
        first_order_hold: true,
        hold_after: 5,
        stale_ns: 50_000_000,
        future_slack_ns: 1_000_000,
        daemon_id: 1,
        t_start: 0.0,
    };
    Controller::new(cfg.tick_law(), cfg.feedback.capacity(), settings)
}

/// Per-tick cost over `ticks` ticks of the demo preset's run, with `before` done before each.
fn ticks(cfg: &Config, ticks: u64, before: Before, evict: &mut [u8]) -> Histogram<u64> {
    let mut h = side_by_side(cfg, &[cfg], ticks, before, evict);
    h.remove(0)
}

/// [`ticks`] of one controller per config in `ctl_cfgs`, on the states of `cfg`'s run, each
/// state ticked by one after the other: controllers compared on the same states in the same
/// moments (a gain that moves would otherwise move the arm, and with it how often the safety
/// filter binds; and this VM's speed moves between runs by more than the differences sought).
fn side_by_side(
    cfg: &Config,
    ctl_cfgs: &[&Config],
    ticks: u64,
    before: Before,
    evict: &mut [u8],
) -> Vec<Histogram<u64>> {
    let mut ctls: Vec<_> = ctl_cfgs.iter().map(|c| controller(c)).collect();
    let mut sim = Simulation::new(
        cfg.model::<3>(),
        cfg.law_params(),
        1e-3,
        cfg.initial_state(),
        2.0,
    );
    let mut hs: Vec<_> = ctls.iter().map(|_| histogram()).collect();
    let t0 = protocol::monotonic_ns();
    let mut prev: Option<StateSample> = None;
    for k in 0..ticks {
        sim.step();
        let x = sim.state();
        let mut s = StateSample {
            seq: k,
            stamp_ns: t0 + k * 1_000_000,
            plant_id: 7,
            n: 3,
            ..StateSample::default()
        };
        s.q[..3].copy_from_slice(x.q.as_slice());
        s.qd[..3].copy_from_slice(x.qd.as_slice());
        // Who goes first alternates: the first after the simulation's step finds less in cache.
        let order: Vec<usize> = if k % 2 == 0 {
            (0..ctls.len()).collect()
        } else {
            (0..ctls.len()).rev().collect()
        };
        for i in order {
            let (ctl, h) = (&mut ctls[i], &mut hs[i]);
            if before != Before::Nothing {
                for b in evict.iter_mut().step_by(64) {
                    *b = b.wrapping_add(1);
                }
            }
            if let (Before::EvictionThenRehearsal, Some(p)) = (before, &prev) {
                ctl.rehearse(p);
            }
            // The loop reads the clock while it waits, so the clock is warm in every case.
            black_box(Instant::now());
            let start = Instant::now();
            black_box(ctl.tick(Some(&s), s.stamp_ns + 20_000));
            let ns = start.elapsed().as_nanos() as u64;
            if k >= ticks / 10 {
                h.saturating_record(ns.max(1));
            }
        }
        prev = Some(s);
    }
    hs
}

/// The table: one row per case, with the ratio to the warm tick.
pub fn table(quick: bool) -> Result<String> {
    let mut cfg = Config::preset("demo")?;
    cfg.feedback.t_on = 0.5; // the delay line is read for most of the run
    let n = if quick { 1_500 } else { 10_000 };
    let mut evict = vec![0u8; EVICT_BYTES];
    let mut t = Table::new(&[
        "daemon tick (demo preset, safety on, first-order hold)",
        "p50",
        "p99",
        "max",
        "p50 vs warm",
    ]);
    let warm = summary(&ticks(&cfg, n, Before::Nothing, &mut evict));
    for (name, before) in [
        ("warm: back to back", Before::Nothing),
        ("cold: caches evicted before each tick", Before::Eviction),
        (
            "rehearsed: evicted, then `Controller::rehearse` on the previous state",
            Before::EvictionThenRehearsal,
        ),
    ] {
        let s = if before == Before::Nothing {
            warm
        } else {
            summary(&ticks(&cfg, n, before, &mut evict))
        };
        row(&mut t, name, s, warm);
    }
    // The loop's share of issue 27: the speed-gradient step on every tick, next to a fixed μ.
    let mut auto = cfg.clone();
    auto.feedback.auto = Some(control::adapt::AutoMu::default());
    let pair = side_by_side(&cfg, &[&cfg, &auto], n, Before::Nothing, &mut evict);
    let (fixed, auto) = (summary(&pair[0]), summary(&pair[1]));
    row(
        &mut t,
        "warm, mu = \"auto\" (the gain adapts on the tick), ratio to a fixed μ ticked alternately on the same states",
        auto,
        fixed,
    );
    Ok(t.render())
}

fn row(t: &mut Table, name: &str, s: [u64; 5], warm: [u64; 5]) {
    t.row(vec![
        name.into(),
        fmt_ns(s[0] as f64),
        fmt_ns(s[2] as f64),
        fmt_ns(s[4] as f64),
        format!("{:.2}×", s[0] as f64 / warm[0].max(1) as f64),
    ]);
}
