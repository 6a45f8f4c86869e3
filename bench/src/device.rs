//! `chaosd-bench device`: the command-interface acceptance rows that need the real processes.
//! The Panda in position mode through chaosd-bridge and chaosd-fakebot (a device that checks
//! every command as a robot does), with the limiter on and off, on the demo's set-up and on one
//! whose law asks more than the arm can do. One `chaosd demo` per row, one after the other: each
//! needs both cores, and side by side in one run the rows share the machine's state.

use crate::report::{self, Report};
use anyhow::{bail, Context, Result};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// One row: a set-up, the limiter on or off, and how long it runs.
struct Row {
    label: &'static str,
    /// A config file, or the built-in Panda set-up.
    config: Option<PathBuf>,
    limiter: bool,
    seconds: f64,
}

/// What a row measured, from the daemon's and the device's summaries.
struct Outcome {
    stops: u64,
    first: String,
    cycles: u64,
    missed: u64,
    brakes: u64,
    tracking: String,
    residual: String,
    clamps: u64,
}

/// The Panda with stiff task gains and the safety filter off: the law's q̈ at the start is a
/// few times the acceleration limits, and only the limiter stands between it and the device.
fn unbounded_panda(dir: &Path) -> Result<PathBuf> {
    let cfg = control::config::spatial::PANDA_PAPER
        .replace("kp = 40.0", "kp = 900.0")
        .replace("kv = 15.0", "kv = 60.0")
        .replace("[safety]\nenabled = true", "[safety]\nenabled = false");
    if !(cfg.contains("kp = 900.0") && cfg.contains("enabled = false")) {
        bail!("the panda preset changed: cannot derive the unbounded set-up from it");
    }
    let path = dir.join("unbounded.toml");
    std::fs::write(&path, cfg).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

pub fn run(quick: bool, out: &Path, command: &str) -> Result<crate::report::Output> {
    let mut report = Report::new(out, "device")?;
    let minute = if quick { 20.0 } else { 60.0 };
    let unbounded = unbounded_panda(&report.dir)?;
    let rows = [
        ("the demo's set-up", None, minute),
        ("kp 900, kv 60, filter off", Some(unbounded), 4.0),
    ]
    .into_iter()
    .flat_map(|(label, config, seconds)| {
        [true, false].map(|limiter| Row {
            label,
            config: config.clone(),
            limiter,
            seconds,
        })
    });
    let mut table = String::from(
        "| set-up | limiter | s | reflex stops | first stop | missed answers | brakes | tracking RMS | residual before → after | clamped joint-ticks |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
    );
    for (i, row) in rows.enumerate() {
        let dir = report.dir.join(format!(
            "{}-{}",
            report::slug(row.label),
            if row.limiter { "on" } else { "off" }
        ));
        let o = one(&row, &dir, i).with_context(|| format!("device row {:?}", row.label))?;
        table.push_str(&format!(
            "| {} | {} | {:.0} | {} | {} | {} of {} | {} | {} | {} | {} |\n",
            row.label,
            if row.limiter { "on" } else { "off" },
            row.seconds,
            o.stops,
            o.first,
            o.missed,
            o.cycles,
            o.brakes,
            o.tracking,
            o.residual,
            o.clamps
        ));
    }
    report.push_tables(
        &format!(
            "## Commanding a real arm, through the device\n\n{}, {}. `{command}`\n\n\
         The Panda in position mode at 1 kHz through chaosd-bridge and chaosd-fakebot over UDP on \
         the loopback (the state trigger), one `chaosd demo` per row. The target: 0 reflex stops \
         with the limiter on; off, the count and the first reason show what it prevents. Missed \
         answers and brakes are this VM's stalls; tracking is the RMS after the first 2 s (n/a \
         when the device stopped at once).\n\n{table}",
            report::now_utc(),
            report::machine()
        ),
        &[crate::book::names::DEVICE],
    )?;
    report.finish()
}

/// Runs one row's demo into `dir` and reads its summaries.
fn one(row: &Row, dir: &Path, i: usize) -> Result<Outcome> {
    let chaosd = crate::e2e::sibling("chaosd")?;
    let ns = format!("bench-device-{}-{i}", std::process::id());
    let mut cmd = Command::new(chaosd);
    cmd.arg("demo");
    match &row.config {
        Some(c) => cmd.arg("--config").arg(c),
        None => cmd.args(["--robot", "panda"]),
    };
    cmd.args(["--mode", "position", "--bridge", "udp", "--namespace", &ns])
        .arg("--duration")
        .arg(row.seconds.to_string())
        .arg("--output")
        .arg(dir);
    if !row.limiter {
        cmd.arg("--no-limiter");
    }
    crate::device::run_demo(cmd)?;
    let read = |f: &str| crate::e2e::read_json(&dir.join(f));
    let (d, f) = (read("daemon-summary.json")?, read("fakebot-summary.json")?);
    let n = |v: &Value| v.as_u64().unwrap_or(0);
    let before = d["period_residual_before"].as_f64();
    let after = d["period_residual_after"].as_f64();
    Ok(Outcome {
        stops: n(&f["counters"]["reflex_stops"]),
        first: d["first_device_stop"]
            .as_str()
            .map_or("–".into(), |s| s.replace('|', "/")),
        cycles: n(&f["counters"]["cycles"]),
        missed: n(&f["counters"]["missed"]),
        brakes: n(&f["counters"]["brakes"]),
        tracking: d["tracking_rms_m"]
            .as_f64()
            .filter(|t| t.is_finite())
            .map_or("n/a".into(), |t| format!("{t:.1e} m")),
        residual: match (before, after) {
            (Some(b), Some(a)) => format!("{b:.3} → {a:.3} rad/s ({:.0}×)", b / a),
            _ => "n/a".into(),
        },
        clamps: d["command"]["counts"]
            .as_array()
            .into_iter()
            .flatten()
            .flat_map(|j| j.as_array().into_iter().flatten())
            .map(n)
            .sum(),
    })
}

/// Runs a prepared `chaosd demo` to its end (hardened: it dies with the bench); its stderr in
/// the error if it failed.
pub fn run_demo(mut cmd: Command) -> Result<()> {
    crate::child::harden(&mut cmd);
    let o = cmd.output().context("cannot run chaosd demo")?;
    if !o.status.success() {
        bail!(
            "chaosd demo failed ({}): {}",
            o.status,
            String::from_utf8_lossy(&o.stderr)
        );
    }
    Ok(())
}
