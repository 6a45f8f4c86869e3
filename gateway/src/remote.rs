//! The remote client: `status`, `get`, `set`, `watch` and `fleet` through a gateway, as the local
//! `chaosctl` commands do (same output, same exit codes: 0 done, 1 refused, 2 bad usage, 3 no
//! answer).
//!
//! A request for a namespace without `--host` first asks every gateway for that namespace's
//! status: exactly one host must answer (several: the command names them and asks for `--host`),
//! so a `set` never reaches two daemons by accident.

use crate::keys::{self, Outcome, Reply, Request};
use crate::session::{self, Role};
use clap::Args;
use protocol::{Op, ServiceNames};
use std::io::Write;
use std::time::{Duration, Instant};
use zenoh::query::{ConsolidationMode, QueryTarget};
use zenoh::{Session, Wait};

/// Which daemon: its namespace and, when several hosts use that namespace, its host.
#[derive(Args, Debug, Clone)]
pub struct Target {
    /// The daemon's namespace.
    #[arg(long, default_value = protocol::DEFAULT_NAMESPACE, global = true)]
    pub namespace: String,
    /// The gateway host serving it (needed only when several hosts serve that namespace).
    #[arg(long, global = true)]
    pub host: Option<String>,
}

/// Why a remote command failed, and its exit code (as `chaosctl`'s).
#[derive(Debug)]
pub struct Fail {
    pub code: u8,
    pub msg: String,
}

impl Fail {
    pub fn usage(msg: impl Into<String>) -> Self {
        Self {
            code: 2,
            msg: msg.into(),
        }
    }
    pub fn unreachable(msg: impl Into<String>) -> Self {
        Self {
            code: 3,
            msg: msg.into(),
        }
    }
}

/// A connection to the Zenoh network through one gateway.
pub struct Remote {
    session: Session,
    endpoint: String,
    timeout: Duration,
}

/// One answer to a control query: who answered, and what.
pub struct Answer {
    pub host: String,
    pub namespace: String,
    pub reply: Reply,
}

impl Remote {
    pub fn connect(endpoint: &str, timeout: f64) -> Result<Self, Fail> {
        if !(timeout.is_finite() && timeout > 0.0 && timeout <= 3600.0) {
            return Err(Fail::usage(format!(
                "--timeout {timeout}: must be between 0 and 3600 s"
            )));
        }
        session::validate_endpoint(endpoint).map_err(|e| Fail::usage(format!("--remote: {e}")))?;
        let wait = Duration::from_secs_f64(timeout);
        let session = session::open(Role::Client, &[], &[endpoint.to_string()], wait).map_err(|e| {
            Fail::unreachable(format!(
                "no gateway at {endpoint}: {e:#} (is chaosd-gateway serve --listen {endpoint} running?)"
            ))
        })?;
        Ok(Self {
            session,
            endpoint: endpoint.to_string(),
            timeout: wait,
        })
    }

    pub fn session(&self) -> &Session {
        &self.session
    }

    pub fn timeout(&self) -> Duration {
        self.timeout
    }

    /// Sends `req` to every queryable on `key` and collects the answers.
    pub fn query(&self, key: &str, req: &Request) -> Result<Vec<Answer>, Fail> {
        let payload = serde_json::to_string(req).map_err(|e| Fail::usage(e.to_string()))?;
        let replies = self
            .session
            .get(key)
            .payload(payload)
            .target(QueryTarget::All)
            .consolidation(ConsolidationMode::None)
            .timeout(self.timeout)
            .wait()
            .map_err(|e| Fail::unreachable(format!("query {key} via {}: {e}", self.endpoint)))?;
        let mut out = Vec::new();
        while let Ok(r) = replies.recv() {
            match r.result() {
                Ok(sample) => {
                    let k = sample.key_expr().as_str();
                    let Some((host, namespace)) = keys::parse(k) else {
                        continue;
                    };
                    let reply: Reply = serde_json::from_slice(&sample.payload().to_bytes())
                        .map_err(|e| {
                            Fail::unreachable(format!("malformed answer from {k}: {e}"))
                        })?;
                    out.push(Answer {
                        host: host.to_string(),
                        namespace: namespace.to_string(),
                        reply,
                    });
                }
                Err(e) => {
                    let body = e.payload().try_to_string().map(|s| s.into_owned());
                    return Err(Fail::unreachable(format!(
                        "error answer to {key}: {}",
                        body.unwrap_or_else(|_| "(not text)".into())
                    )));
                }
            }
        }
        Ok(out)
    }

    /// One request to the daemon `t` names; returns (host, body) or the failure.
    pub fn request(&self, t: &Target, op: Op, args: &str) -> Result<(String, String), Fail> {
        ServiceNames::new(&t.namespace)
            .map_err(|e| Fail::usage(format!("--namespace {:?}: {e}", t.namespace)))?;
        if let Some(h) = &t.host {
            keys::validate_host(h).map_err(Fail::usage)?;
        }
        let ns = Some(t.namespace.as_str());
        let status = Request {
            op: Op::Status as u32,
            args: String::new(),
        };
        let host = match &t.host {
            Some(h) => h.clone(),
            None => {
                let mut answers = self.query(&keys::key(None, ns, "control"), &status)?;
                match answers.len() {
                    0 => return Err(self.nobody(t)),
                    1 if op == Op::Status => {
                        let a = answers.remove(0);
                        return outcome(a);
                    }
                    1 => answers.remove(0).host,
                    _ => {
                        let hosts: Vec<String> = answers.into_iter().map(|a| a.host).collect();
                        return Err(Fail::usage(format!(
                            "namespace {:?} is served on hosts {}: choose one with --host",
                            t.namespace,
                            hosts.join(", ")
                        )));
                    }
                }
            }
        };
        let req = Request {
            op: op as u32,
            args: args.to_string(),
        };
        let mut answers = self.query(&keys::key(Some(&host), ns, "control"), &req)?;
        match answers.len() {
            1 => outcome(answers.remove(0)),
            0 => Err(self.nobody(t)),
            n => Err(Fail::unreachable(format!(
                "{n} gateways answered for host {host}, namespace {:?}: two gateways use the same --host",
                t.namespace
            ))),
        }
    }

    fn nobody(&self, t: &Target) -> Fail {
        Fail::unreachable(format!(
            "no gateway reachable through {} serves namespace {:?}{} within {} s",
            self.endpoint,
            t.namespace,
            t.host
                .as_deref()
                .map(|h| format!(" on host {h}"))
                .unwrap_or_default(),
            self.timeout.as_secs_f64()
        ))
    }
}

fn outcome(a: Answer) -> Result<(String, String), Fail> {
    match a.reply.outcome {
        Outcome::Ok => Ok((a.host, a.reply.body)),
        Outcome::Refused => Err(Fail {
            code: 1,
            msg: format!("refused: {}", a.reply.body),
        }),
        o => Err(Fail {
            code: o.code(),
            msg: format!("host {}: {}", a.host, a.reply.body),
        }),
    }
}

/// `watch`: the daemon's telemetry as the gateway publishes it, one line (or JSON object) per
/// sample, until `count` samples or no sample for the timeout.
pub fn watch(r: &Remote, t: &Target, json: bool, count: Option<u64>) -> Result<(), Fail> {
    ServiceNames::new(&t.namespace)
        .map_err(|e| Fail::usage(format!("--namespace {:?}: {e}", t.namespace)))?;
    if let Some(h) = &t.host {
        keys::validate_host(h).map_err(Fail::usage)?;
    }
    let key = keys::key(t.host.as_deref(), Some(&t.namespace), "telemetry");
    let sub = r
        .session()
        .declare_subscriber(key.clone())
        .wait()
        .map_err(|e| Fail::unreachable(format!("cannot subscribe to {key}: {e}")))?;
    let mut out = std::io::stdout().lock();
    let mut seen = 0u64;
    while count.is_none_or(|c| seen < c) {
        let sample = match sub.recv_timeout(r.timeout()) {
            Ok(Some(s)) => s,
            Ok(None) => {
                return Err(Fail::unreachable(format!(
                    "no telemetry on {key} for {} s: is a gateway serving namespace {:?}?",
                    r.timeout().as_secs_f64(),
                    t.namespace
                )))
            }
            Err(e) => return Err(Fail::unreachable(format!("{key}: {e}"))),
        };
        seen += 1;
        let text = sample.payload().try_to_string().map(|s| s.into_owned());
        let Ok(text) = text else { continue };
        let line = if json {
            text
        } else {
            match serde_json::from_str::<serde_json::Value>(&text) {
                Ok(v) => watch_line(&v),
                Err(_) => continue,
            }
        };
        if writeln!(out, "{line}").and_then(|_| out.flush()).is_err() {
            return Ok(()); // the reader went away
        }
    }
    Ok(())
}

fn watch_line(v: &serde_json::Value) -> String {
    let f = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    format!(
        "chaosd {}/{} | t {:8.2} s | {:<4} | feedback {} μ={:.2} τ={:.2} | track {:.2e} m | residual {:.3e} rad/s | late p99 {:.1} µs | overruns {} | seq {}",
        v["host"].as_str().unwrap_or("?"),
        v["namespace"].as_str().unwrap_or("?"),
        f("t"),
        v["mode"].as_str().unwrap_or("?"),
        if v["feedback_active"] == true { "ON " } else if v["feedback_on"] == true { "armed" } else { "off" },
        f("mu"),
        f("tau"),
        f("tracking_error"),
        f("period_residual"),
        f("lateness_p99_us"),
        v["overruns"],
        v["seq"],
    )
}

/// `fleet`: every controller any gateway on the network serves, one line each.
pub fn fleet(r: &Remote, json: bool) -> Result<String, Fail> {
    let status = Request {
        op: Op::Status as u32,
        args: String::new(),
    };
    let mut answers = r.query(&keys::key(None, None, "control"), &status)?;
    answers.sort_by(|a, b| (&a.host, &a.namespace).cmp(&(&b.host, &b.namespace)));
    if json {
        let list: Vec<serde_json::Value> = answers
            .iter()
            .map(|a| {
                serde_json::json!({
                    "host": a.host, "namespace": a.namespace, "outcome": a.reply.outcome,
                    "status": serde_json::from_str::<serde_json::Value>(&a.reply.body)
                        .unwrap_or_else(|_| a.reply.body.clone().into()),
                })
            })
            .collect();
        return Ok(serde_json::Value::Array(list).to_string());
    }
    let mut s = format!(
        "{:<16} {:<20} {:<16} {:<6} {:>6} {:>12} {:>16} {:>14}",
        "HOST", "NAMESPACE", "GATEWAY", "MODE", "μ", "TRACKING m", "RESIDUAL rad/s", "LATE p99 µs"
    );
    for a in &answers {
        s.push('\n');
        s.push_str(&fleet_line(a));
    }
    s.push_str(&format!("\n{} controller(s)", answers.len()));
    Ok(s)
}

fn fleet_line(a: &Answer) -> String {
    if a.reply.outcome != Outcome::Ok {
        return format!(
            "{:<16} {:<20} {:<16} unreachable: {}",
            a.host, a.namespace, "-", a.reply.body
        );
    }
    let v: serde_json::Value = serde_json::from_str(&a.reply.body).unwrap_or_default();
    let num = |x: &serde_json::Value, p: usize, sci: bool| match x.as_f64() {
        Some(x) if sci => format!("{x:.2e}"),
        Some(x) => format!("{x:.p$}"),
        None => "n/a".into(),
    };
    format!(
        "{:<16} {:<20} {:<16} {:<6} {:>6} {:>12} {:>16} {:>14}",
        a.host,
        a.namespace,
        v["gateway"]["access"].as_str().unwrap_or("?"),
        v["mode"].as_str().unwrap_or("?"),
        num(&v["mu"], 2, false),
        num(&v["tracking_error_recent"], 0, true),
        num(&v["gateway"]["period_residual"], 0, true),
        num(&v["histograms"]["lateness"]["p99_us"], 1, false),
    )
}

/// Milliseconds since `t0`, for the bench.
pub fn ms_since(t0: Instant) -> f64 {
    t0.elapsed().as_secs_f64() * 1e3
}
