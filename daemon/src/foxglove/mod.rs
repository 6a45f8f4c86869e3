//! The live view: the Foxglove WebSocket protocol (`foxglove.websocket.v1`) served by the daemon
//! (`[daemon] foxglove = "127.0.0.1:8765"`), with the channels of a recording ([`crate::view`]).
//!
//! Why a thread of its own: the reporter encodes (only while someone is subscribed) and hands
//! each message over a bounded channel with `try_send`, so a slow or stuck viewer costs dropped
//! view messages, never the reporter's time and never the loop's. The thread keeps off the loop's
//! core, accepts viewers, tells them the channels (`advertise`), follows their `subscribe` and
//! `unsubscribe`, and sends each message to the viewers subscribed to its channel. The robot's
//! description is kept and sent to every new subscriber of `/robot_description`.

pub mod client;
pub mod ws;

use crate::view::{Sink, Topic};
use crossbeam::channel::{Receiver, Sender, TrySendError};
use std::collections::HashMap;
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Messages waiting for the server thread; more are dropped (and counted).
const QUEUE: usize = 8192;

/// One encoded message on its way to the viewers.
struct Out {
    topic: Topic,
    unix_ns: u64,
    data: Vec<u8>,
}

/// The reporter's end: a [`Sink`] into the server thread.
pub struct Feed {
    tx: Sender<Out>,
    watched: Arc<AtomicBool>,
    /// Messages the queue had no room for.
    pub dropped: Arc<AtomicU64>,
}

impl Feed {
    /// Whether any viewer is subscribed to anything (the reporter encodes only then).
    pub fn watched(&self) -> bool {
        self.watched.load(Ordering::Relaxed)
    }
}

impl Sink for Feed {
    fn put(&mut self, topic: Topic, _row: u64, unix_ns: u64, data: &[u8]) -> Result<(), String> {
        let out = Out {
            topic,
            unix_ns,
            data: data.to_vec(),
        };
        match self.tx.try_send(out) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(_)) => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
                Ok(())
            }
            Err(TrySendError::Disconnected(_)) => Err("the Foxglove server thread ended".into()),
        }
    }
}

/// The channel id a topic is advertised under.
fn channel_id(t: Topic) -> u32 {
    t as u32 + 1
}

/// The topics a viewer is offered (a replay's text is for `chaosctl replay` only).
fn offered() -> impl Iterator<Item = Topic> {
    Topic::ALL.into_iter().filter(|t| *t != Topic::Replay)
}

/// The `advertise` message: every channel with its schema.
pub fn advertise() -> String {
    let channels: Vec<serde_json::Value> = offered()
        .map(|t| {
            let (name, encoding, schema) = t.schema();
            serde_json::json!({
                "id": channel_id(t), "topic": t.name(), "encoding": t.encoding(),
                "schemaName": name, "schema": schema, "schemaEncoding": encoding,
            })
        })
        .collect();
    serde_json::json!({"op": "advertise", "channels": channels}).to_string()
}

/// A connected viewer: its socket, unread input, and its subscriptions (channel → id).
struct Viewer {
    s: TcpStream,
    input: Vec<u8>,
    subs: HashMap<u32, u32>,
    /// Closed, failed or too slow: dropped at the next pass.
    gone: bool,
}

/// Starts the server on `addr`; its thread keeps off `loop_core` and ends when the feed is
/// dropped.
pub fn spawn(addr: &str, loop_core: Option<usize>) -> anyhow::Result<Feed> {
    let listener = TcpListener::bind(addr)
        .map_err(|e| anyhow::anyhow!("cannot serve the Foxglove view on {addr}: {e}"))?;
    listener.set_nonblocking(true)?;
    let (tx, rx) = crossbeam::channel::bounded(QUEUE);
    let watched = Arc::new(AtomicBool::new(false));
    let w = watched.clone();
    std::thread::Builder::new()
        .name("chaosd-view".into())
        .spawn(move || {
            rt::setup::avoid_core(loop_core);
            serve(listener, rx, w);
        })?;
    tracing::info!("Foxglove view on ws://{addr} (Foxglove: Open connection → Foxglove WebSocket)");
    Ok(Feed {
        tx,
        watched,
        dropped: Arc::new(AtomicU64::new(0)),
    })
}

fn serve(listener: TcpListener, rx: Receiver<Out>, watched: Arc<AtomicBool>) {
    let mut viewers: Vec<Viewer> = Vec::new();
    let mut description: Option<Out> = None;
    let mut frame = Vec::with_capacity(64 * 1024);
    let (greeted, welcome) = crossbeam::channel::unbounded::<Viewer>();
    let greeting = Arc::new(AtomicUsize::new(0));
    loop {
        let mut busy = false;
        while let Ok((s, peer)) = listener.accept() {
            busy = true;
            greet_aside(s, peer, &greeted, &greeting);
        }
        while let Ok(v) = welcome.try_recv() {
            busy = true;
            viewers.push(v);
        }
        for v in &mut viewers {
            if let Err(e) = read(v, description.as_ref(), &mut frame) {
                tracing::debug!("Foxglove viewer gone: {e}");
                v.gone = true;
            }
        }
        viewers.retain(|v| !v.gone);
        loop {
            match rx.try_recv() {
                Ok(out) => {
                    busy = true;
                    send(&mut viewers, &out, &mut frame);
                    if out.topic == Topic::RobotDescription {
                        description = Some(out);
                    }
                }
                Err(crossbeam::channel::TryRecvError::Empty) => break,
                Err(crossbeam::channel::TryRecvError::Disconnected) => return,
            }
        }
        watched.store(
            viewers.iter().any(|v| !v.subs.is_empty()),
            Ordering::Relaxed,
        );
        if !busy {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}

/// The most handshakes in flight at once; a connection beyond them is closed.
const MAX_GREETING: usize = 8;

/// Runs [`greet`] on a thread of its own, which inherits this thread's cores (off the loop's):
/// a client that connects and says nothing holds its handshake for up to 2 s, and must not hold
/// up the stream to the viewers already watching.
fn greet_aside(s: TcpStream, peer: SocketAddr, done: &Sender<Viewer>, greeting: &Arc<AtomicUsize>) {
    if greeting.fetch_add(1, Ordering::AcqRel) >= MAX_GREETING {
        greeting.fetch_sub(1, Ordering::AcqRel);
        tracing::debug!("Foxglove viewer {peer}: {MAX_GREETING} handshakes under way; closed");
        return;
    }
    let (done, count) = (done.clone(), greeting.clone());
    let spawned = std::thread::Builder::new()
        .name("chaosd-view-hs".into())
        .spawn(move || {
            match greet(s) {
                Ok(v) => {
                    let _ = done.send(v);
                }
                Err(e) => tracing::debug!("Foxglove viewer {peer}: {e}"),
            }
            count.fetch_sub(1, Ordering::AcqRel);
        });
    if let Err(e) = spawned {
        greeting.fetch_sub(1, Ordering::AcqRel);
        tracing::debug!("Foxglove viewer {peer}: no thread for its handshake: {e}");
    }
}

/// The handshake, then `serverInfo` and `advertise`.
fn greet(mut s: TcpStream) -> std::io::Result<Viewer> {
    s.set_nonblocking(false)?;
    s.set_read_timeout(Some(Duration::from_secs(2)))?;
    s.set_write_timeout(Some(Duration::from_millis(500)))?;
    s.set_nodelay(true)?;
    ws::handshake(&mut s)?;
    let info = serde_json::json!({
        "op": "serverInfo", "name": "chaosd", "capabilities": [],
        "supportedEncodings": [], "metadata": {}, "sessionId": protocol::new_instance_id().to_string(),
    })
    .to_string();
    let mut out = Vec::new();
    ws::frame(&mut out, ws::TEXT, &[info.as_bytes()]);
    ws::frame(&mut out, ws::TEXT, &[advertise().as_bytes()]);
    s.write_all(&out)?;
    s.set_nonblocking(true)?;
    Ok(Viewer {
        s,
        input: Vec::new(),
        subs: HashMap::new(),
        gone: false,
    })
}

/// Reads what a viewer sent: subscriptions, pings, a close.
fn read(v: &mut Viewer, description: Option<&Out>, frame: &mut Vec<u8>) -> std::io::Result<()> {
    let mut b = [0u8; 4096];
    loop {
        match v.s.read(&mut b) {
            Ok(0) => return Err(std::io::Error::other("closed")),
            Ok(n) => v.input.extend_from_slice(&b[..n]),
            Err(e) if e.kind() == ErrorKind::WouldBlock => break,
            Err(e) => return Err(e),
        }
    }
    while let Some((op, payload)) = ws::take_frame(&mut v.input)? {
        match op {
            ws::TEXT => {
                let new = subscribe(v, &payload);
                if let (Some(d), true) = (description, new.contains(&Topic::RobotDescription)) {
                    send(std::slice::from_mut(v), d, frame);
                }
            }
            ws::PING => {
                frame.clear();
                ws::frame(frame, ws::PONG, &[&payload]);
                write_blocking(&mut v.s, frame)?;
            }
            ws::CLOSE => {
                // RFC 6455 §5.5.1: a Close is answered with a Close (its status code echoed),
                // then the connection ends; best effort, the viewer is leaving anyway.
                frame.clear();
                ws::frame(frame, ws::CLOSE, &[payload.get(..2).unwrap_or_default()]);
                let _ = write_blocking(&mut v.s, frame);
                return Err(std::io::Error::other("closed by the viewer"));
            }
            _ => {}
        }
    }
    Ok(())
}

/// Applies a `subscribe` or `unsubscribe`; returns the topics newly subscribed.
fn subscribe(v: &mut Viewer, text: &[u8]) -> Vec<Topic> {
    let Ok(m) = serde_json::from_slice::<serde_json::Value>(text) else {
        return Vec::new();
    };
    let mut new = Vec::new();
    match m["op"].as_str() {
        Some("subscribe") => {
            for s in m["subscriptions"].as_array().into_iter().flatten() {
                let (Some(id), Some(ch)) = (s["id"].as_u64(), s["channelId"].as_u64()) else {
                    continue;
                };
                if let Some(t) = offered().find(|t| channel_id(*t) as u64 == ch) {
                    v.subs.insert(ch as u32, id as u32);
                    new.push(t);
                }
            }
        }
        Some("unsubscribe") => {
            for id in m["subscriptionIds"].as_array().into_iter().flatten() {
                v.subs.retain(|_, s| Some(*s as u64) != id.as_u64());
            }
        }
        _ => {}
    }
    new
}

/// One `messageData` frame to every viewer subscribed to its channel.
fn send(viewers: &mut [Viewer], out: &Out, frame: &mut Vec<u8>) {
    let ch = channel_id(out.topic);
    for v in viewers.iter_mut() {
        let Some(&sub) = v.subs.get(&ch) else {
            continue;
        };
        frame.clear();
        let head = [&[1u8][..], &sub.to_le_bytes(), &out.unix_ns.to_le_bytes()];
        ws::frame(frame, ws::BINARY, &[head[0], head[1], head[2], &out.data]);
        if v.gone || write_blocking(&mut v.s, frame).is_err() {
            // Too slow or gone: it is dropped at the next pass.
            v.gone = true;
        }
    }
}

/// Writes all of `buf` to a non-blocking socket, waiting at most half a second.
fn write_blocking(s: &mut TcpStream, buf: &[u8]) -> std::io::Result<()> {
    let mut at = 0;
    let until = std::time::Instant::now() + Duration::from_millis(500);
    while at < buf.len() {
        match s.write(&buf[at..]) {
            Ok(0) => return Err(std::io::Error::other("closed")),
            Ok(n) => at += n,
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                if std::time::Instant::now() > until {
                    return Err(std::io::Error::other("a viewer too slow to keep up"));
                }
                std::thread::sleep(Duration::from_micros(200));
            }
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// The reporter's side of the live view: the encoder and the feed.
pub struct Live {
    feed: Feed,
    encoder: crate::view::Encoder,
    offset_ns: i128,
}

impl Live {
    /// The live view of `system` on `[daemon] foxglove`, if it is set.
    pub fn start(
        system: &control::System,
        daemon: &crate::config::DaemonConfig,
    ) -> anyhow::Result<Option<Live>> {
        let Some(addr) = &daemon.foxglove else {
            return Ok(None);
        };
        let mut feed = spawn(addr, daemon.core)?;
        let offset_ns = crate::mcap_recording::clock_offset();
        let mut encoder = crate::view::Encoder::new(crate::view::Scene::of(system), daemon.rate_hz);
        let now = (protocol::monotonic_ns() as i128 + offset_ns).max(0) as u64;
        encoder.start(now, &mut feed).map_err(anyhow::Error::msg)?;
        Ok(Some(Live {
            feed,
            encoder,
            offset_ns,
        }))
    }

    /// One tick whose law ran on `st`, encoded only while a viewer is subscribed.
    pub fn tick(
        &mut self,
        r: &crate::telemetry::TickRecord,
        st: &protocol::StateSample,
        ctx: crate::view::TickContext,
    ) {
        if !self.feed.watched() {
            return;
        }
        let ns = (r.now_ns as i128 + self.offset_ns).max(0) as u64;
        let _ = self.encoder.tick(r, st, ctx, ns, &mut self.feed);
    }

    /// An operator's change: the event, and the new scene.
    pub fn note(&mut self, text: &str, system: Option<&control::System>) {
        let ns = (protocol::monotonic_ns() as i128 + self.offset_ns).max(0) as u64;
        let _ = self
            .encoder
            .event(ns, crate::view::Level::Info, text, &mut self.feed);
        if let Some(s) = system {
            let _ = self
                .encoder
                .set_scene(crate::view::Scene::of(s), ns, &mut self.feed);
        }
    }

    /// View messages dropped because the server thread's queue was full.
    pub fn dropped(&self) -> u64 {
        self.feed.dropped.load(Ordering::Relaxed)
    }
}
