//! `e2e`: the real `chaosd` and `chaosd-plant` processes, as a user runs them, at several rates.
//!
//! Per rate, a config with only `[daemon]` and `[plant]` tables is written (unique namespace, the
//! rate, output into this benchmark's directory, no status lines); everything else keeps the
//! defaults a user gets: hybrid waits, the daemon on core 1 and the plant on core 0 at SCHED_FIFO
//! 50, memory locked. The plant starts first, then the daemon runs for a fixed time and exits by
//! itself; the plant is then stopped with SIGTERM so it writes its summary.
//!
//! The numbers come from the processes' own summaries (`daemon-summary.json`,
//! `plant-summary.json`) and `.hgrm` files, so this benchmark reports exactly what the daemon
//! measures about itself. CPU use is sampled from `/proc/<pid>/stat` (utime + stime, all
//! threads) over a window inside the daemon's run, start-up and shutdown excluded.

use crate::child::{clock_ticks_per_s, cpu_ticks, Child, Stdout};
use crate::latency::unique_namespace;
use crate::plot::Panel;
use crate::report::{header, Report};
use crate::stats::{fmt_ns, Dist, Table};
use anyhow::{anyhow, bail, Context, Result};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

#[derive(Clone, Debug)]
pub struct Options {
    pub rates: Vec<f64>,
    /// How long the daemon runs per rate.
    pub seconds: f64,
}

impl Options {
    pub fn new(quick: bool) -> Self {
        Self {
            rates: vec![1_000.0, 2_000.0, 5_000.0, 10_000.0],
            seconds: if quick { 3.0 } else { 20.0 },
        }
    }

    pub fn validate(&self) -> Result<()> {
        if self.rates.is_empty()
            || self
                .rates
                .iter()
                .any(|r| !(r.is_finite() && (100.0..=10_000.0).contains(r)))
        {
            bail!(
                "e2e rates {:?}: each must be between 100 and 10000 Hz (the daemon's range)",
                self.rates
            );
        }
        if !(self.seconds.is_finite() && (2.5..=3600.0).contains(&self.seconds)) {
            bail!("e2e seconds {}: must be between 2.5 and 3600", self.seconds);
        }
        Ok(())
    }
}

/// `chaosd` or `chaosd-plant`, next to this executable.
fn sibling(name: &str) -> Result<PathBuf> {
    let me = std::env::current_exe().context("cannot locate the chaosd-bench executable")?;
    let p = me.with_file_name(name);
    if !p.is_file() {
        bail!(
            "{} not found next to chaosd-bench: build it into the same target directory first, \
             e.g. `cargo build --release -p daemon -p plant` (with the same CARGO_TARGET_DIR)",
            p.display()
        );
    }
    Ok(p)
}

/// The config file of one rate.
pub fn config_text(namespace: &str, dir: &Path, rate_hz: f64) -> String {
    // TOML strings: the path is written as a literal string, so no escaping is needed unless it
    // holds a quote, which `run` refuses.
    format!(
        "[daemon]\nnamespace = \"{namespace}\"\noutput_dir = '{dir}'\nrate_hz = {rate_hz:.1}\nreport_every_s = 0.0\n\n\
         [plant]\nnamespace = \"{namespace}\"\noutput_dir = '{dir}'\nrate_hz = {rate_hz:.1}\n",
        dir = dir.display()
    )
}

/// What one rate measured.
#[derive(Debug, Clone)]
pub struct RateResult {
    pub rate_hz: f64,
    /// Status requests answered during the run, when a client hammered the control service.
    pub requests: Option<u64>,
    pub daemon: Value,
    pub plant: Value,
    pub cpu_daemon: f64,
    pub cpu_plant: f64,
    pub dir: PathBuf,
}

fn read_json(path: &Path) -> Result<Value> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{} is not JSON", path.display()))
}

/// Sends status requests back to back to the daemon in `ns` until `stop`: what a misbehaving
/// monitoring script would do. Returns how many were answered.
fn hammer(ns: String, stop: Arc<AtomicBool>) -> std::thread::JoinHandle<u64> {
    std::thread::spawn(move || {
        let Ok(node) = protocol::node("bench-hammer") else {
            return 0;
        };
        let Ok(names) = protocol::ServiceNames::new(&ns) else {
            return 0;
        };
        let mut answered = 0;
        while !stop.load(Ordering::Relaxed) {
            let Ok(svc) = protocol::control::open_control_service(&node, &names) else {
                std::thread::sleep(Duration::from_millis(10)); // the daemon is not up yet
                continue;
            };
            let Ok(client) = svc.client_builder().create() else {
                return answered;
            };
            while !stop.load(Ordering::Relaxed) {
                let Ok(req) = protocol::ControlRequest::new(answered, protocol::Op::Status, "")
                else {
                    return answered;
                };
                let Ok(pending) = client.send_copy(req) else {
                    break;
                };
                let until = Instant::now() + Duration::from_millis(200);
                while Instant::now() < until {
                    if let Ok(Some(_)) = pending.receive() {
                        answered += 1;
                        break;
                    }
                    std::hint::spin_loop();
                }
            }
        }
        answered
    })
}

fn one_rate(opts: &Options, rate_hz: f64, report: &Report, hammered: bool) -> Result<RateResult> {
    let (chaosd, plant_exe) = (sibling("chaosd")?, sibling("chaosd-plant")?);
    let dir = report.path(&if hammered {
        format!("{rate_hz:.0}hz-hammered")
    } else {
        format!("{rate_hz:.0}hz")
    });
    std::fs::create_dir_all(&dir)?;
    for f in ["daemon-summary.json", "plant-summary.json"] {
        let _ = std::fs::remove_file(dir.join(f));
    }
    let cfg = dir.join("config.toml");
    let ns = unique_namespace("e2e");
    std::fs::write(&cfg, config_text(&ns, &dir, rate_hz))?;

    let mut cmd = Command::new(&plant_exe);
    cmd.arg("--config")
        .arg(&cfg)
        .args(["--duration", &format!("{}", opts.seconds + 30.0)]);
    let mut plant = Child::spawn("chaosd-plant", cmd, &dir.join("plant.log"), Stdout::Log)?;
    std::thread::sleep(Duration::from_millis(300));
    if plant.poll_exit().is_some() {
        return Err(plant.failure("it stopped at start-up"));
    }
    let mut cmd = Command::new(&chaosd);
    cmd.arg("run")
        .arg("--config")
        .arg(&cfg)
        .args(["--duration", &format!("{}", opts.seconds)]);
    let started = Instant::now();
    let mut daemon = Child::spawn("chaosd", cmd, &dir.join("daemon.log"), Stdout::Log)?;
    let (pid_d, pid_p) = (daemon.pid().unwrap_or(0), plant.pid().unwrap_or(0));
    let stop = Arc::new(AtomicBool::new(false));
    let client = hammered.then(|| hammer(ns.clone(), stop.clone()));

    // CPU window: from 1 s in (start-up done) to 0.3 s before the daemon's end.
    let window = (
        Duration::from_secs(1),
        Duration::from_secs_f64(opts.seconds - 0.3),
    );
    let mut first: Option<(Instant, u64, u64)> = None;
    let mut last: Option<(Instant, u64, u64)> = None;
    let limit = Duration::from_secs_f64(opts.seconds + 30.0);
    loop {
        if let Some(st) = daemon.poll_exit() {
            if !st.success() {
                return Err(daemon.failure("it failed"));
            }
            break;
        }
        if rt::signal::stop_requested() {
            bail!("interrupted");
        }
        if plant.poll_exit().is_some() {
            return Err(plant.failure("it stopped while the daemon was running"));
        }
        let t = started.elapsed();
        if t > limit {
            daemon.kill();
            return Err(daemon.failure(&format!(
                "it did not finish its {} s run within {limit:?}",
                opts.seconds
            )));
        }
        if t >= window.0 && first.is_none() {
            first = Some((Instant::now(), cpu_ticks(pid_d)?, cpu_ticks(pid_p)?));
        }
        if t >= window.1 && last.is_none() {
            last = Some((Instant::now(), cpu_ticks(pid_d)?, cpu_ticks(pid_p)?));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    stop.store(true, Ordering::Relaxed);
    let requests = client.map(|h| h.join().unwrap_or(0));
    plant.terminate(Duration::from_secs(10))?;
    if plant.poll_exit().is_some_and(|s| !s.success()) {
        return Err(plant.failure("it failed"));
    }
    let (Some(a), Some(b)) = (first, last) else {
        bail!(
            "chaosd exited after {:.1} s, before the CPU sampling window ended",
            started.elapsed().as_secs_f64()
        );
    };
    let (secs, hz) = (b.0.duration_since(a.0).as_secs_f64(), clock_ticks_per_s());
    Ok(RateResult {
        rate_hz,
        requests,
        daemon: read_json(&dir.join("daemon-summary.json"))?,
        plant: read_json(&dir.join("plant-summary.json"))?,
        cpu_daemon: (b.1 - a.1) as f64 / hz / secs,
        cpu_plant: (b.2 - a.2) as f64 / hz / secs,
        dir,
    })
}

/// A percentile (µs in the summaries) as text.
fn us(v: &Value, key: &str, p: &str) -> String {
    v[key][p]
        .as_f64()
        .map_or_else(|| "n/a".into(), |x| fmt_ns(x * 1e3))
}

fn count(v: &Value, path: &[&str]) -> String {
    let mut x = v;
    for k in path {
        x = &x[*k];
    }
    x.as_u64().map_or_else(|| "n/a".into(), |n| n.to_string())
}

pub fn table(results: &[RateResult]) -> String {
    let mut t = Table::new(&[
        "rate",
        "daemon ticks",
        "overruns (daemon / plant)",
        "daemon wake-up p50 / p99 / max",
        "state age p50 / p99",
        "command round trip p50 / p99 / p99.9 / max",
        "CPU daemon",
        "CPU plant",
    ]);
    for r in results {
        let (d, p) = (&r.daemon, &r.plant);
        t.row(vec![
            format!("{} kHz", r.rate_hz / 1000.0),
            count(d, &["counters", "ticks"]),
            format!(
                "{} / {}",
                count(d, &["counters", "overruns"]),
                count(p, &["counters", "overruns"])
            ),
            format!(
                "{} / {} / {}",
                us(d, "lateness", "p50_us"),
                us(d, "lateness", "p99_us"),
                us(d, "lateness", "max_us")
            ),
            format!(
                "{} / {}",
                us(d, "state_age", "p50_us"),
                us(d, "state_age", "p99_us")
            ),
            format!(
                "{} / {} / {} / {}",
                us(p, "round_trip", "p50_us"),
                us(p, "round_trip", "p99_us"),
                us(p, "round_trip", "p999_us"),
                us(p, "round_trip", "max_us")
            ),
            format!("{:.0} %", r.cpu_daemon * 100.0),
            format!("{:.0} %", r.cpu_plant * 100.0),
        ]);
    }
    t.render()
}

/// The idle and the hammered run side by side.
pub fn hammer_table(idle: &RateResult, hammered: &RateResult) -> String {
    let mut t = Table::new(&[
        "run",
        "status requests answered",
        "daemon ticks",
        "overruns",
        "wake-up p99 / p99.9 / max",
        "compute p99 / p99.9 / max",
    ]);
    for (name, r) in [("idle", idle), ("hammered", hammered)] {
        let d = &r.daemon;
        t.row(vec![
            name.into(),
            r.requests.map_or_else(|| "0".into(), |n| n.to_string()),
            count(d, &["counters", "ticks"]),
            count(d, &["counters", "overruns"]),
            format!(
                "{} / {} / {}",
                us(d, "lateness", "p99_us"),
                us(d, "lateness", "p999_us"),
                us(d, "lateness", "max_us")
            ),
            format!(
                "{} / {} / {}",
                us(d, "compute", "p99_us"),
                us(d, "compute", "p999_us"),
                us(d, "compute", "max_us")
            ),
        ]);
    }
    t.render()
}

pub fn run(opts: &Options, out: &Path, command: &str) -> Result<String> {
    opts.validate()?;
    let mut report = Report::new(out, "e2e")?;
    if report.dir.display().to_string().contains(['\'', '\n']) {
        bail!(
            "the output directory {} holds a quote or newline, which the config file cannot carry",
            report.dir.display()
        );
    }
    let mut results = Vec::new();
    for &rate in &opts.rates {
        results.push(
            one_rate(opts, rate, &report, false).with_context(|| format!("e2e at {rate} Hz"))?,
        );
    }
    // Does the control service disturb the loop? The first rate again, with a client sending
    // status requests back to back for the whole run.
    let hammered = one_rate(opts, opts.rates[0], &report, true)
        .with_context(|| "e2e with a client hammering status requests")?;
    let rt_line = |v: &Value| match v["realtime"]["sched_fifo"].as_u64() {
        Some(p) => format!("SCHED_FIFO {p}"),
        None => format!("SCHED_OTHER ({})", v["realtime"]["warnings"]),
    };
    report.push(&header("End to end: chaosd and chaosd-plant", command));
    report.push(&format!(
        "The daemon (core 1, {}) and the plant (core 0, {}) with default settings (hybrid waits, memory locked), \
         {} s per rate. Wake-up lateness and state age as the daemon measures them; the command round trip is \
         the plant's: state published → answering command picked up at the plant's next tick, so it includes \
         waiting for that tick. State age is the age of the newest state at the daemon's tick; the two loops start \
         independently, so it is set by their phase and lies anywhere within one period. CPU is utime + stime over the run (100 % = one core).\n\n",
        results.first().map_or("?".into(), |r| rt_line(&r.daemon)),
        results.first().map_or("?".into(), |r| rt_line(&r.plant)),
        opts.seconds
    ));
    report.push(&table(&results));
    report.push(&format!(
        "\n**Control requests vs the loop** at {} kHz: the same run idle and with a client sending `status` requests \
         back to back (each answered before the next is sent) for the whole run.\n\n",
        hammered.rate_hz / 1000.0
    ));
    report.push(&hammer_table(&results[0], &hammered));
    let mut panels = vec![
        Panel {
            title: "command round trip (plant)".into(),
            quantity: "round trip".into(),
            series: Vec::new(),
        },
        Panel {
            title: "daemon wake-up lateness".into(),
            quantity: "lateness".into(),
            series: Vec::new(),
        },
        Panel {
            title: "state age at the daemon's tick".into(),
            quantity: "state age".into(),
            series: Vec::new(),
        },
    ];
    for r in &results {
        let label = format!("{} kHz", r.rate_hz / 1000.0);
        for (panel, file) in panels.iter_mut().zip([
            "plant-round-trip.hgrm",
            "daemon-lateness.hgrm",
            "daemon-state-age.hgrm",
        ]) {
            let path = r.dir.join(file);
            let text = std::fs::read_to_string(&path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            panel.series.push(
                Dist::from_hgrm(&label, &text).with_context(|| format!("in {}", path.display()))?,
            );
            report.files.push(path);
        }
    }
    report.plot("chaosd-bench e2e: daemon and plant processes", &panels)?;
    if results
        .iter()
        .any(|r| r.daemon["counters"]["ticks"].as_u64().unwrap_or(0) == 0)
    {
        return Err(anyhow!(
            "a daemon run recorded no ticks; see the logs under {}",
            report.dir.display()
        ));
    }
    report.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_is_a_valid_daemon_and_plant_config() {
        let text = config_text("bench-e2e-1-2", Path::new("/tmp/x y/1000hz"), 5_000.0);
        let cfg = control::Config::from_toml_str(&text).unwrap();
        let d = daemon::config::DaemonSetup::from_config(cfg.clone()).unwrap();
        assert_eq!(d.daemon.rate_hz, 5_000.0);
        assert_eq!(d.daemon.namespace, "bench-e2e-1-2");
        assert_eq!(d.daemon.output_dir, Path::new("/tmp/x y/1000hz"));
        assert_eq!(d.daemon.report_every_s, 0.0);
        let plant = cfg.plant.as_ref().unwrap();
        assert_eq!(plant["rate_hz"].as_float(), Some(5_000.0));
        assert_eq!(plant["namespace"].as_str(), Some("bench-e2e-1-2"));
    }

    #[test]
    fn table_reads_the_summaries() {
        let daemon: Value = serde_json::json!({
            "counters": {"ticks": 10000, "overruns": 3},
            "lateness": {"p50_us": 1.5, "p99_us": 12.0, "max_us": 900.0},
            "state_age": {"p50_us": 40.0, "p99_us": 95.0}
        });
        let plant: Value = serde_json::json!({
            "counters": {"overruns": 0},
            "round_trip": {"p50_us": 1000.0, "p99_us": 1010.0, "p999_us": 1100.0, "max_us": 2500.0}
        });
        let r = RateResult {
            rate_hz: 1000.0,
            requests: None,
            daemon,
            plant,
            cpu_daemon: 0.12,
            cpu_plant: 0.3,
            dir: PathBuf::new(),
        };
        let hammered = RateResult {
            requests: Some(1234),
            ..r.clone()
        };
        let h = hammer_table(&r, &hammered);
        assert!(
            h.contains("| idle | 0 | 10000 | 3 |") && h.contains("| hammered | 1234 | 10000 | 3 |"),
            "{h}"
        );
        let t = table(&[r]);
        assert!(
            t.contains(
                "| 1 kHz | 10000 | 3 / 0 | 1.50 µs / 12.00 µs / 900.00 µs | 40.00 µs / 95.00 µs |"
            ),
            "{t}"
        );
        assert!(
            t.contains("1.00 ms / 1.01 ms / 1.10 ms / 2.50 ms | 12 % | 30 % |"),
            "{t}"
        );
    }

    #[test]
    fn missing_binaries_are_named() {
        // The test executable lives in deps/, where no chaosd is.
        let e = sibling("chaosd-definitely-not-built")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("chaosd-definitely-not-built not found next to chaosd-bench"),
            "{e}"
        );
        assert!(Options {
            rates: vec![50.0],
            seconds: 3.0
        }
        .validate()
        .is_err());
        assert!(Options {
            rates: vec![1000.0],
            seconds: 1.0
        }
        .validate()
        .is_err());
    }
}
