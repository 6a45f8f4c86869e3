//! Logs for chaosd's processes: levelled and timestamped through `tracing`.
//!
//! On a terminal (or any plain stderr) a line reads
//! `2026-11-23T08:30:00.123456Z  WARN chaosd: message key=value`. Under systemd, when stderr is
//! the journal stream named by `$JOURNAL_STREAM`, each line instead starts with the syslog
//! priority in angle brackets (`<4>chaosd: message`), which journald turns into the entry's
//! priority, and carries no timestamp of its own (the journal stamps every entry). `$CHAOSD_LOG`
//! (`error`, `warn`, `info`, `debug`, `trace`) sets the level; `info` by default.
//!
//! Logging formats text and writes to stderr, so it never happens on a real-time loop thread: the
//! loops hand their news to ordinary threads, which log. [`warn_limited!`] keeps a warning that
//! can repeat (a device reconnecting, a file that cannot be saved) to one line per period, with
//! the count of the lines it held back.

use std::fmt;
use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::fmt::format::Writer;
use tracing_subscriber::fmt::{FmtContext, FormatEvent, FormatFields};
use tracing_subscriber::registry::LookupSpan;

/// Installs the process's logger (once; later calls change nothing).
pub fn init() {
    let (level, bad) = match std::env::var("CHAOSD_LOG") {
        Ok(v) => match v.trim().parse::<Level>() {
            Ok(l) => (l, None),
            Err(_) => (Level::INFO, Some(v)),
        },
        Err(_) => (Level::INFO, None),
    };
    let journald = journald_stderr();
    // Colour only for a person at a terminal: never into the journal, a file or a pipe.
    let ansi =
        !journald && std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none();
    let builder = tracing_subscriber::fmt()
        .with_max_level(level)
        .with_ansi(ansi)
        .with_writer(std::io::stderr);
    let installed = if journald {
        builder.event_format(Journald).try_init()
    } else {
        builder.try_init()
    };
    if installed.is_ok() {
        if let Some(v) = bad {
            tracing::warn!("CHAOSD_LOG = {v:?} is not a level (error, warn, info, debug, trace); logging at info");
        }
    }
}

/// The one line a program ends with when it fails: `NAME: error: WHY`, with the error
/// priority (`<3>`) in front under journald. Plain stderr, so it is never lost to a logger.
pub fn fatal(name: &str, why: &str) {
    let p = if journald_stderr() { "<3>" } else { "" };
    eprintln!("{p}{name}: error: {why}");
}

/// Whether stderr is the journal stream systemd connected (`$JOURNAL_STREAM` is `DEVICE:INODE`
/// of that stream; a child that redirected stderr elsewhere inherits the variable but not the
/// stream, so both numbers are compared).
pub fn journald_stderr() -> bool {
    let Ok(v) = std::env::var("JOURNAL_STREAM") else {
        return false;
    };
    let Some((dev, ino)) = v.split_once(':') else {
        return false;
    };
    let (Ok(dev), Ok(ino)) = (dev.parse::<u64>(), ino.parse::<u64>()) else {
        return false;
    };
    // SAFETY: fstat on fd 2 into a zeroed stat buffer we own.
    let mut st: libc::stat = unsafe { std::mem::zeroed() };
    if unsafe { libc::fstat(2, &mut st) } != 0 {
        return false;
    }
    st.st_dev == dev && st.st_ino == ino
}

/// The syslog priority journald reads from a `<N>` line prefix.
pub fn priority(level: &Level) -> u8 {
    match *level {
        Level::ERROR => 3,
        Level::WARN => 4,
        Level::INFO => 6,
        _ => 7,
    }
}

/// journald's line format: `<priority>target: message fields`.
pub struct Journald;

impl<S, N> FormatEvent<S, N> for Journald
where
    S: Subscriber + for<'a> LookupSpan<'a>,
    N: for<'a> FormatFields<'a> + 'static,
{
    fn format_event(
        &self,
        ctx: &FmtContext<'_, S, N>,
        mut w: Writer<'_>,
        event: &Event<'_>,
    ) -> fmt::Result {
        let m = event.metadata();
        write!(w, "<{}>{}: ", priority(m.level()), m.target())?;
        ctx.field_format().format_fields(w.by_ref(), event)?;
        writeln!(w)
    }
}

/// At most one event per period; counts the ones held back. For [`warn_limited!`].
pub struct Limiter(Mutex<(Option<Instant>, u64)>);

impl Limiter {
    pub const fn new() -> Self {
        Self(Mutex::new((None, 0)))
    }

    /// `Some(held back since the last one)` if an event may go out now, else `None`.
    pub fn allow(&self, every: Duration) -> Option<u64> {
        self.allow_at(every, Instant::now())
    }

    fn allow_at(&self, every: Duration, now: Instant) -> Option<u64> {
        let mut g = self.0.lock().unwrap_or_else(|e| e.into_inner());
        match g.0 {
            Some(last) if now.duration_since(last) < every => {
                g.1 += 1;
                None
            }
            _ => {
                let held = std::mem::take(&mut g.1);
                g.0 = Some(now);
                Some(held)
            }
        }
    }
}

impl Default for Limiter {
    fn default() -> Self {
        Self::new()
    }
}

/// `tracing::warn!`, at most once per `every` (a `Duration`) from this call site; the next line
/// that goes out says how many were held back (`suppressed=N`).
#[macro_export]
macro_rules! warn_limited {
    ($every:expr, $($arg:tt)+) => {{
        static LIMIT: $crate::log::Limiter = $crate::log::Limiter::new();
        if let Some(held) = LIMIT.allow($every) {
            if held > 0 {
                $crate::log::tracing::warn!(suppressed = held, $($arg)+);
            } else {
                $crate::log::tracing::warn!($($arg)+);
            }
        }
    }};
}

#[doc(hidden)]
pub use tracing;

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn the_limiter_lets_one_through_per_period_and_counts_the_rest() {
        let l = Limiter::new();
        let t0 = Instant::now();
        let s = Duration::from_secs(1);
        assert_eq!(l.allow_at(s, t0), Some(0));
        assert_eq!(l.allow_at(s, t0 + Duration::from_millis(10)), None);
        assert_eq!(l.allow_at(s, t0 + Duration::from_millis(900)), None);
        assert_eq!(l.allow_at(s, t0 + Duration::from_millis(1000)), Some(2));
        assert_eq!(l.allow_at(s, t0 + Duration::from_millis(1500)), None);
        assert_eq!(l.allow_at(s, t0 + Duration::from_millis(2100)), Some(1));
    }

    #[derive(Clone, Default)]
    struct Buf(Arc<Mutex<Vec<u8>>>);
    impl std::io::Write for Buf {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    fn capture(journald: bool, f: impl FnOnce()) -> String {
        let buf = Buf::default();
        let w = buf.clone();
        let b = tracing_subscriber::fmt()
            .with_max_level(Level::INFO)
            .with_ansi(false)
            .with_writer(move || w.clone());
        if journald {
            tracing::subscriber::with_default(b.event_format(Journald).finish(), f);
        } else {
            tracing::subscriber::with_default(b.finish(), f);
        }
        let v = buf.0.lock().unwrap().clone();
        String::from_utf8(v).unwrap()
    }

    #[test]
    fn journald_lines_carry_the_priority_and_terminal_lines_a_timestamp() {
        let j = capture(true, || {
            tracing::error!("boom");
            tracing::warn!(n = 3, "careful");
            tracing::info!("fine");
            tracing::debug!("hidden");
        });
        let lines: Vec<&str> = j.lines().collect();
        assert_eq!(lines.len(), 3, "{j}");
        assert!(
            lines[0].starts_with("<3>") && lines[0].ends_with("boom"),
            "{j}"
        );
        assert!(
            lines[1].starts_with("<4>") && lines[1].contains("careful n=3"),
            "{j}"
        );
        assert!(lines[2].starts_with("<6>"), "{j}");
        let t = capture(false, || tracing::warn!("careful"));
        // 2026-11-23T08:30:00.123456Z  WARN rt::log::tests: careful
        assert!(
            t.as_bytes()[4] == b'-' && t.contains('T') && t.contains("WARN"),
            "{t}"
        );
        assert!(t.trim_end().ends_with("careful"), "{t}");
    }

    #[test]
    fn warn_limited_holds_back_repeats() {
        let out = capture(false, || {
            for _ in 0..5 {
                crate::warn_limited!(Duration::from_secs(3600), "again");
            }
        });
        assert_eq!(out.lines().count(), 1, "{out}");
    }
}
