//! Readiness and liveness for systemd: `READY=1` once the loop ticks, `WATCHDOG=1` only while it
//! keeps ticking.
//!
//! The loop's only part is one relaxed store of its tick count into [`LOOP_TICKS`] per tick
//! ([`beat`]): no allocation, no lock, no system call. Everything else runs on an ordinary
//! thread, off the loop's core: it polls the counter four times per watchdog period and pings
//! systemd only if the counter moved since its previous look. A loop that stops ticking (stuck
//! in a tick, descheduled, deadlocked) therefore stops the pings within a quarter period, and
//! systemd kills and restarts the service one `WatchdogSec` later, while the process's other
//! threads are still alive and could have kept pinging.
//!
//! Without `$NOTIFY_SOCKET` (not started by systemd) the thread is not started.

use rt::notify::Notifier;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Ticks the loop has run (its `counters.ticks`), published with a relaxed store.
pub static LOOP_TICKS: AtomicU64 = AtomicU64::new(0);

/// The loop's part, once per tick.
#[inline(always)]
pub fn beat(ticks: u64) {
    LOOP_TICKS.store(ticks, Ordering::Relaxed);
}

/// Starts the notifier thread if systemd asked for notifications. `running` false stops it.
pub fn spawn(
    avoid_core: Option<usize>,
    running: Arc<AtomicBool>,
) -> anyhow::Result<Option<JoinHandle<()>>> {
    let notifier = match Notifier::from_env() {
        Ok(Some(n)) => n,
        Ok(None) => return Ok(None),
        Err(e) => {
            tracing::warn!(
                "NOTIFY_SOCKET unusable ({e}): systemd will not hear READY or watchdog pings"
            );
            return Ok(None);
        }
    };
    let period = rt::notify::watchdog_period();
    let h = std::thread::Builder::new()
        .name("chaosd-notify".into())
        .spawn(move || {
            rt::setup::avoid_core(avoid_core);
            notify(&notifier, period, &running);
        })?;
    Ok(Some(h))
}

fn send(n: &Notifier, msg: &str) {
    if let Err(e) = n.send(msg) {
        rt::warn_limited!(Duration::from_secs(60), "cannot notify systemd: {e}");
    }
}

fn notify(n: &Notifier, period: Option<Duration>, running: &AtomicBool) {
    let poll = period.map_or(Duration::from_millis(50), |p| {
        (p / 4).clamp(Duration::from_millis(1), Duration::from_secs(1))
    });
    let start = LOOP_TICKS.load(Ordering::Relaxed);
    // READY once the loop has ticked.
    loop {
        if !running.load(Ordering::Relaxed) {
            return;
        }
        if LOOP_TICKS.load(Ordering::Relaxed) != start {
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    send(n, "READY=1\nSTATUS=control loop running");
    tracing::info!(
        watchdog_ms = period.map(|p| p.as_millis() as u64),
        "told systemd READY"
    );
    let Some(period) = period else {
        while running.load(Ordering::Relaxed) {
            std::thread::sleep(poll);
        }
        send(n, "STOPPING=1");
        return;
    };
    let mut seen = LOOP_TICKS.load(Ordering::Relaxed);
    send(n, "WATCHDOG=1");
    let mut moved_at = Instant::now();
    let mut said_stalled = false;
    while running.load(Ordering::Relaxed) {
        std::thread::sleep(poll);
        let now = LOOP_TICKS.load(Ordering::Relaxed);
        if now != seen {
            seen = now;
            moved_at = Instant::now();
            send(n, "WATCHDOG=1");
            if said_stalled {
                said_stalled = false;
                tracing::info!("the control loop ticks again; watchdog pings resumed");
            }
        } else if !said_stalled && moved_at.elapsed() >= poll * 2 {
            said_stalled = true;
            tracing::error!(
                stalled_ms = moved_at.elapsed().as_millis() as u64,
                "the control loop has stopped ticking: no watchdog pings; systemd restarts the service {} ms after the last one",
                period.as_millis()
            );
        }
    }
    send(n, "STOPPING=1");
}
