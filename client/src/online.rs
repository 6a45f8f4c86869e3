//! The online commands: talk to a running chaosd over its control and telemetry services.
//!
//! Every request has a deadline: when no daemon answers, the error names the namespace that was
//! tried, and the command exits instead of hanging. Exit codes: 0 done, 1 the daemon refused (the
//! message says why; nothing changed), 2 bad usage, 3 no daemon answered.

use clap::{Args, Subcommand};
use iceoryx2::prelude::ipc;
use protocol::{ControlRequest, ControlResponse, Op, ServiceNames, TelemetrySample};
use std::io::{IsTerminal, Write};
use std::process::ExitCode;
use std::time::{Duration, Instant};

#[derive(Args, Debug, Clone)]
pub struct Conn {
    /// The daemon's namespace.
    #[arg(long, default_value = protocol::DEFAULT_NAMESPACE, global = true)]
    pub namespace: String,
    /// Seconds to wait for an answer.
    #[arg(long, default_value_t = 2.0, global = true)]
    pub timeout: f64,
}

#[derive(Subcommand, Debug)]
pub enum Online {
    /// Mode, parameters, counters and latency of a running daemon.
    Status {
        #[command(flatten)]
        conn: Conn,
        /// Print the daemon's raw JSON.
        #[arg(long)]
        json: bool,
    },
    /// The running configuration, as TOML.
    Get {
        #[command(flatten)]
        conn: Conn,
    },
    /// Change parameters, all or nothing: `set mu 1.5 tau 1.0`, `set task.center 1 2`.
    Set {
        #[command(flatten)]
        conn: Conn,
        /// KEY VALUE pairs (mu, tau, t_on, feedback, kp, kv, alpha, secondary, w1, w2, task.center, task.radius, task.period, ...).
        #[arg(required = true, num_args = 1.., allow_negative_numbers = true)]
        pairs: Vec<String>,
    },
    /// Add, remove or list obstacles.
    Obstacle {
        #[command(flatten)]
        conn: Conn,
        #[command(subcommand)]
        action: ObstacleAction,
    },
    /// Delayed feedback on (from now) or off.
    Dfc {
        #[command(flatten)]
        conn: Conn,
        #[arg(value_parser = ["on", "off"])]
        state: String,
    },
    /// Latency percentiles since start (or the last reset).
    Hist {
        #[command(flatten)]
        conn: Conn,
        /// Reset the histograms.
        #[arg(long)]
        reset: bool,
    },
    /// Record what the daemon does to a file in its output directory: MCAP (every channel; open it
    /// in Foxglove, `chaosctl export` it), or CSV rows for a name ending in `.csv`.
    Record {
        #[command(flatten)]
        conn: Conn,
        #[command(subcommand)]
        action: RecordAction,
    },
    /// Leave FAULT (the runaway guard tripped, or the device stopped with a reflex error, and
    /// the arm is braking): the daemon sends HOLD (a device clears its reflex stop on it) until
    /// the next fresh state, then controls again with a fresh history. Refused when not in
    /// FAULT. `recover` is the same command, by libfranka's name.
    #[command(visible_alias = "recover")]
    Resume {
        #[command(flatten)]
        conn: Conn,
    },
    /// Stall the control loop for MS milliseconds (1..=10000), to check a deployment's watchdog:
    /// the plant brakes on its command timeout, and a `WatchdogSec` below MS makes systemd
    /// restart the daemon. Not for normal operation.
    DebugStall {
        #[command(flatten)]
        conn: Conn,
        ms: u64,
    },
    /// Stop the daemon cleanly (it writes its histograms).
    Shutdown {
        #[command(flatten)]
        conn: Conn,
    },
    /// Live telemetry: a view refreshed in place, or JSON lines with --json.
    Watch {
        #[command(flatten)]
        conn: Conn,
        /// One JSON object per telemetry sample.
        #[arg(long)]
        json: bool,
        /// Stop after this many samples.
        #[arg(long)]
        count: Option<u64>,
    },
}

#[derive(Subcommand, Debug)]
pub enum ObstacleAction {
    /// Add an obstacle: `X Y RADIUS` (a circle, planar arm) or `X Y Z RADIUS` (a sphere,
    /// spatial robot), in m.
    Add {
        /// X Y RADIUS (planar arm) or X Y Z RADIUS (spatial robot), in m.
        #[arg(allow_negative_numbers = true, required = true, num_args = 3..=4, value_name = "NUMBER")]
        values: Vec<f64>,
        /// Safety margin (m).
        #[arg(long, default_value_t = 0.1)]
        margin: f64,
    },
    /// Remove obstacle N, numbered from 1 as `ls` and every message number them.
    Rm { number: usize },
    /// List the obstacles.
    Ls,
}

#[derive(Subcommand, Debug)]
pub enum RecordAction {
    /// Start recording to NAME (a relative path inside the output directory): MCAP (open it in
    /// Foxglove; `chaosctl export NAME --csv` for a table), or CSV when NAME ends in `.csv`.
    Start { name: Option<String> },
    /// Stop and close the file.
    Stop,
}

// The request each command sends, in one place for `chaosctl` and `chaosd-gateway --remote`.

impl ObstacleAction {
    /// The request this action sends: its operation and argument string.
    pub fn request(&self) -> (Op, String) {
        match self {
            ObstacleAction::Add { values, margin } => {
                let v: Vec<String> = values.iter().map(f64::to_string).collect();
                (Op::ObstacleAdd, format!("{} margin={margin}", v.join(" ")))
            }
            ObstacleAction::Rm { number } => (Op::ObstacleRemove, number.to_string()),
            ObstacleAction::Ls => (Op::ObstacleList, String::new()),
        }
    }
}

impl RecordAction {
    /// The request this action sends: its operation and argument string.
    pub fn request(&self) -> (Op, String) {
        match self {
            RecordAction::Start { name } => (Op::RecordStart, name.clone().unwrap_or_default()),
            RecordAction::Stop => (Op::RecordStop, String::new()),
        }
    }
}

/// `dfc on|off` as an operation.
pub fn dfc_op(state: &str) -> Op {
    if state == "on" {
        Op::DfcOn
    } else {
        Op::DfcOff
    }
}

/// `hist [--reset]` as an operation.
pub fn hist_op(reset: bool) -> Op {
    if reset {
        Op::HistReset
    } else {
        Op::HistSnapshot
    }
}

/// Why a command failed, and its exit code.
#[derive(Debug)]
pub enum Failure {
    Refused(String),
    Usage(String),
    Unreachable(String),
}

impl Failure {
    /// The exit code and the message, without the "refused: " prefix.
    pub fn parts(&self) -> (u8, &str) {
        match self {
            Failure::Refused(m) => (1, m),
            Failure::Usage(m) => (2, m),
            Failure::Unreachable(m) => (3, m),
        }
    }

    pub fn exit(self) -> ExitCode {
        let (code, msg) = match self {
            Failure::Refused(m) => (1, format!("refused: {m}")),
            Failure::Usage(m) => (2, m),
            Failure::Unreachable(m) => (3, m),
        };
        // `<3>` in front under journald (the exporter runs as a unit), plain on a terminal.
        rt::log::fatal("chaosctl", &msg);
        ExitCode::from(code)
    }
}

fn node() -> Result<iceoryx2::node::Node<ipc::Service>, Failure> {
    protocol::node("chaosctl").map_err(|e| Failure::Unreachable(e.to_string()))
}

pub fn names(conn: &Conn) -> Result<ServiceNames, Failure> {
    if !(conn.timeout.is_finite() && conn.timeout > 0.0 && conn.timeout <= 3600.0) {
        return Err(Failure::Usage(format!(
            "--timeout {}: must be between 0 and 3600 s",
            conn.timeout
        )));
    }
    ServiceNames::new(&conn.namespace)
        .map_err(|e| Failure::Usage(format!("--namespace {:?}: {e}", conn.namespace)))
}

/// Sends one request and waits for the answer.
pub fn request(conn: &Conn, op: Op, args: &str) -> Result<String, Failure> {
    let names = names(conn)?;
    Link::open(names)?.request(op, args, Duration::from_secs_f64(conn.timeout))
}

/// An open connection to one daemon's control service, for any number of requests: `chaosctl`
/// opens one per command, the Zenoh gateway keeps one per namespace. Both build and check every
/// request here, so a request through the gateway meets the same checks as a local one.
pub struct Link {
    names: ServiceNames,
    client: iceoryx2::port::client::Client<ipc::Service, ControlRequest, (), ControlResponse, ()>,
    // Dropped after the port.
    _node: iceoryx2::node::Node<ipc::Service>,
}

impl Link {
    /// Connects to the control service of the daemon in `names`' namespace.
    pub fn open(names: ServiceNames) -> Result<Self, Failure> {
        let node = node()?;
        let service =
            protocol::control::open_control_service(&node, &names).map_err(|e| match e {
                protocol::ServiceError::NotRunning { .. } => not_running(&names),
                other => {
                    Failure::Unreachable(format!("namespace {:?}: {other}", names.namespace()))
                }
            })?;
        let client = service.client_builder().create().map_err(|e| {
            Failure::Unreachable(format!("cannot connect to {}: {e:?}", names.control()))
        })?;
        Ok(Self {
            names,
            client,
            _node: node,
        })
    }

    pub fn names(&self) -> &ServiceNames {
        &self.names
    }

    /// Sends one request and waits up to `timeout` for the answer.
    pub fn request(&self, op: Op, args: &str, timeout: Duration) -> Result<String, Failure> {
        let names = &self.names;
        let req = ControlRequest::new(std::process::id() as u64, op, args)
            .map_err(|e| Failure::Usage(e.to_string()))?;
        let pending = self.client.send_copy(req).map_err(|e| {
            Failure::Unreachable(format!("cannot send to {}: {e:?}", names.control()))
        })?;
        if pending.number_of_server_connections() == 0 {
            return Err(not_running(names));
        }
        let deadline = Instant::now() + timeout;
        loop {
            match pending.receive() {
                Ok(Some(r)) => {
                    let r: ControlResponse = *r;
                    let body = r
                        .body()
                        .map_err(|e| Failure::Unreachable(format!("malformed answer: {e}")))?
                        .to_string();
                    return if r.is_ok() {
                        Ok(body)
                    } else {
                        Err(Failure::Refused(body))
                    };
                }
                Ok(None) => {}
                Err(e) => {
                    return Err(Failure::Unreachable(format!(
                        "lost the connection to {}: {e:?}",
                        names.control()
                    )))
                }
            }
            if Instant::now() >= deadline {
                return Err(Failure::Unreachable(format!(
                    "no answer from chaosd in namespace {:?} within {} s",
                    names.namespace(),
                    timeout.as_secs_f64()
                )));
            }
            // Answers come from the daemon's reporter thread within about a millisecond; a
            // short sleep keeps a remote status round trip well inside its 5 ms budget.
            std::thread::sleep(Duration::from_micros(200));
        }
    }
}

fn not_running(names: &ServiceNames) -> Failure {
    Failure::Unreachable(format!(
        "no chaosd answers in namespace {:?} (service {}): is the daemon running?",
        names.namespace(),
        names.control()
    ))
}

pub fn pretty(body: &str) -> String {
    serde_json::from_str::<serde_json::Value>(body)
        .ok()
        .and_then(|v| serde_json::to_string_pretty(&v).ok())
        .unwrap_or_else(|| body.to_string())
}

pub fn human_status(body: &str) -> String {
    let Ok(v) = serde_json::from_str::<serde_json::Value>(body) else {
        return body.to_string();
    };
    let f = |k: &str| match &v[k] {
        serde_json::Value::String(s) => s.clone(),
        other => other.to_string(),
    };
    let lat = &v["histograms"]["lateness"];
    let us = |x: &serde_json::Value| x.as_f64().map_or("n/a".to_string(), |x| format!("{x:.1}"));
    let c = &v["counters"];
    format!(
        "chaosd in namespace {} (pid {}): {} at t = {:.1} s, {} Hz {} wait\n\
         arm       {}\n\
         feedback  {} (active: {}), μ = {}, τ = {} s, t_on = {} s, max τ = {} s\n\
         control   K_p = {}, K_v = {}, α = {}, secondary {}, {} obstacles; recent tracking error {} m\n\
         timing    lateness p50 {} µs, p99 {} µs, max {} µs; overruns {}\n\
         trigger   {}; state → command p50 {} µs, p99 {} µs; {} of answered states answered within one period\n\
         counters  {} ticks, {} commands, {} rejected samples, {} holds, {} plant restarts, {} params applied\n\
         law       tracking lost on {} ticks, near-singular on {}, target out of reach on {}, non-finite results {}\n\
         recording {}{}{}",
        f("namespace"), f("pid"), f("mode"), v["t"].as_f64().unwrap_or(0.0), f("rate_hz"), f("wait"),
        v["arm"].as_str().unwrap_or("n/a"),
        if v["feedback"].as_bool() == Some(true) { "on" } else { "off" }, f("feedback_active"), v["mu"].as_f64().map_or_else(|| f("mu"), daemon::number::short), f("tau"), f("t_on"), f("max_tau"),
        f("kp"), f("kv"), f("alpha"), f("secondary"), f("obstacles"),
        v["tracking_error_recent"].as_f64().map_or("n/a".into(), |x| format!("{x:.2e}")),
        us(&lat["p50_us"]), us(&lat["p99_us"]), us(&lat["max_us"]), c["overruns"],
        f("trigger"), us(&v["state_to_command"]["p50_us"]), us(&v["state_to_command"]["p99_us"]),
        v["answered_within_period"].as_f64().map_or("n/a".into(), |x| format!("{:.3} %", x * 100.0)),
        c["ticks"], c["commands"],
        ["rejected_invalid", "rejected_stale", "rejected_out_of_order", "rejected_future", "plant_faults"]
            .iter()
            .map(|k| c[*k].as_u64().unwrap_or(0))
            .sum::<u64>(),
        c["holds_entered"], c["plant_restarts"], c["params_applied"],
        c["track_lost"], c["singular"], c["out_of_reach"], c["nonfinite"],
        v["recording"].as_str().unwrap_or("off"),
        core_gone(&v),
        v["handshake"].as_str().map_or(String::new(), |why| format!("\nhandshake {why}")),
    ) + &chaos_status(&v)
        + &blocked_part(&v)
}

/// The chaos monitor's line: the verdict, since when, and its evidence.
fn chaos_status(v: &serde_json::Value) -> String {
    let c = &v["chaos"];
    let Some(verdict) = c["verdict"].as_str() else {
        return String::new(); // an older daemon
    };
    let num = |k: &str, f: &dyn Fn(f64) -> String| c[k].as_f64().map_or("n/a".into(), f);
    format!(
        "
chaos     {verdict} since t = {:.1} s: λ = {}, K = {}, residual {} rad/s ({} a period) over {} periods{}",
        c["since"].as_f64().unwrap_or(f64::NAN),
        num("lyapunov", &|l| format!("{l:+.3}/s")),
        num("k", &|k| format!("{k:.2}")),
        num("residual", &|r| format!("{r:.1e}")),
        num("residual_trend", &|r| format!("×{r:.3}")),
        c["periods"],
        if c["mu_auto"].as_bool() == Some(true) { "; μ adapts (auto)" } else { "" },
    )
}

/// `BLOCKED` and why, when the daemon is; and whether it steers onto a planned cycle.
fn blocked_part(v: &serde_json::Value) -> String {
    let mut s = String::new();
    let b = &v["blocked"];
    if let Some(reason) = b["reason"].as_str() {
        s.push_str(&format!(
            "\nBLOCKED   since t = {:.1} s ({}): {reason}",
            b["since"].as_f64().unwrap_or(f64::NAN),
            b["action"].as_str().unwrap_or("?")
        ));
    }
    if v["plan"]["steering"].as_bool() == Some(true) {
        s.push_str("\nplan      steering onto a planned clean cycle");
    }
    s
}

/// State trigger: how often the loop's core was gone while it ran (`rt::gaps`), so that late
/// answers can be told apart from a slow law. Empty for the clock trigger or an older daemon.
fn core_gone(v: &serde_json::Value) -> String {
    let gaps = |k: &str| serde_json::from_value::<rt::gaps::Gaps>(v["counters"][k].clone()).ok();
    let (Some(g), Some(w), Some(rate)) =
        (gaps("wait_gaps"), gaps("late_wakes"), v["rate_hz"].as_f64())
    else {
        return String::new();
    };
    if v["trigger"] != "state" || rate <= 0.0 {
        return String::new();
    }
    format!(
        "\ncore gone {}",
        rt::gaps::describe(&g, &w, (1e9 / rate) as u64)
    )
}

pub fn telemetry_json(t: &TelemetrySample) -> serde_json::Value {
    let n = (t.n as usize).min(protocol::MAX_JOINTS);
    serde_json::json!({
        "seq": t.seq, "stamp_ns": t.stamp_ns, "t": t.t,
        "mode": match protocol::Mode::try_from(t.mode) { Ok(m) => format!("{m:?}"), Err(_) => format!("unknown({})", t.mode) },
        "feedback_on": t.feedback_on == 1, "feedback_active": t.feedback_active == 1,
        "mu": t.mu, "tau": t.tau, "t_on": t.t_on,
        "tracking_error": t.tracking_error, "period_residual": t.period_residual,
        "clearance": if t.clearance.is_finite() { Some(t.clearance) } else { None },
        "time_in_contact": t.time_in_contact,
        "lateness_p50_us": t.lateness_p50_us, "lateness_p99_us": t.lateness_p99_us, "lateness_max_us": t.lateness_max_us,
        "ticks": t.ticks, "overruns": t.overruns, "telemetry_dropped": t.telemetry_dropped,
        "rejected": t.rejected, "holds": t.holds,
        "state_seq": t.state_seq, "phi": t.phi, "q": &t.q[..n], "qd": &t.qd[..n],
        "interface": protocol::interface::name(t.interface),
        "device": protocol::DeviceStatus::from_code(t.device)
            .filter(|d| *d != protocol::DeviceStatus::Ok)
            .map(|d| d.name()),
        "saturations": saturations_json(&t.saturations),
        "blocked": match t.blocked { 0 => None, 1 => Some("hold"), _ => Some("best-effort") },
        "steering": t.steering == 1,
        "chaos": control::monitor::Verdict::from_code(t.chaos).name(),
        "lyapunov": t.lyapunov.is_finite().then_some(t.lyapunov),
        "k01": t.k01.is_finite().then_some(t.k01),
        "mu_auto": t.mu_auto == 1,
    })
}

/// The limiter's clamps since start, by kind (`{"jerk": 4, ...}`).
fn saturations_json(counts: &[u64; 6]) -> serde_json::Value {
    control::command::LimitKind::ALL
        .iter()
        .zip(counts)
        .map(|(k, n)| (k.name().to_string(), serde_json::json!(n)))
        .collect::<serde_json::Map<_, _>>()
        .into()
}

/// The watch line's command part: the interface, the limiter's clamps so far, and the
/// device's stop when it has one (`position, clamped 6` / `torque, device: jerk limit…`).
fn command_part(t: &TelemetrySample) -> String {
    let mode = protocol::interface::name(t.interface).unwrap_or("?");
    let clamped: u64 = t.saturations.iter().sum();
    let mut s = format!("{mode}, clamped {clamped}");
    if let Some(d) =
        protocol::DeviceStatus::from_code(t.device).filter(|d| *d != protocol::DeviceStatus::Ok)
    {
        s.push_str(&format!(", device: {d}"));
    }
    s
}

/// The watch line's chaos monitor part: `chaotic λ +0.31/s K 0.98`.
fn chaos_part(t: &TelemetrySample) -> String {
    let mut s = control::monitor::Verdict::from_code(t.chaos)
        .name()
        .to_string();
    if t.lyapunov.is_finite() {
        s.push_str(&format!(" λ {:+.2}/s", t.lyapunov));
    }
    if t.k01.is_finite() {
        s.push_str(&format!(" K {:.2}", t.k01));
    }
    s
}

/// The watch line's mode: `Run`, or `BLOCKED (hold)` while blocked, with `steering` when the
/// self-motion is steered onto a planned cycle.
fn mode_part(t: &TelemetrySample, v: &serde_json::Value) -> String {
    let mut s = match v["blocked"].as_str() {
        Some(action) => format!("BLOCKED ({action})"),
        None => v["mode"].as_str().unwrap_or("?").to_string(),
    };
    if t.steering == 1 {
        s.push_str(", steering");
    }
    s
}

fn watch(conn: &Conn, json: bool, count: Option<u64>) -> Result<(), Failure> {
    let names = names(conn)?;
    let node = node()?;
    let svc = protocol::control::open_telemetry_service(&node, &names)
        .map_err(|e| Failure::Unreachable(e.to_string()))?;
    let sub = svc.subscriber_builder().create().map_err(|e| {
        Failure::Unreachable(format!("cannot subscribe to {}: {e:?}", names.telemetry()))
    })?;
    let tty = std::io::stdout().is_terminal() && !json;
    let mut seen = 0u64;
    let mut last_sample = Instant::now();
    let mut out = std::io::stdout().lock();
    while count.is_none_or(|c| seen < c) {
        let mut got = None;
        while let Ok(Some(s)) = sub.receive() {
            got = Some(*s);
        }
        match got {
            Some(t) => {
                last_sample = Instant::now();
                seen += 1;
                let line = if json {
                    telemetry_json(&t).to_string()
                } else {
                    let v = telemetry_json(&t);
                    format!(
                        "chaosd {} | t {:8.2} s | {:<4} | {} | feedback {} μ={:.3}{} τ={:.2} | {} | track {:.2e} m | residual {:.3e} rad/s | clearance {} | contact {:.2} s | late p99 {:.1} µs max {:.1} µs | overruns {} | rejected {} | holds {} | drops {}",
                        names.namespace(), t.t, mode_part(&t, &v), command_part(&t),
                        if t.feedback_active == 1 { "ON " } else if t.feedback_on == 1 { "armed" } else { "off" },
                        t.mu, if t.mu_auto == 1 { " (auto)" } else { "" }, t.tau, chaos_part(&t), t.tracking_error, t.period_residual,
                        if t.clearance.is_finite() { format!("{:+.3} m", t.clearance) } else { "n/a".into() },
                        t.time_in_contact, t.lateness_p99_us, t.lateness_max_us, t.overruns, t.rejected, t.holds, t.telemetry_dropped
                    )
                };
                let res = if tty {
                    write!(out, "\r\x1b[2K{line}")
                } else {
                    writeln!(out, "{line}")
                };
                if res.and_then(|_| out.flush()).is_err() {
                    return Ok(()); // the reader went away (a closed pipe): stop quietly
                }
            }
            None => {
                if last_sample.elapsed() > Duration::from_secs_f64(conn.timeout) {
                    if tty {
                        let _ = writeln!(out);
                    }
                    return Err(Failure::Unreachable(format!(
                        "no telemetry from chaosd in namespace {:?} for {} s (service {})",
                        names.namespace(),
                        conn.timeout,
                        names.telemetry()
                    )));
                }
                std::thread::sleep(Duration::from_millis(5));
            }
        }
    }
    if tty {
        let _ = writeln!(out);
    }
    Ok(())
}

pub fn run(cmd: Online) -> ExitCode {
    let result = match cmd {
        Online::Status { conn, json } => {
            request(&conn, Op::Status, "").map(|b| if json { b } else { human_status(&b) })
        }
        Online::Get { conn } => request(&conn, Op::GetConfig, ""),
        Online::Set { conn, pairs } => {
            request(&conn, Op::Set, &pairs.join(" ")).map(|b| pretty(&b))
        }
        Online::Obstacle { conn, action } => {
            let (op, args) = action.request();
            request(&conn, op, &args).map(|b| pretty(&b))
        }
        Online::Dfc { conn, state } => request(&conn, dfc_op(&state), "").map(|b| pretty(&b)),
        Online::Hist { conn, reset } => request(&conn, hist_op(reset), "").map(|b| pretty(&b)),
        Online::Record { conn, action } => {
            let (op, args) = action.request();
            request(&conn, op, &args).map(|b| pretty(&b))
        }
        Online::Shutdown { conn } => request(&conn, Op::Shutdown, ""),
        Online::Resume { conn } => request(&conn, Op::Resume, ""),
        Online::DebugStall { conn, ms } => request(&conn, Op::DebugStall, &ms.to_string()),
        Online::Watch { conn, json, count } => watch(&conn, json, count).map(|_| String::new()),
    };
    match result {
        Ok(body) => {
            if !body.is_empty() {
                println!("{body}");
            }
            ExitCode::SUCCESS
        }
        Err(f) => f.exit(),
    }
}
