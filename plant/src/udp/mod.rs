//! A real bridge to a device over UDP, and a device emulator that speaks the same protocol.
//!
//! The protocol is modelled on Franka's FCI and KUKA's RSI: **the device owns the clock.** Every
//! cycle it sends its state with a sequence number; the bridge must answer with a command that
//! echoes that number before the device's next cycle, or the device counts the cycle as missed,
//! keeps its previous command, and after a configured number of misses in a row brakes. It
//! resumes as soon as an answer arrives in time again.
//!
//! * [`bridge::UdpBridge`] is a [`crate::Plant`] (`device_clocked`): its `read` waits for the
//!   device's next state packet, its `write` sends the answer. `chaosd-bridge` serves it with
//!   the ordinary plant loop, so the daemon cannot tell it from the simulator.
//! * [`fakebot`] is the device: a separate process (`chaosd-fakebot`) that integrates the arm
//!   (the simulator's model), owns the clock, counts late and missing answers, and can inject
//!   packet loss, delay spikes and its own restart.
//!
//! ## Wire format, version 3
//!
//! One UDP datagram per message, fixed size, all integers and floats **little-endian**, floats
//! IEEE-754 binary64. Arrays always have 7 entries (`MAX_JOINTS`); entries `n..` are zero and
//! ignored. A receiver drops (and counts) every datagram whose length, magic, version, `n`
//! (2..=12), mode, interface or used floats (finite) are wrong; it never trusts a field it has not
//! checked. (Version 3 had arrays of 7 entries: a 216-byte state and a 312-byte command; version 2
//! carried q̈ commands only; version 1 had arrays of 6 entries.)
//!
//! **State** (device → bridge, 336 bytes, sent once per device cycle):
//!
//! | offset | type | field |
//! |---|---|---|
//! | 0 | `[u8; 4]` | magic `b"CDST"` |
//! | 4 | u16 | version = 4 |
//! | 6 | u16 | `n`, joints in use |
//! | 8 | u64 | `seq`: the device's cycle counter, +1 per cycle, 0 at each device start |
//! | 16 | u64 | `session`: random per device start; a new value means the device restarted |
//! | 24 | u64 | device time: ns since the device started, on its cycle grid (cycles run × period, counting cycles its own overruns skipped; libfranka's `time`). The daemon advances its command stream by the difference between two states |
//! | 32 | u32 | flags: bit 0 braking (also before the first answer: the arm stands on its brakes), bit 1 holding, bit 2 stopped by a reflex error; bits 8..=11: the device takes command interface 0..=3 |
//! | 36 | u32 | missed answers in a row |
//! | 40 | u32 | missed answers since start (saturating) |
//! | 44 | u16 | status: why the device stopped (`protocol::DeviceStatus` code; 0 while it runs) |
//! | 46 | u16 | the joint the status is about (1-based; 0: none) |
//! | 48 | `[f64; 12]` | `q`, joint angles (rad); entries from `n` on are zero |
//! | 144 | `[f64; 12]` | `qd`, joint rates (rad/s) |
//! | 240 | `[f64; 12]` | `tau`, measured joint torques (N·m; zeros from an arm without sensors) |
//!
//! **Command** (bridge → device, 512 bytes, at most one per state):
//!
//! | offset | type | field |
//! |---|---|---|
//! | 0 | `[u8; 4]` | magic `b"CDCM"` |
//! | 4 | u16 | version = 4 |
//! | 6 | u16 | `n`, must equal the device's |
//! | 8 | u64 | `seq` of the state this answers (echoed) |
//! | 16 | u64 | `session` of that state (echoed) |
//! | 24 | u32 | mode: 0 run, 1 hold (come to rest and stay; also clears a reflex stop), 2 brake |
//! | 28 | u32 | interface: 0 acceleration (`qdd`, `qddd`), 1 velocity (`qd`), 2 position (`q`), 3 torque (`tau`) |
//! | 32 | `[f64; 12]` | `qdd`: q̈ at the answered state (rad/s²) |
//! | 128 | `[f64; 12]` | `qddd`: its rate (rad/s³); the device applies q̈ + q⃛·s, s from the answered state |
//! | 224 | `[f64; 12]` | `q`: the reference position, reached one cycle after the answered state (rad) |
//! | 320 | `[f64; 12]` | `qd`: the reference velocity (rad/s) |
//! | 416 | `[f64; 12]` | `tau`: joint torques (N·m) |
//!
//! **A robot's rules (the device's side, [`rules`]).** Each RUN command is judged as a robot's
//! controller judges a stream: a position outside the joint's range; a velocity, acceleration
//! or jerk (finite differences over the cycles since the last command) beyond the arm's
//! limits; a first command that does not continue the arm's motion; a torque or torque rate
//! beyond its limit; an interface the device does not take. Any of them stops the device with
//! that status (a reflex stop): it brakes, reports the status and the joint in every state, and
//! ignores RUN commands until a HOLD clears it.
//!
//! **Timing rules (the device's side).** A command answers in time if it echoes the `seq` and
//! `session` of the newest state and arrives before the device's next cycle starts; the device
//! then applies it for that whole cycle. A command echoing an older `seq` is late: counted and
//! dropped. A command with another `session` answers a previous device start: counted and
//! dropped. No answer in time: the device keeps the previous command (ramped on) and counts a
//! miss; after `max_missed` misses in a row it brakes (state flag bit 0) until an answer comes
//! in time again. A strict device (`--stop-after-missed N`, as FCI is) instead stops after N
//! misses in a row with a reflex error, lost packets (`communication_constraints_violation`),
//! latched until a HOLD. Before the first answer after a start, the device holds its initial state.
//!
//! **The bridge's side.** It answers every state the daemon answers, echoing the number of the
//! state the daemon's command answers. A device silent for longer than its `lost` timeout is
//! reported lost (the bridge publishes nothing, so the daemon holds); a new `session` is a
//! restarted device, reported and followed.

pub mod bridge;
pub mod fakebot;
pub mod rules;
pub mod wait;
pub mod wire;
