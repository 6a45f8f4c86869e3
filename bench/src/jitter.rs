//! `jitter`: how late a fixed-rate loop wakes up, per wait strategy, next to cyclictest.
//!
//! The loop measured is the daemon's own: `rt::clock::Schedule` for absolute deadlines and
//! `rt::wait_until` with the daemon's default hybrid spin window, on a pinned thread set up by
//! `rt::setup::apply` exactly as the daemon sets up its loop thread (memory locked; timer slack
//! 1 ns when not SCHED_FIFO). Lateness is wake-up time minus deadline, and no work is done per
//! tick, so this is the wait alone.
//!
//! cyclictest is run with the same core, rate, scheduling policy and priority, memory locked, and
//! the same 1 ns timer slack (see `child::with_fine_slack`), so its rows are the reference for
//! what a plain `clock_nanosleep` loop achieves on this machine and kernel. It runs twice: as
//! people run it, which holds a PM QoS request (/dev/cpu_dma_latency = 0) that keeps idle CPUs
//! polling and so shortens every wake-up, and with `--default-system`, without it, as chaosd's
//! loops run. The target compares the daemon's hybrid wait with the first, stronger one.
//!
//! Configurations are interleaved in short blocks, round after round ([`crate::plan`]). Each
//! (rate, method) pair runs a SCHED_OTHER block and then a SCHED_FIFO block, so real-time blocks
//! always alternate with ordinary ones: a FIFO spin never holds a core for longer than one block
//! (the kernel's RT throttling would otherwise pause it, and everything else on that core
//! starves meanwhile). Priority 99 is refused.

use crate::child::{with_fine_slack, Child, Stdout};
use crate::cyclictest;
use crate::plan::interleave;
use crate::plot::Panel;
use crate::report::{header, slug, Output, Report};
use crate::stats::{fmt_ns, histogram, ratio, summary, Bound, Dist, Table, Target};
use anyhow::{anyhow, bail, Result};
use hdrhistogram::Histogram;
use rt::clock::Schedule;
use rt::WaitStrategy;
use std::collections::HashMap;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    Wait(WaitStrategy),
    /// cyclictest; `pm_qos` = its default system tuning (see `cyclictest::args`).
    Cyclictest {
        pm_qos: bool,
    },
}

/// cyclictest as people run it: the reference for the target.
const CYCLICTEST: Method = Method::Cyclictest { pm_qos: true };

impl std::hash::Hash for Method {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        match self {
            Method::Wait(w) => w.name().hash(state),
            Method::Cyclictest { pm_qos } => ("cyclictest", pm_qos).hash(state),
        }
    }
}

impl Method {
    fn label(self) -> String {
        match self {
            Method::Wait(WaitStrategy::Hybrid) => "chaosd hybrid".into(),
            Method::Wait(w) => format!("chaosd {}", w.name()),
            Method::Cyclictest { pm_qos: true } => "cyclictest".into(),
            Method::Cyclictest { pm_qos: false } => "cyclictest --default-system".into(),
        }
    }
}

/// One configuration: a rate, a method and a scheduling class.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Cfg {
    pub rate_hz: u32,
    pub method: Method,
    pub fifo: bool,
}

impl Cfg {
    fn sched(&self) -> &'static str {
        if self.fifo {
            "SCHED_FIFO"
        } else {
            "SCHED_OTHER"
        }
    }
    fn label(&self) -> String {
        format!("{} {}", self.method.label(), self.sched())
    }
    fn slug(&self) -> String {
        slug(&format!(
            "{}hz {} {}",
            self.rate_hz,
            self.method.label(),
            if self.fifo { "fifo" } else { "other" }
        ))
    }
}

#[derive(Clone, Debug)]
pub struct Options {
    pub rates: Vec<u32>,
    pub rounds: usize,
    pub block: Duration,
    /// SCHED_FIFO priority of the real-time runs (the daemon's default).
    pub priority: u8,
    pub core: usize,
    /// The hybrid wait's spin window (the daemon's default).
    pub spin_us: f64,
    /// cyclictest's histogram limit.
    pub limit_us: u64,
}

impl Options {
    pub fn new(quick: bool) -> Self {
        let d = daemon::config::DaemonConfig::default();
        Self {
            rates: vec![1_000, 5_000, 10_000],
            rounds: if quick { 3 } else { 12 },
            block: Duration::from_millis(if quick { 150 } else { 500 }),
            priority: d.priority,
            core: d.core.unwrap_or(1),
            spin_us: d.spin_us,
            limit_us: 20_000,
        }
    }

    pub fn validate(&self) -> Result<()> {
        if !(1..=98).contains(&self.priority) {
            bail!("jitter priority {}: must be 1..=98 (99 would let a spinning loop starve the kernel's own threads)", self.priority);
        }
        if self.block < Duration::from_millis(20) || self.block > Duration::from_millis(500) {
            bail!("jitter block {:?}: must be 20..=500 ms (a SCHED_FIFO spin holds its core for one block)", self.block);
        }
        if self.rounds == 0 {
            bail!("jitter rounds must be at least 1");
        }
        if self
            .rates
            .iter()
            .any(|&r| !(100..=20_000).contains(&r) || 1_000_000 % r != 0)
        {
            bail!("jitter rates {:?}: each must be 100..=20000 Hz with a whole-µs period (cyclictest's unit)", self.rates);
        }
        Ok(())
    }
}

/// Our loop, on its own thread: `loops` ticks at `rate`, lateness in ns, plus skipped periods.
fn our_block(
    cfg: Cfg,
    strategy: WaitStrategy,
    opts: &Options,
    loops: u64,
) -> Result<(Histogram<u64>, u64, rt::setup::RtReport)> {
    let (core, priority, spin_ns) = (
        opts.core,
        if cfg.fifo { opts.priority } else { 0 },
        (opts.spin_us * 1000.0) as u64,
    );
    std::thread::Builder::new()
        .name("jitter-loop".into())
        .spawn(move || {
            let rt = rt::setup::apply(rt::setup::RtRequest {
                core: Some(core),
                priority,
                lock_memory: true,
            });
            let mut h = histogram();
            let period = 1_000_000_000 / u64::from(cfg.rate_hz);
            let mut sched = Schedule::new(period, rt::monotonic_ns());
            for _ in 0..loops {
                let deadline = sched.deadline();
                let woke = rt::wait_until(deadline, strategy, spin_ns);
                h.saturating_record(woke.saturating_sub(deadline).max(1));
                sched.advance(rt::monotonic_ns());
            }
            (h, sched.overruns, rt)
        })?
        .join()
        .map_err(|_| anyhow!("the jitter loop thread panicked"))
}

/// One cyclictest run: its lateness histogram and its overflow count.
fn cyclictest_block(
    exe: &Path,
    cfg: Cfg,
    pm_qos: bool,
    opts: &Options,
    loops: u64,
    report: &Report,
) -> Result<(Histogram<u64>, u64)> {
    let period_us = 1_000_000 / u64::from(cfg.rate_hz);
    let mut cmd = Command::new(exe);
    cmd.args(cyclictest::args(
        opts.core,
        cfg.fifo.then_some(opts.priority),
        period_us,
        loops,
        opts.limit_us,
        pm_qos,
    ));
    let log = report.path(&format!("{}.txt", cfg.slug()));
    let mut c = Child::spawn("cyclictest", cmd, &log, Stdout::Log)?;
    c.wait_success(Duration::from_secs(15) + Duration::from_micros(period_us * loops) * 2)?;
    let text = std::fs::read_to_string(&log)?;
    let r = cyclictest::parse(&text, opts.limit_us)
        .map_err(|e| c.failure(&format!("its output is unreadable: {e:#}")))?;
    Ok((r.hist, r.overflows))
}

struct Series {
    hist: Histogram<u64>,
    /// Periods our loop skipped, or cyclictest's histogram overflows.
    overruns: u64,
}

pub fn run(opts: &Options, out: &Path, command: &str) -> Result<Output> {
    opts.validate()?;
    let mut report = Report::new(out, "jitter")?;
    let ct = cyclictest::find();
    let mut methods: Vec<Method> = WaitStrategy::ALL.iter().map(|&w| Method::Wait(w)).collect();
    if ct.is_some() {
        methods.push(CYCLICTEST);
        methods.push(Method::Cyclictest { pm_qos: false });
    }
    let pairs: Vec<(u32, Method)> = opts
        .rates
        .iter()
        .flat_map(|&r| methods.iter().map(move |&m| (r, m)))
        .collect();
    let mut results: HashMap<Cfg, Series> = HashMap::new();
    let mut fifo_refused: Option<String> = None;
    let mut ct_failed: Option<String> = None;
    let t0 = std::time::Instant::now();
    for order in interleave(&pairs, opts.rounds) {
        for (rate_hz, method) in order {
            for fifo in [false, true] {
                if rt::signal::stop_requested() {
                    bail!("interrupted");
                }
                if (fifo && fifo_refused.is_some())
                    || (matches!(method, Method::Cyclictest { .. }) && ct_failed.is_some())
                {
                    continue;
                }
                let cfg = Cfg {
                    rate_hz,
                    method,
                    fifo,
                };
                let loops = (opts.block.as_secs_f64() * f64::from(rate_hz)).round() as u64;
                let (h, overruns) = match (method, &ct) {
                    (Method::Wait(w), _) => {
                        let (h, o, rt) = our_block(cfg, w, opts, loops)?;
                        if fifo && rt.sched_fifo.is_none() {
                            fifo_refused = Some(rt.warnings.join("; "));
                            continue;
                        }
                        (h, o)
                    }
                    (Method::Cyclictest { pm_qos }, Some(exe)) => {
                        match with_fine_slack(|| {
                            cyclictest_block(exe, cfg, pm_qos, opts, loops, &report)
                        }) {
                            Ok(r) => r,
                            Err(e) => {
                                // The reference failing (no permission, a different build)
                                // does not invalidate our own rows: report it and go on.
                                ct_failed = Some(format!("{e:#}"));
                                continue;
                            }
                        }
                    }
                    (Method::Cyclictest { .. }, None) => {
                        unreachable!("cyclictest is only planned when found")
                    }
                };
                let s = results.entry(cfg).or_insert_with(|| Series {
                    hist: histogram(),
                    overruns: 0,
                });
                s.hist
                    .add(&h)
                    .map_err(|e| anyhow!("histogram merge: {e:?}"))?;
                s.overruns += overruns;
            }
        }
    }
    // The loop threads locked the process's memory, as the daemon does; later benchmarks should
    // not inherit that.
    // SAFETY: plain syscall.
    unsafe { libc::munlockall() };

    report.push(&header("Loop wake-up lateness", command));
    report.push(&format!(
        "A fixed-rate loop on core {} wakes for absolute deadlines and records wake-up time − deadline. chaosd's \
         loops use `rt::wait_until` (hybrid: sleep, then spin the last {} µs, the daemon's default); cyclictest \
         (rt-tests) uses clock_nanosleep. By default cyclictest also holds /dev/cpu_dma_latency at 0 µs while it \
         runs (idle CPUs poll instead of halting, which shortens wake-ups); `cyclictest --default-system` runs \
         without that, as chaosd's loops do. SCHED_FIFO runs use priority {}; every run locks memory and has a \
         1 ns timer slack. {} interleaved rounds of {} ms blocks per configuration, {:.0} s in all.\n\n",
        opts.core,
        opts.spin_us,
        opts.priority,
        opts.rounds,
        opts.block.as_millis(),
        t0.elapsed().as_secs_f64()
    ));
    if ct.is_none() {
        report.push("cyclictest is not installed, so its rows are missing and the hybrid-versus-cyclictest target is not checked: run `scripts/install-cyclictest.sh`.\n\n");
    }
    if let Some(why) = &ct_failed {
        report.push(&format!(
            "cyclictest failed, so its rows are missing or incomplete and the target below is not checked where they are: {why}\n\n"
        ));
    }
    if let Some(why) = &fifo_refused {
        report.push(&format!(
            "SCHED_FIFO was refused ({why}); only SCHED_OTHER rows were measured.\n\n"
        ));
    }
    let (text, targets) = table(opts, &methods, &results);
    report.run_detail(format!(
        "{} rounds × {} ms blocks per configuration",
        opts.rounds,
        opts.block.as_millis()
    ));
    report.table(crate::book::names::JITTER, &text)?;
    report.push("\n");
    for t in &targets {
        report.push(&t.line());
    }

    let mut panels = Vec::new();
    for &rate in &opts.rates {
        let mut series = Vec::new();
        for &m in &methods {
            for fifo in [false, true] {
                let cfg = Cfg {
                    rate_hz: rate,
                    method: m,
                    fifo,
                };
                if let Some(s) = results.get(&cfg) {
                    report.hgrm(&cfg.slug(), &s.hist)?;
                    series.push(Dist::of_histogram(&cfg.label(), &s.hist));
                }
            }
        }
        panels.push(Panel {
            title: format!("{} kHz", f64::from(rate) / 1000.0),
            quantity: "wake-up lateness".into(),
            series,
        });
    }
    report.plot("chaosd-bench jitter: loop wake-up lateness", &panels)?;
    report.finish()
}

/// The table, and per rate and scheduler the target "the daemon's hybrid wait beats cyclictest's
/// p99" as the ratio cyclictest p99 / hybrid p99 (> 1 when hybrid is better).
fn table(
    opts: &Options,
    methods: &[Method],
    results: &HashMap<Cfg, Series>,
) -> (String, Vec<Target>) {
    let mut t = Table::new(&[
        "rate",
        "wait",
        "scheduler",
        "p50",
        "p90",
        "p99",
        "p99.9",
        "max",
        "skipped periods",
    ]);
    // cyclictest reports no skipped periods; its column shows wake-ups beyond its histogram.
    let mut targets = Vec::new();
    for &rate in &opts.rates {
        for fifo in [true, false] {
            for &m in methods {
                let cfg = Cfg {
                    rate_hz: rate,
                    method: m,
                    fifo,
                };
                let Some(s) = results.get(&cfg) else { continue };
                let p = summary(&s.hist);
                let mut row = vec![
                    format!("{} kHz", f64::from(rate) / 1000.0),
                    m.label(),
                    cfg.sched().into(),
                ];
                row.extend(p.iter().map(|&v| fmt_ns(v as f64)));
                row.push(if matches!(m, Method::Cyclictest { .. }) {
                    format!("n/a ({} over {} ms)", s.overruns, opts.limit_us / 1000)
                } else {
                    s.overruns.to_string()
                });
                t.row(row);
            }
            let p99 = |m: Method| {
                results
                    .get(&Cfg {
                        rate_hz: rate,
                        method: m,
                        fifo,
                    })
                    .map_or(f64::NAN, |s| summary(&s.hist)[2] as f64)
            };
            if methods.contains(&CYCLICTEST)
                && results.contains_key(&Cfg {
                    rate_hz: rate,
                    method: CYCLICTEST,
                    fifo,
                })
            {
                targets.push(Target::new(
                    format!(
                        "{} kHz, {}: cyclictest p99 / chaosd hybrid p99 ({} vs {})",
                        f64::from(rate) / 1000.0,
                        if fifo { "SCHED_FIFO" } else { "SCHED_OTHER" },
                        fmt_ns(p99(CYCLICTEST)),
                        fmt_ns(p99(Method::Wait(WaitStrategy::Hybrid)))
                    ),
                    ratio(p99(CYCLICTEST), p99(Method::Wait(WaitStrategy::Hybrid))),
                    Bound::AtLeast(1.0),
                ));
            }
        }
    }
    (t.render(), targets)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_refuse_unsafe_settings() {
        let mut o = Options::new(true);
        assert!(o.validate().is_ok());
        o.priority = 99;
        assert!(o.validate().unwrap_err().to_string().contains("1..=98"));
        let mut o = Options::new(false);
        o.block = Duration::from_secs(2);
        assert!(o.validate().is_err());
        let mut o = Options::new(false);
        o.rates = vec![3_000];
        assert!(o.validate().is_err(), "333.33 µs is not a whole-µs period");
    }

    #[test]
    fn a_short_loop_records_every_tick() {
        let o = Options::new(true);
        let cfg = Cfg {
            rate_hz: 5_000,
            method: Method::Wait(WaitStrategy::Spin),
            fifo: false,
        };
        // Every tick is recorded, late or not (how late depends on the machine's load).
        let (h, _, _) = our_block(cfg, WaitStrategy::Spin, &o, 200).unwrap();
        assert_eq!(h.len(), 200);
        assert_eq!(cfg.slug(), "5000hz-chaosd-spin-other");
    }

    #[test]
    fn hybrid_versus_cyclictest_target() {
        let o = Options {
            rates: vec![1_000],
            ..Options::new(true)
        };
        let methods = [Method::Wait(WaitStrategy::Hybrid), CYCLICTEST];
        let series = |ns: u64| {
            let mut h = histogram();
            for i in 0..1000 {
                h.record(ns + i).unwrap();
            }
            Series {
                hist: h,
                overruns: 0,
            }
        };
        let mut r = HashMap::new();
        r.insert(
            Cfg {
                rate_hz: 1_000,
                method: methods[0],
                fifo: true,
            },
            series(500),
        );
        r.insert(
            Cfg {
                rate_hz: 1_000,
                method: methods[1],
                fifo: true,
            },
            series(20_000),
        );
        r.insert(
            Cfg {
                rate_hz: 1_000,
                method: methods[0],
                fifo: false,
            },
            series(40_000),
        );
        r.insert(
            Cfg {
                rate_hz: 1_000,
                method: methods[1],
                fifo: false,
            },
            series(20_000),
        );
        let (text, targets) = table(&o, &methods, &r);
        assert_eq!(targets.len(), 2);
        assert!(
            targets[0].what.contains("SCHED_FIFO") && targets[0].met(),
            "{targets:?}"
        );
        assert!(
            targets[1].what.contains("SCHED_OTHER") && !targets[1].met(),
            "{targets:?}"
        );
        assert!(
            text.contains("| 1 kHz | cyclictest | SCHED_FIFO |"),
            "{text}"
        );
    }
}
