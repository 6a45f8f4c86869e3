//! What an MCAP recording costs the reporter thread (issue 26): it encodes every answered state
//! (a CDR joint state, three small JSON messages) and, at 50 Hz, the 3-D channels, and LZ4
//! compresses the chunks, off the loop's core. The states are a 1 kHz run of the paper's arm;
//! each tick's encoding and write is timed alone, and the file's size gives the bytes per hour.

use crate::stats::{fmt_ns, histogram, summary, Table};
use anyhow::{anyhow, Result};
use control::{Config, Simulation, System};
use daemon::mcap_recording::McapRecording;
use daemon::telemetry::TickRecord;
use daemon::view::TickContext;
use protocol::{CommandSample, StateSample};
use std::time::Instant;

pub fn table(quick: bool) -> Result<String> {
    let cfg = Config::preset("paper")?;
    let seconds = if quick { 20.0 } else { 120.0 };
    let dir = std::env::temp_dir().join(format!("chaosd-bench-record-{}", std::process::id()));
    rt::files::create_dir_all(&dir)?;
    let limit = daemon::rotate::Limit {
        max_bytes: None,
        keep: 0,
    };
    let system = System::Planar(cfg.clone());
    let mut rec =
        McapRecording::start(&dir, "bench.mcap", &system, 1000.0, limit).map_err(|e| anyhow!(e))?;
    let mut sim = Simulation::new(
        cfg.model::<3>(),
        cfg.law_params(),
        1e-3,
        cfg.initial_state(),
        2.0,
    );
    let ctx = TickContext {
        chaos: control::monitor::Verdict::Chaotic,
        blocked: None,
    };
    let (mut h, mut total_ns) = (histogram(), 0u64);
    let steps = (seconds / 1e-3) as u64;
    for k in 0..steps {
        let x = *sim.state();
        let out = sim.step();
        let mut st = StateSample {
            seq: k,
            stamp_ns: k * 1_000_000,
            n: 3,
            ..StateSample::default()
        };
        st.q[..3].copy_from_slice(x.q.as_slice());
        st.qd[..3].copy_from_slice(x.qd.as_slice());
        let mut c = CommandSample {
            seq: k,
            n: 3,
            ..CommandSample::default()
        };
        c.qdd[..3].copy_from_slice(out.qdd.as_slice());
        let mut r = TickRecord::blank();
        (r.t, r.now_ns, r.ran_law, r.command) = (k as f64 * 1e-3, k * 1_000_000, true, Some(c));
        (r.tracking_error, r.period_residual) = (out.tracking_error, out.period_residual);
        let start = Instant::now();
        rec.tick(&r, &st, ctx).map_err(|e| anyhow!(e))?;
        let ns = start.elapsed().as_nanos() as u64;
        total_ns += ns;
        h.saturating_record(ns.max(1));
    }
    rec.finish().map_err(|e| anyhow!(e))?;
    let bytes = std::fs::metadata(dir.join("bench.mcap"))?.len();
    let _ = std::fs::remove_dir_all(&dir);
    let mut t = Table::new(&[
        "MCAP recording on the reporter thread (paper arm, 1 kHz)",
        "n",
        "p50",
        "p99",
        "max",
    ]);
    let s = summary(&h);
    t.row(vec![
        "one answered state: encode and write (3-D channels every 20th)".into(),
        h.len().to_string(),
        fmt_ns(s[0] as f64),
        fmt_ns(s[2] as f64),
        fmt_ns(s[4] as f64),
    ]);
    Ok(format!(
        "{}\nIn all: {:.2} % of one core over the {seconds:.0} s run, none of it on the loop's core; the file: {:.0} bytes a tick, {:.2} GB an hour.\n",
        t.render(),
        total_ns as f64 / (seconds * 1e9) * 100.0,
        bytes as f64 / steps as f64,
        bytes as f64 / seconds * 3600.0 / 1e9
    ))
}
