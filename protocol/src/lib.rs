//! chaosd's wire contract: what the daemon and the plant say to each other over iceoryx2.
//!
//! Both processes depend on this crate and nothing else for the shape of their messages, so they
//! cannot disagree about a field, a unit, a service name or a queue depth.
//!
//! * **Plain data, no serialisation.** [`StateSample`] and [`CommandSample`] are `#[repr(C)]`,
//!   `Copy`, fixed-size structs that derive iceoryx2's `ZeroCopySend`. A publisher loans a slot in
//!   shared memory, writes the struct into it and sends an offset; nothing is encoded and no
//!   buffer is built per message. Arrays are sized for [`MAX_JOINTS`]; `n` says how many entries
//!   are used.
//! * **Distrust what arrives.** Shared memory is written by another process. Every sample is
//!   checked with `validate` before use (joint count, finite numbers, known enum values). Sequence
//!   and staleness checks need history and a clock, so they belong to the daemon, not here.
//! * **One place for QoS.** iceoryx2 fixes a service's capacities when the first process creates
//!   it; later openers only have to ask for *no more* than that. [`qos`] holds the single set of
//!   settings and the `open_*` helpers that apply them and then check that an existing service
//!   matches exactly.
//! * **A handshake before control.** Each side publishes the arm it is built for
//!   ([`handshake`]); the daemon runs a plant only when both agree, and either names both sides
//!   when they do not.
//! * **Versioned type names.** Each sample's iceoryx2 type name carries [`WIRE_VERSION`]. A
//!   process built with a different layout fails to open the service (`IncompatibleTypes`)
//!   instead of misreading bytes.
//!
//! **Architecture invariant:** this crate does no I/O of its own. It defines types and names, and
//! its `qos` helpers only open iceoryx2 services when asked to, and `node()` looks at iceoryx2's
//! directories before it joins.
//!
//! Units on the wire: angles in rad, rates in rad/s, accelerations in rad/s², times in ns of
//! `CLOCK_MONOTONIC` (see [`monotonic_ns`]).
//!
//! ```no_run
//! use iceoryx2::prelude::*;
//! use protocol::{open_state_service, ServiceNames, StateSample};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let names = ServiceNames::new("lab")?; // chaosd/lab/...
//! let node = NodeBuilder::new()
//!     .name(&NodeName::new("chaosd-daemon")?)
//!     .signal_handling_mode(SignalHandlingMode::Disabled)
//!     .create::<ipc::Service>()?;
//! let states = open_state_service(&node, &names)?.subscriber_builder().create()?;
//!
//! // Once per tick: drain the queue, keep the newest sample, check it before use.
//! let mut newest: Option<StateSample> = None;
//! while let Some(sample) = states.receive()? {
//!     newest = Some(*sample);
//! }
//! if let Some(state) = newest {
//!     state.validate(3)?;
//! }
//! # Ok(())
//! # }
//! ```

pub mod board;
pub mod control;
pub mod device;
pub mod handshake;
pub mod names;
pub mod node;
pub mod qos;
pub mod sample;

pub use control::{
    ControlRequest, ControlResponse, ControlService, Op, Status, TelemetrySample, TelemetryService,
    LIMIT_BREACH_KINDS,
};
pub use device::{interface, DeviceStatus};
pub use handshake::{mismatch, ArmInfo, FloatingBase};
pub use names::{
    validate_namespace, NamespaceError, ServiceNames, DEFAULT_NAMESPACE, MAX_NAMESPACE_LEN,
    SERVICE_ROOT,
};
pub use node::{check_dirs, node, DirError, NodeError};
pub use qos::{
    open_command_service, open_state_service, Channel, CommandService, PubSubQos, ServiceError,
    StateService, COMMAND_QOS, STATE_QOS,
};
pub use sample::{
    flags, CommandSample, Field, Mode, SampleError, SampleKind, StateSample, UnknownMode,
};

/// Largest supported arm; the length of every per-joint array on the wire.
pub const MAX_JOINTS: usize = 12;
/// Smallest supported arm.
pub const MIN_JOINTS: usize = 2;

/// Wire-format version, embedded in the iceoryx2 type names of the samples. Bump it whenever a
/// sample's layout or the meaning of a field changes.
pub const WIRE_VERSION: u32 = 9;

/// Nanoseconds of `CLOCK_MONOTONIC`, the clock every `*_ns` stamp on the wire uses.
///
/// Both processes must run on the same host (shared memory implies it), so their monotonic
/// clocks agree and stamps can be subtracted across processes. No allocation, no system call on
/// Linux (vDSO).
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC is always available on Linux.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    debug_assert_eq!(rc, 0, "clock_gettime(CLOCK_MONOTONIC) failed");
    (ts.tv_sec as u64) * 1_000_000_000 + ts.tv_nsec as u64
}

/// A random, non-zero 64-bit id for one process start (`StateSample::plant_id`,
/// `CommandSample::daemon_id`). A peer that sees the id change knows the other side restarted and
/// must reset its sequence tracking. Zero is never returned, so it can mean "unknown".
pub fn new_instance_id() -> u64 {
    let mut bytes = [0u8; 8];
    // SAFETY: the buffer is valid for 8 writable bytes.
    let got = unsafe { libc::getrandom(bytes.as_mut_ptr().cast(), bytes.len(), 0) };
    let mut id = if got == bytes.len() as isize {
        u64::from_ne_bytes(bytes)
    } else {
        // No entropy source: mix pid and clocks (splitmix64). Unique enough to tell restarts apart.
        let mut realtime = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: valid, writable timespec.
        unsafe { libc::clock_gettime(libc::CLOCK_REALTIME, &mut realtime) };
        let seed = (u64::from(std::process::id()) << 32)
            ^ monotonic_ns()
            ^ (realtime.tv_sec as u64).wrapping_mul(1_000_000_007)
            ^ realtime.tv_nsec as u64;
        let mut z = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    if id == 0 {
        id = 1;
    }
    id
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_clock_advances() {
        let a = monotonic_ns();
        let b = monotonic_ns();
        assert!(a > 0);
        assert!(b >= a);
    }

    #[test]
    fn instance_ids_are_nonzero_and_differ() {
        let a = new_instance_id();
        let b = new_instance_id();
        assert_ne!(a, 0);
        assert_ne!(b, 0);
        assert_ne!(a, b);
    }
}
