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
//! ## Wire format, version 2
//!
//! One UDP datagram per message, fixed size, all integers and floats **little-endian**, floats
//! IEEE-754 binary64. Arrays always have 7 entries (`MAX_JOINTS`); entries `n..` are zero and
//! ignored. A receiver drops (and counts) every datagram whose length, magic, version, `n`
//! (2..=7), mode or used floats (finite) are wrong; it never trusts a field it has not checked.
//! (Version 1 had arrays of 6 entries: a 144-byte state and a 128-byte command.)
//!
//! **State** (device → bridge, 160 bytes, sent once per device cycle):
//!
//! | offset | type | field |
//! |---|---|---|
//! | 0 | `[u8; 4]` | magic `b"CDST"` |
//! | 4 | u16 | version = 2 |
//! | 6 | u16 | `n`, joints in use |
//! | 8 | u64 | `seq`: the device's cycle counter, +1 per cycle, 0 at each device start |
//! | 16 | u64 | `session`: random per device start; a new value means the device restarted |
//! | 24 | u64 | device time, ns since the device started (informative) |
//! | 32 | u32 | flags: bit 0 braking, bit 1 holding; other bits 0 |
//! | 36 | u32 | missed answers in a row |
//! | 40 | u32 | missed answers since start (saturating) |
//! | 44 | u32 | reserved, 0 |
//! | 48 | `[f64; 7]` | `q`, joint angles (rad) |
//! | 104 | `[f64; 7]` | `qd`, joint rates (rad/s) |
//!
//! **Command** (bridge → device, 144 bytes, at most one per state):
//!
//! | offset | type | field |
//! |---|---|---|
//! | 0 | `[u8; 4]` | magic `b"CDCM"` |
//! | 4 | u16 | version = 2 |
//! | 6 | u16 | `n`, must equal the device's |
//! | 8 | u64 | `seq` of the state this answers (echoed) |
//! | 16 | u64 | `session` of that state (echoed) |
//! | 24 | u32 | mode: 0 run, 1 hold (come to rest and stay), 2 brake |
//! | 28 | u32 | reserved, 0 |
//! | 32 | `[f64; 7]` | `qdd`: q̈ at the answered state (rad/s²) |
//! | 88 | `[f64; 7]` | `qddd`: its rate (rad/s³); the device applies q̈ + q⃛·s, s from the answered state |
//!
//! **Timing rules (the device's side).** A command answers in time if it echoes the `seq` and
//! `session` of the newest state and arrives before the device's next cycle starts; the device
//! then applies it for that whole cycle. A command echoing an older `seq` is late: counted and
//! dropped. A command with another `session` answers a previous device start: counted and
//! dropped. No answer in time: the device keeps the previous command (ramped on) and counts a
//! miss; after `max_missed` misses in a row it brakes (state flag bit 0) until an answer comes
//! in time again. Before the first answer after a start, the device holds its initial state.
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
