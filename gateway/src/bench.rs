//! `chaosd-gateway bench`: the two numbers the gateway is judged by, measured against running
//! gateways (start the daemons and gateways first; `scripts/gateway-bench.sh` does it all).
//!
//! 1. **Remote status round trip**: `--requests` status requests, one after another, to one
//!    controller (`--namespace`, `--host`), from the query leaving this process to its answer
//!    arriving: percentiles.
//! 2. **Telemetry loss**: every telemetry sample on the network (`chaosd/*/*/telemetry`) for
//!    `--seconds`; per controller, the daemon's telemetry sequence numbers show every sample the
//!    chain daemon → iceoryx2 → gateway → Zenoh → here lost (a gap) or repeated.

use crate::keys;
use crate::remote::{ms_since, Fail, Remote, Target};
use clap::Args;
use protocol::Op;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};
use zenoh::Wait;

#[derive(Args, Debug)]
pub struct BenchArgs {
    #[command(flatten)]
    pub target: Target,
    /// Status requests for the round trip (0: skip).
    #[arg(long, default_value_t = 2000)]
    pub requests: usize,
    /// Seconds of telemetry to count (0: skip).
    #[arg(long, default_value_t = 60.0)]
    pub seconds: f64,
}

pub fn run(r: &Remote, a: &BenchArgs) -> Result<String, Fail> {
    if !(a.seconds.is_finite() && (0.0..=86_400.0).contains(&a.seconds)) {
        return Err(Fail::usage(format!(
            "--seconds {}: must be between 0 and 86400",
            a.seconds
        )));
    }
    if a.requests > 10_000_000 {
        return Err(Fail::usage("--requests: at most 10000000"));
    }
    let mut out = String::new();
    if a.requests > 0 {
        out.push_str(&round_trip(r, &a.target, a.requests)?);
    }
    if a.seconds > 0.0 {
        out.push_str(&telemetry(r, a.seconds)?);
    }
    Ok(out)
}

fn round_trip(r: &Remote, t: &Target, n: usize) -> Result<String, Fail> {
    // The first request resolves the host; time only requests to a known host.
    let (host, _) = r.request(t, Op::Status, "")?;
    let target = Target {
        namespace: t.namespace.clone(),
        host: Some(host.clone()),
    };
    for _ in 0..20 {
        r.request(&target, Op::Status, "")?; // warm-up
    }
    let mut ms = Vec::with_capacity(n);
    for _ in 0..n {
        let t0 = Instant::now();
        r.request(&target, Op::Status, "")?;
        ms.push(ms_since(t0));
    }
    ms.sort_by(f64::total_cmp);
    let q = |p: f64| ms[((p * (n - 1) as f64).round() as usize).min(n - 1)];
    Ok(format!(
        "remote status round trip to {host}/{} ({n} requests, one at a time): p50 {:.2} ms, p90 {:.2} ms, p99 {:.2} ms, p99.9 {:.2} ms, max {:.2} ms\n",
        t.namespace,
        q(0.5),
        q(0.9),
        q(0.99),
        q(0.999),
        ms[n - 1]
    ))
}

#[derive(Default)]
struct Stream {
    first: Option<u64>,
    last: u64,
    received: u64,
    lost: u64,
    repeated: u64,
}

fn telemetry(r: &Remote, seconds: f64) -> Result<String, Fail> {
    let key = keys::key(None, None, "telemetry");
    let sub = r
        .session()
        .declare_subscriber(key.clone())
        .wait()
        .map_err(|e| Fail::unreachable(format!("cannot subscribe to {key}: {e}")))?;
    let mut streams: BTreeMap<String, Stream> = BTreeMap::new();
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    loop {
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break;
        }
        let Ok(Some(sample)) = sub.recv_timeout(left) else {
            continue;
        };
        let Ok(v) = serde_json::from_slice::<serde_json::Value>(&sample.payload().to_bytes())
        else {
            continue;
        };
        let Some(seq) = v["seq"].as_u64() else {
            continue;
        };
        let s = streams
            .entry(sample.key_expr().as_str().to_string())
            .or_default();
        s.received += 1;
        match s.first {
            None => s.first = Some(seq),
            Some(_) if seq > s.last => s.lost += seq - s.last - 1,
            Some(_) => s.repeated += 1,
        }
        s.last = s.last.max(seq);
    }
    let mut out = format!(
        "telemetry over {seconds} s from {} controller(s):\n",
        streams.len()
    );
    let (mut got, mut lost) = (0, 0);
    for (k, s) in &streams {
        let span = s.last - s.first.unwrap_or(0) + 1;
        out.push_str(&format!(
            "  {k}: {} received ({:.1} Hz), sequence span {span}, {} lost, {} repeated or out of order\n",
            s.received,
            s.received as f64 / seconds,
            s.lost,
            s.repeated
        ));
        got += s.received;
        lost += s.lost;
    }
    out.push_str(&format!("  total: {got} received, {lost} lost\n"));
    Ok(out)
}
