//! What the plant loop measured, and the files it writes at exit.
//!
//! The loop records into fixed-bound histograms (no allocation); everything that formats or
//! touches the disk happens here, after the last cycle.

use crate::config::PlantConfig;
use anyhow::{Context, Result};
use hdrhistogram::Histogram;
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
    pub ipc_errors: u64,
    /// Cycles in which the plant had no state to publish (`PlantError::Unavailable` from `read`:
    /// a bridge whose device is silent).
    pub read_misses: u64,
    /// Actuations the plant could not deliver (`PlantError::Unavailable` from `write`).
    pub write_errors: u64,
    /// State trigger: cycles whose answer came before the answer deadline.
    pub answered_in_time: u64,
    /// State trigger: cycles without an answer by the deadline, while a controller was answering.
    pub late_cycles: u64,
    /// State trigger: cycles without an answer once the controller had fallen silent: the run of
    /// unanswered cycles that ended in a command timeout (a controller that stopped or died),
    /// every cycle after the controller's brake command (a clean shutdown), and every cycle after
    /// either until answers return. Not late cycles: nobody was answering.
    pub silent_cycles: u64,
    /// State trigger: answers that arrived after their deadline (dropped).
    pub late_answers: u64,
    /// State trigger: times `max_late_cycles` late cycles in a row made the plant brake.
    pub late_brakes: u64,
    /// Substeps in which a joint's torque was clamped at its effort limit ([`crate::Plant::effort_clamps`]).
    pub effort_clamps: u64,
}

impl PlantCounters {
    /// State trigger: the share of published states answered within the same cycle.
    pub fn in_time_share(&self) -> Option<f64> {
        let waited = self.answered_in_time + self.late_cycles;
        (waited > 0).then(|| self.answered_in_time as f64 / waited as f64)
    }
}

/// The loop's histograms (ns).
pub struct Histograms {
    /// State stamp → answering command published by the daemon.
    pub to_cmd: Histogram<u64>,
    /// State published → answering command picked up by the plant.
    pub rtt: Histogram<u64>,
    pub lateness: Histogram<u64>,
    /// The plant's read of one cycle: the simulation's physics over the period (or a bridge's
    /// read of its device), what a plant costs its core each cycle.
    pub step: Histogram<u64>,
}

impl Histograms {
    pub fn new() -> Self {
        Self {
            to_cmd: hist::new_ns(),
            rtt: hist::new_ns(),
            lateness: hist::new_ns(),
            step: hist::new_ns(),
        }
    }
}

impl Default for Histograms {
    fn default() -> Self {
        Self::new()
    }
}

/// What a plant that judges contact on its own geometry saw (MuJoCo: [`crate::Plant::contacts`]).
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct ContactReport {
    /// Whether the model has collision geometry on the arm (without it, nothing is judged).
    pub judged: bool,
    /// Geoms on the arm's moving links.
    pub robot_geoms: usize,
    /// Periods in which a link touched an obstacle.
    pub obstacle_contact_periods: u64,
    pub first_contact_s: Option<f64>,
    /// The first such contact's geoms ("link / obstacle").
    pub first_pair: Option<String>,
    /// Periods in which the arm touched itself (body pairs touching at the start are excluded
    /// from contact).
    pub self_contact_periods: u64,
    pub first_self_contact_s: Option<f64>,
    pub first_self_pair: Option<String>,
    /// Pairs of the arm's bodies that touch in the start pose (the model's own overlap).
    pub overlapping_at_start: usize,
    /// The smallest signed distance (m) between an arm geom and an obstacle; None: no obstacle.
    pub smallest_distance_m: Option<f64>,
    /// Obstacles in MuJoCo's world at the end (the daemon's, followed live).
    pub obstacles: usize,
    /// Times a live edit of the daemon's obstacles moved MuJoCo's.
    pub scene_updates: u64,
    /// How far the model's geometry reaches out of the set-up's capsules (m) on the link where
    /// it reaches farthest (1-based), measured at the start: the filter keeps the capsules
    /// clear, so a link whose geometry is outside them can touch where the filter reports
    /// clearance. None: every link's geometry is inside its capsule (or nothing is judged).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub outside_capsules: Option<(usize, f64)>,
}

#[derive(Clone, Debug, Serialize)]
pub struct PlantSummary {
    pub namespace: String,
    pub rate_hz: f64,
    pub trigger: rt::Trigger,
    pub realtime: rt::setup::RtReport,
    pub duration_s: f64,
    pub counters: PlantCounters,
    /// State trigger: answered in time / (answered in time + late), if any cycle waited.
    pub in_time_share: Option<f64>,
    /// State stamp → answering command published (both stamps on CLOCK_MONOTONIC).
    pub state_to_command: Percentiles,
    /// State published → answering command picked up by the plant (the full round trip).
    pub round_trip: Percentiles,
    pub lateness: Percentiles,
    /// The plant's read of one cycle (its physics over the period).
    pub step: Percentiles,
    /// The plant's own contact judgement (MuJoCo), if it makes one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contacts: Option<ContactReport>,
    pub files: Vec<PathBuf>,
}

pub const SUMMARY_FILE: &str = "plant-summary.json";

/// Writes the histograms, the interval log and the summary; returns the summary.
pub fn write(
    cfg: &PlantConfig,
    realtime: rt::setup::RtReport,
    (counters, contacts): (PlantCounters, Option<ContactReport>),
    h: &Histograms,
    start_ns: u64,
    wall_start: SystemTime,
) -> Result<PlantSummary> {
    let out = &cfg.output_dir;
    let named = [
        ("state-to-command", &h.to_cmd),
        ("round-trip", &h.rtt),
        ("lateness", &h.lateness),
        ("step", &h.step),
    ];
    let mut files = Vec::new();
    for (name, hg) in named {
        let p = out.join(format!("plant-{name}.hgrm"));
        hist::save_hgrm(hg, &p).with_context(|| format!("cannot write {}", p.display()))?;
        files.push(p);
    }
    let hlog = out.join("plant.hlog");
    let elapsed =
        std::time::Duration::from_nanos(protocol::monotonic_ns().saturating_sub(start_ns));
    hist::save_hlog(&named, wall_start, elapsed, &hlog)
        .with_context(|| format!("cannot write {}", hlog.display()))?;
    files.push(hlog);
    files.push(out.join(SUMMARY_FILE));
    let summary = PlantSummary {
        namespace: cfg.namespace.clone(),
        rate_hz: cfg.rate_hz,
        trigger: cfg.trigger,
        realtime,
        duration_s: elapsed.as_secs_f64(),
        counters,
        in_time_share: counters.in_time_share(),
        state_to_command: Percentiles::of(&h.to_cmd),
        round_trip: Percentiles::of(&h.rtt),
        lateness: Percentiles::of(&h.lateness),
        step: Percentiles::of(&h.step),
        contacts,
        files,
    };
    rt::files::write(
        &out.join(SUMMARY_FILE),
        serde_json::to_string_pretty(&summary)?,
    )?;
    Ok(summary)
}
