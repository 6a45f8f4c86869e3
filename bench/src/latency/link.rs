//! The transports compared by `latency`, behind one two-line interface, [`Link`].
//!
//! Each transport carries a [`StateSample`] one way and a [`CommandSample`] back, the daemon's
//! real payloads, so every series moves the same bytes. The ping and pong loops
//! ([`ping_block`], [`pong_block`]) are generic over the link and monomorphised per transport, so
//! the loop around the transport is identical code for all of them and costs the same.
//!
//! Links never wait forever: a receive gives up after its timeout with an error, so a dead or
//! wedged peer is reported instead of hanging the benchmark. Busy-polling links read the clock
//! only after many empty polls, so the timeout costs nothing on the fast path.

use anyhow::{anyhow, bail, Context, Result};
use hdrhistogram::Histogram;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{ipc, CallbackProgression, ServiceName, ZeroCopySend};
use iceoryx2::waitset::{WaitSet, WaitSetGuard};
use protocol::{monotonic_ns, CommandSample, Mode, ServiceNames, StateSample, MAX_JOINTS};
use rt::WaitStrategy;

/// An opened iceoryx2 event service (the benchmark's wake-up path).
type EventsService<S> = iceoryx2::service::port_factory::event::PortFactory<S>;
use std::cell::{Cell, UnsafeCell};
use std::fmt::Debug;
use std::mem::MaybeUninit;
use std::net::UdpSocket;
use std::os::fd::{AsRawFd, FromRawFd, RawFd};
use std::os::unix::net::UnixStream;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// One endpoint of a two-way link: sends `Out`, receives `In`.
pub trait Link<Out, In> {
    fn send(&self, v: &Out) -> Result<()>;
    /// The next message, or an error after `timeout`.
    fn recv(&self, timeout: Duration) -> Result<In>;
}

/// A message type for which every bit pattern is a valid value, so it may be received as raw
/// bytes from a socket.
///
/// # Safety
/// The type must be `#[repr(C)]`, `Copy`, and made of integers and floats only (no bool, enum,
/// reference or pointer). Padding, if any, is never read as bytes here: it is written and read
/// only by the kernel (see `send_raw` / `recv_raw`).
pub unsafe trait AnyBits: Copy + 'static {}

// SAFETY: protocol's samples are repr(C) with u64/u32/f64 fields and arrays of them only; enum-like
// values (mode, flags) travel as plain u32 (see protocol::sample).
unsafe impl AnyBits for StateSample {}
// SAFETY: as above.
unsafe impl AnyBits for CommandSample {}

/// Writes `v` whole to a socket. The bytes are handed to the kernel by pointer, never viewed as a
/// Rust byte slice, so a padding byte is never read by Rust code.
fn send_raw<T: AnyBits>(fd: RawFd, v: &T) -> Result<()> {
    let (ptr, len) = ((v as *const T).cast::<u8>(), std::mem::size_of::<T>());
    let mut sent = 0;
    while sent < len {
        // SAFETY: ptr..ptr+len is the value `v`, alive for the call.
        let n = unsafe { libc::send(fd, ptr.add(sent).cast(), len - sent, libc::MSG_NOSIGNAL) };
        if n < 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() == std::io::ErrorKind::Interrupted {
                continue;
            }
            return Err(e).context("socket send failed");
        }
        sent += n as usize;
    }
    Ok(())
}

/// Reads one `T` from a socket (a whole datagram, or `size_of::<T>()` bytes of a stream); the
/// socket's receive timeout bounds the wait.
fn recv_raw<T: AnyBits>(fd: RawFd, stream: bool) -> Result<T> {
    let mut v = MaybeUninit::<T>::uninit();
    let len = std::mem::size_of::<T>();
    let flags = if stream {
        libc::MSG_WAITALL
    } else {
        libc::MSG_TRUNC
    };
    loop {
        // SAFETY: v is writable for len bytes.
        let n = unsafe { libc::recv(fd, v.as_mut_ptr().cast(), len, flags) };
        if n < 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() == std::io::ErrorKind::Interrupted {
                continue;
            }
            return Err(e).context("socket receive failed (or timed out)");
        }
        if n as usize != len {
            bail!("received a message of {n} bytes, expected {len}");
        }
        // SAFETY: all len bytes were written by the kernel, and every bit pattern is a valid T.
        return Ok(unsafe { v.assume_init() });
    }
}

/// Polls `ready` until it yields, reading the clock only every 1024 empty polls.
#[inline(always)]
fn spin_until<T>(timeout: Duration, mut ready: impl FnMut() -> Result<Option<T>>) -> Result<T> {
    let mut spins = 0u32;
    let mut deadline = 0u64;
    loop {
        if let Some(v) = ready()? {
            return Ok(v);
        }
        core::hint::spin_loop();
        spins = spins.wrapping_add(1);
        if spins.is_multiple_of(1024) {
            let now = monotonic_ns();
            if deadline == 0 {
                deadline = now + timeout.as_nanos() as u64;
            } else if now > deadline {
                bail!("no message within {timeout:?}");
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The floor: a sequence number and a payload in shared memory, spun on.

/// One direction of the shared-memory link, on its own cache lines (128 B: the adjacent-line
/// prefetcher pairs lines), so the two directions never share a line.
#[repr(C, align(128))]
pub struct Slot<T> {
    seq: AtomicU64,
    data: UnsafeCell<MaybeUninit<T>>,
}

/// The shared area: parent → peer and peer → parent.
#[repr(C)]
pub struct Area {
    ping: Slot<StateSample>,
    pong: Slot<CommandSample>,
}

// SAFETY: the payload cell is only written by the one sender of its direction and read by the
// one receiver after the Release/Acquire hand-over of `seq`; strict ping-pong means a payload is
// never written while it is being read.
unsafe impl<T: Send> Sync for Slot<T> {}

/// A shared mapping of an [`Area`]: a memfd the peer process inherits, or anonymous (threads).
pub struct ShmRegion {
    ptr: *mut Area,
    len: usize,
    fd: Option<RawFd>,
}

// SAFETY: the region only hands out `&Area`, which is Sync; the descriptor and the mapping
// itself are only changed through `&mut self` or on drop.
unsafe impl Sync for ShmRegion {}
// SAFETY: as above; the mapping is process-wide, not tied to a thread.
unsafe impl Send for ShmRegion {}

impl ShmRegion {
    fn map(fd: RawFd, len: usize) -> Result<*mut Area> {
        let flags = if fd < 0 {
            libc::MAP_SHARED | libc::MAP_ANONYMOUS
        } else {
            libc::MAP_SHARED
        };
        // SAFETY: a fresh mapping of `len` bytes; the kernel zero-fills it (a valid Area: zero
        // sequence numbers, uninitialised payloads).
        let p = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ | libc::PROT_WRITE,
                flags,
                fd,
                0,
            )
        };
        if p == libc::MAP_FAILED {
            bail!(
                "mmap of the shared area failed: {}",
                std::io::Error::last_os_error()
            );
        }
        Ok(p.cast())
    }

    fn len() -> usize {
        std::mem::size_of::<Area>().next_multiple_of(4096)
    }

    /// A memfd mapping whose descriptor (not close-on-exec) a child process inherits.
    pub fn create() -> Result<Self> {
        let len = Self::len();
        // SAFETY: a NUL-terminated name; flags 0 = no MFD_CLOEXEC, on purpose.
        let fd = unsafe { libc::memfd_create(c"chaosd-bench-floor".as_ptr(), 0) };
        if fd < 0 {
            bail!("memfd_create failed: {}", std::io::Error::last_os_error());
        }
        // SAFETY: our own descriptor.
        if unsafe { libc::ftruncate(fd, len as libc::off_t) } != 0 {
            let e = std::io::Error::last_os_error();
            // SAFETY: closing our own descriptor.
            unsafe { libc::close(fd) };
            bail!("ftruncate of the memfd failed: {e}");
        }
        let ptr = Self::map(fd, len).inspect_err(|_| {
            // SAFETY: closing our own descriptor.
            unsafe { libc::close(fd) };
        })?;
        Ok(Self {
            ptr,
            len,
            fd: Some(fd),
        })
    }

    /// Maps an inherited memfd and closes the descriptor (the mapping stays).
    pub fn open(fd: RawFd) -> Result<Self> {
        let ptr = Self::map(fd, Self::len())
            .with_context(|| format!("cannot map the inherited memfd {fd}"))?;
        // SAFETY: the descriptor was handed to us and is no longer needed.
        unsafe { libc::close(fd) };
        Ok(Self {
            ptr,
            len: Self::len(),
            fd: None,
        })
    }

    /// An anonymous shared mapping, for two threads of one process (the tests).
    #[cfg(test)]
    pub fn anonymous() -> Result<Self> {
        Ok(Self {
            ptr: Self::map(-1, Self::len())?,
            len: Self::len(),
            fd: None,
        })
    }

    pub fn fd(&self) -> Option<RawFd> {
        self.fd
    }

    /// Closes the descriptor once the child has inherited it.
    pub fn close_fd(&mut self) {
        if let Some(fd) = self.fd.take() {
            // SAFETY: our own descriptor, closed once.
            unsafe { libc::close(fd) };
        }
    }

    fn area(&self) -> &Area {
        // SAFETY: mapped, zero-initialised, suitably aligned (page-aligned) and alive while self is.
        unsafe { &*self.ptr }
    }

    /// The parent's end: sends states, receives commands.
    ///
    /// A link starts from the sequence numbers it finds, so both ends must be created before the
    /// first message is sent.
    pub fn parent(&self) -> ShmLink<'_, StateSample, CommandSample> {
        ShmLink::new(&self.area().ping, &self.area().pong)
    }

    /// The peer's end.
    pub fn peer(&self) -> ShmLink<'_, CommandSample, StateSample> {
        ShmLink::new(&self.area().pong, &self.area().ping)
    }
}

impl Drop for ShmRegion {
    fn drop(&mut self) {
        self.close_fd();
        // SAFETY: unmapping our own mapping once; no link outlives the region (borrowed from it).
        unsafe { libc::munmap(self.ptr.cast(), self.len) };
    }
}

pub struct ShmLink<'a, Out, In> {
    out: &'a Slot<Out>,
    inn: &'a Slot<In>,
    sent: Cell<u64>,
    seen: Cell<u64>,
}

impl<'a, Out, In> ShmLink<'a, Out, In> {
    fn new(out: &'a Slot<Out>, inn: &'a Slot<In>) -> Self {
        Self {
            out,
            inn,
            sent: Cell::new(out.seq.load(Ordering::Acquire)),
            seen: Cell::new(inn.seq.load(Ordering::Acquire)),
        }
    }
}

impl<Out: Copy, In: Copy> Link<Out, In> for ShmLink<'_, Out, In> {
    #[inline]
    fn send(&self, v: &Out) -> Result<()> {
        // SAFETY: only this end writes `out`, and the receiver reads it only after the store below.
        unsafe { (*self.out.data.get()).write(*v) };
        let n = self.sent.get() + 1;
        self.sent.set(n);
        self.out.seq.store(n, Ordering::Release);
        Ok(())
    }

    #[inline]
    fn recv(&self, timeout: Duration) -> Result<In> {
        let expected = self.seen.get() + 1;
        let got = spin_until(timeout, || {
            let s = self.inn.seq.load(Ordering::Acquire);
            Ok((s != self.seen.get()).then_some(s))
        })?;
        if got != expected {
            bail!(
                "shared-memory sequence jumped from {} to {got}",
                expected - 1
            );
        }
        self.seen.set(got);
        // SAFETY: the Acquire load saw the writer's Release store after it wrote the payload.
        Ok(unsafe { (*self.inn.data.get()).assume_init_read() })
    }
}

// ---------------------------------------------------------------------------------------------
// iceoryx2: the daemon's state and command services (its QoS), plus one event service per
// direction for the wake-up variants.

fn node() -> Result<iceoryx2::node::Node<ipc::Service>> {
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    iceoryx2::prelude::NodeBuilder::new()
        .signal_handling_mode(iceoryx2::prelude::SignalHandlingMode::Disabled)
        .config(&iceoryx2::config::Config::default())
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("cannot create an iceoryx2 node: {e:?}"))
}

fn wake_service(
    node: &iceoryx2::node::Node<ipc::Service>,
    names: &ServiceNames,
    dir: &str,
) -> Result<EventsService<ipc::Service>> {
    let name = format!("chaosd-bench/{}/{dir}-wake", names.namespace());
    node.service_builder(
        &ServiceName::new(&name).map_err(|e| anyhow!("bad service name {name}: {e:?}"))?,
    )
    .event()
    .max_notifiers(1)
    .max_listeners(1)
    .max_nodes(2)
    .open_or_create()
    .map_err(|e| anyhow!("cannot open the event service {name}: {e:?}"))
}

/// The iceoryx2 ports of one side. Field order is drop order: ports before their services,
/// services before the node.
pub struct IoxPorts<Out: Debug + ZeroCopySend + 'static, In: Debug + ZeroCopySend + 'static> {
    publisher: Publisher<ipc::Service, Out, ()>,
    subscriber: Subscriber<ipc::Service, In, ()>,
    notifier: Notifier<ipc::Service>,
    listener: Listener<ipc::Service>,
    _services: (
        protocol::StateService<ipc::Service>,
        protocol::CommandService<ipc::Service>,
        EventsService<ipc::Service>,
        EventsService<ipc::Service>,
    ),
    _node: iceoryx2::node::Node<ipc::Service>,
}

type Services = (
    iceoryx2::node::Node<ipc::Service>,
    protocol::StateService<ipc::Service>,
    protocol::CommandService<ipc::Service>,
    EventsService<ipc::Service>,
    EventsService<ipc::Service>,
);

fn services(names: &ServiceNames) -> Result<Services> {
    let node = node()?;
    let state = protocol::open_state_service(&node, names)?;
    let command = protocol::open_command_service(&node, names)?;
    let ping = wake_service(&node, names, "ping")?;
    let pong = wake_service(&node, names, "pong")?;
    Ok((node, state, command, ping, pong))
}

fn port_err<E: Debug>(what: &'static str) -> impl FnOnce(E) -> anyhow::Error {
    move |e| anyhow!("cannot create the {what}: {e:?}")
}

impl IoxPorts<StateSample, CommandSample> {
    /// The parent: publishes states and wakes the peer; subscribes to commands.
    pub fn parent(names: &ServiceNames) -> Result<Self> {
        let (node, state, command, ping, pong) = services(names)?;
        Ok(Self {
            publisher: state
                .publisher_builder()
                .create()
                .map_err(port_err("state publisher"))?,
            subscriber: command
                .subscriber_builder()
                .create()
                .map_err(port_err("command subscriber"))?,
            notifier: ping
                .notifier_builder()
                .create()
                .map_err(port_err("ping notifier"))?,
            listener: pong
                .listener_builder()
                .create()
                .map_err(port_err("pong listener"))?,
            _services: (state, command, ping, pong),
            _node: node,
        })
    }
}

impl IoxPorts<CommandSample, StateSample> {
    /// The peer: the mirror image.
    pub fn peer(names: &ServiceNames) -> Result<Self> {
        let (node, state, command, ping, pong) = services(names)?;
        Ok(Self {
            publisher: command
                .publisher_builder()
                .create()
                .map_err(port_err("command publisher"))?,
            subscriber: state
                .subscriber_builder()
                .create()
                .map_err(port_err("state subscriber"))?,
            notifier: pong
                .notifier_builder()
                .create()
                .map_err(port_err("pong notifier"))?,
            listener: ping
                .listener_builder()
                .create()
                .map_err(port_err("ping listener"))?,
            _services: (state, command, ping, pong),
            _node: node,
        })
    }
}

impl<Out: Debug + ZeroCopySend + Copy, In: Debug + ZeroCopySend + Copy> IoxPorts<Out, In> {
    /// The daemon's publish path: loan a slot, write, send.
    #[inline]
    fn publish(&self, v: &Out) -> Result<()> {
        let s = self
            .publisher
            .loan_uninit()
            .map_err(|e| anyhow!("iceoryx2 loan failed: {e:?}"))?;
        s.write_payload(*v)
            .send()
            .map_err(|e| anyhow!("iceoryx2 send failed: {e:?}"))?;
        Ok(())
    }

    #[inline]
    fn take(&self) -> Result<Option<In>> {
        match self.subscriber.receive() {
            Ok(Some(s)) => Ok(Some(*s)),
            Ok(None) => Ok(None),
            Err(e) => Err(anyhow!("iceoryx2 receive failed: {e:?}")),
        }
    }

    fn notify(&self) -> Result<()> {
        self.notifier
            .notify()
            .map_err(|e| anyhow!("iceoryx2 notify failed: {e:?}"))?;
        Ok(())
    }

    /// Receive after wake-ups from `wait` (which gets the time left), until a sample is there.
    fn recv_woken(
        &self,
        timeout: Duration,
        mut wait: impl FnMut(Duration) -> Result<()>,
    ) -> Result<In> {
        let start = monotonic_ns();
        let limit = timeout.as_nanos() as u64;
        loop {
            let waited = monotonic_ns() - start;
            if waited > limit {
                bail!("no message within {timeout:?}");
            }
            wait(Duration::from_nanos(limit - waited))?;
            if let Some(v) = self.take()? {
                return Ok(v);
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// iceoryx2 blackboard: one latest-value entry per direction, polled through its generation
// counter. No loan, no queue, no sample returned: a write is a copy into a free cell and one
// counter increment, and an empty poll is one relaxed load.

type Board = iceoryx2::service::port_factory::blackboard::PortFactory<ipc::Service, u64>;
type BoardWriter<T> = iceoryx2::port::writer::EntryHandleMut<ipc::Service, u64, T>;
type BoardReader<T> = iceoryx2::port::reader::EntryHandle<ipc::Service, u64, T>;
type BoardValue<T> = iceoryx2::port::reader::BlackboardValue<T>;

/// Where a payload carries its round-trip number.
pub trait Numbered: Copy + Default + Debug + ZeroCopySend + 'static {
    fn number(&self) -> u64;
}

impl Numbered for StateSample {
    fn number(&self) -> u64 {
        self.seq
    }
}

impl Numbered for CommandSample {
    fn number(&self) -> u64 {
        self.state_seq
    }
}

fn board_name(names: &ServiceNames, dir: &str) -> Result<ServiceName> {
    let name = format!("chaosd-bench/{}/{dir}-board", names.namespace());
    ServiceName::new(&name).map_err(|e| anyhow!("bad service name {name}: {e:?}"))
}

fn create_board<T: Numbered>(
    node: &iceoryx2::node::Node<ipc::Service>,
    names: &ServiceNames,
    dir: &str,
) -> Result<Board> {
    node.service_builder(&board_name(names, dir)?)
        .blackboard_creator::<u64>()
        .max_readers(1)
        .max_nodes(2)
        .add::<T>(0, T::default())
        .create()
        .map_err(|e| anyhow!("cannot create the {dir} blackboard: {e:?}"))
}

fn open_board(
    node: &iceoryx2::node::Node<ipc::Service>,
    names: &ServiceNames,
    dir: &str,
) -> Result<Board> {
    node.service_builder(&board_name(names, dir)?)
        .blackboard_opener::<u64>()
        .open()
        .map_err(|e| anyhow!("cannot open the {dir} blackboard: {e:?}"))
}

/// One side's blackboard entries. Field order is drop order: entries before their services,
/// services before the node.
pub struct BoardLink<Out: Numbered, In: Numbered> {
    out: BoardWriter<Out>,
    inn: BoardReader<In>,
    /// The newest value read, whose generation an empty poll compares against.
    last: std::cell::RefCell<Option<BoardValue<In>>>,
    _boards: (Board, Board),
    _node: iceoryx2::node::Node<ipc::Service>,
}

impl<Out: Numbered, In: Numbered> BoardLink<Out, In> {
    fn new(node: iceoryx2::node::Node<ipc::Service>, out: Board, inn: Board) -> Result<Self> {
        let writer = out
            .writer_builder()
            .create()
            .map_err(port_err("blackboard writer"))?;
        let reader = inn
            .reader_builder()
            .create()
            .map_err(port_err("blackboard reader"))?;
        Ok(Self {
            out: writer
                .entry::<Out>(&0)
                .map_err(port_err("blackboard writer entry"))?,
            inn: reader
                .entry::<In>(&0)
                .map_err(port_err("blackboard reader entry"))?,
            last: std::cell::RefCell::new(None),
            _boards: (out, inn),
            _node: node,
        })
    }
}

impl BoardLink<StateSample, CommandSample> {
    /// The parent creates both blackboards (before the peer starts) and writes states.
    pub fn parent(names: &ServiceNames) -> Result<Self> {
        let node = node()?;
        let ping = create_board::<StateSample>(&node, names, "ping")?;
        let pong = create_board::<CommandSample>(&node, names, "pong")?;
        Self::new(node, ping, pong)
    }
}

impl BoardLink<CommandSample, StateSample> {
    /// The peer opens them and writes commands.
    pub fn peer(names: &ServiceNames) -> Result<Self> {
        let node = node()?;
        let ping = open_board(&node, names, "ping")?;
        let pong = open_board(&node, names, "pong")?;
        Self::new(node, pong, ping)
    }
}

impl<Out: Numbered, In: Numbered> Link<Out, In> for BoardLink<Out, In> {
    #[inline]
    fn send(&self, v: &Out) -> Result<()> {
        self.out.update_with_copy(*v);
        Ok(())
    }

    #[inline]
    fn recv(&self, timeout: Duration) -> Result<In> {
        let mut last = self.last.borrow_mut();
        let seen = last.as_ref().map_or(0, |v| v.number());
        let v = spin_until(timeout, || {
            if last.as_ref().is_some_and(|v| self.inn.is_up_to_date(v)) {
                return Ok(None);
            }
            let v = self.inn.get();
            let fresh = v.number() != seen;
            *last = Some(v);
            Ok(fresh.then_some(()))
        });
        v?;
        Ok(**last.as_ref().expect("a fresh value was just stored"))
    }
}

/// iceoryx2, the receiver busy-polls its subscriber (what the daemon's loop does each tick).
pub struct IoxPoll<'a, Out: Debug + ZeroCopySend + 'static, In: Debug + ZeroCopySend + 'static>(
    pub &'a IoxPorts<Out, In>,
);

impl<Out: Debug + ZeroCopySend + Copy, In: Debug + ZeroCopySend + Copy> Link<Out, In>
    for IoxPoll<'_, Out, In>
{
    #[inline]
    fn send(&self, v: &Out) -> Result<()> {
        self.0.publish(v)
    }
    #[inline]
    fn recv(&self, timeout: Duration) -> Result<In> {
        spin_until(timeout, || self.0.take())
    }
}

/// iceoryx2 with an event per sample; the receiver sleeps in `Listener::timed_wait`.
pub struct IoxListen<'a, Out: Debug + ZeroCopySend + 'static, In: Debug + ZeroCopySend + 'static>(
    pub &'a IoxPorts<Out, In>,
);

impl<Out: Debug + ZeroCopySend + Copy, In: Debug + ZeroCopySend + Copy> Link<Out, In>
    for IoxListen<'_, Out, In>
{
    fn send(&self, v: &Out) -> Result<()> {
        self.0.publish(v)?;
        self.0.notify()
    }
    fn recv(&self, timeout: Duration) -> Result<In> {
        let l = &self.0.listener;
        self.0.recv_woken(timeout, |left| {
            l.timed_wait(|_| {}, left)
                .map_err(|e| anyhow!("iceoryx2 listener wait failed: {e:?}"))?;
            Ok(())
        })
    }
}

/// iceoryx2 with an event per sample; the receiver sleeps in a `WaitSet` (epoll) with the
/// listener attached. The WaitSet borrows the ports, so it is built per block (outside timing).
pub struct IoxWaitSet<
    'a,
    'w,
    'g,
    Out: Debug + ZeroCopySend + 'static,
    In: Debug + ZeroCopySend + 'static,
> {
    ports: &'a IoxPorts<Out, In>,
    waitset: &'w WaitSet<ipc::Service>,
    guard: &'g WaitSetGuard<'w, 'a, ipc::Service>,
}

/// A WaitSet that leaves signals to us, as every chaosd process does.
pub fn waitset() -> Result<WaitSet<ipc::Service>> {
    iceoryx2::prelude::WaitSetBuilder::new()
        .signal_handling_mode(iceoryx2::prelude::SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("cannot create a WaitSet: {e:?}"))
}

/// Runs `body` with a WaitSet link over `ports`.
pub fn with_waitset<Out, In, R>(
    ports: &IoxPorts<Out, In>,
    body: impl FnOnce(&IoxWaitSet<'_, '_, '_, Out, In>) -> Result<R>,
) -> Result<R>
where
    Out: Debug + ZeroCopySend + Copy,
    In: Debug + ZeroCopySend + Copy,
{
    let ws = waitset()?;
    let guard = ws
        .attach_notification(&ports.listener)
        .map_err(|e| anyhow!("cannot attach the listener to the WaitSet: {e:?}"))?;
    let link = IoxWaitSet {
        ports,
        waitset: &ws,
        guard: &guard,
    };
    body(&link)
}

impl<Out: Debug + ZeroCopySend + Copy, In: Debug + ZeroCopySend + Copy> Link<Out, In>
    for IoxWaitSet<'_, '_, '_, Out, In>
{
    fn send(&self, v: &Out) -> Result<()> {
        self.ports.publish(v)?;
        self.ports.notify()
    }
    fn recv(&self, timeout: Duration) -> Result<In> {
        let (l, ws, guard) = (&self.ports.listener, self.waitset, self.guard);
        self.ports.recv_woken(timeout, |left| {
            ws.wait_and_process_once_with_timeout(
                |id| {
                    if id.has_event_from(guard) {
                        // Consume the event, or the WaitSet fires again at once.
                        let _ = l.try_wait(|_| {});
                    }
                    CallbackProgression::Continue
                },
                left,
            )
            .map_err(|e| anyhow!("WaitSet wait failed: {e:?}"))?;
            Ok(())
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Kernel sockets.

/// A connected Unix stream socket (blocking, with a read timeout).
pub struct UnixLink(pub UnixStream);

/// A socketpair: the parent's end (close-on-exec) and the raw descriptor of the peer's end (not
/// close-on-exec, for the child to inherit).
pub fn unix_pair() -> Result<(UnixStream, RawFd)> {
    let mut fds = [0; 2];
    // SAFETY: fds has room for the two descriptors.
    if unsafe { libc::socketpair(libc::AF_UNIX, libc::SOCK_STREAM, 0, fds.as_mut_ptr()) } != 0 {
        bail!("socketpair failed: {}", std::io::Error::last_os_error());
    }
    // SAFETY: fds[0] is ours; mark it close-on-exec so other children do not inherit it.
    unsafe { libc::fcntl(fds[0], libc::F_SETFD, libc::FD_CLOEXEC) };
    // SAFETY: a fresh descriptor owned from here on by the UnixStream.
    Ok((unsafe { UnixStream::from_raw_fd(fds[0]) }, fds[1]))
}

impl UnixLink {
    pub fn new(s: UnixStream, timeout: Duration) -> Result<Self> {
        s.set_read_timeout(Some(timeout))?;
        Ok(Self(s))
    }
}

impl<Out: AnyBits, In: AnyBits> Link<Out, In> for UnixLink {
    fn send(&self, v: &Out) -> Result<()> {
        send_raw(self.0.as_raw_fd(), v).context("Unix socket")
    }
    fn recv(&self, _timeout: Duration) -> Result<In> {
        recv_raw(self.0.as_raw_fd(), true).context("Unix socket")
    }
}

/// A connected UDP socket on 127.0.0.1 (blocking, with a read timeout).
pub struct UdpLink(pub UdpSocket);

impl UdpLink {
    pub fn new(s: UdpSocket, timeout: Duration) -> Result<Self> {
        s.set_read_timeout(Some(timeout))?;
        Ok(Self(s))
    }
}

impl<Out: AnyBits, In: AnyBits> Link<Out, In> for UdpLink {
    fn send(&self, v: &Out) -> Result<()> {
        send_raw(self.0.as_raw_fd(), v).context("UDP")
    }
    fn recv(&self, _timeout: Duration) -> Result<In> {
        recv_raw(self.0.as_raw_fd(), false).context("UDP")
    }
}

// ---------------------------------------------------------------------------------------------
// Threads of one process.

/// Bounded crossbeam channels, one per direction, between two threads.
pub struct ChanLink<Out, In> {
    pub tx: crossbeam::channel::Sender<Out>,
    pub rx: crossbeam::channel::Receiver<In>,
}

impl<Out: Copy, In> Link<Out, In> for ChanLink<Out, In> {
    fn send(&self, v: &Out) -> Result<()> {
        self.tx
            .send(*v)
            .map_err(|_| anyhow!("the channel's peer thread is gone"))
    }
    fn recv(&self, timeout: Duration) -> Result<In> {
        self.rx
            .recv_timeout(timeout)
            .map_err(|e| anyhow!("channel receive: {e}"))
    }
}

// ---------------------------------------------------------------------------------------------
// The loops.

/// The peer's answer: a command that echoes the state's identity and touches its payload, as a
/// controller's would.
#[inline]
pub fn answer(s: &StateSample) -> CommandSample {
    let mut qdd = [0.0; MAX_JOINTS];
    for (a, (q, qd)) in qdd.iter_mut().zip(s.q.iter().zip(&s.qd)) {
        *a = -q - qd;
    }
    CommandSample {
        seq: s.seq,
        state_seq: s.seq,
        state_stamp_ns: s.stamp_ns,
        daemon_id: 1,
        mode: Mode::Run as u32,
        n: s.n,
        qdd,
        ..CommandSample::default()
    }
}

/// Runs `warm + n` round trips, recording the last `n` in `h` (ns). `seq` numbers the states
/// across blocks. Every reply must answer the state just sent, or the block fails.
pub fn ping_block<L: Link<StateSample, CommandSample>>(
    link: &L,
    seq: &mut u64,
    warm: usize,
    n: usize,
    timeout: Duration,
    pace: Option<Pace>,
    h: &mut Histogram<u64>,
) -> Result<()> {
    let mut next = monotonic_ns();
    let mut s = StateSample {
        plant_id: 1,
        n: 3,
        q: std::array::from_fn(|i| [0.1, 0.2, 0.3].get(i).copied().unwrap_or(0.0)),
        qd: [0.01; MAX_JOINTS],
        ..StateSample::default()
    };
    for i in 0..warm + n {
        if let Some(p) = pace {
            next = p.wait(next);
        }
        *seq += 1;
        s.seq = *seq;
        let t0 = monotonic_ns();
        s.stamp_ns = t0;
        link.send(&s)?;
        let c = link
            .recv(timeout)
            .with_context(|| format!("waiting for the reply to state {}", s.seq))?;
        let t1 = monotonic_ns();
        if c.state_seq != s.seq || c.state_stamp_ns != t0 {
            bail!(
                "the reply to state {} (stamp {t0}) answers state {} (stamp {})",
                s.seq,
                c.state_seq,
                c.state_stamp_ns
            );
        }
        if i >= warm {
            h.saturating_record((t1 - t0).max(1));
        }
    }
    Ok(())
}

/// Round trips spaced at a control loop's period instead of back to back.
///
/// Why: back to back, both sides stay hot in the caches and on the CPU. A controller at 1 kHz
/// sends once per millisecond and waits in between, and on a shared host its caches and its
/// vCPU go cold in that millisecond. Paced, the same ping-pong is the floor under the end-to-end
/// state → command latency at that rate: what no daemon code can go below on this machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pace {
    pub period_ns: u64,
    /// How the sender waits for its next period (the daemon's and the plant's strategies).
    pub wait: WaitStrategy,
    /// The hybrid wait's spin window.
    pub spin_ns: u64,
}

impl Pace {
    /// Waits for the period after `last` (or, behind schedule, not at all) and returns its start.
    pub fn wait(&self, last: u64) -> u64 {
        let due = last + self.period_ns;
        let now = monotonic_ns();
        if due <= now {
            return now;
        }
        rt::wait_until(due, self.wait, self.spin_ns);
        due
    }
}

/// Answers `n` states.
pub fn pong_block<L: Link<CommandSample, StateSample>>(
    link: &L,
    n: usize,
    timeout: Duration,
) -> Result<()> {
    for i in 0..n {
        let s = link
            .recv(timeout)
            .with_context(|| format!("waiting for state {} of {n} of the block", i + 1))?;
        link.send(&answer(&s))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::histogram;

    const T: Duration = Duration::from_secs(10);

    #[test]
    fn a_pace_waits_one_period_or_restarts_when_behind() {
        let p = Pace {
            period_ns: 200_000,
            wait: WaitStrategy::Hybrid,
            spin_ns: 50_000,
        };
        let t0 = monotonic_ns();
        let t1 = p.wait(t0);
        assert_eq!(t1, t0 + 200_000);
        assert!(monotonic_ns() >= t1);
        // Far behind: no wait, and the schedule restarts from now.
        let before = monotonic_ns();
        let t2 = p.wait(t0 - 1_000_000_000);
        assert!(t2 >= before);
    }

    #[test]
    fn paced_ping_pong_records_every_round_trip() {
        let region = ShmRegion::anonymous().unwrap();
        let (parent, peer) = (region.parent(), region.peer());
        let pace = Pace {
            period_ns: 100_000,
            wait: WaitStrategy::Sleep,
            spin_ns: 0,
        };
        std::thread::scope(|s| {
            s.spawn(move || pong_block(&peer, 50, T).unwrap());
            let (mut h, mut seq) = (histogram(), 0);
            let t0 = monotonic_ns();
            ping_block(&parent, &mut seq, 0, 50, T, Some(pace), &mut h).unwrap();
            assert_eq!(h.len(), 50);
            // 50 periods of 100 µs: the pings waited for them.
            assert!(monotonic_ns() - t0 >= 50 * 100_000);
        });
    }

    #[test]
    fn blackboard_ping_pong_between_threads_answers_every_state() {
        let _g = crate::iox_test_lock();
        let names = ServiceNames::new(&crate::latency::unique_namespace("board")).unwrap();
        let parent = BoardLink::parent(&names).unwrap();
        let n = 2_000;
        std::thread::scope(|s| {
            let names = &names;
            s.spawn(move || pong_block(&BoardLink::peer(names).unwrap(), n + 10, T).unwrap());
            let (mut h, mut seq) = (histogram(), 0);
            // ping_block fails on any reply that answers another state than the one just sent.
            ping_block(&parent, &mut seq, 10, n, T, None, &mut h).unwrap();
            assert_eq!(h.len(), n as u64);
        });
    }

    #[test]
    fn shared_memory_ping_pong_between_threads() {
        let region = ShmRegion::anonymous().unwrap();
        let n = 20_000;
        let (parent, peer) = (region.parent(), region.peer());
        std::thread::scope(|s| {
            s.spawn(move || pong_block(&peer, n + 10, T).unwrap());
            let mut h = histogram();
            let mut seq = 0;
            ping_block(&parent, &mut seq, 10, n, T, None, &mut h).unwrap();
            assert_eq!(h.len(), n as u64);
            assert_eq!(seq, n as u64 + 10);
        });
    }

    #[test]
    fn a_silent_peer_times_out() {
        let region = ShmRegion::anonymous().unwrap();
        let e = ping_block(
            &region.parent(),
            &mut 0,
            0,
            1,
            Duration::from_millis(50),
            None,
            &mut histogram(),
        )
        .unwrap_err();
        assert!(format!("{e:#}").contains("no message within 50ms"), "{e:#}");
    }

    /// A link whose peer answers the wrong state.
    struct Confused;
    impl Link<StateSample, CommandSample> for Confused {
        fn send(&self, _: &StateSample) -> Result<()> {
            Ok(())
        }
        fn recv(&self, _: Duration) -> Result<CommandSample> {
            Ok(answer(&StateSample {
                seq: 99,
                ..StateSample::default()
            }))
        }
    }

    #[test]
    fn a_reply_to_another_state_fails_the_block() {
        let e = ping_block(&Confused, &mut 0, 0, 5, T, None, &mut histogram())
            .unwrap_err()
            .to_string();
        assert!(e.contains("the reply to state 1"), "{e}");
    }

    #[test]
    fn sockets_and_channels_carry_the_samples() {
        let (a, b) = unix_pair().unwrap();
        // SAFETY: b is a fresh descriptor from unix_pair, owned by this stream from here on.
        let b = unsafe { UnixStream::from_raw_fd(b) };
        let (pa, pb) = (UnixLink::new(a, T).unwrap(), UnixLink::new(b, T).unwrap());
        let u1 = UdpSocket::bind("127.0.0.1:0").unwrap();
        let u2 = UdpSocket::bind("127.0.0.1:0").unwrap();
        u1.connect(u2.local_addr().unwrap()).unwrap();
        u2.connect(u1.local_addr().unwrap()).unwrap();
        let (ua, ub) = (UdpLink::new(u1, T).unwrap(), UdpLink::new(u2, T).unwrap());
        let (t1, r1) = crossbeam::channel::bounded(1);
        let (t2, r2) = crossbeam::channel::bounded(1);
        let ca = ChanLink { tx: t1, rx: r2 };
        let cb = ChanLink { tx: t2, rx: r1 };
        std::thread::scope(|s| {
            s.spawn(|| {
                pong_block::<UnixLink>(&pb, 100, T).unwrap();
                pong_block::<UdpLink>(&ub, 100, T).unwrap();
                pong_block(&cb, 100, T).unwrap();
            });
            let mut seq = 0;
            let mut h = histogram();
            ping_block::<UnixLink>(&pa, &mut seq, 0, 100, T, None, &mut h).unwrap();
            ping_block::<UdpLink>(&ua, &mut seq, 0, 100, T, None, &mut h).unwrap();
            ping_block(&ca, &mut seq, 0, 100, T, None, &mut h).unwrap();
            assert_eq!(h.len(), 300);
        });
    }
}
