//! chaosd-fakebot's device: it owns the clock, integrates the arm, and speaks the UDP protocol
//! of [`super`] the way a strict robot controller does (FCI, RSI): a state every cycle, the
//! answer due before the next one, misses counted, a brake after `max_missed` in a row.
//!
//! It can also misbehave on purpose, so the bridge and the daemon can be tested against a
//! device that loses packets (`loss`), stalls (`spike_every_s` / `spike_ms`) or restarts
//! (`restart_every_s`). One cycle: wait for the deadline → (injected stall or restart) → apply
//! the answer to the last state, or count a miss → integrate one cycle → send the new state →
//! wait (until the next deadline) for its answer, timing the round trip. While answers come, it
//! polls for them without blocking ([`super::wait`]); after a miss it blocks in `ppoll`.
//!
//! Where it runs matters on a small machine. A real device is other hardware with a clock of its
//! own; an emulator shares the cores with the bridge and the daemon, and two loops at
//! SCHED_FIFO that poll for their inputs can keep it from running at all until one of them gives
//! up. So it can be placed like the device it stands in for ([`Placement`]): pinned to the
//! bridge's core at a SCHED_FIFO priority above it, where the clock preempts the bridge on time,
//! and sleeping until its cycle and blocking for the answer ([`AnswerWait::Block`]), so the
//! bridge gets the core whenever the device is not working; the bridge's send then wakes it on
//! its own core, without waking an idle vCPU. docs/performance.md, "The device beside the bridge", has the
//! numbers.

use super::rules::Rules;
use super::wait::{poll_datagram, Window};
use super::wire::{
    DeviceCommand, DeviceMode, DeviceState, COMMAND_LEN, DEVICE_BRAKING, DEVICE_HOLDING,
    DEVICE_STOPPED, STATE_LEN,
};
use crate::seam::{Actuation, Plant};
use crate::sim::SimPlant;
use anyhow::{Context, Result};
use control::command::JointLimits;
use hdrhistogram::Histogram;
use protocol::{interface, monotonic_ns, DeviceStatus, StateSample, MAX_JOINTS};
use rt::clock::Schedule;
use rt::WaitStrategy;
use serde::Serialize;
use std::net::{SocketAddr, UdpSocket};
use std::os::fd::AsRawFd;

/// How the device runs and misbehaves.
#[derive(Clone, Debug)]
pub struct FakebotConfig {
    pub listen: SocketAddr,
    /// Where the states go (the bridge).
    pub peer: SocketAddr,
    pub rate_hz: f64,
    pub max_missed: u32,
    /// Missed answers in a row after which the device stops with a lost-packets reflex error
    /// (latched until a HOLD) instead of braking until answers come again.
    pub stop_after_missed: Option<u32>,
    /// Probability of dropping each packet, in either direction.
    pub loss: f64,
    /// Every `spike_every_s` seconds, delay the answers in transit by `spike_ms`: the device keeps
    /// its clock and sends its states, but sees no answer until the spike is over.
    pub spike_every_s: Option<f64>,
    pub spike_ms: f64,
    /// Restart (new session, initial state, after `restart_pause_ms`) every this many seconds.
    pub restart_every_s: Option<f64>,
    pub restart_pause_ms: f64,
    pub seed: u64,
    /// How it waits for its next cycle.
    pub wait: WaitStrategy,
    pub spin_us: f64,
    pub answer_wait: AnswerWait,
    pub placement: Placement,
    /// The command interfaces it takes (`wire::takes` flag bits).
    pub takes: u32,
    /// Check every command against the arm's limits, as a robot does ([`super::rules`]); off,
    /// it follows whatever it is sent.
    pub enforce: bool,
}

/// How the device waits for the answer to the state it just sent (`--answer-wait poll|block`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum AnswerWait {
    /// Poll without blocking while answers keep coming (a hybrid window that stays open until
    /// the deadline); block after a miss. The fastest when the device has a core to itself.
    Poll,
    /// Block in `ppoll` until the answer or the deadline. Required when the device shares a core
    /// with the bridge at a higher priority: polling there would keep the bridge off the core.
    Block,
}

/// Where the device's thread runs: a core to pin it to, and a SCHED_FIFO priority (0 = the normal
/// scheduler). What the kernel refuses is reported as a warning, and the device runs anyway.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Placement {
    pub core: Option<usize>,
    pub priority: u8,
}

impl Placement {
    /// On a loop's core, 10 SCHED_FIFO steps above its priority, so the device's clock preempts
    /// it; a loop on the normal scheduler (0) gets a device on it too. The cap is 99: a loop at
    /// 90-98 gets a device fewer steps above it, and a loop at 99 one at its own priority, which
    /// does not preempt it (the device then starts its cycle when the loop next blocks).
    ///
    /// ```
    /// use plant::udp::fakebot::Placement;
    /// assert_eq!(Placement::beside(Some(0), 50), Placement { core: Some(0), priority: 60 });
    /// assert_eq!(Placement::beside(None, 95).priority, 99);
    /// assert_eq!(Placement::beside(Some(1), 0).priority, 0);
    /// ```
    pub fn beside(core: Option<usize>, priority: u8) -> Placement {
        Placement {
            core,
            priority: if priority == 0 {
                0
            } else {
                priority.saturating_add(10).min(99)
            },
        }
    }
}

/// What the device counted.
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq, Eq)]
pub struct FakebotCounters {
    pub cycles: u64,
    /// Cycles the device's own lateness skipped (its thread ran a whole period late): no
    /// state went out for them. A real device's clock skips none; here the host's stalls do.
    pub skipped: u64,
    pub states_sent: u64,
    pub answered_in_time: u64,
    /// Cycles whose state got no answer in time.
    pub missed: u64,
    /// Answers to an older state (dropped).
    pub late_answers: u64,
    /// Answers to a previous device start (dropped).
    pub stale_session: u64,
    pub malformed: u64,
    pub states_lost: u64,
    pub commands_lost: u64,
    pub send_errors: u64,
    /// Times `max_missed` misses in a row made the device brake.
    pub brakes: u64,
    pub spikes: u64,
    pub restarts: u64,
    /// Reflex stops: a command broke one of the arm's rules (or used an interface it does not
    /// take), and the device stopped until told to hold.
    pub reflex_stops: u64,
}

/// What the device measured: its counters, and state sent → answer received (the round trip
/// through the bridge and the daemon, as the device sees it).
#[derive(Clone, Debug, Serialize)]
pub struct FakebotSummary {
    pub counters: FakebotCounters,
    pub round_trip: rt::hist::Percentiles,
    /// The first reflex stop: device time (s), joint (1-based, 0: none) and reason.
    pub first_reflex: Option<String>,
    /// When the first and the last brake on missed answers came (s since the device started):
    /// a brake knocks the arm off its path and its cycle, and a run judges what follows it.
    pub first_brake_s: Option<f64>,
    pub last_brake_s: Option<f64>,
}

/// xorshift64*: the loss injector's random numbers (deterministic per seed, no allocation).
struct Rng(u64);

impl Rng {
    fn chance(&mut self, p: f64) -> bool {
        if p <= 0.0 {
            return false;
        }
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11;
        (x as f64) < p * (1u64 << 53) as f64
    }
}

/// The device's run state (reset by a restart).
struct Session {
    id: u64,
    seq: u64,
    /// The device's clock in cycles since the start, counting the cycles its own overruns
    /// skipped (`seq` counts states sent); the state carries it as the device time.
    cycle: u64,
    /// The cycle of the last state sent: the one an answer now answers.
    sent_cycle: u64,
    /// An answer has arrived since the start: from then on the arm moves and misses count.
    started: bool,
    missed_run: u32,
    missed_total: u32,
    braking: bool,
    holding: bool,
    started_ns: u64,
    /// A reflex stop in force: the status and the joint (1-based).
    stopped: Option<(DeviceStatus, u16)>,
}

impl Session {
    fn new() -> Self {
        Self {
            id: protocol::new_instance_id(),
            seq: 0,
            cycle: 0,
            sent_cycle: 0,
            started: false,
            missed_run: 0,
            missed_total: 0,
            braking: false,
            holding: false,
            started_ns: monotonic_ns(),
            stopped: None,
        }
    }
}

/// Runs the device until SIGINT/SIGTERM or `duration`; `make` builds the arm (again on restart).
pub fn run<const N: usize>(
    cfg: &FakebotConfig,
    make: impl Fn() -> SimPlant<N>,
    limits: JointLimits<N>,
    duration: Option<f64>,
) -> Result<FakebotSummary> {
    let socket = UdpSocket::bind(cfg.listen)
        .with_context(|| format!("cannot bind the device socket to {}", cfg.listen))?;
    socket
        .set_nonblocking(true)
        .context("cannot make the device socket non-blocking")?;
    rt::signal::install();
    place(cfg.placement);
    let mut dev = Device {
        cfg,
        socket,
        sim: make(),
        s: Session::new(),
        c: FakebotCounters::default(),
        rng: Rng(cfg.seed | 1),
        sample: StateSample::default(),
        pending: None,
        sent_at: 0,
        rtt: rt::hist::new_ns(),
        spike_until: 0,
        rules: Rules::new(limits, 1.0 / cfg.rate_hz),
        first_reflex: None,
        brakes_at: None,
    };
    dev.sim.activate()?;
    let period = (1e9 / cfg.rate_hz).round() as u64;
    let spin = (cfg.spin_us * 1e3) as u64;
    let start = monotonic_ns();
    let end = duration.map(|d| start + (d * 1e9) as u64);
    let every = |s: Option<f64>| s.map(|s| (s * 1e9) as u64);
    let (mut next_spike, mut next_restart) = (
        every(cfg.spike_every_s).map(|e| start + e),
        every(cfg.restart_every_s).map(|e| start + e),
    );
    let mut sched = Schedule::new(period, start);
    let mut behind = 0;
    while !rt::signal::stop_requested() {
        let deadline = sched.deadline();
        if end.is_some_and(|e| deadline >= e) {
            break;
        }
        rt::wait_until(deadline, cfg.wait, spin);
        if next_restart.is_some_and(|t| deadline >= t) {
            next_restart = every(cfg.restart_every_s).map(|e| deadline + e);
            dev.restart(&make);
            sched = Schedule::new(period, monotonic_ns());
            continue;
        }
        if next_spike.is_some_and(|t| deadline >= t) {
            next_spike = every(cfg.spike_every_s).map(|e| deadline + e);
            dev.c.spikes += 1;
            dev.spike_until = deadline + (cfg.spike_ms * 1e6) as u64;
        }
        dev.cycle(period, behind);
        dev.await_answer(deadline + period);
        // The wait for an answer runs up to the next cycle's start, so a silent controller
        // leaves the device there, due but not late: only a whole period past it is a skipped
        // cycle. (Counted from the wait's end, every miss skipped the next cycle, and a 40 ms
        // silence made 20 misses, not 40: the brake after 20 came or not by chance.)
        behind = sched.advance(monotonic_ns().saturating_sub(period));
        dev.c.skipped += behind;
    }
    dev.sim.deactivate();
    Ok(FakebotSummary {
        counters: dev.c,
        round_trip: rt::hist::Percentiles::of(&dev.rtt),
        first_reflex: dev.first_reflex,
        first_brake_s: dev.brakes_at.map(|(first, _)| first),
        last_brake_s: dev.brakes_at.map(|(_, last)| last),
    })
}

/// Pins and prioritises the calling thread as asked; says on stderr what the kernel refused.
fn place(p: Placement) {
    if p == Placement::default() {
        return;
    }
    let got = rt::setup::apply(rt::setup::RtRequest {
        core: p.core,
        priority: p.priority,
        lock_memory: p.priority > 0,
    });
    for w in &got.warnings {
        eprintln!("chaosd-fakebot: warning: {w}");
    }
    eprintln!("chaosd-fakebot: {}", got.one_line());
}

struct Device<'a, const N: usize> {
    cfg: &'a FakebotConfig,
    socket: UdpSocket,
    sim: SimPlant<N>,
    s: Session,
    c: FakebotCounters,
    rng: Rng,
    sample: StateSample,
    /// The answer to the last state, received while waiting for it.
    pending: Option<DeviceCommand>,
    sent_at: u64,
    rtt: Histogram<u64>,
    /// A delay spike: until then, answers sit in the socket (delayed in transit).
    spike_until: u64,
    /// The arm's rules, and the stream it is judging.
    rules: Rules<N>,
    first_reflex: Option<String>,
    /// (first, last) brake on missed answers, s since the device started.
    brakes_at: Option<(f64, f64)>,
}

impl<const N: usize> Device<'_, N> {
    fn restart(&mut self, make: &impl Fn() -> SimPlant<N>) {
        self.c.restarts += 1;
        rt::clock::sleep_until(monotonic_ns() + (self.cfg.restart_pause_ms * 1e6) as u64);
        self.sim = make();
        self.s = Session::new();
        self.rules.restart();
        self.pending = None;
        // Whatever arrived while "rebooting" answers the old session; take it and count it.
        let _ = self.answer();
    }

    fn cycle(&mut self, period: u64, behind: u64) {
        self.c.cycles += 1;
        self.s.cycle += behind;
        let delayed = monotonic_ns() < self.spike_until;
        if self.s.seq > 0 {
            let got = if delayed {
                None
            } else {
                self.pending.take().or_else(|| self.answer())
            };
            match got {
                Some(cmd) => self.apply(&cmd),
                None => self.miss(),
            }
        }
        let elapsed = if self.s.started {
            (1 + behind) as f64 * period as f64 * 1e-9
        } else {
            0.0
        };
        // The simulator only fails on a non-finite state; then the device stops moving.
        if self.sim.read(elapsed, &mut self.sample).is_err() {
            let _ = self.sim.write(Actuation::Brake);
        }
        self.send_state(period);
        self.s.seq += 1;
        self.s.cycle += 1;
    }

    /// After sending a state: waits for its answer until `until_ns`, and times it.
    fn await_answer(&mut self, until_ns: u64) {
        let fd = self.socket.as_raw_fd();
        if self.spike_until > monotonic_ns() {
            return; // the answer is delayed in transit: it will be found late
        }
        let window = match self.cfg.answer_wait {
            AnswerWait::Block => Window::around(WaitStrategy::Sleep, self.sent_at, 0),
            // While the bridge keeps answering, its answer is due within microseconds: poll for
            // it without blocking up to the deadline. After a miss (a stalled or dead bridge),
            // block.
            AnswerWait::Poll => {
                let spin = (self.cfg.spin_us * 1e3) as u64;
                let w = Window::around(self.cfg.wait, self.sent_at, spin);
                if self.s.started && self.s.missed_run == 0 {
                    w.open_until(until_ns)
                } else {
                    w
                }
            }
        };
        if self.pending.is_none() {
            self.pending = poll_datagram(fd, until_ns, window, || self.answer());
        }
        if self.pending.is_some() {
            let rtt = monotonic_ns().saturating_sub(self.sent_at);
            self.rtt.saturating_record(rtt.max(1));
        }
    }

    /// Takes every queued datagram; returns the command answering the last state, if any.
    fn answer(&mut self) -> Option<DeviceCommand> {
        let mut buf = [0u8; COMMAND_LEN + 1];
        let mut found = None;
        let want = self.s.seq.wrapping_sub(1);
        while let Ok((len, _)) = self.socket.recv_from(&mut buf) {
            if self.rng.chance(self.cfg.loss) {
                self.c.commands_lost += 1;
                continue;
            }
            match DeviceCommand::decode(&buf[..len]) {
                Err(_) => self.c.malformed += 1,
                Ok(c) if c.n as usize != N => self.c.malformed += 1,
                Ok(c) if c.session != self.s.id => self.c.stale_session += 1,
                // A second answer to the same state (a brake after a run) replaces the first.
                Ok(c) if c.seq == want && self.s.seq > 0 => found = Some(c),
                Ok(c) if c.seq < want => self.c.late_answers += 1,
                Ok(_) => self.c.malformed += 1, // a number never sent
            }
        }
        found
    }

    fn apply(&mut self, cmd: &DeviceCommand) {
        self.c.answered_in_time += 1;
        self.s.started = true;
        self.s.missed_run = 0;
        // Told to brake, the arm is braking until a new stream starts (the state says so).
        self.s.braking = cmd.mode == DeviceMode::Brake;
        self.s.holding = cmd.mode == DeviceMode::Hold;
        let a = match cmd.mode {
            DeviceMode::Run if self.s.stopped.is_some() => Actuation::Brake,
            DeviceMode::Run => match self.judge(cmd) {
                Ok(()) => actuation::<N>(cmd),
                Err((status, joint)) => {
                    self.stop(status, joint);
                    Actuation::Brake
                }
            },
            // A hold is the operator's recovery: it clears a reflex stop, and the next run is a
            // new stream that must continue the arm's measured motion.
            DeviceMode::Hold => {
                self.s.stopped = None;
                self.rules.restart();
                Actuation::Hold
            }
            DeviceMode::Brake => {
                self.rules.restart();
                Actuation::Brake
            }
        };
        let _ = self.sim.write(a);
    }

    /// A RUN command against the interfaces the device takes and the arm's rules.
    fn judge(&mut self, cmd: &DeviceCommand) -> Result<(), (DeviceStatus, usize)> {
        if self.cfg.takes >> (super::wire::TAKES_SHIFT + cmd.interface.min(31)) & 1 == 0 {
            return Err((DeviceStatus::InterfaceUnsupported, usize::MAX));
        }
        if !self.cfg.enforce {
            return Ok(());
        }
        let x = &self.sample;
        self.rules
            .check(cmd, &x.q[..N], &x.qd[..N], &x.tau[..N], self.s.sent_cycle)
    }

    /// A reflex stop: brake and say why until told to hold.
    fn stop(&mut self, status: DeviceStatus, joint: usize) {
        let joint = if joint == usize::MAX {
            0
        } else {
            joint as u16 + 1
        };
        self.s.stopped = Some((status, joint));
        self.c.reflex_stops += 1;
        self.rules.restart();
        let t = monotonic_ns().saturating_sub(self.s.started_ns) as f64 * 1e-9;
        self.first_reflex.get_or_insert_with(|| match joint {
            0 => format!("at {t:.3} s: {status}"),
            j => format!("at {t:.3} s: joint {j} {status}"),
        });
    }

    /// No answer in time: the previous command stays (the simulator ramps it on).
    fn miss(&mut self) {
        if !self.s.started {
            return;
        }
        self.c.missed += 1;
        self.s.missed_total = self.s.missed_total.saturating_add(1);
        self.s.missed_run = self.s.missed_run.saturating_add(1);
        if self
            .cfg
            .stop_after_missed
            .is_some_and(|n| self.s.missed_run >= n)
            && self.s.stopped.is_none()
        {
            self.stop(DeviceStatus::LostPackets, usize::MAX);
            let _ = self.sim.write(Actuation::Brake);
        }
        if self.s.missed_run >= self.cfg.max_missed && !self.s.braking {
            self.s.braking = true;
            self.c.brakes += 1;
            let t = monotonic_ns().saturating_sub(self.s.started_ns) as f64 * 1e-9;
            self.brakes_at = Some((self.brakes_at.map_or(t, |(first, _)| first), t));
            // The stream is broken: when answers come again they start a new one.
            self.rules.restart();
            let _ = self.sim.write(Actuation::Brake);
        }
    }

    fn send_state(&mut self, period: u64) {
        let (status, joint) = self.s.stopped.map_or((0, 0), |(s, j)| (s as u16, j));
        let mut st = DeviceState {
            n: N as u16,
            seq: self.s.seq,
            session: self.s.id,
            time_ns: self.s.cycle * period,
            // Before its first answer the arm stands on its brakes, as a robot does.
            flags: if self.s.braking || !self.s.started {
                DEVICE_BRAKING
            } else {
                0
            } | if self.s.holding { DEVICE_HOLDING } else { 0 }
                | if status != 0 { DEVICE_STOPPED } else { 0 }
                | self.cfg.takes,
            missed_run: self.s.missed_run,
            missed_total: self.s.missed_total,
            status,
            joint,
            q: [0.0; MAX_JOINTS],
            qd: [0.0; MAX_JOINTS],
            tau: [0.0; MAX_JOINTS],
        };
        st.q[..N].copy_from_slice(&self.sample.q[..N]);
        st.qd[..N].copy_from_slice(&self.sample.qd[..N]);
        st.tau[..N].copy_from_slice(&self.sample.tau[..N]);
        self.s.sent_cycle = self.s.cycle;
        if self.rng.chance(self.cfg.loss) {
            self.c.states_lost += 1;
            return;
        }
        let mut buf = [0u8; STATE_LEN];
        st.encode(&mut buf);
        self.sent_at = monotonic_ns();
        match self.socket.send_to(&buf, self.cfg.peer) {
            Ok(_) => self.c.states_sent += 1,
            Err(_) => self.c.send_errors += 1,
        }
    }
}

/// What a RUN command asks the arm to do, in its interface.
fn actuation<const N: usize>(c: &DeviceCommand) -> Actuation<'_> {
    let answers = c.seq;
    match c.interface {
        interface::POSITION => Actuation::Position {
            q: &c.q[..N],
            qd: &c.qd[..N],
            since: 0.0,
            answers,
        },
        interface::VELOCITY => Actuation::Velocity {
            qd: &c.qd[..N],
            since: 0.0,
            answers,
        },
        interface::TORQUE => Actuation::Torque {
            tau: &c.tau[..N],
            since: 0.0,
            answers,
        },
        _ => Actuation::Accelerate {
            qdd: &c.qdd[..N],
            qddd: &c.qddd[..N],
            since: 0.0,
            answers,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loss_injection_hits_its_rate() {
        let mut r = Rng(12345);
        let hits = (0..100_000).filter(|_| r.chance(0.01)).count();
        assert!((800..1200).contains(&hits), "{hits}");
        assert!(!(0..1000).any(|_| r.chance(0.0)));
    }
}
