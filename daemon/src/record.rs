//! The telemetry record of one tick, built the same way by every loop (clock- or
//! state-triggered), so the reporter never needs to know which loop ran.

use crate::controller::{Controller, TickOutcome};
use crate::telemetry::TickRecord;
use control::basics::flags as law_flags;
use protocol::StateSample;

/// Timing of one tick (CLOCK_MONOTONIC ns).
#[derive(Clone, Copy, Debug)]
pub struct TickTimes {
    /// When the tick was due: the deadline (clock) or the state's expected arrival (state).
    pub due: u64,
    /// When it started: the wake-up (clock) or the state's receipt (state); the tick's `now`.
    pub woke: u64,
    /// When the command had been sent.
    pub done: u64,
}

/// The record handed to the reporter after the command has left.
pub fn tick_record<const N: usize>(
    ctl: &Controller<N>,
    o: &TickOutcome<N>,
    newest: Option<StateSample>,
    times: TickTimes,
) -> TickRecord {
    let (law, (mu, tau, t_on, feedback_on)) = (o.output, ctl.law().feedback());
    TickRecord {
        t: ctl.time(),
        lateness_ns: times.woke.saturating_sub(times.due),
        compute_ns: times.done.saturating_sub(times.woke),
        state_age_ns: o.state_age_ns,
        mode: o.mode,
        fault: o.fault,
        ran_law: law.is_some(),
        law_flags: law.map_or(0, |l| l.flags),
        tracking_error: law.map_or(f64::NAN, |l| l.tracking_error),
        period_residual: law.map_or(f64::NAN, |l| l.period_residual),
        null_residual: law.map_or(f64::NAN, |l| l.null_residual),
        clearance: law.map_or(f64::INFINITY, |l| l.clearance),
        mu,
        tau,
        t_on,
        feedback_on,
        feedback_active: law.is_some_and(|l| l.flags & law_flags::FEEDBACK_ACTIVE != 0),
        counters: ctl.counters,
        state: newest,
        now_ns: times.woke,
        applied: o.applied,
        command: o.command,
        limiter_hits: o.limiter_hits,
    }
}
