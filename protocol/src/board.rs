//! The fast lane: the newest state and the newest command as iceoryx2 blackboard entries.
//!
//! Why a second path beside publish-subscribe: at 1 kHz on a shared host, a pub-sub send and
//! receive go cold between two cycles, and one state → command round trip costs 6–8 µs of
//! iceoryx2 alone (`chaosd-bench latency --pace-us 1000`). A blackboard entry is a lock-free
//! latest-value cell in shared memory: a write is a copy into a free cell and one counter
//! increment, and a poll that finds nothing is one load of that counter. Paced the same way, its
//! round trip is about 1.5 µs. Latest-value is exactly what both loops want (the daemon ticks on
//! the newest state, the plant applies the newest answer), and nothing is queued or returned.
//!
//! The lane is an addition, never a replacement: a state-triggered plant with `fast_lane` writes
//! each state here first, and still publishes the same sample on pub-sub once the cycle's answer
//! is in, so every observer of the pub-sub services (tests, `chaosctl`, a daemon without the
//! lane) sees exactly what it saw before. Readers drop the pub-sub copy of what they already took
//! from the board. An entry has one writer at most: a second plant (or daemon) in the namespace
//! cannot write to it.

use crate::names::ServiceNames;
use crate::qos::{Channel, ServiceError};
use iceoryx2::node::Node;
use iceoryx2::port::reader::{BlackboardValue, EntryHandle};
use iceoryx2::port::writer::EntryHandleMut;
use iceoryx2::prelude::{ipc, ServiceName, ZeroCopySend};
use iceoryx2::service::port_factory::blackboard::PortFactory;
use std::cell::RefCell;
use std::fmt::Debug;

/// While the fast lane brings the samples, a loop waiting for one looks at the pub-sub queue
/// only every this many polls: there it finds only the lane's copies, and a pub-sub receive costs
/// many board polls.
pub const PUBSUB_EVERY: u32 = 16;

/// Whether a wait's `poll`-th poll (counted from 1) looks at the pub-sub queue too: always,
/// unless the lane brought the last sample (`lane_first`); then every [`PUBSUB_EVERY`]th.
///
/// ```
/// use protocol::board::{pubsub_due, PUBSUB_EVERY};
/// assert!((1..40).all(|p| pubsub_due(false, p)));
/// let due: Vec<u32> = (1..=40).filter(|&p| pubsub_due(true, p)).collect();
/// assert_eq!(due, [PUBSUB_EVERY, 2 * PUBSUB_EVERY]);
/// ```
#[inline]
pub fn pubsub_due(lane_first: bool, poll: u32) -> bool {
    !lane_first || poll.is_multiple_of(PUBSUB_EVERY)
}

/// The one key of each board.
const KEY: u64 = 0;
/// Nodes that may hold a board open at once: the plant, the daemon, a restarted one of each while
/// the dead one is not yet cleaned up, and observers.
const MAX_NODES: usize = 8;
/// Readers at once (the other loop, a restarted one, observers).
const MAX_READERS: usize = 4;

/// An opened blackboard with one entry of `T` under [`KEY`].
pub struct Board<T> {
    service: PortFactory<ipc::Service, u64>,
    _value: std::marker::PhantomData<T>,
}

/// The board's name: the pub-sub channel's name with `/board` appended.
fn board_name(names: &ServiceNames, channel: Channel) -> String {
    let base = match channel {
        Channel::State => names.state(),
        _ => names.command(),
    };
    format!("{base}/board")
}

impl<T: ZeroCopySend + Copy + Default + Debug + 'static> Board<T> {
    /// Opens the board of `channel` ([`Channel::State`] or [`Channel::Command`]), creating it if
    /// it does not exist yet. Either loop may come first; a race between two creators is retried.
    pub fn open(
        node: &Node<ipc::Service>,
        names: &ServiceNames,
        channel: Channel,
    ) -> Result<Self, ServiceError> {
        let name = board_name(names, channel);
        let sn = ServiceName::new(&name).map_err(|_| ServiceError::InvalidName { channel })?;
        let mut last = None;
        for _ in 0..20 {
            let opened = node
                .service_builder(&sn)
                .blackboard_opener::<u64>()
                .max_readers(MAX_READERS)
                .max_nodes(MAX_NODES)
                .open();
            let open_err = match opened {
                Ok(service) => return Ok(Self::wrap(service)),
                Err(e) => e,
            };
            let created = node
                .service_builder(&sn)
                .blackboard_creator::<u64>()
                .max_readers(MAX_READERS)
                .max_nodes(MAX_NODES)
                .add::<T>(KEY, T::default())
                .create();
            match created {
                Ok(service) => return Ok(Self::wrap(service)),
                Err(e) => last = Some((open_err, e)),
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        let (open, create) = last.expect("the loop ran at least once");
        Err(ServiceError::Board {
            channel,
            open,
            create,
        })
    }

    fn wrap(service: PortFactory<ipc::Service, u64>) -> Self {
        Self {
            service,
            _value: std::marker::PhantomData,
        }
    }

    /// The board's one writer. Fails while another process writes it.
    pub fn writer(&self) -> Result<BoardWriter<T>, PortError> {
        let w = self
            .service
            .writer_builder()
            .create()
            .map_err(PortError::of)?;
        let entry = w.entry::<T>(&KEY).map_err(PortError::of)?;
        Ok(BoardWriter { entry })
    }

    /// A reader that reports only values written after it was made: what is on the board now
    /// was written for somebody else (a previous run, a dead peer).
    pub fn reader(&self) -> Result<BoardReader<T>, PortError> {
        let r = self
            .service
            .reader_builder()
            .create()
            .map_err(PortError::of)?;
        let entry = r.entry::<T>(&KEY).map_err(PortError::of)?;
        let seen = entry.get();
        Ok(BoardReader {
            entry,
            seen: RefCell::new(seen),
        })
    }
}

/// Writes the newest value. No allocation, no syscall, no lock.
pub struct BoardWriter<T: Copy + 'static> {
    entry: EntryHandleMut<ipc::Service, u64, T>,
}

impl<T: Copy + Debug + ZeroCopySend + 'static> BoardWriter<T> {
    #[inline]
    pub fn write(&self, v: T) {
        self.entry.update_with_copy(v);
    }
}

/// Polls for a newer value. No allocation, no syscall, no lock.
pub struct BoardReader<T: Copy + 'static> {
    entry: EntryHandle<ipc::Service, u64, T>,
    seen: RefCell<BlackboardValue<T>>,
}

impl<T: Copy + Debug + ZeroCopySend + 'static> BoardReader<T> {
    /// The value written since the last call, if any. Each write is reported once; of several
    /// writes between two calls, only the newest.
    #[inline]
    pub fn take(&self) -> Option<T> {
        let mut seen = self.seen.borrow_mut();
        if self.entry.is_up_to_date(&seen) {
            return None;
        }
        *seen = self.entry.get();
        Some(**seen)
    }
}

/// Where a sample says who wrote it and its number in that writer's stream.
pub trait Origin: Copy + Default + Debug + ZeroCopySend + 'static {
    /// (the writer's instance id, the sample's sequence number)
    fn origin(&self) -> (u64, u64);
}

impl Origin for crate::StateSample {
    fn origin(&self) -> (u64, u64) {
        (self.plant_id, self.seq)
    }
}

impl Origin for crate::CommandSample {
    fn origin(&self) -> (u64, u64) {
        (self.daemon_id, self.seq)
    }
}

/// One loop's end of the fast lane: writes `Out` to its board, takes `In` from the other.
///
/// It also tells which samples that came by pub-sub were already taken from the board (their
/// copies), so the reader drops them before they are counted as repeats. Field order is drop
/// order: the entries before their boards.
pub struct Lane<Out: Origin, In: Origin> {
    out: BoardWriter<Out>,
    inn: BoardReader<In>,
    /// The newest sample taken from the board: its writer and sequence number.
    taken: core::cell::Cell<Option<(u64, u64)>>,
    _boards: (Board<Out>, Board<In>),
}

/// Why a board's port could not be made: iceoryx2's own refusal, in its words.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct PortError(pub String);

impl PortError {
    fn of(e: impl core::fmt::Debug) -> Self {
        Self(format!("{e:?}"))
    }
}

/// Why a lane could not be opened: which board, and which step.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LaneError {
    #[error(transparent)]
    Open(#[from] ServiceError),
    #[error("cannot write the {channel} board: {error}")]
    Write { channel: Channel, error: PortError },
    #[error("cannot read the {channel} board: {error}")]
    Read { channel: Channel, error: PortError },
}

/// The plant's end: states out, commands in.
pub type PlantLane = Lane<crate::StateSample, crate::CommandSample>;
/// The daemon's end: commands out, states in.
pub type DaemonLane = Lane<crate::CommandSample, crate::StateSample>;

impl<Out: Origin, In: Origin> Lane<Out, In> {
    /// Opens both boards and takes `out`'s one writer slot; the error says which step failed.
    fn open(
        node: &Node<ipc::Service>,
        names: &ServiceNames,
        out: Channel,
        inn: Channel,
    ) -> Result<Self, LaneError> {
        let out_board = Board::<Out>::open(node, names, out)?;
        let in_board = Board::<In>::open(node, names, inn)?;
        Ok(Self {
            out: out_board.writer().map_err(|error| LaneError::Write {
                channel: out,
                error,
            })?,
            inn: in_board.reader().map_err(|error| LaneError::Read {
                channel: inn,
                error,
            })?,
            taken: core::cell::Cell::new(None),
            _boards: (out_board, in_board),
        })
    }

    /// Puts a sample on the board. No allocation, no syscall, no lock.
    #[inline]
    pub fn write(&self, v: &Out) {
        self.out.write(*v);
    }

    /// The sample written to the other board since the last call, if any.
    #[inline]
    pub fn take(&self) -> Option<In> {
        let v = self.inn.take()?;
        self.taken.set(Some(v.origin()));
        Some(v)
    }

    /// Whether `v`, which came by pub-sub, was already taken from the board (its copy), or is
    /// older than one that was.
    #[inline]
    pub fn seen(&self, v: &In) -> bool {
        let (who, seq) = v.origin();
        self.taken.get().is_some_and(|(w, s)| w == who && seq <= s)
    }
}

impl PlantLane {
    /// The plant's end of the lane in `names`' namespace.
    pub fn plant(node: &Node<ipc::Service>, names: &ServiceNames) -> Result<Self, LaneError> {
        Self::open(node, names, Channel::State, Channel::Command)
    }
}

impl DaemonLane {
    /// The daemon's end of the lane in `names`' namespace.
    pub fn daemon(node: &Node<ipc::Service>, names: &ServiceNames) -> Result<Self, LaneError> {
        Self::open(node, names, Channel::Command, Channel::State)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::StateSample;

    fn names(tag: &str) -> ServiceNames {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .subsec_nanos();
        ServiceNames::new(&format!("board-{tag}-{}-{nanos}", std::process::id())).unwrap()
    }

    #[test]
    fn a_reader_sees_each_newest_value_once_and_nothing_from_before_it() {
        let names = names("once");
        let (a, b) = (crate::node("a").unwrap(), crate::node("b").unwrap());
        let wb = Board::<StateSample>::open(&a, &names, Channel::State).unwrap();
        let w = wb.writer().unwrap();
        let s = |seq| StateSample {
            seq,
            ..StateSample::default()
        };
        w.write(s(1)); // before any reader: nobody's business
        let rb = Board::<StateSample>::open(&b, &names, Channel::State).unwrap();
        let r = rb.reader().unwrap();
        assert_eq!(r.take().map(|v| v.seq), None);
        w.write(s(2));
        assert_eq!(r.take().map(|v| v.seq), Some(2));
        assert_eq!(r.take().map(|v| v.seq), None);
        w.write(s(3));
        w.write(s(4));
        assert_eq!(r.take().map(|v| v.seq), Some(4));
        assert_eq!(r.take().map(|v| v.seq), None);
        // One writer at most: a second process cannot write the same board.
        assert!(rb.writer().is_err());
        drop(w);
        assert!(rb.writer().is_ok());
    }

    #[test]
    fn a_lane_carries_both_ways_and_knows_the_pubsub_copies() {
        let names = names("lane");
        let (a, b) = (crate::node("a").unwrap(), crate::node("b").unwrap());
        let plant = PlantLane::plant(&a, &names).unwrap();
        let daemon = DaemonLane::daemon(&b, &names).unwrap();
        let s = StateSample {
            plant_id: 7,
            seq: 3,
            ..StateSample::default()
        };
        plant.write(&s);
        assert_eq!(daemon.take().map(|v| v.seq), Some(3));
        assert!(daemon.seen(&s), "the pub-sub copy of a taken state");
        assert!(
            daemon.seen(&StateSample { seq: 2, ..s }),
            "older than a taken one"
        );
        assert!(!daemon.seen(&StateSample { seq: 4, ..s }), "newer");
        assert!(
            !daemon.seen(&StateSample { plant_id: 8, ..s }),
            "another plant"
        );
        let c = crate::CommandSample {
            daemon_id: 5,
            seq: 1,
            state_seq: 3,
            ..crate::CommandSample::default()
        };
        assert!(!plant.seen(&c), "nothing taken yet");
        daemon.write(&c);
        assert_eq!(plant.take().map(|v| v.state_seq), Some(3));
        assert!(plant.seen(&c));
        // A second plant in the namespace cannot take the state board's writer slot.
        assert!(PlantLane::plant(&crate::node("c").unwrap(), &names).is_err());
    }

    #[test]
    fn the_state_and_command_boards_are_separate_services() {
        let names = names("sep");
        let n = crate::node("n").unwrap();
        let st = Board::<StateSample>::open(&n, &names, Channel::State).unwrap();
        let cm = Board::<crate::CommandSample>::open(&n, &names, Channel::Command).unwrap();
        let (sw, cr) = (st.writer().unwrap(), cm.reader().unwrap());
        sw.write(StateSample {
            seq: 9,
            ..StateSample::default()
        });
        assert!(cr.take().is_none());
    }
}
