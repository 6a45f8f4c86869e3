//! What the plant accepts from the command stream, and which of its states a command answers.
//!
//! Kept apart from the loop so both triggers share one set of rules: a command is used only if
//! it validates, answers a state of this plant run (or is a HOLD/BRAKE, which need no state),
//! and moves its daemon's sequence forward; a new daemon id is a restarted daemon. The ring of
//! published states lets a command's ramp start at the state it answers (`since`) and times the
//! round trip from when that state was really published.

use protocol::{CommandSample, Mode};

/// Counters the intake keeps (part of the plant's summary).
#[derive(Clone, Copy, Debug, Default, serde::Serialize, PartialEq, Eq)]
pub struct IntakeCounters {
    pub commands_received: u64,
    pub commands_rejected: u64,
    pub daemon_restarts: u64,
}

/// Validation and sequence tracking of received commands.
#[derive(Debug)]
pub struct Intake {
    n: usize,
    /// Start of this plant run: commands answering older states are leftovers.
    start_ns: u64,
    daemon_id: u64,
    last_seq: Option<u64>,
    pub counters: IntakeCounters,
}

impl Intake {
    pub fn new(n: usize, start_ns: u64) -> Self {
        Self {
            n,
            start_ns,
            daemon_id: 0,
            last_seq: None,
            counters: IntakeCounters::default(),
        }
    }

    /// Whether `cmd` may be used; counts it either way. Never allocates.
    pub fn accept(&mut self, cmd: &CommandSample) -> bool {
        // Leftovers from a dead daemon, answers to a previous plant's states, garbage: drop.
        let answers_us = cmd.state_stamp_ns >= self.start_ns || cmd.mode != Mode::Run as u32;
        if cmd.validate(self.n).is_err() || !answers_us {
            self.counters.commands_rejected += 1;
            return false;
        }
        if cmd.daemon_id != self.daemon_id {
            if self.daemon_id != 0 {
                self.counters.daemon_restarts += 1;
            }
            self.daemon_id = cmd.daemon_id;
        } else if self.last_seq.is_some_and(|l| cmd.seq <= l) {
            self.counters.commands_rejected += 1;
            return false;
        }
        self.last_seq = Some(cmd.seq);
        self.counters.commands_received += 1;
        true
    }
}

/// One published state: its sequence number, the plant time it describes (s of integrated
/// time since the run started) and when it was published (CLOCK_MONOTONIC ns).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Published {
    pub seq: u64,
    pub plant_time: f64,
    pub at_ns: u64,
}

/// The most recent published states, by sequence number (a fixed ring: no allocation).
#[derive(Debug)]
pub struct PublishedRing([Published; 64]);

impl Default for PublishedRing {
    fn default() -> Self {
        Self(
            [Published {
                seq: u64::MAX,
                plant_time: 0.0,
                at_ns: 0,
            }; 64],
        )
    }
}

impl PublishedRing {
    pub fn push(&mut self, p: Published) {
        self.0[(p.seq % 64) as usize] = p;
    }

    /// The state `seq`, if it is still in the ring.
    pub fn get(&self, seq: u64) -> Option<Published> {
        let p = self.0[(seq % 64) as usize];
        (p.seq == seq).then_some(p)
    }

    /// How far (s) the plant has advanced since the state `seq`; an unknown (too old) state
    /// gives a huge value, which makes a simulator hold the ramp's end.
    pub fn since(&self, seq: u64, plant_time: f64) -> f64 {
        self.get(seq).map_or(1e3, |p| plant_time - p.plant_time)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cmd(seq: u64, daemon: u64, mode: Mode) -> CommandSample {
        CommandSample {
            seq,
            state_seq: 0,
            state_stamp_ns: 100,
            stamp_ns: 200,
            daemon_id: daemon,
            mode: mode as u32,
            n: 3,
            ..CommandSample::default()
        }
    }

    #[test]
    fn rejects_garbage_old_answers_and_repeats_and_sees_restarts() {
        let mut i = Intake::new(3, 50);
        assert!(i.accept(&cmd(0, 7, Mode::Run)));
        assert!(!i.accept(&cmd(0, 7, Mode::Run)), "repeat");
        let mut old = cmd(1, 7, Mode::Run);
        old.state_stamp_ns = 10; // answers a state from before this run
        assert!(!i.accept(&old));
        let mut bad = cmd(2, 7, Mode::Run);
        bad.qdd[1] = f64::NAN;
        assert!(!i.accept(&bad));
        assert!(i.accept(&cmd(0, 8, Mode::Hold)), "a new daemon starts over");
        assert_eq!(
            i.counters,
            IntakeCounters {
                commands_received: 2,
                commands_rejected: 3,
                daemon_restarts: 1
            }
        );
        let mut r = PublishedRing::default();
        r.push(Published {
            seq: 5,
            plant_time: 0.25,
            at_ns: 9,
        });
        assert_eq!(r.since(5, 0.5), 0.25);
        assert_eq!(r.since(69, 0.5), 1e3);
    }
}
