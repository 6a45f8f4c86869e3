//! The bytes of the UDP device protocol (the layout is specified in [`super`]): encoding into
//! and decoding from fixed-size buffers, with every malformed input a [`WireError`], never a
//! panic. No allocation.

use protocol::MAX_JOINTS;

/// Protocol version carried in every packet. 4: arrays of 12 joints (a torso and a 7-joint
/// arm fit); 3 had 7, and brought the command interfaces (position, velocity, torque), the
/// device's status and measured torques; 2 had q̈ commands only.
pub const VERSION: u16 = 4;
/// `b"CDST"`: a state packet (device → bridge).
pub const STATE_MAGIC: [u8; 4] = *b"CDST";
/// `b"CDCM"`: a command packet (bridge → device).
pub const COMMAND_MAGIC: [u8; 4] = *b"CDCM";
/// Bytes of one per-joint array: `MAX_JOINTS` f64s.
const ARRAY_BYTES: usize = 8 * MAX_JOINTS;
/// Offsets of the state's arrays (after its fixed 48-byte header): `q`, `qd`, `tau`.
const STATE_Q: usize = 48;
const STATE_QD: usize = STATE_Q + ARRAY_BYTES;
const STATE_TAU: usize = STATE_QD + ARRAY_BYTES;
/// Size of a state packet (bytes): 336 for 12 joints.
pub const STATE_LEN: usize = STATE_TAU + ARRAY_BYTES;
/// Offsets of the command's arrays (after its fixed 32-byte header): `qdd`, `qddd`, `q`, `qd`,
/// `tau`.
const COMMAND_QDD: usize = 32;
const COMMAND_QDDD: usize = COMMAND_QDD + ARRAY_BYTES;
const COMMAND_Q: usize = COMMAND_QDDD + ARRAY_BYTES;
const COMMAND_QD: usize = COMMAND_Q + ARRAY_BYTES;
const COMMAND_TAU: usize = COMMAND_QD + ARRAY_BYTES;
/// Size of a command packet (bytes): 512 for 12 joints.
pub const COMMAND_LEN: usize = COMMAND_TAU + ARRAY_BYTES;

/// Device state flag: the device is braking (too many missed answers, or told to).
pub const DEVICE_BRAKING: u32 = 1 << 0;
/// Device state flag: the device is holding (told to).
pub const DEVICE_HOLDING: u32 = 1 << 1;
/// Device state flag: the device stopped with a reflex error (`status` says which).
pub const DEVICE_STOPPED: u32 = 1 << 2;
/// Device state flags: bit `TAKES_SHIFT + i` set when the device takes command interface `i`
/// (`protocol::interface`).
pub const TAKES_SHIFT: u32 = 8;

/// The flag bits of a device that takes the interfaces `codes`.
pub fn takes(codes: &[u32]) -> u32 {
    codes.iter().fold(0, |f, c| f | 1 << (TAKES_SHIFT + c))
}

/// The device's state for one cycle.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DeviceState {
    pub n: u16,
    /// Cycle counter, +1 per cycle from 0 at each device start.
    pub seq: u64,
    /// Random per device start: a new session is a restarted device.
    pub session: u64,
    /// The device's own clock: ns since it started, on its cycle grid (`cycles × period`).
    pub time_ns: u64,
    pub flags: u32,
    /// Missed answers in a row, as the device counts them.
    pub missed_run: u32,
    /// Missed and late answers since the device started (saturating).
    pub missed_total: u32,
    /// Why the device stopped (`protocol::DeviceStatus` code, 0: it did not) and the joint
    /// (1-based; 0: none).
    pub status: u16,
    pub joint: u16,
    pub q: [f64; MAX_JOINTS],
    pub qd: [f64; MAX_JOINTS],
    /// Measured joint torques (N·m).
    pub tau: [f64; MAX_JOINTS],
}

impl DeviceState {
    /// Whether the device takes command interface `code`.
    pub fn takes(&self, code: u32) -> bool {
        code < 4 && self.flags >> (TAKES_SHIFT + code) & 1 == 1
    }
}

/// What the device should do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum DeviceMode {
    Run = 0,
    Hold = 1,
    Brake = 2,
}

/// The bridge's answer to one state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeviceCommand {
    pub n: u16,
    /// The `seq` of the state this answers.
    pub seq: u64,
    /// The `session` of that state.
    pub session: u64,
    pub mode: DeviceMode,
    /// Which field the device follows (`protocol::interface`).
    pub interface: u32,
    /// q̈ + q⃛·s, s from the answered state's measurement (rad/s², rad/s³).
    pub qdd: [f64; MAX_JOINTS],
    pub qddd: [f64; MAX_JOINTS],
    /// The reference position and velocity, reached one cycle after the answered state.
    pub q: [f64; MAX_JOINTS],
    pub qd: [f64; MAX_JOINTS],
    /// Joint torques (N·m).
    pub tau: [f64; MAX_JOINTS],
}

impl DeviceCommand {
    /// A command answering state `seq` of `session` that moves nothing.
    pub fn still(n: u16, seq: u64, session: u64, mode: DeviceMode) -> Self {
        Self {
            n,
            seq,
            session,
            mode,
            interface: 0,
            qdd: [0.0; MAX_JOINTS],
            qddd: [0.0; MAX_JOINTS],
            q: [0.0; MAX_JOINTS],
            qd: [0.0; MAX_JOINTS],
            tau: [0.0; MAX_JOINTS],
        }
    }
}

/// Why a packet was dropped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    #[error("packet of {got} bytes, expected {expected}")]
    Length { got: usize, expected: usize },
    #[error("bad magic {0:?}")]
    Magic([u8; 4]),
    #[error("protocol version {0}, expected {VERSION}")]
    Version(u16),
    #[error("n = {0} joints is outside 2..={MAX_JOINTS}")]
    Joints(u16),
    #[error("non-finite value at byte {0}")]
    NonFinite(usize),
    #[error("unknown mode {0}")]
    Mode(u32),
    #[error("unknown command interface {0}")]
    Interface(u32),
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}
fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}
fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(a)
}

/// Reads `out.len()` used entries of a per-joint array at `at`; unused entries stay 0.
fn f64s_at(b: &[u8], at: usize, n: usize, out: &mut [f64; MAX_JOINTS]) -> Result<(), WireError> {
    for (j, v) in out.iter_mut().enumerate().take(n) {
        let x = f64::from_le_bytes(b[at + 8 * j..at + 8 * j + 8].try_into().unwrap_or([0; 8]));
        if !x.is_finite() {
            return Err(WireError::NonFinite(at + 8 * j));
        }
        *v = x;
    }
    Ok(())
}

fn put_f64s(b: &mut [u8], at: usize, v: &[f64; MAX_JOINTS]) {
    for (j, x) in v.iter().enumerate() {
        b[at + 8 * j..at + 8 * j + 8].copy_from_slice(&x.to_le_bytes());
    }
}

/// Checks length, magic, version and joint count; returns n.
fn header(b: &[u8], len: usize, magic: [u8; 4]) -> Result<usize, WireError> {
    if b.len() != len {
        return Err(WireError::Length {
            got: b.len(),
            expected: len,
        });
    }
    let m = [b[0], b[1], b[2], b[3]];
    if m != magic {
        return Err(WireError::Magic(m));
    }
    let v = u16_at(b, 4);
    if v != VERSION {
        return Err(WireError::Version(v));
    }
    let n = u16_at(b, 6);
    if !(protocol::MIN_JOINTS..=MAX_JOINTS).contains(&(n as usize)) {
        return Err(WireError::Joints(n));
    }
    Ok(n as usize)
}

impl DeviceState {
    pub fn encode(&self, b: &mut [u8; STATE_LEN]) {
        *b = [0; STATE_LEN];
        b[0..4].copy_from_slice(&STATE_MAGIC);
        b[4..6].copy_from_slice(&VERSION.to_le_bytes());
        b[6..8].copy_from_slice(&self.n.to_le_bytes());
        b[8..16].copy_from_slice(&self.seq.to_le_bytes());
        b[16..24].copy_from_slice(&self.session.to_le_bytes());
        b[24..32].copy_from_slice(&self.time_ns.to_le_bytes());
        b[32..36].copy_from_slice(&self.flags.to_le_bytes());
        b[36..40].copy_from_slice(&self.missed_run.to_le_bytes());
        b[40..44].copy_from_slice(&self.missed_total.to_le_bytes());
        b[44..46].copy_from_slice(&self.status.to_le_bytes());
        b[46..48].copy_from_slice(&self.joint.to_le_bytes());
        put_f64s(b, STATE_Q, &self.q);
        put_f64s(b, STATE_QD, &self.qd);
        put_f64s(b, STATE_TAU, &self.tau);
    }

    pub fn decode(b: &[u8]) -> Result<Self, WireError> {
        let n = header(b, STATE_LEN, STATE_MAGIC)?;
        let mut s = Self {
            n: n as u16,
            seq: u64_at(b, 8),
            session: u64_at(b, 16),
            time_ns: u64_at(b, 24),
            flags: u32_at(b, 32),
            missed_run: u32_at(b, 36),
            missed_total: u32_at(b, 40),
            status: u16_at(b, 44),
            joint: u16_at(b, 46),
            ..Self::default()
        };
        f64s_at(b, STATE_Q, n, &mut s.q)?;
        f64s_at(b, STATE_QD, n, &mut s.qd)?;
        f64s_at(b, STATE_TAU, n, &mut s.tau)?;
        Ok(s)
    }
}

impl DeviceCommand {
    pub fn encode(&self, b: &mut [u8; COMMAND_LEN]) {
        *b = [0; COMMAND_LEN];
        b[0..4].copy_from_slice(&COMMAND_MAGIC);
        b[4..6].copy_from_slice(&VERSION.to_le_bytes());
        b[6..8].copy_from_slice(&self.n.to_le_bytes());
        b[8..16].copy_from_slice(&self.seq.to_le_bytes());
        b[16..24].copy_from_slice(&self.session.to_le_bytes());
        b[24..28].copy_from_slice(&(self.mode as u32).to_le_bytes());
        b[28..32].copy_from_slice(&self.interface.to_le_bytes());
        put_f64s(b, COMMAND_QDD, &self.qdd);
        put_f64s(b, COMMAND_QDDD, &self.qddd);
        put_f64s(b, COMMAND_Q, &self.q);
        put_f64s(b, COMMAND_QD, &self.qd);
        put_f64s(b, COMMAND_TAU, &self.tau);
    }

    pub fn decode(b: &[u8]) -> Result<Self, WireError> {
        let n = header(b, COMMAND_LEN, COMMAND_MAGIC)?;
        let mode = match u32_at(b, 24) {
            0 => DeviceMode::Run,
            1 => DeviceMode::Hold,
            2 => DeviceMode::Brake,
            m => return Err(WireError::Mode(m)),
        };
        let interface = u32_at(b, 28);
        if protocol::interface::name(interface).is_none() {
            return Err(WireError::Interface(interface));
        }
        let mut c = Self::still(n as u16, u64_at(b, 8), u64_at(b, 16), mode);
        c.interface = interface;
        f64s_at(b, COMMAND_QDD, n, &mut c.qdd)?;
        f64s_at(b, COMMAND_QDDD, n, &mut c.qddd)?;
        f64s_at(b, COMMAND_Q, n, &mut c.q)?;
        f64s_at(b, COMMAND_QD, n, &mut c.qd)?;
        f64s_at(b, COMMAND_TAU, n, &mut c.tau)?;
        Ok(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A per-joint array from its first entries (the rest zero).
    fn j(v: &[f64]) -> [f64; MAX_JOINTS] {
        let mut a = [0.0; MAX_JOINTS];
        a[..v.len()].copy_from_slice(v);
        a
    }

    fn state() -> DeviceState {
        DeviceState {
            n: 3,
            seq: 42,
            session: 0xDEAD_BEEF,
            time_ns: 7,
            flags: DEVICE_BRAKING,
            missed_run: 2,
            missed_total: 9,
            status: 3,
            joint: 2,
            q: j(&[0.1, 0.2, 0.3]),
            qd: j(&[-1.0, 2.0, -3.0]),
            tau: j(&[5.0, -6.0, 7.0]),
        }
    }

    /// The byte layout is the protocol (the table in the module doc of `udp`). If this test
    /// fails, the layout changed: bump `VERSION` and the table.
    #[test]
    fn the_layout_is_pinned() {
        assert_eq!(MAX_JOINTS, 12);
        assert_eq!(
            (STATE_Q, STATE_QD, STATE_TAU, STATE_LEN),
            (48, 144, 240, 336)
        );
        assert_eq!((COMMAND_QDD, COMMAND_QDDD, COMMAND_Q), (32, 128, 224));
        assert_eq!((COMMAND_QD, COMMAND_TAU, COMMAND_LEN), (320, 416, 512));
        assert_eq!(VERSION, 4);
    }

    #[test]
    fn a_twelve_joint_arm_round_trips() {
        let up = |k: f64| core::array::from_fn(|i| k * (i + 1) as f64);
        let s = DeviceState {
            n: 12,
            q: up(0.1),
            qd: up(-0.1),
            ..state()
        };
        let mut b = [0u8; STATE_LEN];
        s.encode(&mut b);
        let at = |b: &[u8], o: usize| f64::from_le_bytes(b[o..o + 8].try_into().unwrap());
        assert_eq!(at(&b, STATE_Q + 8 * 11), 0.1 * 12.0);
        assert_eq!(at(&b, STATE_QD + 8 * 11), -0.1 * 12.0);
        assert_eq!(DeviceState::decode(&b), Ok(s));
        let c = DeviceCommand {
            interface: protocol::interface::TORQUE,
            qdd: up(1.0),
            qddd: up(-1.0),
            tau: [9.0; MAX_JOINTS],
            ..DeviceCommand::still(12, 1, 2, DeviceMode::Run)
        };
        let mut b = [0u8; COMMAND_LEN];
        c.encode(&mut b);
        assert_eq!(at(&b, COMMAND_QDD + 8 * 11), 12.0);
        assert_eq!(at(&b, COMMAND_QDDD + 8 * 11), -12.0);
        assert_eq!(DeviceCommand::decode(&b), Ok(c));
        let mut thirteen = b;
        thirteen[6..8].copy_from_slice(&13u16.to_le_bytes());
        assert_eq!(DeviceCommand::decode(&thirteen), Err(WireError::Joints(13)));
    }

    #[test]
    fn round_trips_and_pins_the_layout() {
        let mut b = [0u8; STATE_LEN];
        state().encode(&mut b);
        assert_eq!(&b[0..4], b"CDST");
        assert_eq!(u64_at(&b, 8), 42);
        assert_eq!(f64::from_le_bytes(b[144..152].try_into().unwrap()), -1.0);
        assert_eq!(DeviceState::decode(&b), Ok(state()));
        let c = DeviceCommand {
            interface: protocol::interface::POSITION,
            qdd: j(&[1.0, 2.0, 3.0]),
            qddd: j(&[4.0, 5.0, 6.0]),
            q: j(&[0.5, 0.25, 0.125]),
            ..DeviceCommand::still(3, 42, 5, DeviceMode::Hold)
        };
        let mut b = [0u8; COMMAND_LEN];
        c.encode(&mut b);
        assert_eq!(&b[0..4], b"CDCM");
        assert_eq!(u32_at(&b, 24), 1);
        assert_eq!(f64::from_le_bytes(b[128..136].try_into().unwrap()), 4.0);
        assert_eq!(DeviceCommand::decode(&b), Ok(c));
    }

    #[test]
    fn every_malformed_packet_is_an_error() {
        let mut b = [0u8; STATE_LEN];
        state().encode(&mut b);
        assert!(matches!(
            DeviceState::decode(&b[..100]),
            Err(WireError::Length { got: 100, .. })
        ));
        assert!(matches!(
            DeviceState::decode(&[]),
            Err(WireError::Length { .. })
        ));
        let mut bad = b;
        bad[0] = b'X';
        assert!(matches!(
            DeviceState::decode(&bad),
            Err(WireError::Magic(_))
        ));
        let mut bad = b;
        bad[4] = 9;
        assert_eq!(DeviceState::decode(&bad), Err(WireError::Version(9)));
        let mut bad = b;
        bad[6] = 40;
        assert_eq!(DeviceState::decode(&bad), Err(WireError::Joints(40)));
        let mut bad = b;
        bad[56..64].copy_from_slice(&f64::NAN.to_le_bytes());
        assert_eq!(DeviceState::decode(&bad), Err(WireError::NonFinite(56)));
        // A command packet is not a state, and vice versa.
        let mut c = [0u8; COMMAND_LEN];
        c[0..4].copy_from_slice(&COMMAND_MAGIC);
        assert!(DeviceState::decode(&c).is_err());
        c[4..6].copy_from_slice(&VERSION.to_le_bytes());
        c[6..8].copy_from_slice(&3u16.to_le_bytes());
        c[24..28].copy_from_slice(&7u32.to_le_bytes());
        assert_eq!(DeviceCommand::decode(&c), Err(WireError::Mode(7)));
        c[24..28].copy_from_slice(&0u32.to_le_bytes());
        c[28..32].copy_from_slice(&9u32.to_le_bytes());
        assert_eq!(DeviceCommand::decode(&c), Err(WireError::Interface(9)));
        // Random garbage of every length never panics.
        let mut x = 0x1234_5678_u64;
        for len in 0..600 {
            let mut g = [0u8; 600];
            for v in g.iter_mut().take(len) {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                *v = x as u8;
            }
            let _ = DeviceState::decode(&g[..len]);
            let _ = DeviceCommand::decode(&g[..len]);
        }
    }
}
