//! The plant loop: generic over [`Plant`], identical for the simulator and any bridge.
//!
//! Each period: wait for the absolute deadline → drain commands, keep the newest valid one →
//! hand the plant its actuation (the command, or a brake after `command_timeout_ms` of silence) →
//! `read` one period → stamp, number and publish the state. Latencies go into fixed-bound
//! histograms in the loop itself (recording never allocates), and are written at exit.

use crate::config::PlantConfig;
use crate::seam::{Actuation, Plant};
use anyhow::{anyhow, Context, Result};
use protocol::{flags, monotonic_ns, CommandSample, Mode, ServiceNames, StateSample};
use rt::clock::Schedule;
use rt::hist::{self, Percentiles};
use serde::Serialize;
use std::path::PathBuf;
use std::time::SystemTime;

#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq, Eq)]
pub struct PlantCounters {
    pub ticks: u64,
    pub states_published: u64,
    pub commands_received: u64,
    pub commands_rejected: u64,
    pub command_timeouts: u64,
    pub daemon_restarts: u64,
    pub overruns: u64,
    /// Stalls longer than a second, whose time was skipped rather than simulated.
    pub time_jumps: u64,
    pub ipc_errors: u64,
}

#[derive(Clone, Debug, Serialize)]
pub struct PlantSummary {
    pub namespace: String,
    pub rate_hz: f64,
    pub realtime: rt::setup::RtReport,
    pub duration_s: f64,
    pub counters: PlantCounters,
    /// State published → answering command published (both stamps on CLOCK_MONOTONIC).
    pub state_to_command: Percentiles,
    /// State published → answering command picked up by the plant (the full round trip).
    pub round_trip: Percentiles,
    pub lateness: Percentiles,
    pub files: Vec<PathBuf>,
}

pub const SUMMARY_FILE: &str = "plant-summary.json";

/// Runs `plant` until SIGINT/SIGTERM or for `duration` seconds.
pub fn run<P: Plant>(
    plant: &mut P,
    cfg: &PlantConfig,
    duration: Option<f64>,
) -> Result<PlantSummary> {
    let names = ServiceNames::new(&cfg.namespace).map_err(|e| anyhow!("plant.namespace: {e}"))?;
    std::fs::create_dir_all(&cfg.output_dir).with_context(|| {
        format!(
            "cannot create output directory {}",
            cfg.output_dir.display()
        )
    })?;
    rt::signal::install();
    let node = protocol::node("chaosd-plant")?;
    let state = protocol::open_state_service(&node, &names)?;
    let publisher = state.publisher_builder().create().map_err(|e| {
        anyhow!(
            "cannot publish on {}: {e:?} (is another plant already running in namespace {:?}?)",
            names.state(),
            names.namespace()
        )
    })?;
    let command = protocol::open_command_service(&node, &names)?;
    let subscriber = command
        .subscriber_builder()
        .create()
        .map_err(|e| anyhow!("cannot subscribe to {}: {e:?}", names.command()))?;

    let n = plant.n();
    let plant_id = protocol::new_instance_id();
    plant.activate().map_err(|e| anyhow!("{e}"))?;
    let rt_report = rt::setup::apply(rt::setup::RtRequest {
        core: cfg.core,
        priority: cfg.priority,
        lock_memory: cfg.lock_memory,
    });
    for w in &rt_report.warnings {
        eprintln!("chaosd-plant: warning: {w}");
    }
    eprintln!(
        "chaosd-plant: namespace {:?}, {} Hz, {}",
        names.namespace(),
        cfg.rate_hz,
        rt_report.one_line()
    );

    let mut c = PlantCounters::default();
    let (mut to_cmd, mut rtt, mut late) = (hist::new_ns(), hist::new_ns(), hist::new_ns());
    let period = cfg.period_ns();
    let dt = period as f64 * 1e-9;
    let spin = (cfg.spin_us * 1000.0) as u64;
    let timeout = (cfg.command_timeout_ms * 1e6) as u64;
    let start = monotonic_ns();
    let wall_start = SystemTime::now();
    let end = duration.map(|s| start.saturating_add((s * 1e9) as u64));
    let mut sched = Schedule::new(period, start);
    let mut daemon_id = 0u64;
    let mut last_seq: Option<u64> = None;
    let mut last_command_at: Option<u64> = None;
    let mut current: Option<CommandSample> = None;
    let mut timed_out = false;
    let mut seq = 0u64;
    let mut sample = StateSample {
        plant_id,
        n: n as u32,
        ..StateSample::default()
    };
    // Periods actually integrated, and that count for each recent published state: a command's
    // ramp starts at the state it answers, however many periods ago that was.
    let mut integrated: u64 = 0;
    let mut behind: u64 = 0;
    let mut published_at = [(u64::MAX, 0u64); 64];
    let mut fault = None;

    while !rt::signal::stop_requested() {
        let deadline = sched.deadline();
        if end.is_some_and(|e| deadline >= e) {
            break;
        }
        let woke = rt::wait_until(deadline, cfg.wait, spin);
        late.saturating_record(woke.saturating_sub(deadline).max(1));
        loop {
            let cmd = match subscriber.receive() {
                Ok(Some(s)) => *s,
                Ok(None) => break,
                Err(_) => {
                    c.ipc_errors += 1;
                    break;
                }
            };
            // Leftovers from a dead daemon, answers to a previous plant's states, garbage: drop.
            let answers_us = cmd.state_stamp_ns >= start || cmd.mode != Mode::Run as u32;
            if cmd.validate(n).is_err() || !answers_us {
                c.commands_rejected += 1;
                continue;
            }
            if cmd.daemon_id != daemon_id {
                if daemon_id != 0 {
                    c.daemon_restarts += 1;
                }
                daemon_id = cmd.daemon_id;
            } else if last_seq.is_some_and(|l| cmd.seq <= l) {
                c.commands_rejected += 1;
                continue;
            }
            last_seq = Some(cmd.seq);
            c.commands_received += 1;
            last_command_at = Some(woke);
            if cmd.mode == Mode::Run as u32 {
                to_cmd.saturating_record(cmd.stamp_ns.saturating_sub(cmd.state_stamp_ns).max(1));
                rtt.saturating_record(woke.saturating_sub(cmd.state_stamp_ns).max(1));
            }
            current = Some(cmd);
        }
        let silent = last_command_at.is_none_or(|t| woke.saturating_sub(t) > timeout);
        if silent && last_command_at.is_some() && !timed_out {
            timed_out = true;
            c.command_timeouts += 1;
        } else if !silent {
            timed_out = false;
        }
        match current {
            Some(cmd) if !silent && cmd.mode == Mode::Run as u32 => {
                let (a_seq, a_count) = published_at[(cmd.state_seq % 64) as usize];
                // Unknown (too old) answered state: a huge `since` makes the plant hold the ramp's end.
                let since = if a_seq == cmd.state_seq {
                    (integrated - a_count) as f64 * dt
                } else {
                    1e3
                };
                let n = cmd.n as usize;
                plant.write(Actuation::Accelerate {
                    qdd: &cmd.qdd[..n],
                    qddd: &cmd.qddd[..n],
                    since,
                });
            }
            _ => plant.write(Actuation::Brake),
        }
        // Hold the initial state until a controller first answers (see `Plant::read`).
        let step = if last_command_at.is_some() { dt } else { 0.0 };
        // Physics does not pause: after an overrun the periods that were skipped are integrated
        // too, so the state stays on the time its stamp claims.
        // A long stall (SIGSTOP, a paused VM) is not replayed in one tick: at most one second is
        // caught up; beyond that the simulation skips ahead and the jump is counted.
        let max_catch_up = (cfg.rate_hz as u64).max(1);
        if behind > max_catch_up {
            c.time_jumps += 1;
        }
        let periods = 1 + behind.min(max_catch_up);
        let mut failed = None;
        for _ in 0..periods {
            if let Err(e) = plant.read(step, &mut sample) {
                failed = Some(e.to_string());
                break;
            }
            if step > 0.0 {
                integrated += 1;
            }
        }
        if let Some(e) = failed {
            fault = Some(e);
            break;
        }
        sample.seq = seq;
        seq += 1;
        sample.flags = plant.flags() | if timed_out { flags::COMMAND_TIMEOUT } else { 0 };
        sample.stamp_ns = plant.stamp(deadline, monotonic_ns());
        published_at[(sample.seq % 64) as usize] = (sample.seq, integrated);
        match publisher.loan_uninit() {
            Ok(s) => match s.write_payload(sample).send() {
                Ok(_) => c.states_published += 1,
                Err(_) => c.ipc_errors += 1,
            },
            Err(_) => c.ipc_errors += 1,
        }
        c.ticks += 1;
        behind = sched.advance(monotonic_ns());
        c.overruns += behind;
    }
    plant.deactivate();

    let out = &cfg.output_dir;
    let mut files = Vec::new();
    for (name, h) in [
        ("state-to-command", &to_cmd),
        ("round-trip", &rtt),
        ("lateness", &late),
    ] {
        let p = out.join(format!("plant-{name}.hgrm"));
        hist::save_hgrm(h, &p).with_context(|| format!("cannot write {}", p.display()))?;
        files.push(p);
    }
    let hlog = out.join("plant.hlog");
    let elapsed = std::time::Duration::from_nanos(monotonic_ns() - start);
    hist::save_hlog(
        &[
            ("state-to-command", &to_cmd),
            ("round-trip", &rtt),
            ("lateness", &late),
        ],
        wall_start,
        elapsed,
        &hlog,
    )
    .with_context(|| format!("cannot write {}", hlog.display()))?;
    files.push(hlog);
    files.push(out.join(SUMMARY_FILE));
    let summary = PlantSummary {
        namespace: cfg.namespace.clone(),
        rate_hz: cfg.rate_hz,
        realtime: rt_report,
        duration_s: elapsed.as_secs_f64(),
        counters: c,
        state_to_command: Percentiles::of(&to_cmd),
        round_trip: Percentiles::of(&rtt),
        lateness: Percentiles::of(&late),
        files,
    };
    std::fs::write(
        out.join(SUMMARY_FILE),
        serde_json::to_string_pretty(&summary)?,
    )?;
    if let Some(f) = fault {
        return Err(anyhow!("{f}"));
    }
    Ok(summary)
}
