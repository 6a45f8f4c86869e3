//! SIGINT/SIGTERM as a flag the loops poll, so shutdown happens between ticks and the
//! histograms are always written.
//!
//! Supervisors often send more than one signal: `timeout` signals the child and its process
//! group, and `chaosctl shutdown` may be followed by systemd's SIGTERM. So the first stop request
//! (a signal or [`request_stop`]) starts the clean stop, and later signals change nothing. What
//! bounds a stuck stop is a hard timeout: the first request arms `alarm(HARD_STOP_S)`, and
//! SIGALRM's default action ends the process if the clean stop has not finished by then.

use std::sync::atomic::{AtomicBool, Ordering};

/// Seconds a clean stop may take before SIGALRM ends the process.
pub const HARD_STOP_S: u32 = 10;

static STOP: AtomicBool = AtomicBool::new(false);

/// Sets the flag; the first call arms the hard timeout. Async-signal-safe.
fn stop() {
    if !STOP.swap(true, Ordering::SeqCst) {
        // SAFETY: alarm is async-signal-safe.
        unsafe { libc::alarm(HARD_STOP_S) };
    }
}

extern "C" fn on_signal(_: libc::c_int) {
    stop();
}

/// Installs the handler for SIGINT and SIGTERM (idempotent). The first signal asks for a clean
/// stop; later ones are absorbed; [`HARD_STOP_S`] after the first, the process ends regardless.
pub fn install() {
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    unsafe {
        let mut sa: libc::sigaction = std::mem::zeroed();
        sa.sa_sigaction = on_signal as *const () as usize;
        libc::sigemptyset(&mut sa.sa_mask);
        libc::sigaction(libc::SIGINT, &sa, std::ptr::null_mut());
        libc::sigaction(libc::SIGTERM, &sa, std::ptr::null_mut());
    }
}

/// Whether a stop was requested.
#[inline]
pub fn stop_requested() -> bool {
    STOP.load(Ordering::Relaxed)
}

/// Requests a stop from inside the process (a shutdown command, the end of a timed run).
pub fn request_stop() {
    stop();
}
