//! The plant loop: generic over [`Plant`], identical for the simulator and any bridge.
//!
//! One cycle, with `trigger = "clock"` (free-running): wait for the absolute deadline (or, for a
//! device-clocked plant, for the device's next state inside `read`) → drain commands, keep the
//! newest valid one → `write` it (or a brake after `command_timeout_ms` of silence) → `read` one
//! cycle → stamp, number and publish the state. The daemon's answer is applied next cycle.
//!
//! With `trigger = "state"` the answer is applied in the same cycle, as FCI and RSI require:
//! after publishing, the loop waits for the command answering *that* state, up to
//! `answer_deadline_us` after the state went out (within the cycle), and `write`s it the moment
//! it arrives. A late or missing answer leaves the previous command running (the plant keeps
//! ramping it) and counts a late cycle; `max_late_cycles` in a row make the plant brake until
//! answers come in time again.
//! With `fast_lane` (the default) the state goes out on the state board first and the answer is
//! taken from the command board (`protocol::board`); the pub-sub state follows once the cycle's
//! answer is in, off the path.
//! An answer that arrives after its deadline is counted and dropped. Unanswered cycles after the
//! controller left (its brake command at shutdown, or `command_timeout_ms` of silence) are
//! silent, not late: they say nothing about how fast a controller answers.
//!
//! Latencies go into fixed-bound histograms in the loop itself (recording never allocates) and
//! are written at exit ([`crate::report`]).

use crate::config::PlantConfig;
use crate::intake::{Intake, Published, PublishedRing};
use crate::report::{Histograms, PlantCounters, PlantSummary};
use crate::seam::{Actuation, Plant, PlantError};
use anyhow::{anyhow, Context, Result};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ipc;
use iceoryx2::sample_mut_uninit::SampleMutUninit;
use protocol::board::{pubsub_due, PlantLane};
use protocol::{flags, monotonic_ns, CommandSample, Mode, ServiceNames, StateSample};
use rt::clock::Schedule;
use rt::trigger::Window;
use rt::Trigger;
use std::mem::MaybeUninit;
use std::time::SystemTime;

type StatePub = Publisher<ipc::Service, StateSample, ()>;
type CommandSub = Subscriber<ipc::Service, CommandSample, ()>;
/// A state sample loaned ahead of time, so that the loan is not between the read and the send.
type StateSlot = SampleMutUninit<ipc::Service, MaybeUninit<StateSample>, ()>;

/// What the plant was last told to do (state trigger: `write` only when this changes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Applied {
    Nothing,
    Run,
    Hold,
    Brake,
}

/// Everything the loop keeps from one cycle to the next.
struct Loop<'a> {
    cfg: &'a PlantConfig,
    publisher: StatePub,
    /// The next state's sample, loaned at the end of the previous cycle.
    slot: Option<StateSlot>,
    subscriber: CommandSub,
    intake: Intake,
    ring: PublishedRing,
    c: PlantCounters,
    h: Histograms,
    /// The newest command in force.
    current: Option<CommandSample>,
    applied: Applied,
    last_command_at: Option<u64>,
    timed_out: bool,
    /// State trigger: late cycles in a row, and whether they made the plant brake.
    late_run: u32,
    late_braking: bool,
    /// Late cycles since the last command of any kind: reclassified as silent on a timeout.
    late_since_command: u64,
    /// Integrated plant time (s): what `since` is measured in.
    plant_time: f64,
    seq: u64,
    sample: StateSample,
    /// State trigger: the fast lane, if open (`protocol::board`).
    lane: Option<PlantLane>,
    /// The state went out on the lane; its pub-sub copy is still to be sent.
    copy_due: bool,
    /// The newest answer came by the lane, so the daemon reads it: the pub-sub copy of the state
    /// waits for the answer, and the wait looks at pub-sub rarely.
    lane_first: bool,
}

/// Runs `plant` until SIGINT/SIGTERM or for `duration` seconds. `arm` describes the arm it moves
/// ([`crate::handshake::describe`] of the config): a daemon that expects another arm is refused,
/// and the refusal is the error returned.
pub fn run<P: Plant>(
    plant: &mut P,
    cfg: &PlantConfig,
    arm: &protocol::ArmInfo,
    duration: Option<f64>,
) -> Result<PlantSummary> {
    if plant.n() != arm.n as usize {
        return Err(anyhow!(
            "the plant has {} joints, but the daemon's arm is {}",
            plant.n(),
            arm
        ));
    }
    let names = ServiceNames::new(&cfg.namespace).map_err(|e| anyhow!("plant.namespace: {e}"))?;
    rt::files::create_dir_all(&cfg.output_dir).with_context(|| {
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

    let lane = if cfg.trigger == Trigger::State && cfg.fast_lane {
        PlantLane::plant(&node, &names)
            .map_err(|e| tracing::warn!("fast lane off, pub-sub only: {e}"))
            .ok()
    } else {
        None
    };
    let plant_id = protocol::new_instance_id();
    let mut handshake = crate::handshake::Handshake::start(&names, *arm, plant_id, cfg.core)?;

    plant.activate()?;
    let mut rt_report = rt::setup::apply(rt::setup::RtRequest {
        core: cfg.core,
        priority: cfg.priority,
        lock_memory: cfg.lock_memory,
    });
    rt_report.warnings.extend(rt::throttle::warning(
        rt::throttle::RtLimit::read(),
        rt_report.sched_fifo.is_some(),
        cfg.wait,
        (cfg.spin_us * 1000.0) as u64,
        cfg.period_ns(),
    ));
    for w in &rt_report.warnings {
        tracing::warn!("{w}");
    }
    tracing::info!(
        "namespace {:?}, {} Hz, {} trigger, {}",
        names.namespace(),
        cfg.rate_hz,
        cfg.trigger.name(),
        rt_report.one_line()
    );
    let start = monotonic_ns();
    let wall_start = SystemTime::now();
    let slot = publisher.loan_uninit().ok();
    let mut lp = Loop {
        cfg,
        publisher,
        slot,
        subscriber,
        intake: Intake::new(plant.n(), start),
        ring: PublishedRing::default(),
        c: PlantCounters::default(),
        h: Histograms::new(),
        current: None,
        applied: Applied::Nothing,
        last_command_at: None,
        timed_out: false,
        late_run: 0,
        late_braking: false,
        late_since_command: 0,
        plant_time: 0.0,
        seq: 0,
        sample: StateSample {
            plant_id,
            n: plant.n() as u32,
            ..StateSample::default()
        },
        lane,
        copy_due: false,
        lane_first: false,
    };
    let fault = lp.cycles(plant, start, duration).err();
    plant.deactivate();
    lp.c.effort_clamps = plant.effort_clamps();
    let refused = handshake.stop();
    let summary = lp.finish(rt_report, start, wall_start, plant.contacts())?;
    match (fault, refused) {
        (Some(e), _) => Err(anyhow::Error::new(e).context("the plant stopped")),
        (None, Some(why)) => Err(anyhow!(why)),
        (None, None) => Ok(summary),
    }
}

impl Loop<'_> {
    /// The cycles, until a stop request, the end of `duration`, or a plant fault.
    fn cycles<P: Plant>(
        &mut self,
        plant: &mut P,
        start: u64,
        duration: Option<f64>,
    ) -> Result<(), PlantError> {
        let period = self.cfg.period_ns();
        let spin = (self.cfg.spin_us * 1000.0) as u64;
        let end = duration.map(|s| start.saturating_add((s * 1e9) as u64));
        let mut sched = Schedule::new(period, start);
        let mut behind = 0;
        while !rt::signal::stop_requested() {
            let deadline = sched.deadline();
            let woke = if plant.device_clocked() {
                monotonic_ns()
            } else {
                let w = rt::wait_until(deadline, self.cfg.wait, spin);
                self.h
                    .lateness
                    .saturating_record(w.saturating_sub(deadline).max(1));
                w
            };
            if end.is_some_and(|e| woke.max(deadline) >= e) {
                break;
            }
            self.drain(woke);
            self.watchdog(woke);
            self.actuate(plant)?;
            // Hold the initial state until a controller first answers (see `Plant::read`).
            let elapsed = if self.last_command_at.is_some() {
                (1 + behind) as f64 * period as f64 * 1e-9
            } else {
                0.0
            };
            let published = self.read_and_publish(plant, elapsed, deadline)?;
            if published && self.cfg.trigger == Trigger::State {
                // The device's cycle ends when it says (its next state); ours at the next deadline.
                let cycle_end = (!plant.device_clocked()).then(|| deadline + period);
                self.await_answer(plant, cycle_end)?;
            }
            if self.copy_due {
                self.copy_due = false;
                self.send_state();
            }
            self.c.ticks += 1;
            if self.slot.is_none() {
                self.slot = self.publisher.loan_uninit().ok();
            }
            behind = if plant.device_clocked() {
                sched = Schedule::new(period, monotonic_ns());
                0
            } else {
                sched.advance(monotonic_ns())
            };
            self.c.overruns += behind;
        }
        Ok(())
    }

    /// Takes every queued command. Clock trigger: the newest valid one is in force. State
    /// trigger: a RUN command here answers an older state, so it came too late and is dropped.
    fn drain(&mut self, now: u64) {
        loop {
            let cmd = match self.subscriber.receive() {
                Ok(Some(s)) => *s,
                Ok(None) => break,
                Err(_) => {
                    self.c.ipc_errors += 1;
                    break;
                }
            };
            if self.lane.as_ref().is_some_and(|l| l.seen(&cmd)) {
                continue; // the pub-sub copy of an answer taken from the fast lane
            }
            if !self.intake.accept(&cmd) {
                continue;
            }
            self.last_command_at = Some(now);
            self.late_since_command = 0;
            if self.cfg.trigger == Trigger::State && cmd.mode == Mode::Run as u32 {
                self.c.late_answers += 1;
                continue;
            }
            if cmd.mode == Mode::Run as u32 {
                self.record_round_trip(&cmd, now);
            }
            self.current = Some(cmd);
        }
    }

    fn record_round_trip(&mut self, cmd: &CommandSample, now: u64) {
        self.h
            .to_cmd
            .saturating_record(cmd.stamp_ns.saturating_sub(cmd.state_stamp_ns).max(1));
        if let Some(p) = self.ring.get(cmd.state_seq) {
            self.h
                .rtt
                .saturating_record(now.saturating_sub(p.at_ns).max(1));
        }
    }

    /// Brakes after `command_timeout_ms` without any command.
    fn watchdog(&mut self, now: u64) {
        let timeout = (self.cfg.command_timeout_ms * 1e6) as u64;
        let silent = self
            .last_command_at
            .is_none_or(|t| now.saturating_sub(t) > timeout);
        if silent && self.last_command_at.is_some() && !self.timed_out {
            self.timed_out = true;
            self.c.command_timeouts += 1;
            // The unanswered cycles that led up to the timeout were the controller leaving.
            self.c.late_cycles -= self.late_since_command;
            self.c.silent_cycles += std::mem::take(&mut self.late_since_command);
        } else if !silent {
            self.timed_out = false;
        }
    }

    /// What the plant should do now, by the command in force and the watchdogs.
    fn wanted(&self) -> Applied {
        if self.timed_out || self.late_braking {
            return Applied::Brake;
        }
        match self.current.map(|c| Mode::try_from(c.mode)) {
            Some(Ok(Mode::Run)) => Applied::Run,
            Some(Ok(Mode::Hold)) => Applied::Hold,
            Some(_) => Applied::Brake,
            None => Applied::Brake,
        }
    }

    /// Clock trigger: hands the plant its actuation every cycle. State trigger: only when it
    /// changes to a hold or a brake (a RUN answer is written the moment it arrives).
    fn actuate<P: Plant>(&mut self, plant: &mut P) -> Result<(), PlantError> {
        let wanted = self.wanted();
        if self.cfg.trigger == Trigger::State && (wanted == Applied::Run || wanted == self.applied)
        {
            return Ok(());
        }
        self.apply(plant, wanted)
    }

    fn apply<P: Plant>(&mut self, plant: &mut P, what: Applied) -> Result<(), PlantError> {
        let result = match (what, self.current) {
            (Applied::Run, Some(cmd)) => {
                let since = self.ring.since(cmd.state_seq, self.plant_time);
                plant.write(crate::seam::actuation(&cmd, since))
            }
            (Applied::Hold, _) => plant.write(Actuation::Hold),
            _ => plant.write(Actuation::Brake),
        };
        self.applied = what;
        match result {
            Err(PlantError::Unavailable { .. }) => {
                self.c.write_errors += 1;
                Ok(())
            }
            other => other,
        }
    }

    /// Reads one cycle and publishes it; `false` if the plant had no state this cycle.
    fn read_and_publish<P: Plant>(
        &mut self,
        plant: &mut P,
        elapsed: f64,
        deadline: u64,
    ) -> Result<bool, PlantError> {
        self.sample.seq = self.seq;
        let began = monotonic_ns();
        let read = plant.read(elapsed, &mut self.sample);
        self.h
            .step
            .saturating_record(monotonic_ns().saturating_sub(began).max(1));
        match read {
            Ok(()) => {}
            Err(PlantError::Unavailable { .. }) => {
                self.c.read_misses += 1;
                return Ok(false);
            }
            Err(e) => return Err(e),
        }
        self.plant_time += elapsed;
        let s = &mut self.sample;
        self.seq += 1;
        let braked = self.timed_out || self.late_braking;
        s.flags = plant.flags() | if braked { flags::COMMAND_TIMEOUT } else { 0 };
        let now = monotonic_ns();
        s.stamp_ns = if plant.device_clocked() {
            plant.stamp(now, now)
        } else {
            plant.stamp(deadline, now)
        };
        if !plant.device_clocked() {
            // This loop is the device: its clock is the time it has integrated.
            s.device_time_ns = (self.plant_time * 1e9).round() as u64;
        }
        let seq = s.seq;
        // Published = the moment the state goes out; the round trip is measured from here.
        // The pub-sub copy waits for the answer only while the daemon answers on the lane (so it
        // reads the lane too); a daemon without it must get the state on pub-sub at once.
        let at_ns = match &self.lane {
            Some(lane) => {
                let at = monotonic_ns();
                lane.write(&self.sample);
                self.c.states_published += 1;
                if self.lane_first {
                    self.copy_due = true;
                } else {
                    self.send_state();
                }
                at
            }
            None => self.send_state(),
        };
        self.ring.push(Published {
            seq,
            plant_time: self.plant_time,
            at_ns,
        });
        Ok(true)
    }

    /// Publishes the current state on pub-sub, into the sample loaned at the end of the last
    /// cycle; returns when the send started. With the fast lane this is the copy for pub-sub's
    /// readers, sent once the cycle's answer is in.
    fn send_state(&mut self) -> u64 {
        let lane_copy = self.lane.is_some();
        let loaned = match self.slot.take() {
            Some(slot) => Ok(slot),
            None => self.publisher.loan_uninit(),
        };
        let mut at_ns = monotonic_ns();
        match loaned {
            Ok(slot) => {
                let sample = slot.write_payload(self.sample);
                at_ns = monotonic_ns();
                match sample.send() {
                    Ok(_) if lane_copy => {}
                    Ok(_) => self.c.states_published += 1,
                    Err(_) => self.c.ipc_errors += 1,
                }
            }
            Err(_) => self.c.ipc_errors += 1,
        }
        at_ns
    }

    /// State trigger: waits for the command answering the state just published, up to the
    /// answer deadline after the state went out (and never past `cycle_end`), and writes it at
    /// once.
    ///
    /// Why from the publication and not from the cycle's nominal start: the deadline is what the
    /// controller owes, as with FCI (state sent → command received within the cycle), and a
    /// plant that woke late has not given the controller its time. The cycle's end still caps
    /// it, because the clock is this process's: a state published late within its cycle leaves
    /// the controller only the rest of that cycle. A state published after the cycle's end (the
    /// plant woke more than a period late) belongs to the period the plant resumes in, and is
    /// due by that period's end (`PlantConfig::answer_due_ns`); the periods skipped are the
    /// plant's overruns.
    fn await_answer<P: Plant>(
        &mut self,
        plant: &mut P,
        cycle_end: Option<u64>,
    ) -> Result<(), PlantError> {
        let want = self.sample.seq;
        let published = self.ring.get(want).map_or_else(monotonic_ns, |p| p.at_ns);
        let deadline = self.cfg.answer_due_ns(published, cycle_end);
        let spin = (self.cfg.spin_us * 1000.0) as u64;
        // The answer is due within microseconds, and a sleep here costs tens of them on a VM:
        // while the controller keeps answering, a hybrid wait polls without sleeping up to the
        // answer deadline. Once an answer was missed (a stalled or dead controller) it goes back
        // to sleeping between polls, so a missing controller does not cost a spinning core.
        let answering = self.last_command_at.is_some() && self.late_run == 0;
        let mut window = Window::around(self.cfg.wait, published, spin);
        if answering {
            window = window.open_until(deadline);
        }
        let (sub, intake, c) = (&self.subscriber, &mut self.intake, &mut self.c);
        let lane = &self.lane;
        let (lane_first, mut polls) = (self.lane_first, 0u32);
        let poll = || loop {
            // The fast lane first; then pub-sub, minus the copies of what the lane brought
            // (while the lane brings the answers, only now and then: see `pubsub_due`).
            let (cmd, via_lane) = match lane.as_ref().and_then(PlantLane::take) {
                Some(cmd) => (cmd, true),
                None => {
                    polls = polls.wrapping_add(1);
                    if !pubsub_due(lane_first, polls) {
                        return None;
                    }
                    match sub.receive() {
                        Ok(Some(s)) if lane.as_ref().is_some_and(|l| l.seen(&s)) => continue,
                        Ok(Some(s)) => (*s, false),
                        Ok(None) => return None,
                        Err(_) => {
                            c.ipc_errors += 1;
                            return None;
                        }
                    }
                }
            };
            if !intake.accept(&cmd) {
                continue;
            }
            if cmd.state_seq == want || cmd.mode != Mode::Run as u32 {
                return Some((cmd, monotonic_ns(), via_lane));
            }
            c.late_answers += 1;
        };
        let got = rt::trigger::poll_within(window, deadline, poll, || {});
        let Some((cmd, at, via_lane)) = got else {
            return self.late_cycle(plant);
        };
        self.lane_first = via_lane;
        self.last_command_at = Some(at);
        self.late_since_command = 0;
        self.current = Some(cmd);
        // Any answer in time ends a run of late cycles, a HOLD or a brake as much as a RUN: the
        // controller is there and says what it wants. Counting on across them, cycles late
        // seconds apart while the daemon was in FAULT added up to "20 in a row", the plant braked for
        // lateness, and the daemon's HOLD (which clears a device's stop) never reached the
        // device, so the daemon held for ever waiting for states without the stop.
        self.late_run = 0;
        self.late_braking = false;
        self.timed_out = false;
        if cmd.mode == Mode::Run as u32 && cmd.state_seq == want {
            self.record_round_trip(&cmd, at);
            self.c.answered_in_time += 1;
        }
        let wanted = self.wanted();
        self.apply(plant, wanted)
    }

    /// No answer in time: the previous command stays in force (ramped on by the plant); too
    /// many in a row, and the plant brakes.
    fn late_cycle<P: Plant>(&mut self, plant: &mut P) -> Result<(), PlantError> {
        self.lane_first = false; // until an answer comes by the lane again
        if self.last_command_at.is_none() {
            return Ok(()); // no controller yet: nothing is late
        }
        self.late_run = self.late_run.saturating_add(1);
        if self.timed_out || self.controller_left() {
            self.c.silent_cycles += 1; // the controller is gone: silent, not late
            return Ok(());
        }
        self.c.late_cycles += 1;
        self.late_since_command += 1;
        if self.late_run >= self.cfg.max_late_cycles && !self.late_braking {
            self.late_braking = true;
            self.c.late_brakes += 1;
            return self.apply(plant, Applied::Brake);
        }
        Ok(())
    }

    /// The controller said it stopped: its last command is a brake (the daemon sends one as it
    /// shuts down). Until it answers again, nobody is late.
    fn controller_left(&self) -> bool {
        self.current.is_some_and(|c| c.mode == Mode::Brake as u32)
    }

    fn finish(
        self,
        realtime: rt::setup::RtReport,
        start: u64,
        wall_start: SystemTime,
        contacts: Option<crate::report::ContactReport>,
    ) -> Result<PlantSummary> {
        let mut c = self.c;
        c.commands_received = self.intake.counters.commands_received;
        c.commands_rejected = self.intake.counters.commands_rejected;
        c.daemon_restarts = self.intake.counters.daemon_restarts;
        crate::report::write(
            self.cfg,
            realtime,
            (c, contacts),
            &self.h,
            start,
            wall_start,
        )
    }
}
