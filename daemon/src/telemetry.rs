//! What the loop hands the reporter, and what the reporter learns: the types both sides share.
//!
//! The loop sends one small `Copy` [`TickRecord`] per tick through a bounded crossbeam channel
//! with `try_send` (a full queue is a counted drop, never a wait), and takes a [`LoopRequest`] from
//! the control service with `try_recv` between two ticks. The reporter thread
//! ([`crate::reporter`]) turns records into histograms, status lines, telemetry and recordings
//! ([`crate::recording`]), and serves the control service ([`crate::control_service`]).

use crate::controller::Counters;
use control::tick_law::ParamBlock;
use protocol::{CommandSample, Mode, StateSample};
use rt::hist::Percentiles;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// What the control service hands the loop (through a bounded channel the loop `try_recv`s).
// Not boxed: the loop would free the box, and the tick does no heap work at all.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug)]
pub enum LoopRequest {
    /// A validated parameter block, swapped in between two ticks.
    Params(ParamBlock),
    /// Leave FAULT (`chaosctl resume`).
    Resume,
    /// Sleep this many ms between two ticks (`chaosctl debug-stall`, a watchdog check).
    Stall(u64),
    /// The handshake's verdict on one plant start (`crate::handshake`).
    Plant { plant_id: u64, agreed: bool },
    /// The planner's handover: a cycle to steer onto, or none (`crate::deadlock`).
    Steer(Option<control::steer::Steering>),
    /// Blocked with the hold action, or no longer (`crate::deadlock`).
    BlockedHold(bool),
}

/// One tick, as the loop saw it.
#[derive(Clone, Copy, Debug)]
pub struct TickRecord {
    /// Controller time (s).
    pub t: f64,
    pub lateness_ns: u64,
    pub compute_ns: u64,
    pub state_age_ns: Option<u64>,
    pub mode: Mode,
    /// The runaway guard tripped on this tick.
    pub fault: Option<crate::guard::FaultReason>,
    /// Whether the law ran (a fresh state arrived).
    pub ran_law: bool,
    pub law_flags: u32,
    pub tracking_error: f64,
    pub period_residual: f64,
    /// Its self-motion part |(I − J⁺J)(q̇(t) − q̇(t − τ))| (the chaos monitor's evidence).
    pub null_residual: f64,
    pub clearance: f64,
    pub mu: f64,
    pub tau: f64,
    pub t_on: f64,
    pub feedback_on: bool,
    pub feedback_active: bool,
    pub counters: Counters,
    /// The newest state received on this tick, as received (the law used it if `ran_law`).
    pub state: Option<StateSample>,
    /// The tick's clock: the `now` `Controller::tick` was given (CLOCK_MONOTONIC ns).
    pub now_ns: u64,
    /// A control-service change that took effect just before this tick.
    pub applied: Option<crate::controller::Applied>,
    /// The command published, if any.
    pub command: Option<CommandSample>,
    /// Which limits the limiter applied to each joint (bits of `control::command::LimitKind`).
    pub limiter_hits: [u8; protocol::MAX_JOINTS],
}

impl TickRecord {
    /// A RUN tick at t = 0 with nothing in it, for tests and benchmarks to fill in.
    pub fn blank() -> Self {
        Self {
            t: 0.0,
            lateness_ns: 0,
            compute_ns: 0,
            state_age_ns: None,
            mode: protocol::Mode::Run,
            fault: None,
            ran_law: false,
            law_flags: 0,
            tracking_error: 0.0,
            period_residual: 0.0,
            null_residual: 0.0,
            clearance: f64::INFINITY,
            mu: 0.0,
            tau: 0.0,
            t_on: 0.0,
            feedback_on: false,
            feedback_active: false,
            counters: Counters::default(),
            state: None,
            command: None,
            limiter_hits: [0; protocol::MAX_JOINTS],
            now_ns: 0,
            applied: None,
        }
    }
}

/// What the reporter learnt over the run.
#[derive(Clone, Debug, Serialize)]
pub struct DaemonSummary {
    pub namespace: String,
    pub rate_hz: f64,
    pub wait: String,
    pub realtime: rt::setup::RtReport,
    pub duration_s: f64,
    pub counters: Counters,
    pub lateness: Percentiles,
    pub compute: Percentiles,
    pub state_age: Percentiles,
    /// State stamp → command sent (state age + compute), for each state answered.
    pub state_to_command: Percentiles,
    /// Share of answered states whose command left within one period of the state's stamp.
    pub answered_within_period: Option<f64>,
    /// RMS tracking error over ticks after the first 2 s (m).
    pub tracking_rms_m: Option<f64>,
    /// Median, 99th percentile and largest tracking error over the same ticks: a stall of the
    /// host moves the RMS and the tail, a controller that tracks badly moves the median.
    pub tracking: Option<crate::tracking::TrackingSpread>,
    /// The same over every tick, the start-up transient included: what a run that ended (by
    /// a FAULT, say) before 2 s tracked.
    pub tracking_whole_rms_m: Option<f64>,
    pub tracking_whole: Option<crate::tracking::TrackingSpread>,
    /// Mean |q̇(t) − q̇(t − τ)| while the feedback was off (after the first 2 s).
    pub period_residual_before: Option<f64>,
    /// The same over the last 5 s with the feedback on.
    pub period_residual_after: Option<f64>,
    /// Controller time (s) the arm last began to brake or hold under a running stream
    /// (`counters.arm_brakes`): the residual and tracking after it measure a recovery.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_arm_brake_s: Option<f64>,
    /// The same over 2-7 s, feedback or not: the reference of a run whose feedback acts from
    /// the start.
    pub period_residual_start: Option<f64>,
    pub feedback_on_at_s: Option<f64>,
    pub min_clearance_m: Option<f64>,
    /// How close the arm came to its joint limits (states the law used, commands sent).
    pub joint_limits: crate::limits::LimitsSeen,
    /// The command interface and how often the limiter clamped each joint, per kind.
    pub command: crate::saturations::SaturationTable,
    /// Reflex stops the device reported (each a FAULT naming the joint and reason), and the
    /// first.
    pub device_stops: u64,
    pub first_device_stop: Option<String>,
    /// Times the daemon said `Blocked` (no clean cycle, or a trap it could not steer out of),
    /// and the first reason.
    pub blocked_entered: u64,
    pub first_blocked: Option<String>,
    pub time_in_safety_zone_s: f64,
    pub files: Vec<PathBuf>,
    /// The chaos monitor at exit, and its first verdict changes.
    pub chaos: ChaosSummary,
}

/// The summary's `chaos` part.
#[derive(Clone, Debug, Serialize)]
pub struct ChaosSummary {
    pub evidence: control::monitor::Evidence,
    /// μ at the end (where `feedback.mu = "auto"` took it).
    pub mu: f64,
    pub edges: u64,
    pub history: Vec<control::monitor::Edge>,
    /// With `mu = "auto"`: the gain the model chose, and why (`crate::gains`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_gain: Option<String>,
    /// With `mu = "auto"`: the newest steering onto the model's cycle (`crate::targeting`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<crate::targeting::TargetInfo>,
}

/// Name of the JSON summary in the output directory.
pub const SUMMARY_FILE: &str = "daemon-summary.json";

/// Writes the summary once the loop has added what only it knows (the real-time set-up).
pub fn write_summary(summary: &DaemonSummary, dir: &Path) -> anyhow::Result<()> {
    let json = dir.join(SUMMARY_FILE);
    rt::files::write(&json, serde_json::to_string_pretty(summary)?)
        .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", json.display()))
}
