//! The two samples on the control path: plant → daemon [`StateSample`], daemon → plant
//! [`CommandSample`].
//!
//! Both are `#[repr(C)]`, `Copy` and padding-free, so their bytes in shared memory are exactly
//! their fields (the layout tests pin every offset). Enum-like values (`mode`, `flags`) travel as
//! plain `u32`: a corrupt value in a Rust enum would be undefined behaviour, a corrupt `u32` is
//! just a validation error.

use core::fmt;

use iceoryx2::prelude::ZeroCopySend;

use crate::device::{interface, DeviceStatus};
use crate::{MAX_JOINTS, MIN_JOINTS};

/// Bits of [`StateSample::flags`]. Bits not listed here are reserved and must be zero.
pub mod flags {
    /// The arm has a free-floating base; `phi` is its attitude. Otherwise `phi` is 0.
    pub const FLOATING_BASE: u32 = 1 << 0;
    /// The plant is braking (its brakes are engaged or it is executing a brake command).
    pub const BRAKING: u32 = 1 << 1;
    /// The plant is the simulator, not hardware.
    pub const SIMULATED: u32 = 1 << 2;
    /// The plant reports a fault and is not following commands.
    pub const FAULT: u32 = 1 << 3;
    /// The plant is holding position because it has no fresh command (its own watchdog fired).
    pub const COMMAND_TIMEOUT: u32 = 1 << 4;

    /// Every defined bit.
    pub const KNOWN: u32 = FLOATING_BASE | BRAKING | SIMULATED | FAULT | COMMAND_TIMEOUT;
}

/// The plant's measured state, published once per plant tick.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("chaosd::StateSample.v9")]
#[repr(C)]
pub struct StateSample {
    /// Per-plant sequence number, +1 per published sample, starting at 0 after each plant start.
    pub seq: u64,
    /// When the state was measured, ns of the plant's `CLOCK_MONOTONIC`.
    pub stamp_ns: u64,
    /// Random id of this plant process start ([`crate::new_instance_id`]); changes on restart.
    pub plant_id: u64,
    /// Number of joints in use, `MIN_JOINTS..=MAX_JOINTS`.
    pub n: u32,
    /// Bit set of [`flags`].
    pub flags: u32,
    /// Base attitude, rad. 0 for a fixed base.
    pub phi: f64,
    /// Joint angles, rad. Entries `n..` are unused and ignored.
    pub q: [f64; MAX_JOINTS],
    /// Joint rates, rad/s. Entries `n..` are unused and ignored.
    pub qd: [f64; MAX_JOINTS],
    /// Measured joint torques, N·m (zeros from a plant that does not measure them).
    pub tau: [f64; MAX_JOINTS],
    /// A [`DeviceStatus`] as `u32`: why the device stopped, 0 while it runs.
    pub device: u32,
    /// The joint the status is about (1-based; 0: none or all).
    pub device_joint: u32,
    /// The device's own clock when it measured this state, ns since it started, on its cycle
    /// grid (libfranka's `time`): the cycles it has run times its period. The daemon advances
    /// its reference by the difference between two states, so the stream it sends moves on by
    /// exactly the time the device did, whatever the receipt jitter. 0: the plant has no such
    /// clock (the daemon then uses `stamp_ns`).
    pub device_time_ns: u64,
}

/// Which sample an error is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SampleKind {
    State,
    Command,
}

impl fmt::Display for SampleKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            SampleKind::State => "state",
            SampleKind::Command => "command",
        })
    }
}

/// A numeric field of a sample, with its joint index. Displays as `q[2]`, `phi`, ...
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Field {
    Phi,
    Q(usize),
    Qd(usize),
    Qdd(usize),
    Qddd(usize),
    Tau(usize),
}

impl fmt::Display for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Field::Phi => f.write_str("phi"),
            Field::Q(i) => write!(f, "q[{i}]"),
            Field::Qd(i) => write!(f, "qd[{i}]"),
            Field::Qdd(i) => write!(f, "qdd[{i}]"),
            Field::Qddd(i) => write!(f, "qddd[{i}]"),
            Field::Tau(i) => write!(f, "tau[{i}]"),
        }
    }
}

/// Why a received sample was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SampleError {
    #[error("{kind} sample has n = {n}; supported arms have {MIN_JOINTS}..={MAX_JOINTS} joints")]
    JointCountOutOfRange { kind: SampleKind, n: u32 },
    #[error("{kind} sample has n = {n}, but this arm has {expected} joints")]
    JointCountMismatch {
        kind: SampleKind,
        n: u32,
        expected: usize,
    },
    #[error("{kind} sample has non-finite {field}")]
    NonFinite { kind: SampleKind, field: Field },
    #[error("state sample has unknown flag bits {bits:#x}")]
    UnknownFlags { bits: u32 },
    #[error("command sample has {0}")]
    Mode(#[from] UnknownMode),
    #[error("command sample has unknown interface {0} (expected 0 = acceleration, 1 = velocity, 2 = position, 3 = torque)")]
    Interface(u32),
    #[error("state sample has unknown device status {0}")]
    DeviceStatus(u32),
}

fn check_n(kind: SampleKind, n: u32, expected_n: usize) -> Result<usize, SampleError> {
    let used = n as usize;
    if !(MIN_JOINTS..=MAX_JOINTS).contains(&used) {
        return Err(SampleError::JointCountOutOfRange { kind, n });
    }
    if used != expected_n {
        return Err(SampleError::JointCountMismatch {
            kind,
            n,
            expected: expected_n,
        });
    }
    Ok(used)
}

fn check_finite(
    kind: SampleKind,
    values: &[f64],
    field: fn(usize) -> Field,
) -> Result<(), SampleError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(SampleError::NonFinite {
            kind,
            field: field(i),
        }),
        None => Ok(()),
    }
}

/// Entries `..n` of a per-joint array, clamped so that a corrupt `n` can never index out of
/// bounds.
fn used(values: &[f64; MAX_JOINTS], n: u32) -> &[f64] {
    &values[..(n as usize).min(MAX_JOINTS)]
}

impl StateSample {
    /// Checks a received sample before use: `n` is in range and equals the configured arm size,
    /// `phi` and the used `q`/`qd` entries are finite, and no reserved flag bit is set. Unused
    /// entries (`n..`) are ignored. Never allocates.
    pub fn validate(&self, expected_n: usize) -> Result<(), SampleError> {
        const KIND: SampleKind = SampleKind::State;
        let n = check_n(KIND, self.n, expected_n)?;
        if self.flags & !flags::KNOWN != 0 {
            return Err(SampleError::UnknownFlags {
                bits: self.flags & !flags::KNOWN,
            });
        }
        if !self.phi.is_finite() {
            return Err(SampleError::NonFinite {
                kind: KIND,
                field: Field::Phi,
            });
        }
        if DeviceStatus::from_code(self.device).is_none() {
            return Err(SampleError::DeviceStatus(self.device));
        }
        check_finite(KIND, &self.q[..n], Field::Q)?;
        check_finite(KIND, &self.qd[..n], Field::Qd)?;
        check_finite(KIND, &self.tau[..n], Field::Tau)
    }

    /// The device's status (unknown codes, which validation refuses, read as `None`).
    pub fn device_status(&self) -> Option<DeviceStatus> {
        DeviceStatus::from_code(self.device)
    }

    /// Whether every bit of `flag` (one or more of [`flags`]) is set.
    pub fn has_flags(&self, flag: u32) -> bool {
        self.flags & flag == flag
    }

    /// The used joint angles, `q[..n]`.
    pub fn used_q(&self) -> &[f64] {
        used(&self.q, self.n)
    }

    /// The used joint rates, `qd[..n]`.
    pub fn used_qd(&self) -> &[f64] {
        used(&self.qd, self.n)
    }
}

/// What the plant should do with a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum Mode {
    /// Apply `qdd`.
    Run = 0,
    /// Ignore `qdd`; come to rest with the plant's own deceleration and hold there, ready to
    /// follow the next `Run` at once. The daemon sends it while it lacks usable states.
    /// (`plant::Actuation::Hold`; the simulator decelerates with `plant.brake_gain`.)
    Hold = 1,
    /// Ignore `qdd`; stop and engage the brakes.
    Brake = 2,
    /// The controller's runaway guard tripped: ignore `qdd` and brake, as for [`Mode::Brake`].
    /// The daemon stays here until an operator resumes it (`chaosctl resume`).
    Fault = 3,
}

/// A `mode` value that is not a [`Mode`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("unknown mode {0} (expected 0 = run, 1 = hold, 2 = brake, 3 = fault)")]
pub struct UnknownMode(pub u32);

impl TryFrom<u32> for Mode {
    type Error = UnknownMode;

    fn try_from(value: u32) -> Result<Self, Self::Error> {
        match value {
            0 => Ok(Mode::Run),
            1 => Ok(Mode::Hold),
            2 => Ok(Mode::Brake),
            3 => Ok(Mode::Fault),
            other => Err(UnknownMode(other)),
        }
    }
}

impl From<Mode> for u32 {
    fn from(mode: Mode) -> Self {
        mode as u32
    }
}

/// The daemon's command, published once per control tick in answer to a [`StateSample`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("chaosd::CommandSample.v9")]
#[repr(C)]
pub struct CommandSample {
    /// Per-daemon sequence number, +1 per published command, starting at 0 after each start.
    pub seq: u64,
    /// `seq` of the state this command was computed from.
    pub state_seq: u64,
    /// `stamp_ns` of that state (lets the plant measure the full loop latency).
    pub state_stamp_ns: u64,
    /// When the command was published, ns of `CLOCK_MONOTONIC`.
    pub stamp_ns: u64,
    /// Random id of this daemon process start ([`crate::new_instance_id`]).
    pub daemon_id: u64,
    /// A [`Mode`] as `u32`; read it with [`CommandSample::mode`].
    pub mode: u32,
    /// Number of joints in use, `MIN_JOINTS..=MAX_JOINTS`.
    pub n: u32,
    /// Commanded joint accelerations, rad/s². Entries `n..` are unused and ignored.
    pub qdd: [f64; MAX_JOINTS],
    /// Rate of change of `qdd` over the hold interval, rad/s³: the plant applies
    /// `qdd + qddd·s`, s the time since the answered state (a first-order hold; zeros give a
    /// zero-order hold). Entries `n..` are unused and ignored.
    pub qddd: [f64; MAX_JOINTS],
    /// Which field the device follows ([`interface`]): `qdd` (acceleration), `qd` (velocity),
    /// `q` (position) or `tau` (torque). The others are sent too, for logs and feed-forward.
    pub interface: u32,
    /// Zero.
    pub reserved: u32,
    /// The reference position (rad) and velocity (rad/s) at the end of the period.
    pub q: [f64; MAX_JOINTS],
    pub qd: [f64; MAX_JOINTS],
    /// Joint torques (N·m); zeros outside torque mode.
    pub tau: [f64; MAX_JOINTS],
}

impl Default for CommandSample {
    /// All zeros except `mode`, which is [`Mode::Hold`]: a default command never moves the arm.
    fn default() -> Self {
        Self {
            seq: 0,
            state_seq: 0,
            state_stamp_ns: 0,
            stamp_ns: 0,
            daemon_id: 0,
            mode: Mode::Hold as u32,
            n: 0,
            qdd: [0.0; MAX_JOINTS],
            qddd: [0.0; MAX_JOINTS],
            interface: interface::ACCELERATION,
            reserved: 0,
            q: [0.0; MAX_JOINTS],
            qd: [0.0; MAX_JOINTS],
            tau: [0.0; MAX_JOINTS],
        }
    }
}

impl CommandSample {
    /// Checks a received command before use: `n` is in range and equals the configured arm size,
    /// `mode` is a known [`Mode`] and the used `qdd` entries are finite. Unused entries are
    /// ignored. Never allocates.
    pub fn validate(&self, expected_n: usize) -> Result<(), SampleError> {
        const KIND: SampleKind = SampleKind::Command;
        let n = check_n(KIND, self.n, expected_n)?;
        self.mode()?;
        if interface::name(self.interface).is_none() {
            return Err(SampleError::Interface(self.interface));
        }
        check_finite(KIND, &self.qdd[..n], Field::Qdd)?;
        check_finite(KIND, &self.qddd[..n], Field::Qddd)?;
        check_finite(KIND, &self.q[..n], Field::Q)?;
        check_finite(KIND, &self.qd[..n], Field::Qd)?;
        check_finite(KIND, &self.tau[..n], Field::Tau)
    }

    /// The decoded `mode`.
    pub fn mode(&self) -> Result<Mode, UnknownMode> {
        Mode::try_from(self.mode)
    }

    /// The used accelerations, `qdd[..n]`.
    pub fn used_qdd(&self) -> &[f64] {
        used(&self.qdd, self.n)
    }
}

#[cfg(test)]
mod tests {
    use core::mem::{align_of, offset_of, size_of};

    use iceoryx2::prelude::ZeroCopySend;

    use super::*;
    use crate::WIRE_VERSION;

    fn good_state(n: usize) -> StateSample {
        let mut s = StateSample {
            seq: 7,
            stamp_ns: 1_000,
            plant_id: 42,
            n: n as u32,
            flags: flags::SIMULATED,
            phi: 0.1,
            ..StateSample::default()
        };
        for i in 0..n {
            s.q[i] = 0.1 * i as f64;
            s.qd[i] = -0.2 * i as f64;
        }
        s
    }

    fn good_command(n: usize) -> CommandSample {
        let mut c = CommandSample {
            seq: 3,
            state_seq: 7,
            state_stamp_ns: 1_000,
            stamp_ns: 1_500,
            daemon_id: 9,
            mode: Mode::Run.into(),
            n: n as u32,
            ..CommandSample::default()
        };
        for i in 0..n {
            c.qdd[i] = 1.5 * i as f64;
        }
        c
    }

    const BAD: [f64; 3] = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY];

    #[test]
    fn good_samples_pass_for_every_arm_size() {
        for n in MIN_JOINTS..=MAX_JOINTS {
            assert_eq!(good_state(n).validate(n), Ok(()));
            assert_eq!(good_command(n).validate(n), Ok(()));
        }
    }

    #[test]
    fn state_rejects_non_finite_in_each_used_entry() {
        for n in MIN_JOINTS..=MAX_JOINTS {
            for bad in BAD {
                for i in 0..n {
                    let mut s = good_state(n);
                    s.q[i] = bad;
                    assert_eq!(
                        s.validate(n),
                        Err(SampleError::NonFinite {
                            kind: SampleKind::State,
                            field: Field::Q(i)
                        })
                    );
                    let mut s = good_state(n);
                    s.qd[i] = bad;
                    assert_eq!(
                        s.validate(n),
                        Err(SampleError::NonFinite {
                            kind: SampleKind::State,
                            field: Field::Qd(i)
                        })
                    );
                }
                let mut s = good_state(n);
                s.phi = bad;
                assert_eq!(
                    s.validate(n),
                    Err(SampleError::NonFinite {
                        kind: SampleKind::State,
                        field: Field::Phi
                    })
                );
            }
        }
    }

    #[test]
    fn command_rejects_non_finite_in_each_used_entry() {
        for n in MIN_JOINTS..=MAX_JOINTS {
            for bad in BAD {
                for i in 0..n {
                    let mut c = good_command(n);
                    c.qdd[i] = bad;
                    assert_eq!(
                        c.validate(n),
                        Err(SampleError::NonFinite {
                            kind: SampleKind::Command,
                            field: Field::Qdd(i)
                        })
                    );
                }
            }
        }
    }

    #[test]
    fn unused_entries_are_ignored() {
        for n in MIN_JOINTS..MAX_JOINTS {
            let mut s = good_state(n);
            let mut c = good_command(n);
            for i in n..MAX_JOINTS {
                s.q[i] = f64::NAN;
                s.qd[i] = f64::INFINITY;
                c.qdd[i] = f64::NEG_INFINITY;
            }
            assert_eq!(s.validate(n), Ok(()));
            assert_eq!(c.validate(n), Ok(()));
            assert_eq!(s.used_q().len(), n);
            assert_eq!(s.used_qd().len(), n);
            assert_eq!(c.used_qdd().len(), n);
        }
    }

    #[test]
    fn wrong_joint_count_is_rejected() {
        for n in [0u32, 1, 13, 100, u32::MAX] {
            let mut s = good_state(4);
            s.n = n;
            assert_eq!(
                s.validate(4),
                Err(SampleError::JointCountOutOfRange {
                    kind: SampleKind::State,
                    n
                })
            );
            let mut c = good_command(4);
            c.n = n;
            assert_eq!(
                c.validate(4),
                Err(SampleError::JointCountOutOfRange {
                    kind: SampleKind::Command,
                    n
                })
            );
            // A corrupt n must never make the accessors index out of bounds.
            assert!(s.used_q().len() <= MAX_JOINTS);
            assert!(c.used_qdd().len() <= MAX_JOINTS);
        }
        assert_eq!(
            good_state(3).validate(4),
            Err(SampleError::JointCountMismatch {
                kind: SampleKind::State,
                n: 3,
                expected: 4
            })
        );
        assert_eq!(
            good_command(5).validate(4),
            Err(SampleError::JointCountMismatch {
                kind: SampleKind::Command,
                n: 5,
                expected: 4
            })
        );
    }

    #[test]
    fn unknown_mode_and_flags_are_rejected() {
        let mut c = good_command(2);
        c.mode = 4;
        assert_eq!(c.validate(2), Err(SampleError::Mode(UnknownMode(4))));
        for mode in [Mode::Run, Mode::Hold, Mode::Brake, Mode::Fault] {
            assert_eq!(Mode::try_from(u32::from(mode)), Ok(mode));
        }
        assert_eq!(Mode::try_from(99), Err(UnknownMode(99)));

        let mut s = good_state(2);
        s.flags = flags::KNOWN;
        assert_eq!(s.validate(2), Ok(()));
        assert!(s.has_flags(flags::BRAKING | flags::FAULT));
        s.flags = flags::SIMULATED | 1 << 31;
        assert_eq!(
            s.validate(2),
            Err(SampleError::UnknownFlags { bits: 1 << 31 })
        );
    }

    #[test]
    fn default_command_holds() {
        assert_eq!(CommandSample::default().mode(), Ok(Mode::Hold));
    }

    #[test]
    fn error_messages_name_the_field() {
        let mut s = good_state(4);
        s.qd[2] = f64::NAN;
        assert_eq!(
            s.validate(4).unwrap_err().to_string(),
            "state sample has non-finite qd[2]"
        );
        let mut c = good_command(4);
        c.mode = 5;
        assert_eq!(
            c.validate(4).unwrap_err().to_string(),
            "command sample has unknown mode 5 (expected 0 = run, 1 = hold, 2 = brake, 3 = fault)"
        );
        assert_eq!(
            good_state(3).validate(4).unwrap_err().to_string(),
            "state sample has n = 3, but this arm has 4 joints"
        );
        let mut s = good_state(4);
        s.n = 13;
        assert_eq!(
            s.validate(4).unwrap_err().to_string(),
            "state sample has n = 13; supported arms have 2..=12 joints"
        );
    }

    #[test]
    fn errors_are_small_and_copy() {
        fn is_copy<T: Copy>() {}
        is_copy::<SampleError>();
        assert!(size_of::<SampleError>() <= 24);
    }

    /// The byte layout is the wire format. If this test fails, the layout changed: bump
    /// `WIRE_VERSION` and the `type_name`s.
    #[test]
    fn state_layout_is_pinned() {
        assert_eq!(MAX_JOINTS, 12);
        assert_eq!(size_of::<StateSample>(), 344);
        assert_eq!(align_of::<StateSample>(), 8);
        assert_eq!(offset_of!(StateSample, seq), 0);
        assert_eq!(offset_of!(StateSample, stamp_ns), 8);
        assert_eq!(offset_of!(StateSample, plant_id), 16);
        assert_eq!(offset_of!(StateSample, n), 24);
        assert_eq!(offset_of!(StateSample, flags), 28);
        assert_eq!(offset_of!(StateSample, phi), 32);
        assert_eq!(offset_of!(StateSample, q), 40);
        assert_eq!(offset_of!(StateSample, qd), 136);
        assert_eq!(offset_of!(StateSample, tau), 232);
        assert_eq!(offset_of!(StateSample, device), 328);
        assert_eq!(offset_of!(StateSample, device_joint), 332);
        assert_eq!(offset_of!(StateSample, device_time_ns), 336);
    }

    #[test]
    fn command_layout_is_pinned() {
        assert_eq!(MAX_JOINTS, 12);
        assert_eq!(size_of::<CommandSample>(), 536);
        assert_eq!(align_of::<CommandSample>(), 8);
        assert_eq!(offset_of!(CommandSample, seq), 0);
        assert_eq!(offset_of!(CommandSample, state_seq), 8);
        assert_eq!(offset_of!(CommandSample, state_stamp_ns), 16);
        assert_eq!(offset_of!(CommandSample, stamp_ns), 24);
        assert_eq!(offset_of!(CommandSample, daemon_id), 32);
        assert_eq!(offset_of!(CommandSample, mode), 40);
        assert_eq!(offset_of!(CommandSample, n), 44);
        assert_eq!(offset_of!(CommandSample, qdd), 48);
        assert_eq!(offset_of!(CommandSample, qddd), 144);
        assert_eq!(offset_of!(CommandSample, interface), 240);
        assert_eq!(offset_of!(CommandSample, reserved), 244);
        assert_eq!(offset_of!(CommandSample, q), 248);
        assert_eq!(offset_of!(CommandSample, qd), 344);
        assert_eq!(offset_of!(CommandSample, tau), 440);
    }

    #[test]
    fn interface_device_status_and_torques_are_checked() {
        let mut c = good_command(3);
        c.interface = 4;
        assert_eq!(c.validate(3), Err(SampleError::Interface(4)));
        c.interface = crate::interface::TORQUE;
        c.tau[2] = f64::NAN;
        assert_eq!(
            c.validate(3).unwrap_err().to_string(),
            "command sample has non-finite tau[2]"
        );
        let mut s = good_state(3);
        s.device = 99;
        assert_eq!(s.validate(3), Err(SampleError::DeviceStatus(99)));
        s.device = DeviceStatus::JerkLimit as u32;
        assert_eq!(s.validate(3), Ok(()));
        assert_eq!(s.device_status(), Some(DeviceStatus::JerkLimit));
        s.tau[0] = f64::INFINITY;
        assert!(s.validate(3).is_err());
    }

    #[test]
    fn type_names_carry_the_wire_version() {
        let suffix = format!(".v{WIRE_VERSION}");
        // SAFETY: type_name only returns the string set by #[type_name].
        let (state, command) = unsafe {
            (
                <StateSample as ZeroCopySend>::type_name(),
                <CommandSample as ZeroCopySend>::type_name(),
            )
        };
        assert_eq!(state, format!("chaosd::StateSample{suffix}"));
        assert_eq!(command, format!("chaosd::CommandSample{suffix}"));
    }
}
