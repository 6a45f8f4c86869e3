//! `e2e`: the real `chaosd` and `chaosd-plant` processes, as a user runs them, at several rates.
//!
//! Per rate, a config with only `[daemon]` and `[plant]` tables is written (unique namespace, the
//! rate, output into this benchmark's directory, no status lines); everything else keeps the
//! defaults a user gets: hybrid waits, the daemon on core 1 and the plant on core 0 at SCHED_FIFO
//! 50, memory locked. The plant starts first, then the daemon runs for a fixed time and exits by
//! itself; the plant is then stopped with SIGTERM so it writes its summary.
//!
//! The modes side by side: today's free-running loops (`trigger = "clock"`), the same
//! phase-locked, the state trigger over iceoryx2 (`trigger = "state"`: each state answered in its
//! own cycle) with pub-sub alone and with the fast lane (`protocol::board`, the default), and the
//! state trigger through the UDP bridge (`chaosd-fakebot` owning the clock ⇄ `chaosd-bridge` ⇄
//! `chaosd`, on the loopback), with the device placed beside the bridge and, as before,
//! unpinned. The first table keeps the free-running figures; the second puts the modes next to
//! each other at every rate, so the lane's gain and the placement's are ratios within one run.
//!
//! The numbers come from the processes' own summaries (`daemon-summary.json`,
//! `plant-summary.json`) and `.hgrm` files, so this benchmark reports exactly what the daemon
//! measures about itself. CPU use is sampled from `/proc/<pid>/stat` (utime + stime, all
//! threads) over a window inside the daemon's run, start-up and shutdown excluded.

pub mod late;
pub mod result;

use crate::book::names;
use crate::child::{clock_ticks_per_s, cpu_ticks, steal_ticks, Child, Stdout};
use crate::latency::unique_namespace;
use crate::plot::Panel;
use crate::report::{header, Output, Report};
use crate::stats::{fmt_ns, Bound, Dist, Table, Target};
use anyhow::{anyhow, bail, Context, Result};
use result::{Mode, RateResult};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

#[derive(Clone, Debug)]
pub struct Options {
    pub rates: Vec<f64>,
    /// The modes to run at every rate.
    pub modes: Vec<Mode>,
    /// How long the daemon runs per rate.
    pub seconds: f64,
    /// `spin_us` of the daemon and the plant, if not their default.
    pub spin_us: Option<f64>,
}

/// Where chaosd-fakebot runs in the UDP mode. A device has its own hardware and clock; on this
/// 2-vCPU machine it must share a core, and unpinned at the normal scheduler it is kept off both
/// by the two SCHED_FIFO loops polling for their inputs. So it runs beside the plant: on its
/// core, above its priority, blocking for each answer (see `plant::udp::fakebot::Placement`;
/// docs/performance.md, "The device beside the bridge", has the numbers).
pub const DEVICE_ARGS: [&str; 1] = ["--beside-plant"];

impl Options {
    pub fn new(quick: bool) -> Self {
        Self {
            rates: vec![1_000.0, 2_000.0, 5_000.0, 10_000.0],
            modes: Mode::ALL.to_vec(),
            seconds: if quick { 3.0 } else { 20.0 },
            spin_us: None,
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
        if self.modes.is_empty() {
            bail!("e2e modes: at least one of clock, phase, pubsub, state, udp, udp-free");
        }
        if let Some(s) = self.spin_us {
            if !(s.is_finite() && (0.0..=100_000.0).contains(&s)) {
                bail!("e2e spin-us {s}: must be between 0 and 100000");
            }
        }
        if !(self.seconds.is_finite() && (2.5..=3600.0).contains(&self.seconds)) {
            bail!("e2e seconds {}: must be between 2.5 and 3600", self.seconds);
        }
        Ok(())
    }
}

/// `chaosd` or `chaosd-plant`, next to this executable.
pub(crate) fn sibling(name: &str) -> Result<PathBuf> {
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

/// The phase-locked mode's offset at `rate_hz`: 100 µs, or a quarter period at high rates. It
/// must exceed the plant's publishing delay after its stamp (its wake-up and one integration).
pub fn phase_offset_us(rate_hz: f64) -> f64 {
    (0.25e6 / rate_hz).min(100.0)
}

/// The config file of one rate.
pub fn config_text(
    namespace: &str,
    dir: &Path,
    rate_hz: f64,
    mode: Mode,
    spin_us: Option<f64>,
) -> String {
    let trigger = match mode {
        Mode::Clock | Mode::Phase => "clock",
        Mode::State | Mode::PubSub | Mode::Udp | Mode::UdpFree => "state",
    };
    let lane = if mode == Mode::PubSub {
        "fast_lane = false\n"
    } else {
        ""
    };
    let phase = if mode == Mode::Phase {
        format!("phase_offset_us = {:.1}\n", phase_offset_us(rate_hz))
    } else {
        String::new()
    };
    let spin = spin_us.map_or(String::new(), |s| format!("spin_us = {s:.1}\n"));
    // A state may be a whole period old when read: at low rates, more than the default 5 ms.
    let stale_ms = (2e3 / rate_hz).max(5.0);
    // TOML strings: the path is written as a literal string, so no escaping is needed unless it
    // holds a quote, which `run` refuses.
    format!(
        "[daemon]\nnamespace = \"{namespace}\"\noutput_dir = '{dir}'\nrate_hz = {rate_hz:.1}\nreport_every_s = 0.0\nstale_ms = {stale_ms:.1}\ntrigger = \"{trigger}\"\n{lane}{phase}{spin}\n\
         [plant]\nnamespace = \"{namespace}\"\noutput_dir = '{dir}'\nrate_hz = {rate_hz:.1}\ntrigger = \"{trigger}\"\n{lane}{spin}",
        dir = dir.display()
    )
}

pub(crate) fn read_json(path: &Path) -> Result<Value> {
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

/// Two free UDP ports on the loopback for the device and the bridge.
fn free_udp_ports() -> Result<(u16, u16)> {
    let a = std::net::UdpSocket::bind("127.0.0.1:0").context("no free UDP port")?;
    let b = std::net::UdpSocket::bind("127.0.0.1:0").context("no free UDP port")?;
    Ok((a.local_addr()?.port(), b.local_addr()?.port()))
}

/// The plant side: chaosd-plant, or chaosd-fakebot (returned second) and chaosd-bridge.
fn spawn_plant_side(
    mode: Mode,
    cfg: &Path,
    dir: &Path,
    secs: f64,
) -> Result<(Child, Option<Child>)> {
    let base = |exe: &Path| {
        let mut cmd = Command::new(exe);
        cmd.arg("--config")
            .arg(cfg)
            .args(["--duration", &format!("{}", secs + 30.0)]);
        cmd
    };
    if !mode.is_udp() {
        let cmd = base(&sibling("chaosd-plant")?);
        let plant = Child::spawn("chaosd-plant", cmd, &dir.join("plant.log"), Stdout::Log)?;
        return Ok((plant, None));
    }
    let (d, b) = free_udp_ports()?;
    let (d, b) = (format!("127.0.0.1:{d}"), format!("127.0.0.1:{b}"));
    let mut cmd = base(&sibling("chaosd-fakebot")?);
    cmd.args(["--listen", &d, "--peer", &b, "--summary"])
        .arg(dir.join(DEVICE_SUMMARY));
    if mode == Mode::Udp {
        cmd.args(DEVICE_ARGS);
    }
    let device = Child::spawn("chaosd-fakebot", cmd, &dir.join("fakebot.log"), Stdout::Log)?;
    let mut cmd = base(&sibling("chaosd-bridge")?);
    cmd.args(["--device", &d, "--bind", &b]);
    let bridge = Child::spawn("chaosd-bridge", cmd, &dir.join("plant.log"), Stdout::Log)?;
    Ok((bridge, Some(device)))
}

/// Where the UDP modes' device ran: what was asked, and what chaosd-fakebot says the kernel
/// granted (its log's placement line and warnings, from the first `udp` run).
fn device_placement(results: &[RateResult]) -> String {
    let granted = results
        .iter()
        .filter(|r| r.mode == Mode::Udp)
        .find_map(|r| std::fs::read_to_string(r.dir.join("fakebot.log")).ok())
        .map(|log| {
            log.lines()
                .filter_map(|l| l.strip_prefix("chaosd-fakebot: "))
                .filter(|l| l.starts_with("core ") || l.starts_with("warning: "))
                .collect::<Vec<_>>()
                .join("; ")
        })
        .filter(|g| !g.is_empty())
        .unwrap_or_else(|| "not reported".into());
    format!(
        "In the `udp` mode the device was asked to run on the bridge's core, 10 SCHED_FIFO steps \
         above it, sleeping until its cycle and blocking for its answers (`chaosd-fakebot {}`), \
         as a device with a clock of its own would preempt the bridge; it got: {granted}. In \
         `udp-free` it ran unpinned at the normal scheduler and polled for its answers.\n\n",
        DEVICE_ARGS.join(" ")
    )
}

/// What chaosd-fakebot writes at exit in the UDP mode.
const DEVICE_SUMMARY: &str = "fakebot-summary.json";

/// What else runs next to the loops.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Load {
    Idle,
    /// A client sends status requests back to back.
    Hammered,
    /// `chaosctl exporter` runs and is scraped every [`SCRAPE_EVERY`].
    Scraped,
    /// The chaos monitor off (`[daemon] monitor = false`): its cost, side by side.
    NoMonitor,
    /// A Foxglove viewer attached to the live view, subscribed to every channel.
    Viewed,
}

/// A free TCP port on loopback.
fn free_port() -> Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port())
}

/// A Foxglove viewer subscribed to every channel until `stop`: the messages it received.
fn view(addr: String, stop: Arc<AtomicBool>) -> std::thread::JoinHandle<Result<u64>> {
    std::thread::spawn(move || {
        let (mut s, topics) =
            daemon::foxglove::client::subscribe_all(&addr, Duration::from_secs(10))
                .with_context(|| format!("cannot view the daemon at {addr}"))?;
        if topics.len() < 10 {
            bail!("the daemon advertised {topics:?}");
        }
        // The daemon sends all the time; it closes the connection when its run ends.
        s.set_read_timeout(Some(Duration::from_secs(5)))?;
        let mut n = 0;
        while !stop.load(Ordering::Relaxed) {
            match daemon::foxglove::client::read_frame(&mut s) {
                Ok((2, _)) => n += 1,
                Ok(_) => {}
                Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => break,
                Err(e) => return Err(anyhow::anyhow!("the viewer's connection failed: {e}")),
            }
        }
        Ok(n)
    })
}

/// How often the scraped run scrapes `/metrics` (a fast Prometheus set-up).
pub const SCRAPE_EVERY: Duration = Duration::from_millis(100);

/// Scrapes `http://addr/metrics` every [`SCRAPE_EVERY`] until `stop`, timing each from connect to
/// the last byte of the answer. Returns the times (ns, sorted); a failed scrape ends the run with
/// its error.
fn scrape(addr: String, stop: Arc<AtomicBool>) -> std::thread::JoinHandle<Result<Vec<u64>>> {
    use std::io::{Read, Write};
    std::thread::spawn(move || {
        let mut took = Vec::new();
        let mut next = Instant::now();
        while !stop.load(Ordering::Relaxed) {
            let t = Instant::now();
            let mut s = std::net::TcpStream::connect(&addr)
                .with_context(|| format!("cannot connect to the exporter at {addr}"))?;
            s.set_read_timeout(Some(Duration::from_secs(5)))?;
            write!(
                s,
                "GET /metrics HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
            )?;
            let mut text = String::new();
            s.read_to_string(&mut text)?;
            took.push(t.elapsed().as_nanos() as u64);
            // The daemon may take a moment to show up; after 2 s every scrape must carry it.
            let served = text.starts_with("HTTP/1.1 200") && text.contains("chaosd_ticks_total");
            if !served && took.len() > 20 {
                bail!(
                    "scrape {} answered without the daemon's metrics:\n{}",
                    took.len(),
                    text.lines().take(12).collect::<Vec<_>>().join("\n")
                );
            }
            next += SCRAPE_EVERY;
            std::thread::sleep(next.saturating_duration_since(Instant::now()));
        }
        took.sort_unstable();
        Ok(took)
    })
}

fn one_rate(
    opts: &Options,
    rate_hz: f64,
    mode: Mode,
    report: &Report,
    load: Load,
) -> Result<RateResult> {
    let chaosd = sibling("chaosd")?;
    let dir = report.path(&match load {
        Load::Hammered => format!("{rate_hz:.0}hz-hammered"),
        Load::Scraped => format!("{rate_hz:.0}hz-scraped"),
        Load::NoMonitor => format!("{rate_hz:.0}hz-no-monitor"),
        Load::Viewed => format!("{rate_hz:.0}hz-viewed"),
        Load::Idle => format!("{rate_hz:.0}hz{}", mode.slug()),
    });
    std::fs::create_dir_all(&dir)?;
    for f in ["daemon-summary.json", "plant-summary.json", DEVICE_SUMMARY] {
        let _ = std::fs::remove_file(dir.join(f));
    }
    let cfg = dir.join("config.toml");
    let ns = unique_namespace("e2e");
    let mut text = config_text(&ns, &dir, rate_hz, mode, opts.spin_us);
    if load == Load::NoMonitor {
        text = text.replacen("[daemon]\n", "[daemon]\nmonitor = false\n", 1);
    }
    let view_addr = format!("127.0.0.1:{}", free_port()?);
    if load == Load::Viewed {
        let line = format!("[daemon]\nfoxglove = \"{view_addr}\"\n");
        text = text.replacen("[daemon]\n", &line, 1);
    }
    std::fs::write(&cfg, text)?;

    let steal_before = steal_ticks().ok();
    let (mut plant, mut device) = spawn_plant_side(mode, &cfg, &dir, opts.seconds)?;
    std::thread::sleep(Duration::from_millis(300));
    if plant.poll_exit().is_some() {
        return Err(plant.failure("it stopped at start-up"));
    }
    if let Some(d) = device.as_mut() {
        if d.poll_exit().is_some() {
            return Err(d.failure("it stopped at start-up"));
        }
    }
    let mut cmd = Command::new(&chaosd);
    cmd.arg("run")
        .arg("--fresh")
        .arg("--config")
        .arg(&cfg)
        .args(["--duration", &format!("{}", opts.seconds)]);
    let started = Instant::now();
    let mut daemon = Child::spawn("chaosd", cmd, &dir.join("daemon.log"), Stdout::Log)?;
    let (pid_d, pid_p) = (daemon.pid().unwrap_or(0), plant.pid().unwrap_or(0));
    let stop = Arc::new(AtomicBool::new(false));
    let client = (load == Load::Hammered).then(|| hammer(ns.clone(), stop.clone()));
    let viewer = (load == Load::Viewed).then(|| view(view_addr.clone(), stop.clone()));
    let mut exporter = None;
    let scraper = if load == Load::Scraped {
        let mut cmd = Command::new(sibling("chaosctl")?);
        cmd.args(["exporter", "--listen", "127.0.0.1:0", "--namespace", &ns]);
        let mut e = Child::spawn(
            "chaosctl exporter",
            cmd,
            &dir.join("exporter.log"),
            Stdout::Lines,
        )?;
        let line = e.expect(
            "chaosctl exporter: serving http://",
            Duration::from_secs(10),
        )?;
        let addr = line
            .split("/metrics")
            .next()
            .unwrap_or_default()
            .to_string();
        exporter = Some(e);
        Some(scrape(addr, stop.clone()))
    } else {
        None
    };

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
    let steal_after = steal_ticks().ok();
    stop.store(true, Ordering::Relaxed);
    let requests = client.map(|h| h.join().unwrap_or(0));
    let viewed = match viewer.map(|h| h.join()) {
        Some(Ok(r)) => Some(r?),
        Some(Err(_)) => bail!("the viewer thread panicked"),
        None => None,
    };
    let scrapes = match scraper {
        Some(h) => Some(
            h.join()
                .map_err(|_| anyhow::anyhow!("the scraper thread panicked"))??,
        ),
        None => None,
    };
    drop(exporter);
    plant.terminate(Duration::from_secs(10))?;
    if plant.poll_exit().is_some_and(|s| !s.success()) {
        return Err(plant.failure("it failed"));
    }
    if let Some(d) = device.as_mut() {
        d.terminate(Duration::from_secs(10))?;
        if d.poll_exit().is_some_and(|s| !s.success()) {
            return Err(d.failure("it failed"));
        }
    }
    let (Some(a), Some(b)) = (first, last) else {
        bail!(
            "chaosd exited after {:.1} s, before the CPU sampling window ended",
            started.elapsed().as_secs_f64()
        );
    };
    let (secs, hz) = (b.0.duration_since(a.0).as_secs_f64(), clock_ticks_per_s());
    let device = match mode {
        Mode::Udp | Mode::UdpFree => Some(read_json(&dir.join(DEVICE_SUMMARY))?),
        _ => None,
    };
    Ok(RateResult {
        rate_hz,
        mode,
        device,
        requests,
        scrapes,
        viewed,
        daemon: read_json(&dir.join("daemon-summary.json"))?,
        plant: read_json(&dir.join("plant-summary.json"))?,
        cpu_daemon: (b.1 - a.1) as f64 / hz / secs,
        cpu_plant: (b.2 - a.2) as f64 / hz / secs,
        steal_ms: match (steal_before, steal_after) {
            (Some(a), Some(b)) if a.len() == b.len() => a
                .iter()
                .zip(&b)
                .map(|(a, b)| b.saturating_sub(*a) as f64 / hz * 1e3)
                .collect(),
            _ => Vec::new(),
        },
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

/// The three modes side by side at every rate: how soon a state is answered, and how often in
/// its own cycle.
pub fn modes_table(results: &[RateResult]) -> String {
    let mut t = Table::new(&[
        "rate",
        "mode",
        "state published → command at the plant p50 / p99 / p99.9",
        "answered in time",
        "state age p50 / p99",
        "device: state sent → answer received p50 / p99 / p99.9",
        "daemon wake-up p99",
        "CPU daemon / plant",
    ]);
    for r in results {
        let (d, p) = (&r.daemon, &r.plant);
        let share = p["in_time_share"].as_f64().map_or_else(
            || "next tick (by design)".into(),
            |f| format!("{:.3} %", f * 100.0),
        );
        let device = r.device.as_ref().map_or_else(
            || "-".into(),
            |v| {
                format!(
                    "{} / {} / {}",
                    us(v, "round_trip", "p50_us"),
                    us(v, "round_trip", "p99_us"),
                    us(v, "round_trip", "p999_us")
                )
            },
        );
        t.row(vec![
            format!("{} kHz", r.rate_hz / 1000.0),
            r.mode.name().into(),
            format!(
                "{} / {} / {}",
                us(p, "round_trip", "p50_us"),
                us(p, "round_trip", "p99_us"),
                us(p, "round_trip", "p999_us")
            ),
            share,
            format!(
                "{} / {}",
                us(d, "state_age", "p50_us"),
                us(d, "state_age", "p99_us")
            ),
            device,
            us(d, "lateness", "p99_us"),
            format!(
                "{:.0} % / {:.0} %",
                r.cpu_daemon * 100.0,
                r.cpu_plant * 100.0
            ),
        ]);
    }
    t.render()
}

/// The same-cycle targets, for the runs that measure them: state-triggered state → command p50
/// ≤ 2 µs and p99 ≤ 10 µs with ≥ 99.9 % answered in time at 1 and 10 kHz; the UDP device's round
/// trip p99 ≤ 100 µs at 1 kHz; phase-locked state age p99 within 20 µs of the offset.
pub fn targets(results: &[RateResult]) -> Vec<Target> {
    let mut out = Vec::new();
    let num = |v: &Value, key: &str, p: &str| v[key][p].as_f64().unwrap_or(f64::NAN);
    for r in results {
        let khz = r.rate_hz / 1000.0;
        let core_rate = r.rate_hz == 1_000.0 || r.rate_hz == 10_000.0;
        match r.mode {
            Mode::State if core_rate => {
                let p = &r.plant;
                out.push(
                    Target::new(
                        format!("{khz} kHz state-triggered: state → command p50"),
                        num(p, "round_trip", "p50_us"),
                        Bound::AtMost(2.0),
                    )
                    .in_unit("µs"),
                );
                out.push(
                    Target::new(
                        format!("{khz} kHz state-triggered: state → command p99"),
                        num(p, "round_trip", "p99_us"),
                        Bound::AtMost(10.0),
                    )
                    .in_unit("µs"),
                );
                out.push(
                    Target::new(
                        format!("{khz} kHz state-triggered: answered in time"),
                        p["in_time_share"].as_f64().unwrap_or(f64::NAN) * 100.0,
                        Bound::AtLeast(99.9),
                    )
                    .in_unit("%"),
                );
            }
            Mode::Udp if r.rate_hz == 1_000.0 => {
                let d = r.device.as_ref().unwrap_or(&Value::Null);
                out.push(
                    Target::new(
                        format!("{khz} kHz UDP bridge: device state sent → answer received p99"),
                        num(d, "round_trip", "p99_us"),
                        Bound::AtMost(100.0),
                    )
                    .in_unit("µs"),
                );
            }
            Mode::Phase => {
                let off = phase_offset_us(r.rate_hz);
                out.push(
                    Target::new(
                        format!("{khz} kHz phase-locked: |state age p99 − offset {off} µs|"),
                        (num(&r.daemon, "state_age", "p99_us") - off).abs(),
                        Bound::AtMost(20.0),
                    )
                    .in_unit("µs"),
                );
            }
            _ => {}
        }
    }
    out
}

/// The idle, the hammered and the scraped run side by side.
/// The daemon's compute and lateness with the chaos monitor on and off, and the p50 ratio.
pub fn monitor_table(on: &RateResult, off: &RateResult) -> String {
    let p50 = |r: &RateResult| r.daemon["compute"]["p50_us"].as_f64().unwrap_or(f64::NAN);
    side_by_side(
        [("monitor on", on), ("monitor off", off)],
        None,
        ("compute p50, on / off", p50(on) / p50(off), 0),
    )
}

/// The loop with a Foxglove viewer subscribed to every channel, next to the same run without.
pub fn viewer_table(idle: &RateResult, viewed: &RateResult) -> String {
    let p99 = |r: &RateResult| r.daemon["compute"]["p99_us"].as_f64().unwrap_or(f64::NAN);
    side_by_side(
        [("no viewer", idle), ("a viewer on every channel", viewed)],
        Some(("view messages", |r: &RateResult| r.viewed)),
        ("compute p99, viewed / not", p99(viewed) / p99(idle), 1),
    )
}

/// An extra column of counts: its header and how to read it off a run.
type Count<'a> = (&'a str, fn(&RateResult) -> Option<u64>);

/// Two runs of the loop side by side: compute, wake-up, daemon CPU, an optional count, and a
/// ratio (header, value, the row it describes).
fn side_by_side(
    runs: [(&str, &RateResult); 2],
    count: Option<Count>,
    ratio: (&str, f64, usize),
) -> String {
    let mut head = vec![
        "run",
        "compute p50 / p99 / max",
        "wake-up p99 / max",
        "daemon CPU",
    ];
    head.extend(count.map(|c| c.0));
    head.push(ratio.0);
    let mut t = Table::new(&head);
    for (k, (name, r)) in runs.iter().enumerate() {
        let d = &r.daemon;
        let mut row = vec![
            name.to_string(),
            format!(
                "{} / {} / {}",
                us(d, "compute", "p50_us"),
                us(d, "compute", "p99_us"),
                us(d, "compute", "max_us")
            ),
            format!(
                "{} / {}",
                us(d, "lateness", "p99_us"),
                us(d, "lateness", "max_us")
            ),
            format!("{:.1} %", r.cpu_daemon * 100.0),
        ];
        if let Some((_, f)) = count {
            row.push(f(r).map_or("—".into(), |n| n.to_string()));
        }
        row.push(if k == ratio.2 {
            format!("{:.3}", ratio.1)
        } else {
            String::new()
        });
        t.row(row);
    }
    t.render()
}

pub fn hammer_table(idle: &RateResult, hammered: &RateResult, scraped: &RateResult) -> String {
    let mut t = Table::new(&[
        "run",
        "status requests answered",
        "scrapes: n, p50 / p99 / max",
        "daemon ticks",
        "overruns",
        "wake-up p99 / p99.9 / max",
        "compute p99 / p99.9 / max",
    ]);
    for (name, r) in [
        ("idle", idle),
        ("hammered", hammered),
        ("scraped every 100 ms", scraped),
    ] {
        let d = &r.daemon;
        let q = |v: &[u64], p: f64| v[((v.len() - 1) as f64 * p).round() as usize] as f64;
        t.row(vec![
            name.into(),
            r.requests.map_or_else(|| "0".into(), |n| n.to_string()),
            match r.scrapes.as_deref() {
                Some(v) if !v.is_empty() => format!(
                    "{}, {} / {} / {}",
                    v.len(),
                    fmt_ns(q(v, 0.5)),
                    fmt_ns(q(v, 0.99)),
                    fmt_ns(q(v, 1.0))
                ),
                _ => "-".into(),
            },
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

pub fn run(opts: &Options, out: &Path, command: &str) -> Result<Output> {
    opts.validate()?;
    let mut report = Report::new(out, "e2e")?;
    if report.dir.display().to_string().contains(['\'', '\n']) {
        bail!(
            "the output directory {} holds a quote or newline, which the config file cannot carry",
            report.dir.display()
        );
    }
    let mut all = Vec::new();
    for &rate in &opts.rates {
        for &mode in &opts.modes {
            all.push(
                one_rate(opts, rate, mode, &report, Load::Idle)
                    .with_context(|| format!("e2e at {rate} Hz, {}", mode.name()))?,
            );
        }
    }
    let results: Vec<RateResult> = all
        .iter()
        .filter(|r| r.mode == Mode::Clock)
        .cloned()
        .collect();
    // Does the control service disturb the loop? The first rate's free-running run again, with a
    // client sending status requests back to back, and with the exporter scraped every 100 ms
    // (only when the free-running mode is among those asked for: it is the comparison's idle run).
    let load_runs = match results.first() {
        Some(idle) => {
            let hammered = one_rate(opts, idle.rate_hz, Mode::Clock, &report, Load::Hammered)
                .with_context(|| "e2e with a client hammering status requests")?;
            let scraped = one_rate(opts, idle.rate_hz, Mode::Clock, &report, Load::Scraped)
                .with_context(|| "e2e with the exporter scraped every 100 ms")?;
            let quiet = one_rate(opts, idle.rate_hz, Mode::Clock, &report, Load::NoMonitor)
                .with_context(|| "e2e with the chaos monitor off")?;
            let viewed = one_rate(opts, idle.rate_hz, Mode::Clock, &report, Load::Viewed)
                .with_context(|| "e2e with a Foxglove viewer attached")?;
            Some((idle.clone(), hammered, scraped, quiet, viewed))
        }
        None => None,
    };
    let rt_line = |v: &Value| match v["realtime"]["sched_fifo"].as_u64() {
        Some(p) => format!("SCHED_FIFO {p}"),
        None => format!("SCHED_OTHER ({})", v["realtime"]["warnings"]),
    };
    report.push(&header("End to end: chaosd and chaosd-plant", command));
    report.push(&format!(
        "The daemon (core 1, {}) and the plant (core 0, {}) with default settings (hybrid waits{}, memory locked), \
         {} s per rate. Wake-up lateness and state age as the daemon measures them; the command round trip is \
         the plant's: state published → answering command picked up at the plant's next tick, so it includes \
         waiting for that tick. State age is the age of the newest state at the daemon's tick; the two loops start \
         independently, so it is set by their phase and lies anywhere within one period. CPU is utime + stime over the run (100 % = one core). \
         Kernel RT throttling: {}.\n\n",
        all.first().map_or("?".into(), |r| rt_line(&r.daemon)),
        all.first().map_or("?".into(), |r| rt_line(&r.plant)),
        opts.spin_us.map_or(String::new(), |s| format!(" with spin_us = {s}")),
        opts.seconds,
        rt::throttle::RtLimit::read().map_or("unknown".into(), |l| l.describe())
    ));
    report.run_detail(format!("{} s per run", opts.seconds));
    if !results.is_empty() {
        report.table(names::E2E, &table(&results))?;
    }
    report.push(
        "\n**Triggers side by side.** Free-running, the plant applies a command at its next tick, so a \
         command arrives one period after its state by design. State-triggered, the plant publishes, waits for \
         the answer (up to half a period) and applies it in the same cycle; \"answered in time\" is the share of \
         cycles whose answer came before that deadline. Through the UDP bridge the device (chaosd-fakebot) owns \
         the clock; its column is the whole path as the device sees it: state datagram sent → command datagram \
         received, through chaosd-bridge and chaosd.\n\n",
    );
    if opts.modes.iter().any(|m| m.is_udp()) {
        report.push(&device_placement(&all));
    }
    report.table(names::E2E_MODES, &modes_table(&all))?;
    let targets = targets(&all);
    if !targets.is_empty() {
        report.push("\nTargets of the same-cycle work (issue 10), as measured in this run:\n\n");
        for t in &targets {
            report.push(&format!("{}\n", t.line()));
        }
    }
    if all.iter().any(|r| r.plant["in_time_share"].is_f64()) {
        report.push(
            "\n**Whose late cycles.** A late cycle is an answer that missed the plant's deadline, half a \
             period after the state went out. The daemon counts each stretch of at least 10 µs between two clock \
             reads of its loop, outside its tick and its sleeps: its core was gone (the host holding the vCPU, an interrupt, a \
             preemption). It also counts each of its sleeps that woke 10 µs or more late, by how much \
             (`rt::gaps`). A stretch of half a period or more, or a sleep that woke that late, can cost one cycle or \
             more (one of 0.9 ms at 10 kHz, nine). Steal is the time the host ran something else on that vCPU \
             (`/proc/stat`), counted in 10 ms steps over the whole run with its start-up, so each figure is good \
             to about ±10 ms.\n\n",
        );
        report.table(names::E2E_LATE, &late::late_table(&all))?;
    }
    if let Some((idle, hammered, scraped, quiet, viewed)) = &load_runs {
        report.push(&format!(
            "\n**Control requests vs the loop** at {} kHz: the same run idle and with a client sending `status` requests \
             back to back (each answered before the next is sent) for the whole run, and with `chaosctl exporter` \
             scraped every 100 ms over HTTP (scrape time: connect → last byte; target ≤ 5 ms).\n\n",
            hammered.rate_hz / 1000.0
        ));
        report.table(names::E2E_REQUESTS, &hammer_table(idle, hammered, scraped))?;
        report.push(&format!(
            "\n**The chaos monitor's cost** at {} kHz: the idle run (monitor on, the default) next to the \
             same run with `[daemon] monitor = false`. The monitor runs on the reporter thread, off the \
             loop's core; the loop's share is the law's null-space residual, computed either way. \
             Target: compute p50 within 5 % of the run without it.\n\n",
            quiet.rate_hz / 1000.0
        ));
        report.table(names::E2E_MONITOR, &monitor_table(idle, quiet))?;
        report.push(&format!(
            "\n**A Foxglove viewer's cost** at {} kHz: the idle run next to the same run with a viewer \
             attached to the live view (`[daemon] foxglove`) and subscribed to every channel. The \
             reporter encodes, a thread of its own sends, both off the loop's core; target: the loop's \
             compute p99 within 10 % of the idle run's.\n\n",
            viewed.rate_hz / 1000.0
        ));
        report.table(names::E2E_VIEWER, &viewer_table(idle, viewed))?;
    }
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
    let mut by_mode = Panel {
        title: "state published → command at the plant, by mode".into(),
        quantity: "round trip".into(),
        series: Vec::new(),
    };
    for r in all
        .iter()
        .filter(|r| matches!(r.mode, Mode::State | Mode::PubSub) || r.mode.is_udp())
    {
        let path = r.dir.join("plant-round-trip.hgrm");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let label = format!("{} kHz {}", r.rate_hz / 1000.0, r.mode.name());
        by_mode.series.push(
            Dist::from_hgrm(&label, &text).with_context(|| format!("in {}", path.display()))?,
        );
        report.files.push(path);
    }
    if !by_mode.series.is_empty() {
        panels.push(by_mode);
    }
    report.plot("chaosd-bench e2e: daemon and plant processes", &panels)?;
    if all
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
        let text = config_text(
            "bench-e2e-1-2",
            Path::new("/tmp/x y/1000hz"),
            5_000.0,
            Mode::Clock,
            None,
        );
        let cfg = control::Config::from_toml_str(&text).unwrap();
        let d = daemon::config::DaemonSetup::from_config(cfg.clone()).unwrap();
        assert_eq!(d.daemon.rate_hz, 5_000.0);
        assert_eq!(d.daemon.namespace, "bench-e2e-1-2");
        assert_eq!(d.daemon.output_dir, Path::new("/tmp/x y/1000hz"));
        assert_eq!(d.daemon.report_every_s, 0.0);
        let plant = cfg.plant.as_ref().unwrap();
        assert_eq!(plant["rate_hz"].as_float(), Some(5_000.0));
        assert_eq!(plant["namespace"].as_str(), Some("bench-e2e-1-2"));
        let text = config_text(
            "bench-e2e-1-2",
            Path::new("/tmp/x"),
            1_000.0,
            Mode::Udp,
            Some(200.0),
        );
        let cfg = control::Config::from_toml_str(&text).unwrap();
        let d = daemon::config::DaemonSetup::from_config(cfg).unwrap();
        assert_eq!(d.daemon.trigger, rt::Trigger::State);
        assert_eq!(d.daemon.spin_us, 200.0);
        for rate in [1_000.0, 10_000.0] {
            let text = config_text(
                "bench-e2e-1-2",
                Path::new("/tmp/x"),
                rate,
                Mode::Phase,
                None,
            );
            let cfg = control::Config::from_toml_str(&text).unwrap();
            let d = daemon::config::DaemonSetup::from_config(cfg).unwrap();
            assert_eq!(d.daemon.trigger, rt::Trigger::Clock);
            assert_eq!(d.daemon.phase_offset_us, Some(phase_offset_us(rate)));
        }
        assert_eq!(phase_offset_us(1_000.0), 100.0);
        assert_eq!(phase_offset_us(10_000.0), 25.0);
    }

    #[test]
    fn targets_judge_the_runs_that_measure_them() {
        let mk = |mode, rate_hz, daemon: Value, plant: Value, device: Option<Value>| RateResult {
            rate_hz,
            mode,
            device,
            requests: None,
            viewed: None,
            scrapes: None,
            daemon,
            plant,
            cpu_daemon: 0.0,
            cpu_plant: 0.0,
            steal_ms: Vec::new(),
            dir: PathBuf::new(),
        };
        use serde_json::json as j;
        let runs = [
            mk(Mode::Clock, 1e3, j!({}), j!({}), None),
            mk(
                Mode::State,
                1e3,
                j!({}),
                j!({"round_trip": {"p50_us": 1.5, "p99_us": 12.0}, "in_time_share": 0.9995}),
                None,
            ),
            mk(Mode::State, 2e3, j!({}), j!({}), None),
            mk(
                Mode::Udp,
                1e3,
                j!({}),
                j!({}),
                Some(j!({"round_trip": {"p99_us": 80.0}})),
            ),
            mk(
                Mode::Phase,
                1e3,
                j!({"state_age": {"p99_us": 125.0}}),
                j!({}),
                None,
            ),
        ];
        let t = targets(&runs);
        let met: Vec<(bool, &str)> = t.iter().map(|t| (t.met(), t.what.as_str())).collect();
        assert_eq!(t.len(), 5, "{met:?}");
        assert_eq!(
            met.iter().map(|m| m.0).collect::<Vec<_>>(),
            [true, false, true, true, false],
            "{met:?}"
        );
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
            mode: Mode::Clock,
            device: None,
            requests: None,
            viewed: None,
            scrapes: None,
            daemon,
            plant,
            cpu_daemon: 0.12,
            cpu_plant: 0.3,
            steal_ms: vec![20.0, 10.0],
            dir: PathBuf::new(),
        };
        let hammered = RateResult {
            requests: Some(1234),
            ..r.clone()
        };
        let scraped = RateResult {
            scrapes: Some(vec![1_000_000, 2_000_000, 3_000_000]),
            ..r.clone()
        };
        let (mut on, mut off) = (r.clone(), r.clone());
        on.daemon["compute"] = serde_json::json!({"p50_us": 1.5, "p99_us": 3.0, "max_us": 9.0});
        off.daemon["compute"] = serde_json::json!({"p50_us": 2.0, "p99_us": 3.0, "max_us": 9.0});
        let m = monitor_table(&on, &off);
        assert!(
            m.contains("| monitor on | 1.50 µs / 3.00 µs / 9.00 µs |")
                && m.contains("| 12.0 % | 0.750 |"),
            "{m}"
        );
        let h = hammer_table(&r, &hammered, &scraped);
        assert!(
            h.contains("| idle | 0 | - | 10000 | 3 |")
                && h.contains("| hammered | 1234 | - | 10000 | 3 |")
                && h.contains(
                    "| scraped every 100 ms | 0 | 3, 2.00 ms / 3.00 ms / 3.00 ms | 10000 | 3 |"
                ),
            "{h}"
        );
        let t = table(std::slice::from_ref(&r));
        assert!(
            t.contains(
                "| 1 kHz | 10000 | 3 / 0 | 1.50 µs / 12.00 µs / 900.00 µs | 40.00 µs / 95.00 µs |"
            ),
            "{t}"
        );
        // Where the device ran, as its log says; a run without one says so.
        let dir = std::env::temp_dir().join(format!("e2e-placement-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(
            dir.join("fakebot.log"),
            "chaosd-fakebot: warning: SCHED_FIFO priority 60 refused (EPERM)\n\
             chaosd-fakebot: core 0, SCHED_OTHER (timer slack 1 ns), memory not locked\n\
             chaosd-fakebot: round trip ...\n",
        )
        .unwrap();
        let udp = RateResult {
            mode: Mode::Udp,
            dir: dir.clone(),
            ..r.clone()
        };
        let p = device_placement(&[r.clone(), udp.clone()]);
        assert!(
            p.contains(
                "it got: warning: SCHED_FIFO priority 60 refused (EPERM); core 0, SCHED_OTHER"
            ),
            "{p}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(device_placement(&[udp]).contains("it got: not reported"));
        assert!(
            t.contains("1.00 ms / 1.01 ms / 1.10 ms / 2.50 ms | 12 % | 30 % |"),
            "{t}"
        );
        let mut udp = r.clone();
        udp.mode = Mode::Udp;
        udp.plant["in_time_share"] = serde_json::json!(0.9995);
        udp.device = Some(serde_json::json!({
            "round_trip": {"p50_us": 40.0, "p99_us": 80.0, "p999_us": 200.0}
        }));
        let m = modes_table(&[r.clone(), udp]);
        assert!(
            m.contains("| free-running (iceoryx2) |") && m.contains("next tick (by design)"),
            "{m}"
        );
        assert!(
            m.contains("| state-triggered (UDP bridge) |")
                && m.contains("99.950 %")
                && m.contains("40.00 µs / 80.00 µs / 200.00 µs"),
            "{m}"
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
            modes: Mode::ALL.to_vec(),
            seconds: 3.0,
            spin_us: None,
        }
        .validate()
        .is_err());
        assert!(Options {
            rates: vec![1000.0],
            modes: Mode::ALL.to_vec(),
            seconds: 1.0,
            spin_us: None,
        }
        .validate()
        .is_err());
        let mut o = Options::new(true);
        o.spin_us = Some(f64::NAN);
        assert!(o.validate().unwrap_err().to_string().contains("spin-us"));
        o.spin_us = Some(200.0);
        assert!(o.validate().is_ok());
    }
}
