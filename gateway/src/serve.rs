//! `chaosd-gateway serve`: one process per host, bridging the local daemons' iceoryx2 services to
//! Zenoh (key space in `keys.rs`).
//!
//! Per namespace, two threads:
//! - **telemetry**: subscribes to the daemon's telemetry over iceoryx2 and publishes every sample
//!   on `chaosd/<host>/<ns>/telemetry` with congestion control *block*, so Zenoh never drops one;
//!   it reconnects when the daemon restarts.
//! - **control**: answers queries on `chaosd/<host>/<ns>/control` by forwarding them to the daemon
//!   through `client::online::Link`, the code `chaosctl` itself uses, so the same checks apply and
//!   the daemon validates as for a local request; once a second it publishes the daemon's status on
//!   `chaosd/<host>/<ns>/status`.
//!
//! The daemon never sees the network: the gateway is just another local iceoryx2 client, served by
//! the daemon's reporter thread, never by the loop. Access is explicit: without `--allow-changes`
//! the gateway forwards only reads (status, get, obstacle list, histogram snapshot) and refuses
//! everything else itself; it says which mode it is in when it starts and in every status.

use crate::keys::{self, Outcome, Reply, Request};
use crate::session::{self, Role};
use anyhow::{anyhow, bail, Result};
use clap::Args;
use client::online::{telemetry_json, Failure, Link};
use protocol::{Op, ServiceNames};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::qos::CongestionControl;
use zenoh::{Session, Wait};

#[derive(Args, Debug)]
pub struct ServeArgs {
    /// A daemon namespace to serve; repeat for several daemons on this host.
    #[arg(long = "namespace", required = true)]
    pub namespaces: Vec<String>,
    /// This host's name in the key space (default: the machine's host name).
    #[arg(long)]
    pub host: Option<String>,
    /// Zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447; repeatable.
    #[arg(long)]
    pub listen: Vec<String>,
    /// Zenoh endpoint of another gateway to connect to; repeatable.
    #[arg(long)]
    pub connect: Vec<String>,
    /// Let remote clients change the daemons (set, obstacle, dfc, record, resume, shutdown,
    /// histogram reset). Without it the gateway is read-only.
    #[arg(long)]
    pub allow_changes: bool,
    /// Seconds to wait for a daemon's answer to a forwarded request.
    #[arg(long, default_value_t = 2.0)]
    pub timeout: f64,
}

/// The requests a read-only gateway forwards.
pub fn is_read_only(op: Op) -> bool {
    matches!(
        op,
        Op::Status | Op::GetConfig | Op::ObstacleList | Op::HistSnapshot
    )
}

/// The machine's host name, if it is usable as a key chunk.
fn default_host() -> Result<String> {
    let mut buf = [0u8; 256];
    // SAFETY: gethostname writes at most buf.len() bytes into our buffer.
    let rc = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    if rc != 0 {
        bail!("cannot read the host name: give --host NAME");
    }
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    let host = String::from_utf8_lossy(&buf[..end]).into_owned();
    keys::validate_host(&host)
        .map_err(|e| anyhow!("the machine's host name: {e}; give --host NAME"))?;
    Ok(host)
}

/// What one namespace's threads share: the daemon's latest period residual, for the status.
struct Shared {
    host: String,
    names: ServiceNames,
    allow_changes: bool,
    timeout: Duration,
    residual: Mutex<Option<f64>>,
    stop: Arc<AtomicBool>,
}

pub fn run(args: ServeArgs) -> Result<()> {
    let host = match &args.host {
        Some(h) => {
            keys::validate_host(h).map_err(anyhow::Error::msg)?;
            h.clone()
        }
        None => default_host()?,
    };
    let mut names = Vec::new();
    for ns in &args.namespaces {
        let n = ServiceNames::new(ns).map_err(|e| anyhow!("--namespace {ns:?}: {e}"))?;
        if names.iter().any(|m: &ServiceNames| m.namespace() == ns) {
            bail!("--namespace {ns:?} given twice");
        }
        names.push(n);
    }
    if !(args.timeout.is_finite() && args.timeout > 0.0 && args.timeout <= 60.0) {
        bail!("--timeout {}: must be between 0 and 60 s", args.timeout);
    }
    // Block SIGINT/SIGTERM in every thread (they inherit the mask); main waits for them below.
    let signals = block_stop_signals();
    let session = session::open(
        Role::Gateway,
        &args.listen,
        &args.connect,
        Duration::from_secs(10),
    )?;
    let access = if args.allow_changes {
        "CHANGES ALLOWED (--allow-changes): remote clients can change parameters and stop the daemons"
    } else {
        "READ-ONLY: remote clients can watch and read; start with --allow-changes to let them change parameters"
    };
    eprintln!(
        "chaosd-gateway: host {host}, namespaces {}; {access}; listening on {:?}, connected to {:?}; keys {}",
        names.iter().map(|n| n.namespace()).collect::<Vec<_>>().join(", "),
        args.listen,
        args.connect,
        keys::key(Some(&host), None, "{telemetry,status,control}"),
    );
    let stop = Arc::new(AtomicBool::new(false));
    let mut threads = Vec::new();
    for n in names {
        let shared = Arc::new(Shared {
            host: host.clone(),
            names: n,
            allow_changes: args.allow_changes,
            timeout: Duration::from_secs_f64(args.timeout),
            residual: Mutex::new(None),
            stop: stop.clone(),
        });
        let (s1, z1) = (shared.clone(), session.clone());
        threads.push(std::thread::spawn(move || telemetry(&s1, &z1)));
        let (s2, z2) = (shared, session.clone());
        threads.push(std::thread::spawn(move || control(&s2, &z2)));
    }
    let sig = wait_for(&signals);
    eprintln!("chaosd-gateway: signal {sig}: stopping");
    stop.store(true, Ordering::Relaxed);
    for t in threads {
        match t.join() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => eprintln!("chaosd-gateway: {e:#}"),
            Err(_) => eprintln!("chaosd-gateway: a thread panicked"),
        }
    }
    session
        .close()
        .wait()
        .map_err(|e| anyhow!("closing the Zenoh session: {e}"))?;
    Ok(())
}

fn block_stop_signals() -> libc::sigset_t {
    // SAFETY: plain signal-set manipulation on a local set, before any thread is started.
    unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        libc::sigaddset(&mut set, libc::SIGINT);
        libc::sigaddset(&mut set, libc::SIGTERM);
        libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut());
        set
    }
}

fn wait_for(set: &libc::sigset_t) -> i32 {
    let mut sig = 0;
    // SAFETY: sigwait on a set of signals this thread has blocked.
    unsafe { libc::sigwait(set, &mut sig) };
    sig
}

/// Forwards telemetry samples from iceoryx2 to Zenoh until stopped.
fn telemetry(sh: &Shared, session: &Session) -> Result<()> {
    let ns = sh.names.namespace();
    let key = keys::key(Some(&sh.host), Some(ns), "telemetry");
    let publisher = session
        .declare_publisher(key.clone())
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| anyhow!("cannot publish on {key}: {e}"))?;
    let node = protocol::node("chaosd-gateway").map_err(|e| anyhow!("{e}"))?;
    let mut said_waiting = false;
    while !sh.stop.load(Ordering::Relaxed) {
        let sub = match protocol::control::open_telemetry_service(&node, &sh.names)
            .map_err(|e| e.to_string())
            .and_then(|s| {
                s.subscriber_builder()
                    .create()
                    .map_err(|e| format!("{e:?}"))
            }) {
            Ok(s) => s,
            Err(e) => {
                if !said_waiting {
                    eprintln!("chaosd-gateway: namespace {ns}: waiting for chaosd ({e})");
                    said_waiting = true;
                }
                std::thread::sleep(Duration::from_millis(500));
                continue;
            }
        };
        eprintln!("chaosd-gateway: namespace {ns}: forwarding telemetry to {key}");
        said_waiting = false;
        let mut last = Instant::now();
        while !sh.stop.load(Ordering::Relaxed) {
            let mut got = false;
            while let Ok(Some(s)) = sub.receive() {
                got = true;
                let mut v = telemetry_json(&s);
                v["host"] = sh.host.as_str().into();
                v["namespace"] = ns.into();
                if let Ok(mut r) = sh.residual.lock() {
                    *r = Some(s.period_residual);
                }
                publisher
                    .put(v.to_string())
                    .wait()
                    .map_err(|e| anyhow!("publishing on {key}: {e}"))?;
            }
            if got {
                last = Instant::now();
            } else if last.elapsed() > Duration::from_secs(3) {
                // The daemon went away or restarted: open its service again.
                break;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    Ok(())
}

/// Answers control queries and publishes the status once a second, until stopped.
fn control(sh: &Shared, session: &Session) -> Result<()> {
    let ns = sh.names.namespace();
    let key = keys::key(Some(&sh.host), Some(ns), "control");
    let queryable = session
        .declare_queryable(key.clone())
        .wait()
        .map_err(|e| anyhow!("cannot serve {key}: {e}"))?;
    let status_key = keys::key(Some(&sh.host), Some(ns), "status");
    let status_pub = session
        .declare_publisher(status_key.clone())
        .wait()
        .map_err(|e| anyhow!("cannot publish on {status_key}: {e}"))?;
    let mut link: Option<Link> = None;
    let mut next_status = Instant::now();
    while !sh.stop.load(Ordering::Relaxed) {
        let wait = next_status
            .saturating_duration_since(Instant::now())
            .min(Duration::from_millis(200));
        match queryable.recv_timeout(wait) {
            Ok(Some(query)) => {
                let reply = answer(sh, &mut link, query.payload().map(|p| p.to_bytes()));
                let text = serde_json::to_string(&reply)?;
                // Reply on our own key, not the query's (it may be a wildcard): the key is how
                // a client tells which host and namespace answered.
                if let Err(e) = query.reply(key.as_str(), text).wait() {
                    eprintln!("chaosd-gateway: namespace {ns}: cannot reply: {e}");
                }
            }
            Ok(None) => {
                if Instant::now() >= next_status {
                    if let Ok(body) = forward(sh, &mut link, Op::Status, "") {
                        let _ = status_pub.put(with_gateway(sh, &body)).wait();
                    }
                    next_status = Instant::now() + Duration::from_secs(1);
                }
            }
            Err(_) => break, // the session is closing
        }
    }
    Ok(())
}

/// The reply to one query's payload.
fn answer(sh: &Shared, link: &mut Option<Link>, payload: Option<std::borrow::Cow<[u8]>>) -> Reply {
    let usage = |body: String| Reply {
        outcome: Outcome::Usage,
        body,
    };
    let Some(bytes) = payload else {
        return usage("a control query needs a JSON payload {\"op\": N, \"args\": \"...\"}".into());
    };
    let req: Request = match serde_json::from_slice(&bytes) {
        Ok(r) => r,
        Err(e) => return usage(format!("malformed control request: {e}")),
    };
    let op = match Op::try_from(req.op) {
        Ok(op) => op,
        Err(v) => return usage(format!("unknown request op {v}")),
    };
    if !sh.allow_changes && !is_read_only(op) {
        return Reply {
            outcome: Outcome::Refused,
            body: format!(
                "the gateway of host {} is read-only (started without --allow-changes): {op:?} \
                 refused, nothing changed",
                sh.host
            ),
        };
    }
    match forward(sh, link, op, &req.args) {
        Ok(body) => Reply {
            outcome: Outcome::Ok,
            body: if op == Op::Status {
                with_gateway(sh, &body)
            } else {
                body
            },
        },
        Err(f) => {
            let outcome = match f {
                Failure::Refused(_) => Outcome::Refused,
                Failure::Usage(_) => Outcome::Usage,
                Failure::Unreachable(_) => Outcome::Unreachable,
            };
            Reply {
                outcome,
                body: f.parts().1.to_string(),
            }
        }
    }
}

/// One request to the local daemon over iceoryx2, through a link kept open between requests and
/// opened again after a failure.
fn forward(sh: &Shared, link: &mut Option<Link>, op: Op, args: &str) -> Result<String, Failure> {
    if link.is_none() {
        *link = Some(Link::open(sh.names.clone())?);
    }
    let l = link.as_ref().expect("just opened");
    let r = l.request(op, args, sh.timeout);
    if matches!(r, Err(Failure::Unreachable(_))) {
        *link = None;
    }
    r
}

/// The daemon's status JSON with a "gateway" object: host, namespace, access, and the latest
/// period residual from telemetry (the status itself does not carry it).
fn with_gateway(sh: &Shared, body: &str) -> String {
    let Ok(mut v) = serde_json::from_str::<serde_json::Value>(body) else {
        return body.to_string();
    };
    let residual = sh.residual.lock().ok().and_then(|r| *r);
    v["gateway"] = serde_json::json!({
        "host": sh.host,
        "namespace": sh.names.namespace(),
        "access": if sh.allow_changes { "changes-allowed" } else { "read-only" },
        "period_residual": residual,
    });
    v.to_string()
}
