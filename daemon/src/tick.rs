//! One tick of the clock loop, as one function: the loop calls it, and so does
//! `daemon/tests/no_alloc.rs`, so the no-allocation proof is about the loop itself.
//!
//! [`ClockTick::run`] is the compute-and-publish part: take a control-service request → drain the
//! state subscriber, keeping the newest → `Controller::tick` → loan, write, send the command →
//! `try_send` the record to the reporter. Waiting for the deadline and advancing the schedule
//! stay in `service.rs`. No locks, no waiting on other threads, no heap allocation beyond
//! iceoryx2's own per-loan one (see ARCHITECTURE.md's invariants).

use crate::controller::Controller;
use crate::record::{tick_record, TickTimes};
use crate::telemetry::{LoopRequest, TickRecord};
use crate::trigger::{newest_state, send, Drained};
use crossbeam::channel::{Receiver, Sender, TrySendError};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ipc;
use protocol::{monotonic_ns, CommandSample, StateSample};

/// The clock loop's ports and channels.
pub struct ClockTick<'a> {
    pub subscriber: &'a Subscriber<ipc::Service, StateSample, ()>,
    pub publisher: &'a Publisher<ipc::Service, CommandSample, ()>,
    /// Records to the reporter.
    pub tx: &'a Sender<TickRecord>,
    /// Requests from the control service.
    pub requests: &'a Receiver<LoopRequest>,
}

/// What the schedule needs from a tick.
#[derive(Clone, Copy, Debug)]
pub struct Ticked {
    /// When the command had been sent (ns).
    pub done: u64,
    /// The state the tick accepted and answered, if any (the phase lock follows its stamp).
    pub answered: Option<StateSample>,
}

impl ClockTick<'_> {
    /// One tick that was due at `due` and woke at `woke` (CLOCK_MONOTONIC ns).
    ///
    /// The record's counters are those after this tick's command; overruns are counted by the
    /// schedule after it, so a record shows them one tick late.
    pub fn run<const N: usize>(&self, ctl: &mut Controller<N>, due: u64, woke: u64) -> Ticked {
        // A validated parameter block (or a resume) takes effect here, between ticks.
        take_request(ctl, self.requests);
        let mut seen = Drained::default();
        let newest = newest_state(self.subscriber, &mut seen);
        seen.into_counters(ctl);
        let o = ctl.tick(newest.as_ref(), woke);
        crate::watchdog::beat(ctl.counters.ticks);
        if let Some(c) = o.command {
            send(self.publisher, &mut None, c, ctl);
        }
        let done = monotonic_ns();
        let rec = tick_record(ctl, &o, newest, TickTimes { due, woke, done });
        match self.tx.try_send(rec) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => ctl.counters.telemetry_dropped += 1,
            // The reporter is gone: no control service, no histograms. Stop cleanly.
            Err(TrySendError::Disconnected(_)) => rt::signal::request_stop(),
        }
        Ticked {
            done,
            answered: newest.filter(|_| o.state_age_ns.is_some()),
        }
    }
}

/// Applies at most one request from the control service (never blocks).
pub fn take_request<const N: usize>(ctl: &mut Controller<N>, rx: &Receiver<LoopRequest>) {
    match rx.try_recv() {
        Ok(LoopRequest::Params(p)) => {
            ctl.set_params(p);
        }
        Ok(LoopRequest::Resume) => {
            ctl.resume();
        }
        // Only on an operator's explicit `debug-stall`: a stuck tick, to check the watchdog.
        Ok(LoopRequest::Stall(ms)) => std::thread::sleep(std::time::Duration::from_millis(ms)),
        Ok(LoopRequest::Plant { plant_id, agreed }) => ctl.set_plant_verdict(plant_id, agreed),
        Ok(LoopRequest::Steer(s)) => ctl.set_steer(s),
        Ok(LoopRequest::BlockedHold(h)) => ctl.set_blocked_hold(h),
        Err(_) => {}
    }
}
