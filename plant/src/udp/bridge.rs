//! [`UdpBridge`]: the `Plant` that drives a device over the UDP protocol of [`super`].
//!
//! The device owns the clock, so the bridge is `device_clocked`: `read` blocks until the
//! device's next state (up to `timeout`), keeps the newest of any queued ones, and remembers
//! which device `seq` the loop's state number stands for; `write` sends the answer echoing that
//! `seq`. A device silent for `lost_after` is reported lost once (the loop publishes nothing
//! meanwhile, so the daemon's watchdog holds); a new `session` is a restarted device, reported
//! and followed. Malformed, foreign and out-of-order datagrams are counted and dropped.

use super::wait::{poll_datagram, Window};
use super::wire::{
    DeviceCommand, DeviceMode, DeviceState, COMMAND_LEN, DEVICE_BRAKING, DEVICE_HOLDING, STATE_LEN,
};
use crate::seam::{Actuation, Plant, PlantError};
use protocol::{flags, monotonic_ns, StateSample, MAX_JOINTS};
use rt::news::{Courier, Note, Poster};
use rt::WaitStrategy;
use serde::Serialize;
use std::net::{SocketAddr, UdpSocket};
use std::os::fd::AsRawFd;
use std::time::Duration;

/// Where the bridge listens and where the device is.
/// A command's values and the wire array they go to.
type Field<'a> = (&'a [f64], &'a mut [f64; MAX_JOINTS]);

#[derive(Clone, Copy, Debug)]
pub struct BridgeConfig {
    pub bind: SocketAddr,
    pub device: SocketAddr,
    /// How long one `read` waits for a state before the cycle counts as missed.
    pub timeout: Duration,
    /// Silence after which the device is reported lost.
    pub lost_after: Duration,
    /// The device's period: its next state is due one period after the last.
    pub period: Duration,
    /// How to wait for it: `Hybrid` polls without blocking within `spin` either side of the
    /// due time and blocks outside it (see [`super::wait`]), `Spin` always polls, `Sleep` blocks.
    pub wait: WaitStrategy,
    pub spin: Duration,
    /// The plant loop's core: the thread that logs the bridge's news stays off it.
    pub loop_core: Option<usize>,
    /// The command interface the daemon sends (`protocol::interface`); the device must take it.
    pub interface: u32,
}

/// The interfaces a device says it takes, for an error message (start-up only).
fn taken(s: &DeviceState) -> String {
    let names: Vec<&str> = (0..4)
        .filter(|&c| s.takes(c))
        .filter_map(protocol::interface::name)
        .collect();
    if names.is_empty() {
        "no command interface".into()
    } else {
        names.join(", ")
    }
}

/// What the bridge counted.
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq, Eq)]
pub struct BridgeCounters {
    pub states: u64,
    pub commands_sent: u64,
    pub timeouts: u64,
    pub malformed: u64,
    pub out_of_order: u64,
    /// Queued states skipped for a newer one.
    pub superseded: u64,
    pub device_lost: u64,
    pub device_restarts: u64,
    pub send_errors: u64,
    /// Commands for a state no longer remembered (not sent).
    pub unknown_answers: u64,
}

/// Which device state a published state number came from.
#[derive(Clone, Copy, Debug, Default)]
struct Origin {
    loop_seq: u64,
    seq: u64,
    session: u64,
}

/// What the bridge has to say, posted from inside `read` and logged off the loop
/// ([`rt::news`]).
#[derive(Clone, Copy, Debug)]
enum DeviceNote {
    Lost { device: SocketAddr, silent_ms: u64 },
    Back,
    Restarted,
}

impl Note for DeviceNote {
    fn log(&self) {
        match *self {
            DeviceNote::Lost { device, silent_ms } => rt::warn_limited!(
                Duration::from_secs(10),
                "device lost: no state from {device} for {silent_ms} ms"
            ),
            DeviceNote::Back => tracing::info!("the device is back"),
            DeviceNote::Restarted => rt::warn_limited!(
                Duration::from_secs(10),
                "the device restarted (new session)"
            ),
        }
    }
}

pub struct UdpBridge {
    n: usize,
    cfg: BridgeConfig,
    socket: Option<UdpSocket>,
    last: Option<DeviceState>,
    last_rx_ns: u64,
    lost: bool,
    origins: [Origin; 64],
    pub counters: BridgeCounters,
    /// Running between `activate` and `deactivate`.
    courier: Option<Courier<DeviceNote>>,
    news: Option<Poster<DeviceNote>>,
}

fn unavailable(what: &'static str, e: Option<std::io::Error>) -> PlantError {
    PlantError::Unavailable {
        what,
        source: e.map(Into::into),
    }
}

impl UdpBridge {
    pub fn new(n: usize, cfg: BridgeConfig) -> Self {
        Self {
            n,
            cfg,
            socket: None,
            last: None,
            last_rx_ns: 0,
            lost: false,
            origins: [Origin {
                loop_seq: u64::MAX,
                ..Origin::default()
            }; 64],
            counters: BridgeCounters::default(),
            courier: None,
            news: None,
        }
    }

    /// Hands `note` to the courier (never logs here: this runs on the loop).
    fn say(&self, note: DeviceNote) {
        if let Some(p) = &self.news {
            p.post(note);
        }
    }

    /// Checks one datagram: a state of this arm, newer than the last of its session.
    fn admit(&mut self, bytes: &[u8]) -> Option<DeviceState> {
        let s = match DeviceState::decode(bytes) {
            Ok(s) if s.n as usize == self.n => s,
            _ => {
                self.counters.malformed += 1;
                return None;
            }
        };
        match self.last {
            Some(l) if l.session == s.session && s.seq <= l.seq => {
                self.counters.out_of_order += 1;
                None
            }
            Some(l) if l.session != s.session => {
                self.counters.device_restarts += 1;
                self.say(DeviceNote::Restarted);
                Some(s)
            }
            _ => Some(s),
        }
    }

    /// Any more states already queued: keep the newest (one `recv` per datagram, no waiting).
    fn drain(&mut self, sock_fd: i32, newest: &mut DeviceState) {
        let mut buf = [0u8; STATE_LEN + 1];
        loop {
            // SAFETY: `buf` is valid for `buf.len()` writable bytes; MSG_DONTWAIT never blocks.
            let got = unsafe {
                libc::recv(
                    sock_fd,
                    buf.as_mut_ptr().cast(),
                    buf.len(),
                    libc::MSG_DONTWAIT,
                )
            };
            if got < 0 {
                return;
            }
            if let Some(s) = self.admit(&buf[..got as usize]) {
                self.counters.superseded += 1;
                self.last = Some(s);
                *newest = s;
            }
        }
    }

    /// One datagram if one is queued (never blocks): the state, if admissible.
    fn try_take(&mut self, fd: i32) -> Option<Result<DeviceState, std::io::Error>> {
        let mut buf = [0u8; STATE_LEN + 1];
        // SAFETY: `buf` is valid for `buf.len()` writable bytes; MSG_DONTWAIT never blocks.
        let got = unsafe { libc::recv(fd, buf.as_mut_ptr().cast(), buf.len(), libc::MSG_DONTWAIT) };
        if got < 0 {
            let e = std::io::Error::last_os_error();
            return match e.kind() {
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::Interrupted => None,
                _ => Some(Err(e)),
            };
        }
        self.admit(&buf[..got as usize]).map(Ok)
    }

    /// Waits up to `timeout` for the next admissible state, polling without blocking around the
    /// time it is due (one period after the last; at once when there is no last).
    fn next_state(&mut self) -> Result<DeviceState, PlantError> {
        let Some(sock) = self.socket.take() else {
            return Err(PlantError::Fault {
                what: "the bridge was not activated",
                source: None,
            });
        };
        let fd = sock.as_raw_fd();
        let now = monotonic_ns();
        let until = now + self.cfg.timeout.as_nanos() as u64;
        let expected = match self.last {
            Some(_) if !self.lost => self.last_rx_ns + self.cfg.period.as_nanos() as u64,
            _ => now,
        };
        let window = Window::around(self.cfg.wait, expected, self.cfg.spin.as_nanos() as u64);
        let result = match poll_datagram(fd, until, window, || self.try_take(fd)) {
            Some(Ok(mut s)) => {
                self.last = Some(s);
                self.drain(fd, &mut s);
                Ok(s)
            }
            Some(Err(e)) => Err(e),
            None => Err(std::io::ErrorKind::TimedOut.into()),
        };
        self.socket = Some(sock);
        result.map_err(|e| self.silence(e))
    }

    /// No state this cycle: counted, and reported once when it has lasted `lost_after`.
    fn silence(&mut self, e: std::io::Error) -> PlantError {
        self.counters.timeouts += 1;
        let silent = monotonic_ns().saturating_sub(self.last_rx_ns);
        if !self.lost && silent >= self.cfg.lost_after.as_nanos() as u64 {
            self.lost = true;
            self.counters.device_lost += 1;
            self.say(DeviceNote::Lost {
                device: self.cfg.device,
                silent_ms: silent / 1_000_000,
            });
        }
        // A timeout is the common case (every missed cycle): no boxed source, which would
        // allocate on the loop. A real socket error is rare and keeps its source.
        if e.kind() == std::io::ErrorKind::TimedOut {
            unavailable("no state from the device within the timeout", None)
        } else {
            unavailable("no state from the device this cycle", Some(e))
        }
    }

    fn send(&mut self, cmd: &DeviceCommand) -> Result<(), PlantError> {
        let mut buf = [0u8; COMMAND_LEN];
        cmd.encode(&mut buf);
        let Some(sock) = &self.socket else {
            return Err(unavailable("the bridge was not activated", None));
        };
        match sock.send_to(&buf, self.cfg.device) {
            Ok(_) => {
                self.counters.commands_sent += 1;
                Ok(())
            }
            Err(e) => {
                self.counters.send_errors += 1;
                Err(unavailable("command not sent to the device", Some(e)))
            }
        }
    }
}

impl Plant for UdpBridge {
    fn n(&self) -> usize {
        self.n
    }

    fn flags(&self) -> u32 {
        match self.last {
            Some(s) if s.status != 0 => flags::FAULT | flags::BRAKING,
            // Holding or braking, the device follows no stream (as the simulator, it says
            // BRAKING): the daemon's next answer must start one from where the arm is.
            Some(s) if s.flags & (DEVICE_BRAKING | DEVICE_HOLDING) != 0 => flags::BRAKING,
            _ => 0,
        }
    }

    fn activate(&mut self) -> Result<(), PlantError> {
        let act = |what, e: std::io::Error| PlantError::Activation {
            what,
            source: e.into(),
        };
        let sock =
            UdpSocket::bind(self.cfg.bind).map_err(|e| act("cannot bind the bridge socket", e))?;
        // Reads never block: waits happen in `poll_datagram`.
        sock.set_nonblocking(true)
            .map_err(|e| act("cannot make the bridge socket non-blocking", e))?;
        let courier = Courier::start("bridge-news", 64, self.cfg.loop_core)
            .map_err(|e| act("cannot start the bridge's news thread", e))?;
        self.news = Some(courier.poster());
        self.courier = Some(courier);
        self.socket = Some(sock);
        self.last_rx_ns = monotonic_ns();
        Ok(())
    }

    fn write(&mut self, a: Actuation<'_>) -> Result<(), PlantError> {
        let Some(last) = self.last else {
            return Ok(()); // no device state yet: nothing to answer
        };
        let mut cmd =
            DeviceCommand::still(self.n as u16, last.seq, last.session, DeviceMode::Brake);
        cmd.interface = self.cfg.interface;
        let (answers, fields): (u64, [Field<'_>; 2]) = match a {
            Actuation::Accelerate {
                qdd, qddd, answers, ..
            } => (answers, [(qdd, &mut cmd.qdd), (qddd, &mut cmd.qddd)]),
            Actuation::Position { q, qd, answers, .. } => {
                (answers, [(q, &mut cmd.q), (qd, &mut cmd.qd)])
            }
            Actuation::Velocity { qd, answers, .. } => {
                (answers, [(qd, &mut cmd.qd), (&[], &mut cmd.q)])
            }
            Actuation::Torque { tau, answers, .. } => {
                (answers, [(tau, &mut cmd.tau), (&[], &mut cmd.q)])
            }
            Actuation::Hold => {
                cmd.mode = DeviceMode::Hold;
                return self.send(&cmd);
            }
            Actuation::Brake => return self.send(&cmd),
        };
        let o = self.origins[(answers % 64) as usize];
        if o.loop_seq != answers
            || fields
                .iter()
                .any(|(v, _)| !v.is_empty() && v.len() != self.n)
        {
            self.counters.unknown_answers += 1;
            return Ok(());
        }
        for (v, out) in fields {
            out[..v.len()].copy_from_slice(v);
        }
        (cmd.seq, cmd.session, cmd.mode) = (o.seq, o.session, DeviceMode::Run);
        self.send(&cmd)
    }

    fn read(&mut self, _elapsed: f64, out: &mut StateSample) -> Result<(), PlantError> {
        let s = self.next_state()?;
        self.last_rx_ns = monotonic_ns();
        if self.lost {
            self.lost = false;
            self.say(DeviceNote::Back);
        }
        self.counters.states += 1;
        self.origins[(out.seq % 64) as usize] = Origin {
            loop_seq: out.seq,
            seq: s.seq,
            session: s.session,
        };
        if !s.takes(self.cfg.interface) {
            return Err(PlantError::Fault {
                what: "the device does not take the configured command interface",
                source: Some(
                    format!(
                        "command.mode = {:?}: the device at {} takes {}",
                        protocol::interface::name(self.cfg.interface).unwrap_or("?"),
                        self.cfg.device,
                        taken(&s)
                    )
                    .into(),
                ),
            });
        }
        out.n = self.n as u32;
        out.phi = 0.0;
        out.q = s.q;
        out.qd = s.qd;
        out.tau = s.tau;
        // A reflex stop is forwarded as it is: the daemon names the joint and the reason.
        out.device = u32::from(s.status);
        out.device_joint = u32::from(s.joint);
        out.device_time_ns = s.time_ns;
        Ok(())
    }

    fn deactivate(&mut self) {
        let _ = self.write(Actuation::Brake);
        self.news = None;
        self.courier = None; // logs what is left, then joins
    }

    fn device_clocked(&self) -> bool {
        true
    }
}
