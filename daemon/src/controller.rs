//! One control tick, apart from the transport: validate the newest state, keep the delay line,
//! run the law, decide the command.
//!
//! Following rapier's pipeline, persistent state (delay line, sequence tracking, mode, counters)
//! lives here and the loop only moves samples in and out, so the tick can be driven by a test with
//! a mock clock, and its allocation-freedom proven without shared memory in the way.

use crate::guard::{FaultReason, Guard};
use control::command::{Command, MotionGenerator};
use control::hold;
use control::tick_law::{LawScratch, ParamBlock, TickLaw};
use control::{ArmState, ControlOutput, DelayLine, VecN};
use protocol::{CommandSample, Mode, StateSample};
use serde::Serialize;

/// A paused arm counts as at rest below this joint rate (rad/s).
const REST_RATE: f64 = 0.01;

/// The longest gap between two commands the reference catches up over, in periods.
const MAX_GAP_PERIODS: f64 = 64.0;

/// A gap between two runs of the law (periods) after which the arm counts as having moved on
/// unanswered: the guard treats catching up as a re-entry. Shorter gaps (a state lost now and
/// then) change the demand too little to matter.
const REENTRY_GAP_PERIODS: f64 = 5.0;

/// A gap counts as a re-entry at most this often (controller time, s): a plant that drops
/// states all the time must not keep the guard's demand criterion waiting.
const GAP_REENTRY_EVERY_S: f64 = 5.0;

/// Counters of everything the loop saw. Small and `Copy`, so a snapshot rides along with
/// every telemetry record.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Counters {
    pub ticks: u64,
    pub commands: u64,
    pub fresh_states: u64,
    pub rejected_invalid: u64,
    pub rejected_stale: u64,
    pub rejected_out_of_order: u64,
    pub rejected_future: u64,
    pub plant_faults: u64,
    /// Newer samples arrived in the same tick, so these were never used (nor checked).
    pub superseded: u64,
    /// Ticks on which the law reported lost tracking, damped least squares (near a
    /// singularity), a target out of reach, or a non-finite result replaced by zero.
    pub track_lost: u64,
    pub singular: u64,
    pub out_of_reach: u64,
    pub nonfinite: u64,
    /// Ticks on which the safety filter changed the command, had to leave the null space (so
    /// tracking gave way), or found no command meeting every limit.
    pub safety_active: u64,
    pub safety_left_null_space: u64,
    pub safety_infeasible: u64,
    /// Times the runaway guard tripped, and operator resumes out of FAULT.
    pub faults: u64,
    pub resumes: u64,
    pub holds_entered: u64,
    /// Times the arm began to brake or hold under a running stream (a device braking on
    /// missed answers, a brake or a HOLD that reached it): each knocks it off its path and its
    /// cycle, and what the run measures next is the recovery.
    pub arm_brakes: u64,
    pub plant_restarts: u64,
    pub overruns: u64,
    pub telemetry_dropped: u64,
    pub ipc_errors: u64,
    pub params_applied: u64,
    /// Fresh states answered with HOLD because the arm was blocked (no clean cycle; the
    /// `hold` action of `safety.when_blocked`).
    pub blocked_holds: u64,
    /// States from a plant the handshake has not agreed to (not yet, or refused): ignored
    /// unread. Not a rejection: every plant's first states arrive before its handshake.
    pub not_agreed: u64,
    /// State trigger: stretches of the loop without its core, between two of its clock reads
    /// (`rt::gaps`): the host stalling the vCPU, an interrupt, a preemption. Late answers with
    /// these behind them were the machine's, not the law's.
    pub wait_gaps: rt::gaps::Gaps,
    /// State trigger: sleeps in that wait that ended late (`rt::gaps::GapMeter::late_wakes`).
    pub late_wakes: rt::gaps::Gaps,
}

impl Counters {
    /// Every received state that was not used: invalid, stale, out of order, from the future, or
    /// flagged faulty by the plant.
    pub fn rejected(&self) -> u64 {
        self.rejected_invalid
            + self.rejected_stale
            + self.rejected_out_of_order
            + self.rejected_future
            + self.plant_faults
    }
}

/// Why a received state was not used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rejection {
    Invalid(protocol::SampleError),
    Stale {
        age_ns: u64,
    },
    OutOfOrder {
        seq: u64,
        last: u64,
    },
    /// Stamped later than now (plus one period of slack).
    FutureStamp {
        ahead_ns: u64,
    },
    /// The plant flagged a fault: its state is not to be controlled from.
    PlantFault,
    /// From a plant the handshake has not agreed to (`crate::handshake`).
    NotAgreed,
}

/// A change from the control service that took effect between two ticks. The loops take at most
/// one request between two ticks; a recording ([`crate::replay`]) needs to know which tick it
/// preceded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Applied {
    /// A new parameter block ([`Controller::set_params`]).
    Params,
    /// An operator's resume out of FAULT ([`Controller::resume`]).
    Resume,
    /// The handshake's verdict on one plant start ([`Controller::set_plant_verdict`]).
    Plant { plant_id: u64, agreed: bool },
    /// A planned cycle to steer onto, or none ([`Controller::set_steer`]).
    Steer,
    /// Blocked with the hold action, or no longer ([`Controller::set_blocked_hold`]).
    BlockedHold(bool),
}

/// What one tick decided.
#[derive(Clone, Copy, Debug)]
pub struct TickOutcome<const N: usize> {
    pub mode: Mode,
    /// The command to publish, if any.
    pub command: Option<CommandSample>,
    /// The law's output when it ran.
    pub output: Option<ControlOutput<N>>,
    /// Age of the state used (ns).
    pub state_age_ns: Option<u64>,
    pub rejection: Option<Rejection>,
    /// The mode changed on this tick.
    pub mode_changed: bool,
    pub plant_restarted: bool,
    /// The runaway guard tripped on this tick, and why.
    pub fault: Option<FaultReason>,
    /// The change applied since the previous tick, if any.
    pub applied: Option<Applied>,
    /// Which limits the limiter applied to each joint's command (bits of
    /// `control::command::LimitKind`).
    pub limiter_hits: [u8; protocol::MAX_JOINTS],
}

/// Tick-independent settings.
#[derive(Clone, Copy, Debug)]
pub struct ControllerSettings {
    pub rate_hz: f64,
    /// Send q̈'s rate for a first-order hold.
    pub first_order_hold: bool,
    pub hold_after: u32,
    pub stale_ns: u64,
    /// How far in the future a stamp may be (one period covers a simulator's nominal stamps).
    pub future_slack_ns: u64,
    pub daemon_id: u64,
    /// Controller time (s) of the first state: 0, or where a restarted daemon left off.
    pub t_start: f64,
}

pub struct Controller<const N: usize> {
    law: TickLaw<N>,
    settings: ControllerSettings,
    dt: f64,
    delay: DelayLine<N>,
    scratch: LawScratch<N>,
    /// `None`: every plant is controlled (tests, tools). `Some(id)`: only states of plant `id`,
    /// the one the handshake agreed to (0: none yet). Set between ticks, never on the tick.
    agreed_plant: Option<u64>,
    /// The law's q̈ into the configured command interface, through the limiter.
    generator: MotionGenerator<N>,
    /// The planned cycle the self-motion is steered onto, kept across parameter
    /// blocks: the control service's blocks carry none, the planner's handover sets it.
    steer: Option<control::steer::Steering>,
    /// Blocked, holding: fresh states are answered with HOLD (tracking paused) until cleared.
    blocked_hold: bool,
    /// What the tick remembers from one tick to the next: all a rehearsal puts back, with the
    /// counters, the gain and the command stream. The other fields are set between ticks or are
    /// scratch; a new field the tick changes belongs in here, or a rehearsal leaves its change
    /// behind (`rehearsals_change_nothing_on_the_panda_in_any_interface` would see it).
    memory: TickMemory<N>,
    pub counters: Counters,
    /// Inside [`Controller::rehearse`]: the tick runs but leaves the delay line unwritten.
    rehearsing: bool,
}

/// The controller's memory from tick to tick: one `Copy` block, so that a rehearsal (the tick
/// run and undone) restores it with one assignment.
#[derive(Clone, Copy, Debug)]
struct TickMemory<const N: usize> {
    /// Stamp of the first state ever accepted: controller time 0.
    t0_stamp: Option<u64>,
    /// Controller time of the newest accepted state (s).
    t: f64,
    /// Grid index (in periods since `t0_stamp`) of the delay line's first sample.
    delay_origin: i64,
    mode: Mode,
    plant_id: u64,
    last_seq: Option<u64>,
    last_stamp: u64,
    /// Whether the newest accepted state said the plant was braking on its command timeout.
    was_braked: bool,
    /// The last state said BRAKING (the arm braking or holding, not following a stream).
    was_braking: bool,
    last_qd: Option<VecN<N>>,
    missed: u32,
    next_command_seq: u64,
    guard: Guard,
    fault: Option<FaultReason>,
    /// Applied since the last tick.
    applied: Option<Applied>,
    /// A device error already turned into a FAULT: not again until the device reports none.
    device_fault_latched: bool,
    /// Controller time of the last RUN command (the generator advances by the time since).
    last_run_t: Option<f64>,
    /// The device time of that state (`StateSample::device_time_ns`).
    last_run_device_ns: Option<u64>,
    /// When a gap last counted as a re-entry (controller time, s).
    last_gap_reentry: Option<f64>,
    /// While blocked: the arm kept the filter's clearance and was at rest on the newest law
    /// run. A blocked hold hands the arm to the plant's HOLD only then (the filter brakes it
    /// and pushes it out first); nothing is judged on the tick otherwise.
    clear: bool,
}

/// What a tick changes, but the delay line (a rehearsal does not write it) and the scratch: the
/// copy [`Controller::rehearse`] puts back after its tick.
struct Undo<const N: usize> {
    memory: TickMemory<N>,
    counters: Counters,
    gain: (f64, Option<control::adapt::AutoMu>),
    stream: control::command::Stream<N>,
}

impl<const N: usize> Controller<N> {
    /// `max_tau` fixes the delay-line capacity for the daemon's whole life.
    pub fn new(law: TickLaw<N>, max_tau: f64, settings: ControllerSettings) -> Self {
        let dt = 1.0 / settings.rate_hz;
        Self {
            law,
            settings,
            dt,
            delay: DelayLine::new(max_tau.max(law.tau()) / dt, VecN::<N>::zeros()),
            scratch: LawScratch::default(),
            agreed_plant: None,
            generator: MotionGenerator::passthrough(dt),
            steer: None,
            blocked_hold: false,
            memory: TickMemory {
                t0_stamp: None,
                t: settings.t_start,
                delay_origin: 0,
                mode: Mode::Hold,
                plant_id: 0,
                last_seq: None,
                last_stamp: 0,
                was_braked: false,
                was_braking: false,
                last_qd: None,
                missed: 0,
                next_command_seq: 0,
                guard: Guard::default(),
                fault: None,
                applied: None,
                device_fault_latched: false,
                last_run_t: None,
                last_run_device_ns: None,
                last_gap_reentry: None,
                clear: false,
            },
            counters: Counters::default(),
            rehearsing: false,
        }
    }

    /// This controller with the command interface and limiter `generator` (built from the
    /// set-up at the same rate); without one, q̈ passes through unlimited.
    pub fn with_generator(mut self, generator: MotionGenerator<N>) -> Self {
        self.generator = generator;
        self
    }

    /// The command interface, its limiter and its saturation counts.
    pub fn generator(&self) -> &MotionGenerator<N> {
        &self.generator
    }

    /// The law this controller runs.
    pub fn law(&self) -> &TickLaw<N> {
        &self.law
    }

    /// Swaps in a validated parameter block (at a tick boundary; no allocation). A block for
    /// another kind of arm is refused (false) and changes nothing: the control service builds
    /// blocks from the same set-up the loop runs, so it never sends one.
    pub fn set_params(&mut self, p: ParamBlock) -> bool {
        if !control::sim::ClosedLoopLaw::take_block(&mut self.law, p) {
            return false;
        }
        self.law.set_steer(self.steer);
        self.law.set_pause(self.blocked_hold);
        self.memory.applied = Some(Applied::Params);
        self.counters.params_applied += 1;
        true
    }

    /// Steers the self-motion onto a planned cycle, or stops steering (between ticks; no
    /// allocation: the cycle is a `Copy` table). The steering outlives parameter changes until
    /// the next handover.
    pub fn set_steer(&mut self, steer: Option<control::steer::Steering>) {
        self.steer = steer;
        self.law.set_steer(steer);
        self.memory.applied = Some(Applied::Steer);
    }

    /// Blocked with the hold action (`true`): tracking pauses, and the law brakes the arm to
    /// rest through the safety filter (an arm swinging past an obstacle must not coast into
    /// it); once at rest and clear, fresh states are answered with HOLD, so the plant keeps it
    /// there. Or run again (`false`), starting over from the arm's state with a fresh history.
    pub fn set_blocked_hold(&mut self, hold: bool) {
        if self.blocked_hold && !hold {
            self.memory.last_qd = None; // the braking's rates are no history for the Pyragas term
        }
        self.blocked_hold = hold;
        self.memory.clear = false; // judged afresh by the next law run, braking
        self.law.set_pause(hold);
        self.memory.applied = Some(Applied::BlockedHold(hold));
    }

    pub fn mode(&self) -> Mode {
        self.memory.mode
    }

    /// From now on, only states of a plant the handshake agreed to are used: none until
    /// [`Controller::set_plant_verdict`] names one.
    pub fn require_handshake(&mut self) {
        self.agreed_plant = Some(0);
    }

    /// The handshake's verdict on plant `plant_id` (between ticks; no allocation). A refused
    /// plant's states are ignored, so the daemon never sends it a RUN command.
    pub fn set_plant_verdict(&mut self, plant_id: u64, agreed: bool) {
        self.memory.applied = Some(Applied::Plant { plant_id, agreed });
        match (&mut self.agreed_plant, agreed) {
            (Some(id), true) => *id = plant_id,
            (Some(id), false) if *id == plant_id => *id = 0,
            _ => {}
        }
    }

    /// Why the daemon is in FAULT, if it is.
    pub fn fault(&self) -> Option<FaultReason> {
        self.memory.fault
    }

    /// Starts in FAULT (a restarted daemon that had faulted): the plant is braked until resume.
    pub fn enter_fault(&mut self, reason: FaultReason) {
        self.memory.mode = Mode::Fault;
        self.memory.fault = Some(reason);
    }

    /// An operator's resume: FAULT → HOLD, so the next fresh state starts a new run (with a
    /// fresh delay-line history and a fresh guard). Returns false when not in FAULT.
    pub fn resume(&mut self) -> bool {
        if self.memory.mode != Mode::Fault {
            return false;
        }
        self.memory.mode = Mode::Hold;
        self.memory.fault = None;
        self.memory.guard.reset();
        self.memory.last_qd = None;
        self.memory.missed = 0;
        self.memory.applied = Some(Applied::Resume);
        self.counters.resumes += 1;
        true
    }

    /// Controller time (s) of the newest state: the task, t_on and the delay line run on the
    /// *measurement* time, the state's stamp relative to the first state ever accepted. The law is
    /// evaluated for the instant the state describes, not for the instant the tick happens to run,
    /// and the circle's phase does not depend on which process started first.
    pub fn time(&self) -> f64 {
        self.memory.t
    }

    /// Feeds the delay line up to grid index `g`, holding the previous value across gaps.
    ///
    /// A short gap (a missed state) is filled by linear interpolation between the last rate and
    /// this one. A gap longer than the line itself holds no usable history: the line restarts.
    fn feed_delay(&mut self, g: i64, qd: VecN<N>) {
        if self.rehearsing {
            // The slot the real tick will write, brought into the cache, and nothing written.
            std::hint::black_box(self.delay.next_slot());
            return;
        }
        let next = self.memory.delay_origin + self.delay.len() as i64;
        if g < next {
            return; // two states in one grid slot: the first one stays
        }
        let gap = g - next;
        match self.memory.last_qd {
            Some(last) if (gap as f64) <= self.delay.max_delay_steps() => {
                for i in 1..=gap {
                    let w = i as f64 / (gap + 1) as f64;
                    self.delay.push(last + (qd - last) * w);
                }
                self.delay.push(qd);
            }
            _ => self.restart_history(g, qd),
        }
    }

    /// Starts a fresh delay-line history at grid index `g` (q̇ before it = q̇ now).
    fn restart_history(&mut self, g: i64, qd: VecN<N>) {
        if self.rehearsing {
            return;
        }
        self.delay.reset(qd);
        self.memory.delay_origin = g;
        self.delay.push(qd);
    }

    /// Checks a sample without changing any state; returns whether it comes from a new plant.
    fn accept(&self, s: &StateSample, now_ns: u64) -> Result<bool, Rejection> {
        if self
            .agreed_plant
            .is_some_and(|id| id != s.plant_id || id == 0)
        {
            return Err(Rejection::NotAgreed);
        }
        s.validate(N).map_err(Rejection::Invalid)?;
        if s.has_flags(protocol::flags::FAULT) {
            return Err(Rejection::PlantFault);
        }
        // A stamp from the future (a clock mix-up, a corrupt sample) would move controller time
        // ahead for good; one period of slack covers a simulator's nominal stamps.
        if s.stamp_ns > now_ns.saturating_add(self.settings.future_slack_ns) {
            return Err(Rejection::FutureStamp {
                ahead_ns: s.stamp_ns - now_ns,
            });
        }
        let restarted = s.plant_id != self.memory.plant_id;
        if !restarted {
            if let Some(last) = self.memory.last_seq {
                if s.seq <= last || s.stamp_ns < self.memory.last_stamp {
                    return Err(Rejection::OutOfOrder { seq: s.seq, last });
                }
            }
        }
        let age = now_ns.saturating_sub(s.stamp_ns);
        if age > self.settings.stale_ns {
            return Err(Rejection::Stale { age_ns: age });
        }
        Ok(restarted && self.memory.plant_id != 0)
    }

    /// One tick at time `now_ns` with the newest received state, if any.
    pub fn tick(&mut self, newest: Option<&StateSample>, now_ns: u64) -> TickOutcome<N> {
        let mut out = TickOutcome {
            mode: self.memory.mode,
            command: None,
            output: None,
            state_age_ns: None,
            rejection: None,
            mode_changed: false,
            plant_restarted: false,
            fault: None,
            applied: self.memory.applied.take(),
            limiter_hits: [0; protocol::MAX_JOINTS],
        };
        let mut fresh = None;
        if let Some(s) = newest {
            match self.accept(s, now_ns) {
                Ok(restarted) => {
                    let t0 = *self.memory.t0_stamp.get_or_insert(s.stamp_ns);
                    // Controller time never runs backwards (a restarted plant's stamps may start
                    // a little behind the last one seen).
                    let t = (self.settings.t_start + s.stamp_ns.saturating_sub(t0) as f64 * 1e-9)
                        .max(self.memory.t);
                    let g = (t / self.dt).round() as i64;
                    // The plant braked on its own (no commands reached it, e.g. while this
                    // loop was stalled): it has not been following the last rates either.
                    let braked = s.has_flags(protocol::flags::COMMAND_TIMEOUT)
                        && self.memory.last_stamp != 0
                        && !self.memory.was_braked;
                    self.memory.was_braked = s.has_flags(protocol::flags::COMMAND_TIMEOUT);
                    if restarted
                        || self.memory.last_qd.is_none()
                        || self.memory.mode == Mode::Hold
                        || braked
                    {
                        // New history: after a restart, a HOLD or a plant-side brake (the plant
                        // was braking, not following the last rates) the old q̇ would feed the
                        // Pyragas term lies, and catching the circle again is a re-entry.
                        self.memory.last_qd = None;
                        self.restart_history(g, arm_state::<N>(s).qd);
                        self.memory.guard.reenter(t);
                    } else if self.unanswered_since_last_run(t) {
                        // The arm moved on without answers for a while (this loop or the plant
                        // was stalled): catching up is a re-entry too, not a runaway.
                        self.memory.last_gap_reentry = Some(t);
                        self.memory.guard.reenter(t);
                    }
                    let braking = s.has_flags(protocol::flags::BRAKING);
                    if braking && !self.memory.was_braking && self.memory.last_stamp != 0 {
                        self.counters.arm_brakes += 1;
                    }
                    self.memory.was_braking = braking;
                    if restarted || self.memory.last_stamp == 0 || braking {
                        // The command stream starts again exactly when the arm's does: a new
                        // plant, or an arm braking or holding (by the device on its own, by a
                        // brake or a hold that reached it), which follows no stream; the first
                        // answer that reaches it starts a new one from the state it answers.
                        // Nothing else restarts it: a COMMAND_TIMEOUT or this loop's HOLD says
                        // what was meant, not what reached the arm (a brake sent for a state the
                        // device has left is dropped), and a stream restarted under an arm that
                        // went on following the old one is a jump or a jerk it stops for.
                        let x = arm_state::<N>(s);
                        self.restart_generator(&x);
                    }
                    self.memory.plant_id = s.plant_id;
                    self.memory.last_stamp = s.stamp_ns;
                    if restarted {
                        self.counters.plant_restarts += 1;
                        out.plant_restarted = true;
                    }
                    self.memory.t = t;
                    self.memory.last_seq = Some(s.seq);
                    self.counters.fresh_states += 1;
                    out.state_age_ns = Some(now_ns.saturating_sub(s.stamp_ns));
                    fresh = Some(s);
                }
                Err(r) => {
                    if r == Rejection::PlantFault {
                        self.device_fault(s, &mut out);
                    }
                    match r {
                        Rejection::Invalid(_) => self.counters.rejected_invalid += 1,
                        Rejection::Stale { .. } => self.counters.rejected_stale += 1,
                        Rejection::OutOfOrder { .. } => self.counters.rejected_out_of_order += 1,
                        Rejection::FutureStamp { .. } => self.counters.rejected_future += 1,
                        Rejection::PlantFault => self.counters.plant_faults += 1,
                        Rejection::NotAgreed => self.counters.not_agreed += 1,
                    }
                    out.rejection = Some(r);
                }
            }
        }

        let prev_mode = self.memory.mode;
        match fresh {
            Some(s) if self.memory.mode == Mode::Fault => {
                // Keep braking; answer the newest state so the plant sees the controller alive.
                self.memory.missed = 0;
                out.command = Some(self.fault_command(s, now_ns));
            }
            Some(s) if self.blocked_hold && self.memory.clear => {
                self.hold_blocked(s, now_ns, &mut out)
            }
            Some(s) => self.run_law(s, now_ns, &mut out),
            None => self.missed_state(now_ns, &mut out),
        }
        out.mode = self.memory.mode;
        out.mode_changed = prev_mode != self.memory.mode;
        self.counters.ticks += 1;
        if out.command.is_some() {
            self.counters.commands += 1;
        }
        out
    }

    /// A state flagged FAULT that names a device error: the daemon goes to FAULT, naming the
    /// joint and the reason, once per device error (a resume does not re-enter it while the
    /// device still reports the same stop; a state without one re-arms it).
    fn device_fault(&mut self, s: &StateSample, out: &mut TickOutcome<N>) {
        let Some(status) = s
            .device_status()
            .filter(|d| *d != protocol::DeviceStatus::Ok)
        else {
            return;
        };
        if self.memory.device_fault_latched {
            return;
        }
        self.memory.device_fault_latched = true;
        let reason = FaultReason::Device {
            status,
            joint: s.device_joint,
        };
        if self.memory.mode != Mode::Fault {
            self.memory.mode = Mode::Fault;
            self.memory.fault = Some(reason);
            self.counters.faults += 1;
            out.fault = Some(reason);
        }
    }

    /// Runs the tick the loop expects next (on `s` one period on) and undoes it: changes
    /// nothing but scratch space.
    ///
    /// Why: the loop spends most of a period asleep, and on this kind of machine a tick after a
    /// sleep costs about three times one after a spin (code, model and delay line evicted). A
    /// rehearsal while waiting for the next state brings them back into this core's caches, so
    /// the real tick, which stands between a state and its command, runs warm. It is the tick
    /// itself, not a part of it: a rehearsal that ran the law and the command alone left the
    /// rest of the tick's code cold (a rehearsed tick 3.3 µs, warm 1.2 µs; rehearsed and then a
    /// twin controller's full tick, 1.3 µs). The result is bit-for-bit the same with or without
    /// rehearsals (tested).
    pub fn rehearse(&mut self, s: &StateSample) {
        if self.memory.mode != Mode::Run || s.n as usize != N {
            return;
        }
        let period = (self.dt * 1e9).round() as u64;
        let next = StateSample {
            seq: s.seq.wrapping_add(1),
            stamp_ns: s.stamp_ns.saturating_add(period),
            device_time_ns: match s.device_time_ns {
                0 => 0,
                d => d.saturating_add(period),
            },
            ..*s
        };
        let undo = self.undo_point();
        self.rehearsing = true;
        std::hint::black_box(self.tick(Some(&next), next.stamp_ns));
        self.rehearsing = false;
        self.undo(undo);
    }

    /// Everything [`Self::tick`] may change, but the delay line and the scratch.
    fn undo_point(&self) -> Undo<N> {
        Undo {
            memory: self.memory,
            counters: self.counters,
            gain: self.law.gain(),
            stream: self.generator.stream(),
        }
    }

    /// Puts back what [`Self::undo_point`] saved.
    fn undo(&mut self, u: Undo<N>) {
        self.memory = u.memory;
        self.counters = u.counters;
        self.law.set_gain(u.gain);
        self.generator.set_stream(u.stream);
    }

    /// The law (and, for a first-order hold, its rate) at controller time `t` on `x`, reading
    /// the delay line: what both the tick and a rehearsal evaluate.
    fn hold_command(&mut self, t: f64, x: &ArmState<N>) -> hold::HeldCommand<N> {
        let (delay, origin, dt) = (&self.delay, self.memory.delay_origin as f64, self.dt);
        hold::command(
            &self.law,
            t,
            x,
            dt,
            self.settings.first_order_hold,
            |at| delay.sample(at / dt - origin),
            &mut self.scratch,
        )
    }

    /// A fresh, accepted state: run the law, count what it reports, let the guard judge.
    fn run_law(&mut self, s: &StateSample, now_ns: u64, out: &mut TickOutcome<N>) {
        self.memory.missed = 0;
        self.memory.mode = Mode::Run;
        self.memory.device_fault_latched = false;
        let m = arm_state(s);
        let x = self.law_state(&m);
        let t = self.memory.t;
        self.feed_delay((t / self.dt).round() as i64, x.qd);
        self.memory.last_qd = Some(x.qd);
        let held = self.hold_command(t, &x);
        let mut o = held.output;
        self.law.adapt(&o, self.dt);
        if x.q != m.q {
            // The law ran on the reference: the tracking error reported is the arm's own.
            if let Some(p) = self.law.tool_position(&m.q) {
                o.tracking_error = (p - o.p_desired).norm();
            }
        }
        self.count_flags(o.flags);
        out.output = Some(o);
        // Paused (blocked, braking to rest), the target moves on without the arm: a growing
        // tracking error is the pause, not a runaway. Rates and demand are judged as ever.
        let mut judged = o;
        // A detour leaves the path on purpose: the same holds for it.
        if o.flags & control::basics::flags::DETOUR != 0 {
            judged.tracking_error = 0.0;
        }
        if self.blocked_hold {
            judged.tracking_error = 0.0;
            self.memory.clear =
                o.clearance >= self.law.safety().clearance && x.qd.amax() <= REST_RATE;
        }
        if let Some(reason) = self
            .memory
            .guard
            .check(t, self.law.safety(), &x.qd, &judged)
        {
            self.memory.mode = Mode::Fault;
            self.memory.fault = Some(reason);
            self.counters.faults += 1;
            out.fault = Some(reason);
            out.command = Some(self.fault_command(s, now_ns));
            return;
        }
        let periods = self.periods_since_last_run(s, t);
        self.memory.last_run_t = Some(t);
        self.memory.last_run_device_ns = Some(s.device_time_ns);
        let c = self
            .generator
            .next_over(&m.q, &m.qd, &held.qdd, &held.qddd, periods);
        self.generator.commit(&c);
        out.limiter_hits[..N].copy_from_slice(&c.hits);
        out.command = Some(self.command(Mode::Run, &c, s, now_ns));
    }

    /// Blocked, holding: the plant brings the arm to rest and keeps it there; the next RUN
    /// starts a fresh history (as after any HOLD).
    fn hold_blocked(&mut self, s: &StateSample, now_ns: u64, out: &mut TickOutcome<N>) {
        self.memory.missed = 0;
        self.memory.mode = Mode::Hold;
        self.counters.blocked_holds += 1;
        out.command = Some(self.command(Mode::Hold, &self.still(), s, now_ns));
    }

    /// The command stream starts again from the arm's measured state `x`.
    fn restart_generator(&mut self, x: &ArmState<N>) {
        self.generator.restart(&x.q, &x.qd);
        self.memory.last_run_t = None;
        self.memory.last_run_device_ns = None;
    }

    /// The periods the device moved on by since the last command (1 unless states went
    /// missing): the reference moves on by as much, so the stream the device judges stays
    /// continuous. By the device's own clock when it has one (a bridge's receipt stamps jitter
    /// by up to a period, and a wrong count is a velocity step the device stops for); else by
    /// the stamps.
    ///
    /// Capped at [`MAX_GAP_PERIODS`] (a device that went that long without answers has braked
    /// and says so, and the stream restarts; the cap bounds the catch-up's cost).
    fn periods_since_last_run(&self, s: &StateSample, t: f64) -> u32 {
        let by_device = self
            .memory
            .last_run_device_ns
            .filter(|&last| s.device_time_ns > last)
            .map(|last| (s.device_time_ns - last) as f64 * 1e-9);
        by_device
            .or_else(|| self.memory.last_run_t.map(|last| t - last))
            .map_or(1, |e| {
                (e / self.dt).round().clamp(1.0, MAX_GAP_PERIODS) as u32
            })
    }

    /// Whether states went missing for [`REENTRY_GAP_PERIODS`] or more before this one, at
    /// controller time `t`, and no gap counted as a re-entry in the last
    /// [`GAP_REENTRY_EVERY_S`].
    fn unanswered_since_last_run(&self, t: f64) -> bool {
        let gap = self
            .memory
            .last_run_t
            .is_some_and(|last| t - last >= (REENTRY_GAP_PERIODS - 0.5) * self.dt);
        gap && self
            .memory
            .last_gap_reentry
            .is_none_or(|last| t - last >= GAP_REENTRY_EVERY_S)
    }

    /// The state the law runs on: the measured one, or the generator's reference in position
    /// and velocity modes (`MotionGenerator::law_state`).
    fn law_state(&self, m: &ArmState<N>) -> ArmState<N> {
        let (q, qd) = self.generator.law_state(&m.q, &m.qd);
        ArmState { q, qd, phi: m.phi }
    }

    /// A command that moves nothing (HOLD, BRAKE, FAULT), in the configured interface.
    fn still(&self) -> Command<N> {
        Command::still(self.generator.mode())
    }

    fn count_flags(&mut self, f: u32) {
        use control::basics::flags as lf;
        let c = &mut self.counters;
        c.track_lost += u64::from(f & lf::TRACK_LOST != 0);
        c.singular += u64::from(f & lf::SINGULAR != 0);
        c.out_of_reach += u64::from(f & lf::OUT_OF_REACH != 0);
        c.nonfinite += u64::from(f & lf::NONFINITE != 0);
        c.safety_active += u64::from(f & lf::SAFETY_ACTIVE != 0);
        c.safety_left_null_space += u64::from(f & lf::SAFETY_LEFT_NULL_SPACE != 0);
        c.safety_infeasible += u64::from(f & lf::SAFETY_INFEASIBLE != 0);
    }

    /// No usable state this tick: HOLD after `hold_after` misses; keep telling the plant.
    fn missed_state(&mut self, now_ns: u64, out: &mut TickOutcome<N>) {
        self.memory.missed = self.memory.missed.saturating_add(1);
        if self.memory.missed >= self.settings.hold_after && self.memory.mode == Mode::Run {
            self.memory.mode = Mode::Hold;
            self.counters.holds_entered += 1;
        }
        let last = StateSample {
            seq: self.memory.last_seq.unwrap_or(0),
            ..StateSample::default()
        };
        if self.memory.mode == Mode::Fault {
            out.command = Some(self.fault_command(&last, now_ns));
        } else if self.memory.mode == Mode::Hold && self.memory.last_seq.is_some() {
            // Tell the plant to hold while its states are missing or unusable.
            out.command = Some(self.command(Mode::Hold, &self.still(), &last, now_ns));
        }
    }

    fn fault_command(&mut self, answers: &StateSample, now_ns: u64) -> CommandSample {
        self.command(Mode::Fault, &self.still(), answers, now_ns)
    }

    /// A braking command for shutdown.
    pub fn brake_command(&mut self, now_ns: u64) -> CommandSample {
        let last = StateSample {
            seq: self.memory.last_seq.unwrap_or(0),
            ..StateSample::default()
        };
        self.command(Mode::Brake, &self.still(), &last, now_ns)
    }

    fn command(
        &mut self,
        mode: Mode,
        cmd: &Command<N>,
        answers: &StateSample,
        now_ns: u64,
    ) -> CommandSample {
        let c = self.next_command(mode, cmd, answers, now_ns);
        self.memory.next_command_seq += 1;
        c
    }

    /// The command [`Self::command`] builds, without taking its number.
    fn next_command(
        &self,
        mode: Mode,
        cmd: &Command<N>,
        answers: &StateSample,
        now_ns: u64,
    ) -> CommandSample {
        let mut c = CommandSample {
            seq: self.memory.next_command_seq,
            state_seq: answers.seq,
            state_stamp_ns: answers.stamp_ns,
            stamp_ns: now_ns,
            daemon_id: self.settings.daemon_id,
            mode: mode.into(),
            n: N as u32,
            interface: cmd.mode.code(),
            ..CommandSample::default()
        };
        c.qdd[..N].copy_from_slice(cmd.qdd.as_slice());
        c.qddd[..N].copy_from_slice(cmd.qddd.as_slice());
        // An acceleration command is q̈ and its rate alone (recordings compare it field by
        // field); the other interfaces carry their reference, and torque its torques.
        if cmd.mode != control::command::CommandMode::Acceleration {
            c.q[..N].copy_from_slice(cmd.q.as_slice());
            c.qd[..N].copy_from_slice(cmd.qd.as_slice());
            c.tau[..N].copy_from_slice(cmd.tau.as_slice());
        }
        c
    }
}

/// The arm state a sample carries (its first `N` joints).
fn arm_state<const N: usize>(s: &StateSample) -> ArmState<N> {
    ArmState {
        q: VecN::<N>::from_column_slice(&s.q[..N]),
        qd: VecN::<N>::from_column_slice(&s.qd[..N]),
        phi: s.phi,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::system::System;
    use control::Config;

    /// The tests' loop: 1 kHz, first-order hold, HOLD after 5 missed states.
    fn settings() -> ControllerSettings {
        ControllerSettings {
            rate_hz: 1000.0,
            first_order_hold: true,
            hold_after: 5,
            stale_ns: 5_000_000,
            future_slack_ns: 1_000_000,
            daemon_id: 9,
            t_start: 0.0,
        }
    }

    fn controller() -> Controller<3> {
        let cfg = Config::preset("paper").unwrap();
        let settings = settings();
        Controller::new(cfg.tick_law::<3>(), 2.0, settings)
    }

    fn state(seq: u64, stamp: u64) -> StateSample {
        let mut s = StateSample {
            seq,
            stamp_ns: stamp,
            plant_id: 77,
            n: 3,
            ..StateSample::default()
        };
        s.q[1] = 1.57;
        s.q[2] = 1.57;
        s
    }

    #[test]
    fn a_blocked_hold_brakes_through_the_filter_and_holds_clear_of_the_obstacle() {
        // The daemon's set-up (filter on) tracking the circle; at 4.47 s a disc appears on the
        // hand's path ahead of it, and 40 ms later (the planner's answer) the hold begins: the
        // arm must brake to rest under the filter, never inside the clearance, and then be
        // handed to the plant's HOLD. The plant's blind hold at once coasted 0.1 m into the disc.
        let cfg = Config::default();
        let mut c = Controller::<3>::new(cfg.tick_law::<3>(), 2.0, controller().settings);
        let model = cfg.model::<3>();
        let mut x = cfg.initial_state::<3>();
        let clearance = cfg.safety.clearance;
        let (mut min, mut first_hold) = (f64::INFINITY, None);
        let t0 = 1_000_000_000u64;
        for k in 0..6000u64 {
            if k == 4470 {
                let mut p = *c.law().planar_params().unwrap();
                let mut o = control::secondary::ObstacleSet::new();
                o.push(control::config::ObstacleConfig::disc(1.5, 2.0, 0.2).to_ball())
                    .unwrap();
                p.obstacles = o;
                // A tight growth guard: the pause's growing tracking error must not trip it.
                p.core.safety.guard_tracking_error = 0.2;
                p.core.safety.guard_growth_time = 0.1;
                assert!(c.set_params(ParamBlock::Planar(p)));
            }
            if k == 4510 {
                c.set_blocked_hold(true);
            }
            let mut s = state(k, t0 + k * 1_000_000);
            s.q[..3].copy_from_slice(x.q.as_slice());
            s.qd[..3].copy_from_slice(x.qd.as_slice());
            let o = c.tick(Some(&s), s.stamp_ns);
            if let Some(out) = o.output.filter(|_| k >= 4470) {
                min = min.min(out.clearance);
            }
            let cmd = o.command.unwrap();
            // The simulated plant's HOLD: brake blind, q̈ = −20·q̇ (its default brake gain).
            let (qdd, qddd) = if cmd.mode() == Ok(Mode::Hold) {
                first_hold.get_or_insert(k);
                (-x.qd * 20.0, VecN::<3>::zeros())
            } else {
                (
                    VecN::<3>::from_column_slice(&cmd.qdd[..3]),
                    VecN::<3>::from_column_slice(&cmd.qddd[..3]),
                )
            };
            x = control::hold::integrate(&model, &x, &qdd, &qddd, 0.0, 1e-3, 1e-3, 4);
        }
        assert!(min >= clearance - 1e-3, "clearance {min} < {clearance}");
        let mut plant_clearance = f64::INFINITY;
        let mut kin = control::Kinematics::<3>::default();
        model.kinematics(0.0, &x.q, &x.qd, &mut kin);
        let obstacles = c.law().planar_params().unwrap().obstacles;
        plant_clearance = plant_clearance.min(control::secondary::clearance(&kin, &obstacles).0);
        assert!(
            plant_clearance >= clearance - 1e-3,
            "at rest {plant_clearance}"
        );
        let held = first_hold.expect("the plant's HOLD once at rest");
        assert!((4520..5600).contains(&held), "held from tick {held}");
        assert_eq!(c.mode(), Mode::Hold, "{:?}", c.fault());
        assert!(c.counters.blocked_holds > 0);
    }

    #[test]
    fn the_reference_moves_on_by_the_device_clock_when_there_is_one() {
        let mut c = controller();
        let mut s = state(1, 0);
        // No device clock: the controller's time (from the stamps) says how long it was.
        c.memory.last_run_t = Some(1.0);
        assert_eq!(c.periods_since_last_run(&s, 1.0031), 3);
        // A device clock overrules jittery stamps: 1 ms on it is one period.
        c.memory.last_run_device_ns = Some(5_000_000);
        s.device_time_ns = 6_000_000;
        assert_eq!(c.periods_since_last_run(&s, 1.0031), 1);
        s.device_time_ns = 9_000_000;
        assert_eq!(c.periods_since_last_run(&s, 1.0016), 4);
        // A clock behind the last one (a restarted device) falls back on the stamps.
        s.device_time_ns = 1_000_000;
        assert_eq!(c.periods_since_last_run(&s, 1.0031), 3);
        // The first command of a stream covers one period; a long gap is capped.
        c.memory.last_run_t = None;
        c.memory.last_run_device_ns = None;
        assert_eq!(c.periods_since_last_run(&s, 5.0), 1);
        c.memory.last_run_t = Some(1.0);
        assert_eq!(c.periods_since_last_run(&s, 5.0), MAX_GAP_PERIODS as u32);
    }

    #[test]
    fn rehearsals_change_no_command_bit() {
        // Two controllers on the same chaotic trajectory (safety filter on, feedback from 0.3 s
        // so the delay line is read); one rehearses before every tick, on the previous state and
        // on a state it never gets. Every command must be identical to the bit.
        let mut cfg = Config::preset("demo").unwrap();
        cfg.feedback.t_on = 0.3;
        let make = || {
            let settings = settings();
            Controller::<3>::new(cfg.tick_law::<3>(), 2.0, settings)
        };
        let (mut plain, mut rehearsed) = (make(), make());
        let mut sim = control::Simulation::new(
            cfg.model::<3>(),
            cfg.law_params(),
            1e-3,
            cfg.initial_state(),
            2.0,
        );
        let t0 = 1_000_000_000;
        let mut prev: Option<StateSample> = None;
        for k in 0..1500u64 {
            sim.step();
            let x = sim.state();
            let mut s = state(k, t0 + k * 1_000_000);
            s.q[..3].copy_from_slice(x.q.as_slice());
            s.qd[..3].copy_from_slice(x.qd.as_slice());
            if let Some(p) = &prev {
                rehearsed.rehearse(p);
                let mut odd = *p;
                odd.qd[0] += 3.0;
                rehearsed.rehearse(&odd);
            }
            let now = s.stamp_ns + 20_000;
            let (a, b) = (plain.tick(Some(&s), now), rehearsed.tick(Some(&s), now));
            let (a, b) = (a.command.unwrap(), b.command.unwrap());
            for j in 0..3 {
                assert_eq!(a.qdd[j].to_bits(), b.qdd[j].to_bits(), "tick {k}");
                assert_eq!(a.qddd[j].to_bits(), b.qddd[j].to_bits(), "tick {k}");
            }
            prev = Some(s);
        }
        assert_eq!(plain.counters.commands, 1500);
    }

    #[test]
    fn rehearsals_change_nothing_on_the_panda_in_any_interface() {
        // A rehearsal is a whole tick undone: every interface's stream (the limiter, the
        // reference, torque's last command), the counters and the saturations must come out of
        // it as they went in. The plant here is a perfect servo onto each command's reference.
        use control::command::CommandMode;
        // The gain adapts from the first tick (a rehearsal's adaptation must be undone too).
        let base = control::config::spatial::PANDA_PAPER
            .replace("mu = 1.0\nt_on = 60.0", "mu = \"auto\"\nt_on = 0.0");
        assert!(base.contains("mu = \"auto\""));
        for mode in ["acceleration", "position", "velocity", "torque"] {
            let text = format!("{base}\n[command]\nmode = \"{mode}\"\n");
            let sys = System::parse(&text, &control::system::builtin_robot).unwrap();
            let settings = settings();
            let make = || {
                Controller::<7>::new(sys.tick_law::<7>(), 2.0, settings)
                    .with_generator(sys.generator::<7>(1e-3).unwrap())
            };
            let (mut plain, mut rehearsed) = (make(), make());
            let x0 = sys.initial_state::<7>();
            let mut s = StateSample {
                plant_id: 77,
                n: 7,
                stamp_ns: 1_000_000_000,
                ..StateSample::default()
            };
            s.q[..7].copy_from_slice(x0.q.as_slice());
            s.qd[..7].copy_from_slice(x0.qd.as_slice());
            for k in 0..600u64 {
                s.seq = k;
                s.stamp_ns = 1_000_000_000 + k * 1_000_000;
                rehearsed.rehearse(&s);
                let mut odd = s;
                odd.qd[3] += 2.0;
                rehearsed.rehearse(&odd);
                let now = s.stamp_ns + 20_000;
                let (a, b) = (plain.tick(Some(&s), now), rehearsed.tick(Some(&s), now));
                let (a, b) = (a.command.unwrap(), b.command.unwrap());
                let bits = |c: &CommandSample| {
                    [c.q, c.qd, c.qdd, c.qddd, c.tau].map(|v| v.map(f64::to_bits))
                };
                assert_eq!(bits(&a), bits(&b), "{mode}, tick {k}");
                assert_eq!(plain.counters, rehearsed.counters, "{mode}, tick {k}");
                // The next state: where the command's reference (or its acceleration) puts the arm.
                match sys.command_mode() {
                    CommandMode::Acceleration | CommandMode::Torque => {
                        for j in 0..7 {
                            s.q[j] += s.qd[j] * 1e-3;
                            s.qd[j] += a.qdd[j] * 1e-3;
                        }
                    }
                    CommandMode::Position | CommandMode::Velocity => {
                        s.q[..7].copy_from_slice(&a.q[..7]);
                        s.qd[..7].copy_from_slice(&a.qd[..7]);
                    }
                }
            }
            assert_eq!(plain.memory.mode, Mode::Run, "{mode}");
            assert_eq!(
                plain.generator.saturations, rehearsed.generator.saturations,
                "{mode}"
            );
            assert_eq!(plain.law.gain(), rehearsed.law.gain(), "{mode}");
        }
    }

    #[test]
    fn commands_answer_states_and_hold_then_resume() {
        let mut c = controller();
        let now = 1_000_000_000;
        let o = c.tick(Some(&state(0, now)), now);
        let cmd = o.command.unwrap();
        assert_eq!(
            (cmd.state_seq, cmd.mode, cmd.daemon_id),
            (0, Mode::Run as u32, 9)
        );
        assert!(cmd.validate(3).is_ok());
        // Five ticks with nothing fresh: HOLD.
        let mut modes = vec![];
        for k in 1..=5 {
            modes.push(c.tick(None, now + k * 1_000_000).mode);
        }
        assert_eq!(
            modes,
            [Mode::Run, Mode::Run, Mode::Run, Mode::Run, Mode::Hold]
        );
        assert_eq!(c.counters.holds_entered, 1);
        let t = now + 7_000_000;
        let o = c.tick(Some(&state(1, t)), t);
        assert_eq!(o.mode, Mode::Run);
        assert!(o.mode_changed);
        assert_eq!(o.command.unwrap().state_seq, 1);
        // Missed ticks in RUN publish nothing; the one HOLD tick published command 1.
        assert_eq!(o.command.unwrap().seq, 2);
    }

    #[test]
    fn bad_states_never_reach_the_law() {
        let mut c = controller();
        let now = 5_000_000_000;
        c.tick(Some(&state(10, now - 8_000_000)), now - 8_000_000);
        let mut nan = state(11, now);
        nan.qd[2] = f64::NAN;
        let o = c.tick(Some(&nan), now);
        assert!(matches!(o.rejection, Some(Rejection::Invalid(_))));
        assert!(o.output.is_none() && o.command.is_none());
        let o = c.tick(Some(&state(10, now)), now);
        assert!(matches!(
            o.rejection,
            Some(Rejection::OutOfOrder { seq: 10, last: 10 })
        ));
        let o = c.tick(Some(&state(12, now - 6_000_000)), now);
        assert!(matches!(o.rejection, Some(Rejection::Stale { .. })));
        let mut wrong_n = state(13, now);
        wrong_n.n = 4;
        assert!(matches!(
            c.tick(Some(&wrong_n), now).rejection,
            Some(Rejection::Invalid(_))
        ));
        assert_eq!(c.counters.rejected_invalid, 2);
        assert_eq!(c.counters.rejected_out_of_order, 1);
        assert_eq!(c.counters.rejected_stale, 1);
        // A restarted plant (new id) starts its sequence again and is accepted.
        let mut s = state(0, now);
        s.plant_id = 78;
        let o = c.tick(Some(&s), now);
        assert!(o.plant_restarted && o.command.is_some());
    }

    fn controller_time(c: &Controller<3>) -> f64 {
        c.time()
    }

    #[test]
    fn future_stamps_are_refused_and_do_not_move_time() {
        let mut c = controller();
        let now = 1_000_000_000;
        c.tick(Some(&state(0, now)), now);
        for stamp in [u64::MAX, now + 2_500_000] {
            let o = c.tick(Some(&state(1, stamp)), now + 1_000_000);
            assert!(
                matches!(o.rejection, Some(Rejection::FutureStamp { .. })),
                "{stamp}"
            );
        }
        assert_eq!(c.counters.rejected_future, 2);
        assert_eq!(controller_time(&c), 0.0);
        // Within one period ahead is a simulator's nominal stamp: accepted.
        assert!(c
            .tick(Some(&state(1, now + 1_500_000)), now + 1_000_000)
            .rejection
            .is_none());
    }

    #[test]
    fn a_restart_is_seen_even_when_the_new_plants_first_sample_is_stale() {
        let mut c = controller();
        let now = 1_000_000_000;
        c.tick(Some(&state(50, now)), now);
        let mut first = state(0, now);
        first.plant_id = 99;
        let o = c.tick(Some(&first), now + 20_000_000); // 20 ms old: stale
        assert!(matches!(o.rejection, Some(Rejection::Stale { .. })));
        let mut second = state(1, now + 21_000_000);
        second.plant_id = 99;
        let o = c.tick(Some(&second), now + 21_000_000);
        assert!(o.plant_restarted && o.command.is_some());
        assert_eq!(c.counters.plant_restarts, 1);
    }

    #[test]
    fn history_restarts_after_a_hold_and_long_gaps_are_not_filled_with_old_rates() {
        let mut c = controller();
        let mut p = *c.law().planar_params().unwrap();
        p.core.mu = 1.0;
        p.core.t_on = 0.0;
        c.set_params(ParamBlock::Planar(p));
        let t0 = 1_000_000_000u64;
        let mut s = state(0, t0);
        s.qd[0] = 10.0;
        for k in 0..100u64 {
            s.seq = k;
            s.stamp_ns = t0 + k * 1_000_000;
            c.tick(Some(&s), s.stamp_ns);
        }
        // Silence long enough for HOLD, then the plant is back at rest.
        for k in 100..140u64 {
            c.tick(None, t0 + k * 1_000_000);
        }
        assert_eq!(c.mode(), Mode::Hold);
        let mut rest = state(140, t0 + 140_000_000);
        rest.qd = [0.0; protocol::MAX_JOINTS];
        let o = c.tick(Some(&rest), rest.stamp_ns);
        // The delay line restarted at the resting state: the Pyragas residual is zero, not
        // |0 − 10| from the rates before the hold.
        assert_eq!(o.output.unwrap().period_residual, 0.0);
    }

    #[test]
    fn an_arm_that_begins_to_brake_under_a_running_stream_is_counted_once_per_brake() {
        let mut c = controller();
        let t0 = 1_000_000_000u64;
        let mut s = state(0, t0);
        // The arm stands on its brakes until the first answer: that is no brake.
        s.flags |= protocol::flags::BRAKING;
        for k in 0..300u64 {
            if k == 3 || k == 200 {
                s.flags &= !protocol::flags::BRAKING;
            }
            if k == 100 || k == 250 {
                s.flags |= protocol::flags::BRAKING; // braked for 100 and for 50 states
            }
            s.seq = k;
            s.stamp_ns = t0 + k * 1_000_000;
            c.tick(Some(&s), s.stamp_ns);
        }
        assert_eq!(c.counters.arm_brakes, 2);
    }

    #[test]
    fn catching_up_after_a_plant_side_brake_or_a_gap_is_a_reentry_not_a_runaway() {
        // The same excessive demand (a tiny qdd_max set at 0.7 s): on a plant that keeps
        // following, FAULT after guard_time; on states saying the plant braked on its command
        // timeout (this daemon was stalled), or after four states went missing (a stall too
        // short for a brake or a hold), only once the re-entry window has passed.
        #[derive(Clone, Copy, PartialEq)]
        enum Before {
            Answered,
            Braked,
            Missing(u64),
            /// Four states missing at 0.1 s already: the second gap within 5 s is no re-entry.
            MissingAgain,
        }
        let run = |before: Before| {
            let mut c = controller();
            let t0 = 1_000_000_000u64;
            let mut s = state(0, t0);
            let mut first_fault = None;
            for k in 0..1500u64 {
                if k == 700 {
                    let mut p = *c.law().planar_params().unwrap();
                    p.core.safety.qdd_max = [1e-6; control::MAX_JOINTS];
                    c.set_params(ParamBlock::Planar(p));
                    if before == Before::Braked {
                        s.flags |= protocol::flags::COMMAND_TIMEOUT;
                    }
                }
                if k == 702 {
                    s.flags &= !protocol::flags::COMMAND_TIMEOUT; // commands reach it again
                }
                s.seq = k;
                s.stamp_ns = t0 + k * 1_000_000;
                let missing = match before {
                    Before::Missing(m) => (700..700 + m).contains(&k),
                    Before::MissingAgain => (100..104).contains(&k) || (700..704).contains(&k),
                    _ => false,
                };
                if missing {
                    c.tick(None, s.stamp_ns);
                    continue;
                }
                if c.tick(Some(&s), s.stamp_ns).fault.is_some() {
                    first_fault = Some(k);
                    break;
                }
            }
            first_fault
        };
        let plain = run(Before::Answered).expect("the demand must trip the guard");
        assert!((700..=722).contains(&plain), "{plain}");
        let window = (crate::guard::REENTRY_S * 1e3) as u64;
        let braked = run(Before::Braked).expect("the window must end");
        assert!((700 + window..=722 + window).contains(&braked), "{braked}");
        let gap = run(Before::Missing(4)).expect("the window must end");
        assert!((704 + window..=726 + window).contains(&gap), "{gap}");
        // One state lost is no re-entry, nor is a second gap soon after a first.
        let lost = run(Before::Missing(1)).expect("the demand must trip the guard");
        assert!((701..=723).contains(&lost), "{lost}");
        let again = run(Before::MissingAgain).expect("the demand must trip the guard");
        assert!((704..=726).contains(&again), "{again}");
    }

    #[test]
    fn a_runaway_ends_in_a_braked_fault_that_only_resume_leaves() {
        let mut c = controller();
        let t0 = 1_000_000_000u64;
        let mut s = state(0, t0);
        s.qd[1] = 60.0;
        let mut p = *c.law().planar_params().unwrap();
        p.core.safety.qd_max = [20.0; control::MAX_JOINTS];
        c.set_params(ParamBlock::Planar(p));
        let mut tripped_at = None;
        for k in 0..100u64 {
            s.seq = k;
            s.stamp_ns = t0 + k * 1_000_000;
            let o = c.tick(Some(&s), s.stamp_ns);
            if let Some(f) = o.fault {
                tripped_at = Some(k);
                assert!(f.to_string().contains("joint 2 rate 60.00"), "{f}");
            }
            if o.mode == Mode::Fault {
                assert_eq!(o.command.unwrap().mode, Mode::Fault as u32);
            }
            if o.mode == Mode::Fault && o.fault.is_none() {
                assert!(o.output.is_none(), "the law must not run in FAULT");
            }
        }
        assert_eq!(tripped_at, Some(20), "20 ms of excess at 1 kHz");
        assert_eq!((c.mode(), c.counters.faults), (Mode::Fault, 1));
        // Silence does not turn FAULT into HOLD, and the plant keeps being told to brake.
        for k in 100..140u64 {
            let o = c.tick(None, t0 + k * 1_000_000);
            assert_eq!(
                (o.mode, o.command.unwrap().mode),
                (Mode::Fault, Mode::Fault as u32)
            );
        }
        // Resume: HOLD, then RUN on the next fresh (now slow) state.
        assert!(c.resume());
        assert!(!c.resume());
        assert_eq!(c.mode(), Mode::Hold);
        s.qd[1] = 1.0;
        s.seq = 200;
        s.stamp_ns = t0 + 140_000_000;
        let o = c.tick(Some(&s), s.stamp_ns);
        assert_eq!(
            (o.mode, o.command.unwrap().mode),
            (Mode::Run, Mode::Run as u32)
        );
        assert_eq!(c.counters.resumes, 1);
    }

    #[test]
    fn only_the_plant_the_handshake_agreed_to_is_controlled() {
        let mut c = controller();
        c.require_handshake();
        let now = 1_000_000_000;
        // No verdict yet: ignored, no command (not even HOLD), not a rejection.
        let o = c.tick(Some(&state(0, now)), now);
        assert_eq!((o.rejection, o.command), (Some(Rejection::NotAgreed), None));
        // A refused plant stays ignored.
        c.set_plant_verdict(77, false);
        for k in 1..20 {
            let t = now + k * 1_000_000;
            let o = c.tick(Some(&state(k, t)), t);
            assert!(o.command.is_none() && o.output.is_none());
        }
        assert_eq!((c.counters.not_agreed, c.counters.rejected()), (20, 0));
        assert_eq!(c.mode(), Mode::Hold);
        // Agreed: runs.
        c.set_plant_verdict(77, true);
        let t = now + 20_000_000;
        let o = c.tick(Some(&state(20, t)), t);
        assert_eq!(o.command.unwrap().mode, Mode::Run as u32);
        // Another plant start (new id) is not covered by that verdict.
        let mut other = state(0, t + 1_000_000);
        other.plant_id = 78;
        let o = c.tick(Some(&other), t + 1_000_000);
        assert_eq!(o.rejection, Some(Rejection::NotAgreed));
    }

    #[test]
    fn a_short_gap_is_interpolated() {
        let mut c = controller();
        let t0 = 1_000_000_000u64;
        let mut s = state(0, t0);
        c.tick(Some(&s), t0);
        // Three periods later, q̇ has moved from 0 to 3: the missed samples become 1 and 2.
        s.seq = 1;
        s.stamp_ns = t0 + 3_000_000;
        s.qd[0] = 3.0;
        c.tick(Some(&s), s.stamp_ns);
        let d = |steps_back: f64| {
            c.delay
                .sample(3.0 - steps_back - c.memory.delay_origin as f64)[0]
        };
        assert_eq!((d(0.0), d(1.0), d(2.0), d(3.0)), (3.0, 2.0, 1.0, 0.0));
    }
}
