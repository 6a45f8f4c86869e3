//! News from a real-time loop, logged by an ordinary thread.
//!
//! Logging formats text, may take the logger's lock and writes to stderr (a syscall that can
//! block on a full pipe or a slow journal), so a loop must never log itself. Yet a loop is where
//! things happen: a bridge's device goes silent or restarts inside `read`. So the loop *posts* a
//! small `Copy` value describing what happened into a fixed-capacity lock-free queue (no
//! allocation, no lock, no syscall), and a [`Courier`] thread, off the loop's core, takes it out
//! and logs it. If the queue is full the note is dropped and counted, never waited for: the loop
//! comes first, and the courier says how many it lost.
//!
//! ```
//! use rt::news::{Courier, Note};
//!
//! #[derive(Clone, Copy)]
//! enum BridgeNote { DeviceLost { ms: u64 } }
//!
//! impl Note for BridgeNote {
//!     fn log(&self) {
//!         match self {
//!             BridgeNote::DeviceLost { ms } => tracing::warn!("device lost: silent for {ms} ms"),
//!         }
//!     }
//! }
//!
//! let courier = Courier::<BridgeNote>::start("bridge-news", 64, None).unwrap();
//! let poster = courier.poster();
//! assert!(poster.post(BridgeNote::DeviceLost { ms: 250 })); // from the loop: never blocks
//! drop(courier); // logs whatever is still queued, then stops its thread
//! ```

use crossbeam::queue::ArrayQueue;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// How often the courier looks for news: logs are for people, 20 ms is instant to them.
const POLL: Duration = Duration::from_millis(20);

/// Something a loop reports: how it is logged runs on the courier's thread, never the loop's.
pub trait Note: Copy + Send + 'static {
    fn log(&self);
}

struct Shared<T> {
    queue: ArrayQueue<T>,
    dropped: AtomicU64,
    running: AtomicBool,
}

/// The loop's end: posts notes without allocating, locking or blocking. Cheap to clone.
pub struct Poster<T>(Arc<Shared<T>>);

impl<T> Clone for Poster<T> {
    fn clone(&self) -> Self {
        Self(self.0.clone())
    }
}

impl<T: Note> Poster<T> {
    /// Queues `note` for the courier; `false` (and counted) if the queue is full.
    pub fn post(&self, note: T) -> bool {
        let ok = self.0.queue.push(note).is_ok();
        if !ok {
            self.0.dropped.fetch_add(1, Ordering::Relaxed);
        }
        ok
    }

    /// Notes dropped so far because the queue was full.
    pub fn dropped(&self) -> u64 {
        self.0.dropped.load(Ordering::Relaxed)
    }
}

/// The thread that logs what the loop posted. Dropping it logs what is left and joins it.
pub struct Courier<T: Note> {
    shared: Arc<Shared<T>>,
    thread: Option<JoinHandle<()>>,
}

impl<T: Note> Courier<T> {
    /// Starts the thread `name` with room for `capacity` notes (at least 1), kept off
    /// `avoid_core` (the loop's core).
    pub fn start(name: &str, capacity: usize, avoid_core: Option<usize>) -> std::io::Result<Self> {
        let shared = Arc::new(Shared {
            queue: ArrayQueue::new(capacity.max(1)),
            dropped: AtomicU64::new(0),
            running: AtomicBool::new(true),
        });
        let s = shared.clone();
        let thread = std::thread::Builder::new()
            .name(name.into())
            .spawn(move || {
                crate::setup::avoid_core(avoid_core);
                let mut reported = 0;
                while s.running.load(Ordering::Relaxed) {
                    std::thread::sleep(POLL);
                    reported = deliver(&s, reported);
                }
                deliver(&s, reported);
            })?;
        Ok(Self {
            shared,
            thread: Some(thread),
        })
    }

    /// A handle for the loop.
    pub fn poster(&self) -> Poster<T> {
        Poster(self.shared.clone())
    }
}

/// Logs every queued note, then the drops since `reported`; returns the drops now reported.
fn deliver<T: Note>(s: &Shared<T>, reported: u64) -> u64 {
    while let Some(n) = s.queue.pop() {
        n.log();
    }
    let dropped = s.dropped.load(Ordering::Relaxed);
    if dropped > reported {
        tracing::warn!(
            "{} notes from the loop were dropped (the news queue was full)",
            dropped - reported
        );
    }
    dropped
}

impl<T: Note> Drop for Courier<T> {
    fn drop(&mut self) {
        self.shared.running.store(false, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    static LOGGED: Mutex<Vec<(u32, String)>> = Mutex::new(Vec::new());

    #[derive(Clone, Copy)]
    struct Tagged(u32);
    impl Note for Tagged {
        fn log(&self) {
            let thread = std::thread::current().name().unwrap_or("").to_string();
            LOGGED.lock().unwrap().push((self.0, thread));
        }
    }

    #[test]
    fn notes_are_logged_in_order_on_the_courier_thread_and_overflow_is_counted() {
        let courier = Courier::<Tagged>::start("test-news", 3, None).unwrap();
        let p = courier.poster();
        // Faster than the courier polls: the fourth does not fit.
        let posted: Vec<bool> = (0..4).map(|i| p.post(Tagged(i))).collect();
        assert_eq!(posted, [true, true, true, false]);
        assert_eq!(p.dropped(), 1);
        drop(courier);
        let logged = LOGGED.lock().unwrap().clone();
        assert_eq!(
            logged.iter().map(|l| l.0).collect::<Vec<_>>(),
            [0, 1, 2],
            "in order, the dropped one absent"
        );
        assert!(logged.iter().all(|l| l.1 == "test-news"), "{logged:?}");
    }
}
