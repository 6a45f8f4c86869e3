//! `chaosctl exporter`: the daemons' telemetry as Prometheus metrics on `/metrics`.
//!
//! A process of its own, so a scraper never touches the daemon: one thread subscribes to the
//! telemetry stream of each namespace and keeps the newest sample; the main thread answers HTTP
//! requests from those samples (a minimal HTTP/1.1 server on `std::net`: one request per
//! connection, `GET`/`HEAD /metrics`, 404 for any other path). The daemon's loop does no work
//! for it: the reporter thread publishes telemetry whether or not anyone listens.
//!
//! Every series carries a `namespace` label. Counters are totals since the daemon started (they
//! restart from 0 when it does, which Prometheus handles as a counter reset). The latency
//! distributions are summaries' quantiles (0.5, 0.99, 0.999 and 1 for the maximum) over the
//! daemon's last complete 10 s metrics window. A namespace whose telemetry is older than
//! [`STALE`] reports only `chaosd_up 0` and the age.

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use protocol::{ServiceNames, TelemetrySample};
use std::fmt::Write as _;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Telemetry older than this: the daemon is taken as down.
pub const STALE: Duration = Duration::from_secs(3);

#[derive(Args, Debug)]
pub struct ExporterArgs {
    /// Address and port to serve `/metrics` on (port 0: any free port, printed at start).
    #[arg(long, default_value = "127.0.0.1:9464")]
    listen: SocketAddr,
    /// A daemon namespace to export; repeat for several (default: the default namespace).
    #[arg(long = "namespace")]
    namespaces: Vec<String>,
}

/// The newest sample of each namespace and when it arrived.
type Latest = Arc<Mutex<Vec<Option<(TelemetrySample, Instant)>>>>;

pub fn run(a: ExporterArgs) -> Result<()> {
    let mut namespaces = a.namespaces.clone();
    if namespaces.is_empty() {
        namespaces.push(protocol::DEFAULT_NAMESPACE.to_string());
    }
    let mut names = Vec::new();
    for ns in &namespaces {
        let n = ServiceNames::new(ns).map_err(|e| anyhow!("--namespace {ns:?}: {e}"))?;
        if names
            .iter()
            .any(|m: &ServiceNames| m.namespace() == n.namespace())
        {
            bail!("--namespace {ns:?} given twice");
        }
        names.push(n);
    }
    let listener =
        TcpListener::bind(a.listen).with_context(|| format!("cannot listen on {}", a.listen))?;
    let latest: Latest = Arc::new(Mutex::new(vec![None; names.len()]));
    subscribe(names.clone(), latest.clone())?;
    let addr = listener.local_addr()?;
    println!(
        "chaosctl exporter: serving http://{addr}/metrics for namespace{} {}",
        if names.len() > 1 { "s" } else { "" },
        namespaces.join(", ")
    );
    let _ = std::io::stdout().flush();
    let labels: Vec<String> = names.iter().map(|n| n.namespace().to_string()).collect();
    for stream in listener.incoming() {
        // One connection at a time: answers take microseconds, and a slow client is cut off by
        // the timeouts below.
        match stream {
            Ok(s) => {
                let _ = serve(s, &labels, &latest);
            }
            // Out of file descriptors or the like: do not spin on it.
            Err(_) => std::thread::sleep(Duration::from_millis(10)),
        }
    }
    Ok(())
}

/// Starts the subscriber thread; returns once every subscription exists (or why one failed).
fn subscribe(names: Vec<ServiceNames>, latest: Latest) -> Result<()> {
    let (ok_tx, ok_rx) = std::sync::mpsc::channel::<Result<(), String>>();
    std::thread::Builder::new()
        .name("exporter-telemetry".into())
        .spawn(move || {
            let subs = (|| -> Result<_, String> {
                let node = protocol::node("chaosctl-exporter").map_err(|e| e.to_string())?;
                let mut subs = Vec::new();
                for n in &names {
                    let s = protocol::control::open_telemetry_service(&node, n)
                        .map_err(|e| format!("namespace {:?}: {e}", n.namespace()))?
                        .subscriber_builder()
                        .create()
                        .map_err(|e| format!("cannot subscribe to {}: {e:?}", n.telemetry()))?;
                    subs.push(s);
                }
                Ok((node, subs))
            })();
            let (_node, subs) = match subs {
                Ok(s) => {
                    let _ = ok_tx.send(Ok(()));
                    s
                }
                Err(e) => {
                    let _ = ok_tx.send(Err(e));
                    return;
                }
            };
            loop {
                for (i, s) in subs.iter().enumerate() {
                    let mut newest = None;
                    while let Ok(Some(t)) = s.receive() {
                        newest = Some(*t);
                    }
                    if let Some(t) = newest {
                        let mut l = latest.lock().unwrap_or_else(|e| e.into_inner());
                        l[i] = Some((t, Instant::now()));
                    }
                }
                std::thread::sleep(Duration::from_millis(10));
            }
        })?;
    match ok_rx.recv() {
        Ok(Ok(())) => Ok(()),
        Ok(Err(e)) => Err(anyhow!(e)),
        Err(_) => Err(anyhow!("the telemetry thread ended at start")),
    }
}

/// Reads one request and answers it.
fn serve(mut s: TcpStream, labels: &[String], latest: &Latest) -> std::io::Result<()> {
    s.set_read_timeout(Some(Duration::from_secs(2)))?;
    s.set_write_timeout(Some(Duration::from_secs(2)))?;
    let mut buf = [0u8; 8192];
    let mut n = 0;
    while !buf[..n].windows(4).any(|w| w == b"\r\n\r\n") {
        if n == buf.len() {
            return respond(
                &mut s,
                431,
                "text/plain",
                "request header too large\n",
                false,
            );
        }
        let k = s.read(&mut buf[n..])?;
        if k == 0 {
            return Ok(());
        }
        n += k;
    }
    let head = String::from_utf8_lossy(&buf[..n]);
    let mut first = head.lines().next().unwrap_or("").split_whitespace();
    let (method, target) = (first.next().unwrap_or(""), first.next().unwrap_or(""));
    let path = target.split('?').next().unwrap_or("");
    match (method, path) {
        ("GET" | "HEAD", "/metrics") => {
            let samples = latest.lock().unwrap_or_else(|e| e.into_inner()).clone();
            let body = render(labels, &samples, Instant::now());
            respond(
                &mut s,
                200,
                "text/plain; version=0.0.4; charset=utf-8",
                &body,
                method == "HEAD",
            )
        }
        ("GET" | "HEAD", _) => respond(
            &mut s,
            404,
            "text/plain",
            "not found: metrics are at /metrics\n",
            method == "HEAD",
        ),
        _ => respond(&mut s, 405, "text/plain", "only GET and HEAD\n", false),
    }
}

fn respond(
    s: &mut TcpStream,
    code: u16,
    ctype: &str,
    body: &str,
    head: bool,
) -> std::io::Result<()> {
    let reason = match code {
        200 => "OK",
        404 => "Not Found",
        405 => "Method Not Allowed",
        _ => "Request Header Fields Too Large",
    };
    let mut out = format!(
        "HTTP/1.1 {code} {reason}\r\nContent-Type: {ctype}\r\nContent-Length: {}\r\nConnection: close\r\n",
        body.len()
    );
    if code == 405 {
        out.push_str("Allow: GET, HEAD\r\n");
    }
    out.push_str("\r\n");
    if !head {
        out.push_str(body);
    }
    s.write_all(out.as_bytes())?;
    s.flush()
}

/// A float as the exposition format writes it.
fn num(v: f64) -> String {
    if v.is_nan() {
        "NaN".into()
    } else if v == f64::INFINITY {
        "+Inf".into()
    } else if v == f64::NEG_INFINITY {
        "-Inf".into()
    } else {
        format!("{v}")
    }
}

fn escape(v: &str) -> String {
    v.replace('\\', "\\\\")
        .replace('"', "\\\"")
        .replace('\n', "\\n")
}

type Get = fn(&TelemetrySample) -> f64;

/// Plain series: name, type, help, value.
const SERIES: &[(&str, &str, &str, Get)] = &[
    ("chaosd_ticks_total", "counter", "Control ticks run.", |t| {
        t.ticks as f64
    }),
    (
        "chaosd_overruns_total",
        "counter",
        "Control periods skipped because a tick ran late.",
        |t| t.overruns as f64,
    ),
    (
        "chaosd_faults_total",
        "counter",
        "Runaway-guard trips (FAULT entered).",
        |t| t.faults as f64,
    ),
    (
        "chaosd_rejected_samples_total",
        "counter",
        "Plant states rejected (invalid, stale, out of order, from the future, flagged faulty).",
        |t| t.rejected as f64,
    ),
    (
        "chaosd_telemetry_dropped_total",
        "counter",
        "Tick records the loop dropped because the reporter's queue was full.",
        |t| t.telemetry_dropped as f64,
    ),
    (
        "chaosd_holds_total",
        "counter",
        "Times the daemon entered HOLD for lack of fresh states.",
        |t| t.holds as f64,
    ),
    (
        "chaosd_plant_restarts_total",
        "counter",
        "Plant restarts the daemon noticed.",
        |t| t.plant_restarts as f64,
    ),
    (
        "chaosd_safety_active_ticks_total",
        "counter",
        "Ticks on which the safety filter changed the command.",
        |t| t.safety_active as f64,
    ),
    (
        "chaosd_tracking_lost_ticks_total",
        "counter",
        "Ticks with the tracking error above control.track_loss.",
        |t| t.track_lost as f64,
    ),
    (
        "chaosd_mode_code",
        "gauge",
        "Mode: 0 run, 1 hold, 2 brake, 3 fault.",
        |t| t.mode as f64,
    ),
    (
        "chaosd_blocked",
        "gauge",
        "Blocked (no clean cycle, or a trap steering did not end): 0 no, 1 holding, 2 best-effort.",
        |t| t.blocked as f64,
    ),
    (
        "chaosd_steering",
        "gauge",
        "1 while the self-motion is steered onto a planned clean cycle.",
        |t| t.steering as f64,
    ),
    ("chaosd_mu", "gauge", "Pyragas feedback gain mu.", |t| t.mu),
    (
        "chaosd_mu_auto",
        "gauge",
        "1 if mu adapts (feedback.mu = \"auto\").",
        |t| t.mu_auto as f64,
    ),
    (
        "chaosd_mu_model",
        "gauge",
        "The gain the daemon chose from its model for mu = \"auto\" (NaN until chosen).",
        |t| t.mu_model,
    ),
    (
        "chaosd_chaos_verdict",
        "gauge",
        "The chaos monitor's verdict: 0 unknown, 1 chaotic, 2 converging, 3 periodic (tau), 4 regular (another period or quasi-periodic).",
        |t| t.chaos as f64,
    ),
    (
        "chaosd_chaos_lyapunov_per_second",
        "gauge",
        "The monitor's finite-time largest Lyapunov estimate (NaN until it has one).",
        |t| t.lyapunov,
    ),
    (
        "chaosd_chaos_k01",
        "gauge",
        "The monitor's 0-1 test K (about 1 chaotic, about 0 regular; NaN until it has one).",
        |t| t.k01,
    ),
    ("chaosd_tau_seconds", "gauge", "Feedback delay tau.", |t| {
        t.tau
    }),
    (
        "chaosd_feedback_on",
        "gauge",
        "1 if the feedback switch is on.",
        |t| t.feedback_on as f64,
    ),
    (
        "chaosd_feedback_active",
        "gauge",
        "1 if the delayed term was applied on the newest tick.",
        |t| t.feedback_active as f64,
    ),
    (
        "chaosd_tracking_error_meters",
        "gauge",
        "RMS end-effector tracking error over the last telemetry interval.",
        |t| t.tracking_error,
    ),
    (
        "chaosd_period_residual_rad_per_second",
        "gauge",
        "Mean |qd(t) - qd(t - tau)| over the last telemetry interval.",
        |t| t.period_residual,
    ),
    (
        "chaosd_clearance_meters",
        "gauge",
        "Smallest obstacle clearance over the last telemetry interval (+Inf without obstacles).",
        |t| t.clearance,
    ),
    (
        "chaosd_controller_time_seconds",
        "gauge",
        "Controller time of the newest tick.",
        |t| t.t,
    ),
    (
        "chaosd_metrics_window_seconds",
        "gauge",
        "Length of the window the latency quantiles cover.",
        |t| t.window_s,
    ),
];

/// Distributions: name, help, the four values (p50, p99, p99.9, max) in µs.
type Dist = fn(&TelemetrySample) -> [f64; 4];
const DISTRIBUTIONS: &[(&str, &str, Dist)] = &[
    (
        "chaosd_wakeup_lateness_seconds",
        "Wake-up lateness of the control loop past its deadline.",
        |t| t.lateness_us,
    ),
    (
        "chaosd_compute_seconds",
        "Time from wake-up to command sent, per tick.",
        |t| t.compute_us,
    ),
    (
        "chaosd_state_age_seconds",
        "Age of the state used at the tick.",
        |t| t.state_age_us,
    ),
];

/// The command interface, the limiter's clamps and the limit breaches per kind of limit, and
/// the device's status.
fn command_series(o: &mut String, live: &[(String, &TelemetrySample)]) {
    let _ = writeln!(
        o,
        "# HELP chaosd_limiter_saturations_total Joint-ticks the command limiter clamped, per kind of limit.\n# TYPE chaosd_limiter_saturations_total counter"
    );
    for (l, t) in live {
        for (kind, n) in control::command::LimitKind::ALL.iter().zip(t.saturations) {
            let _ = writeln!(
                o,
                "chaosd_limiter_saturations_total{{namespace=\"{l}\",kind=\"{}\"}} {n}",
                kind.name()
            );
        }
    }
    let _ = writeln!(
        o,
        "# HELP chaosd_limit_breaches_total States past a position or speed limit, and commands past an acceleration, jerk or effort limit, per kind.\n# TYPE chaosd_limit_breaches_total counter"
    );
    for (l, t) in live {
        for (kind, n) in protocol::LIMIT_BREACH_KINDS.iter().zip(t.limit_breaches) {
            let _ = writeln!(
                o,
                "chaosd_limit_breaches_total{{namespace=\"{l}\",kind=\"{kind}\"}} {n}"
            );
        }
    }
    let _ = writeln!(
        o,
        "# HELP chaosd_command_interface 1 for the interface the daemon sends.\n# TYPE chaosd_command_interface gauge"
    );
    for (l, t) in live {
        for code in 0..4u32 {
            let name = protocol::interface::name(code).unwrap_or("?");
            let _ = writeln!(
                o,
                "chaosd_command_interface{{namespace=\"{l}\",interface=\"{name}\"}} {}",
                u8::from(t.interface == code)
            );
        }
    }
    let _ = writeln!(
        o,
        "# HELP chaosd_device_status Status code the device reports (0: running; else a reflex stop, protocol::DeviceStatus).\n# TYPE chaosd_device_status gauge"
    );
    for (l, t) in live {
        let _ = writeln!(o, "chaosd_device_status{{namespace=\"{l}\"}} {}", t.device);
    }
}

/// The exposition text for every namespace.
pub fn render(
    labels: &[String],
    samples: &[Option<(TelemetrySample, Instant)>],
    now: Instant,
) -> String {
    let mut o = String::new();
    let live: Vec<(String, &TelemetrySample)> = labels
        .iter()
        .zip(samples)
        .filter_map(|(l, s)| match s {
            Some((t, at)) if now.duration_since(*at) <= STALE => Some((escape(l), t)),
            _ => None,
        })
        .collect();
    let _ = writeln!(
        o,
        "# HELP chaosd_up 1 if the daemon's telemetry arrived within the last {} s.",
        STALE.as_secs()
    );
    let _ = writeln!(o, "# TYPE chaosd_up gauge");
    for (l, s) in labels.iter().zip(samples) {
        let up = s
            .as_ref()
            .is_some_and(|(_, at)| now.duration_since(*at) <= STALE);
        let _ = writeln!(
            o,
            "chaosd_up{{namespace=\"{}\"}} {}",
            escape(l),
            u8::from(up)
        );
    }
    let _ = writeln!(o, "# HELP chaosd_telemetry_age_seconds Time since the newest telemetry sample arrived (NaN: none yet).");
    let _ = writeln!(o, "# TYPE chaosd_telemetry_age_seconds gauge");
    for (l, s) in labels.iter().zip(samples) {
        let age = s
            .as_ref()
            .map_or(f64::NAN, |(_, at)| now.duration_since(*at).as_secs_f64());
        let _ = writeln!(
            o,
            "chaosd_telemetry_age_seconds{{namespace=\"{}\"}} {}",
            escape(l),
            num(age)
        );
    }
    if live.is_empty() {
        return o;
    }
    for (name, kind, help, get) in SERIES {
        let _ = writeln!(o, "# HELP {name} {help}\n# TYPE {name} {kind}");
        for (l, t) in &live {
            let _ = writeln!(o, "{name}{{namespace=\"{l}\"}} {}", num(get(t)));
        }
    }
    let _ = writeln!(
        o,
        "# HELP chaosd_mode 1 for the daemon's current mode.\n# TYPE chaosd_mode gauge"
    );
    for (l, t) in &live {
        for (i, m) in ["run", "hold", "brake", "fault"].iter().enumerate() {
            let _ = writeln!(
                o,
                "chaosd_mode{{namespace=\"{l}\",mode=\"{m}\"}} {}",
                u8::from(t.mode as usize == i)
            );
        }
    }
    command_series(&mut o, &live);
    for (name, help, get) in DISTRIBUTIONS {
        let _ = writeln!(o, "# HELP {name} {help} Quantiles over the daemon's last complete metrics window (1 = the maximum).\n# TYPE {name} gauge");
        for (l, t) in &live {
            for (q, v) in ["0.5", "0.99", "0.999", "1"].iter().zip(get(t)) {
                let _ = writeln!(
                    o,
                    "{name}{{namespace=\"{l}\",quantile=\"{q}\"}} {}",
                    num(v * 1e-6)
                );
            }
        }
        let _ = writeln!(
            o,
            "# HELP {name}_window_count Ticks in that window.\n# TYPE {name}_window_count gauge"
        );
        for (l, t) in &live {
            let _ = writeln!(
                o,
                "{name}_window_count{{namespace=\"{l}\"}} {}",
                t.window_ticks
            );
        }
    }
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_family_is_declared_once_and_its_series_follow() {
        let now = Instant::now();
        let t = TelemetrySample {
            ticks: 1234,
            mode: 3,
            clearance: f64::INFINITY,
            tracking_error: f64::NAN,
            lateness_us: [1.0, 2.0, 3.0, 4.0],
            interface: protocol::interface::TORQUE,
            device: protocol::DeviceStatus::JerkLimit as u32,
            saturations: [0, 0, 0, 7, 0, 2],
            limit_breaches: [0, 3, 0, 0, 1],
            ..Default::default()
        };
        let labels = vec!["a".to_string(), "b".to_string()];
        let text = render(&labels, &[Some((t, now)), None], now);
        assert!(text.contains("chaosd_up{namespace=\"a\"} 1\n"), "{text}");
        assert!(text.contains("chaosd_up{namespace=\"b\"} 0\n"), "{text}");
        assert!(text.contains("chaosd_ticks_total{namespace=\"a\"} 1234\n"));
        assert!(
            !text.contains("chaosd_ticks_total{namespace=\"b\"}"),
            "a dead daemon has no counters"
        );
        assert!(text.contains("chaosd_mode{namespace=\"a\",mode=\"fault\"} 1\n"));
        assert!(text.contains("chaosd_mode{namespace=\"a\",mode=\"run\"} 0\n"));
        assert!(text.contains("chaosd_clearance_meters{namespace=\"a\"} +Inf\n"));
        assert!(
            text.contains("chaosd_limiter_saturations_total{namespace=\"a\",kind=\"jerk\"} 7\n")
        );
        assert!(text.contains("chaosd_limit_breaches_total{namespace=\"a\",kind=\"speed\"} 3\n"));
        assert!(text.contains("chaosd_limit_breaches_total{namespace=\"a\",kind=\"effort\"} 1\n"));
        assert!(text.contains("chaosd_command_interface{namespace=\"a\",interface=\"torque\"} 1\n"));
        assert!(text.contains("chaosd_device_status{namespace=\"a\"} 3\n"));
        assert!(text.contains("chaosd_tracking_error_meters{namespace=\"a\"} NaN\n"));
        assert!(
            text.contains(
                "chaosd_wakeup_lateness_seconds{namespace=\"a\",quantile=\"0.999\"} 0.000003\n"
            ),
            "{text}"
        );
        // The text format: a family's TYPE line comes once, before its samples.
        let mut seen = std::collections::HashSet::new();
        for line in text.lines().filter(|l| l.starts_with("# TYPE ")) {
            assert!(
                seen.insert(line.split_whitespace().nth(2).unwrap().to_string()),
                "{line}"
            );
        }
        let stale = render(
            &labels,
            &[Some((t, now)), None],
            now + STALE + Duration::from_secs(1),
        );
        assert!(stale.contains("chaosd_up{namespace=\"a\"} 0\n"));
        assert!(!stale.contains("chaosd_ticks_total"));
    }

    #[test]
    fn the_dashboard_asks_only_for_metrics_the_exporter_serves() {
        let now = Instant::now();
        let text = render(
            &["a".into()],
            &[Some((TelemetrySample::default(), now))],
            now,
        );
        let dash = include_str!("../../deploy/grafana/chaosd.json");
        let mut n = 0;
        for (i, _) in dash.match_indices("chaosd_") {
            let name: String = dash[i..]
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            n += 1;
            assert!(
                text.contains(&format!("\n{name}{{")),
                "the dashboard queries {name}, which the exporter does not serve"
            );
        }
        assert!(n > 10, "{n} metric names in the dashboard");
    }
}
