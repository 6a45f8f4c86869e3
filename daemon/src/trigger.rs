//! The state-triggered loop (`[daemon] trigger = "state"`), and the phase lock of the clock loop.
//!
//! Real robot interfaces are device-clocked: the device sends its state every cycle and the
//! answer must come back within the same cycle (Franka FCI at 1 kHz, KUKA RSI every 4 ms). Here a
//! tick runs the moment a state arrives, and only what the answer needs stands between the two:
//! receive → `Controller::tick` → write into a sample loaned *before* the state came → send.
//! Taking the parameter block, the telemetry record and the next loan all happen after the send,
//! while the plant is already applying the command. With the fast lane (`protocol::board`) the
//! state comes from the state board and the command goes out on the command board; its pub-sub
//! copy is sent after the path, in [`StateLoop::after`]. The watchdog stays: a period with no state
//! past its expected arrival is a tick without a state, and `hold_after` of them are HOLD.
//!
//! [`PhaseLock`] is the clock loop's counterpart: instead of a free-running phase it puts each
//! deadline `phase_offset_us` after the plant's state stamps, so the state age is that offset,
//! not wherever the two processes' start phases happened to fall.

use crate::controller::{Controller, TickOutcome};
use crate::record::{tick_record, TickTimes};
use crate::telemetry::TickRecord;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ipc;
use iceoryx2::sample_mut_uninit::SampleMutUninit;
use protocol::board::{pubsub_due, DaemonLane};
use protocol::{monotonic_ns, CommandSample, StateSample};
use rt::gaps::GapMeter;
use rt::trigger::Window;
use rt::WaitStrategy;
use std::mem::MaybeUninit;

/// A command sample loaned ahead of time, so that the loan is not on the path to the send.
pub type CommandSlot = SampleMutUninit<ipc::Service, MaybeUninit<CommandSample>, ()>;

/// The loop's ports and channels.
pub struct Ports<'a> {
    pub subscriber: &'a Subscriber<ipc::Service, StateSample, ()>,
    pub publisher: &'a Publisher<ipc::Service, CommandSample, ()>,
    pub tx: &'a crossbeam::channel::Sender<TickRecord>,
    /// State trigger: the fast lane, if open. States come from it first; commands go out on it,
    /// and their pub-sub copies after the path.
    pub lane: Option<&'a DaemonLane>,
}

/// How the loop waits.
#[derive(Clone, Copy, Debug)]
pub struct Timing {
    pub period_ns: u64,
    pub wait: WaitStrategy,
    pub spin_ns: u64,
    /// Stop at this time (ns), if set.
    pub end_ns: Option<u64>,
}

/// What draining the state queue saw besides the newest sample.
#[derive(Clone, Copy, Debug, Default)]
pub struct Drained {
    pub superseded: u64,
    pub ipc_errors: u64,
}

impl Drained {
    /// Adds these counts to the controller's counters.
    pub fn into_counters<const N: usize>(self, ctl: &mut Controller<N>) {
        ctl.counters.superseded += self.superseded;
        ctl.counters.ipc_errors += self.ipc_errors;
    }
}

/// Drains the state queue and returns the newest sample, counting the superseded ones.
pub fn newest_state(
    sub: &Subscriber<ipc::Service, StateSample, ()>,
    seen: &mut Drained,
) -> Option<StateSample> {
    newest_state_but(sub, seen, |_| false)
}

/// The newest state: from the fast lane if it brought one, else from the pub-sub queue, minus
/// the pub-sub copies of what the lane brought. `poll` counts the wait's polls; while `lane_first`
/// (the lane brought the last state) pub-sub is looked at only when [`pubsub_due`]. Returns the
/// state and whether it came by the lane.
pub fn newest_unseen(
    sub: &Subscriber<ipc::Service, StateSample, ()>,
    lane: Option<&DaemonLane>,
    lane_first: bool,
    poll: u32,
    seen: &mut Drained,
) -> Option<(StateSample, bool)> {
    let Some(lane) = lane else {
        return newest_state(sub, seen).map(|s| (s, false));
    };
    if let Some(s) = lane.take() {
        return Some((s, true));
    }
    if !pubsub_due(lane_first, poll) {
        return None;
    }
    newest_state_but(sub, seen, |s| lane.seen(s)).map(|s| (s, false))
}

/// [`newest_state`], dropping the samples `skip` names without counting them.
fn newest_state_but(
    sub: &Subscriber<ipc::Service, StateSample, ()>,
    seen: &mut Drained,
    skip: impl Fn(&StateSample) -> bool,
) -> Option<StateSample> {
    let mut newest = None;
    loop {
        match sub.receive() {
            Ok(Some(s)) if skip(&s) => {}
            Ok(Some(s)) => {
                if newest.is_some() {
                    seen.superseded += 1;
                }
                newest = Some(*s);
            }
            Ok(None) => return newest,
            Err(_) => {
                seen.ipc_errors += 1;
                return newest;
            }
        }
    }
}

/// Sends `c` in the pre-loaned `slot` (or a fresh loan if there is none).
pub fn send<const N: usize>(
    publisher: &Publisher<ipc::Service, CommandSample, ()>,
    slot: &mut Option<CommandSlot>,
    c: CommandSample,
    ctl: &mut Controller<N>,
) {
    let loaned = match slot.take() {
        Some(s) => Ok(s),
        None => publisher.loan_uninit(),
    };
    match loaned {
        Ok(s) => {
            if s.write_payload(c).send().is_err() {
                ctl.counters.ipc_errors += 1;
            }
        }
        Err(_) => ctl.counters.ipc_errors += 1,
    }
}

/// What one state-triggered tick did on the path from state to command.
pub struct Answered<const N: usize> {
    pub got: Option<StateSample>,
    pub outcome: TickOutcome<N>,
    pub seen: Drained,
    /// The state's expected arrival this tick waited around (ns).
    pub due: u64,
    pub woke: u64,
    /// When the command had been sent (ns).
    pub done: u64,
}

/// The state-triggered loop's state between ticks. [`state_loop`] calls [`StateLoop::answer`]
/// then [`StateLoop::after`] until it stops; `daemon/tests/no_alloc.rs` calls the same two.
pub struct StateLoop<'a> {
    ports: &'a Ports<'a>,
    timing: Timing,
    /// The next command's sample, loaned before its state arrives.
    slot: Option<CommandSlot>,
    /// When the next state is due (ns).
    expected: u64,
    /// The newest accepted state: what a rehearsal runs the law on while waiting for the next.
    last: Option<StateSample>,
    /// Ticks since the last accepted state.
    missed: u32,
    /// A command that went out on the fast lane; its pub-sub copy is sent in `after`.
    copy: Option<CommandSample>,
    /// The newest state came by the fast lane: wait on the board, and look at pub-sub rarely.
    lane_first: bool,
    /// Where the wait for each state lost its core.
    meter: GapMeter,
}

impl<'a> StateLoop<'a> {
    pub fn new(ports: &'a Ports<'a>, timing: Timing) -> Self {
        Self {
            ports,
            timing,
            slot: ports.publisher.loan_uninit().ok(),
            expected: monotonic_ns() + timing.period_ns,
            last: None,
            missed: 0,
            copy: None,
            lane_first: false,
            meter: GapMeter::default(),
        }
    }

    /// The path from state to command: waits for the next state (rehearsing the law on the last
    /// one), ticks, and sends into the pre-loaned sample. No allocation.
    pub fn answer<const N: usize>(&mut self, ctl: &mut Controller<N>) -> Answered<N> {
        let (timing, expected) = (self.timing, self.expected);
        // No state for a whole period past its expected arrival: a tick without one.
        let give_up = expected + timing.period_ns;
        let mut seen = Drained::default();
        // While the plant keeps publishing, a late state is most likely a moment away: keep
        // polling without sleeping until the tick gives up on it (a sleep costs tens of µs here).
        // After a missed state the window closes as configured, so a dead plant costs no core.
        let mut window = Window::around(timing.wait, expected, timing.spin_ns);
        if self.last.is_some() && self.missed == 0 {
            window = window.open_until(give_up);
        }
        let got = {
            let (ctl, last, sub, lane) = (
                &mut *ctl,
                &self.last,
                self.ports.subscriber,
                self.ports.lane,
            );
            let (lane_first, mut poll) = (self.lane_first, 0u32);
            rt::trigger::poll_within_metered(
                window,
                give_up,
                &mut self.meter,
                || {
                    poll = poll.wrapping_add(1);
                    newest_unseen(sub, lane, lane_first, poll, &mut seen)
                },
                || {
                    if let Some(s) = last {
                        ctl.rehearse(s);
                    }
                },
            )
        };
        let woke = monotonic_ns();
        // The tick (woke → done) is the compute histogram's, not the meter's: a slow law must
        // not pass for a missing core.
        self.meter.close_at(woke);
        let got = got.map(|(s, via_lane)| {
            self.lane_first = via_lane;
            s
        });
        let outcome = ctl.tick(got.as_ref(), woke);
        match (outcome.command, self.ports.lane) {
            (Some(c), Some(lane)) => {
                lane.write(&c);
                self.copy = Some(c);
            }
            (Some(c), None) => send(self.ports.publisher, &mut self.slot, c, ctl),
            (None, _) => {}
        }
        let done = monotonic_ns();
        self.meter.read_at(done);
        Answered {
            got,
            outcome,
            seen,
            due: expected,
            woke,
            done,
        }
    }

    /// Everything off the path, while the plant applies the command: the pub-sub copy of a
    /// command that went out on the fast lane, counters, when the next state is due, the next
    /// loan (iceoryx2's one allocation), `between` (what the control service sent), and the
    /// telemetry record.
    pub fn after<const N: usize>(
        &mut self,
        ctl: &mut Controller<N>,
        a: Answered<N>,
        between: &mut impl FnMut(&mut Controller<N>),
    ) {
        let period = self.timing.period_ns;
        if let Some(c) = self.copy.take() {
            send(self.ports.publisher, &mut self.slot, c, ctl);
        }
        // Off the path: the watchdog thread reads this line now and then, and a write to a line
        // another core holds costs a transfer.
        crate::watchdog::beat(ctl.counters.ticks);
        a.seen.into_counters(ctl);
        ctl.counters.wait_gaps = self.meter.gaps;
        ctl.counters.late_wakes = self.meter.late_wakes;
        if a.outcome.state_age_ns.is_some() {
            self.last = a.got;
            self.missed = 0;
        } else {
            self.missed += 1;
        }
        self.expected = match (a.got, a.outcome.state_age_ns) {
            (Some(s), Some(_)) => s
                .stamp_ns
                .saturating_add(period)
                .clamp(a.woke, a.woke + 2 * period),
            _ => (a.due + period).max(a.woke),
        };
        if self.slot.is_none() {
            self.slot = self.ports.publisher.loan_uninit().ok();
        }
        between(ctl);
        let times = TickTimes {
            due: a.due,
            woke: a.woke,
            done: a.done,
        };
        let rec = tick_record(ctl, &a.outcome, a.got, times);
        match self.ports.tx.try_send(rec) {
            Ok(()) => {}
            Err(crossbeam::channel::TrySendError::Full(_)) => ctl.counters.telemetry_dropped += 1,
            Err(crossbeam::channel::TrySendError::Disconnected(_)) => rt::signal::request_stop(),
        }
    }
}

/// Runs state-triggered ticks until a stop request or `timing.end_ns`. `between` runs after each
/// command has left: it takes what the control service sent (a parameter block, ...) without
/// waiting, exactly as the clock loop does before its tick.
pub fn state_loop<const N: usize>(
    ctl: &mut Controller<N>,
    ports: &Ports<'_>,
    timing: Timing,
    mut between: impl FnMut(&mut Controller<N>),
) {
    let mut l = StateLoop::new(ports, timing);
    while !rt::signal::stop_requested() {
        if timing.end_ns.is_some_and(|e| monotonic_ns() >= e) {
            break;
        }
        let a = l.answer(ctl);
        l.after(ctl, a, &mut between);
    }
}

/// Clock trigger with `phase_offset_us`: keeps the tick `offset_ns` after the plant's states.
#[derive(Clone, Copy, Debug)]
pub struct PhaseLock {
    period_ns: u64,
    offset_ns: u64,
}

impl PhaseLock {
    pub fn new(period_ns: u64, offset_ns: u64) -> Self {
        Self {
            period_ns,
            offset_ns,
        }
    }

    /// The deadline after `next_deadline` that lies `offset_ns` after a multiple of the period
    /// from `stamp_ns` (the newest accepted state's stamp), moved by at most a quarter period per
    /// call, so a single odd stamp cannot throw the loop around.
    ///
    /// ```
    /// use daemon::trigger::PhaseLock;
    /// let lock = PhaseLock::new(1_000_000, 50_000);
    /// // States stamped at ...000 µs; the free-running deadline fell at 10 400 µs.
    /// let mut d = 10_400_000;
    /// for _ in 0..4 {
    ///     d = lock.align(d, 9_000_000) + 1_000_000;
    /// }
    /// assert_eq!(d % 1_000_000, 50_000);
    /// ```
    pub fn align(&self, next_deadline: u64, stamp_ns: u64) -> u64 {
        let p = self.period_ns as i64;
        let target = stamp_ns as i64 + self.offset_ns as i64;
        // Signed distance from the target phase, folded into (−p/2, p/2].
        let mut err = (next_deadline as i64 - target).rem_euclid(p);
        if err > p / 2 {
            err -= p;
        }
        let step = err.clamp(-p / 4, p / 4);
        (next_deadline as i64 - step) as u64
    }
}
