//! systemd's readiness and watchdog protocol (`sd_notify`), without libsystemd.
//!
//! Under `Type=notify` systemd passes a unix datagram socket in `$NOTIFY_SOCKET` (a path, or an
//! abstract name written with a leading `@`), and with `WatchdogSec=` the period in
//! `$WATCHDOG_USEC` (and the pid it is meant for in `$WATCHDOG_PID`). A service sends
//! newline-separated `KEY=VALUE` lines as one datagram: `READY=1` once it serves, `WATCHDOG=1`
//! at least once per period while it is healthy, `STOPPING=1` when it begins to stop, and
//! `STATUS=…` for `systemctl status`. That is the whole protocol; it needs no crate.
//!
//! Nothing here is called from a real-time loop: these are system calls.

use std::io;
use std::os::unix::net::{SocketAddr, UnixDatagram};
use std::time::Duration;

/// A connection to the service manager's notification socket.
#[derive(Debug)]
pub struct Notifier {
    socket: UnixDatagram,
    addr: SocketAddr,
}

impl Notifier {
    /// The socket named by `$NOTIFY_SOCKET`, or `None` when the variable is unset or empty (not
    /// started by systemd, or not `Type=notify`). An unusable value is an error.
    pub fn from_env() -> io::Result<Option<Self>> {
        match std::env::var_os("NOTIFY_SOCKET") {
            None => Ok(None),
            Some(v) if v.is_empty() => Ok(None),
            Some(v) => {
                let v = v.to_str().ok_or_else(|| {
                    io::Error::new(io::ErrorKind::InvalidInput, "NOTIFY_SOCKET is not UTF-8")
                })?;
                Self::connect(v).map(Some)
            }
        }
    }

    /// A notifier for `name`: a filesystem path, or `@name` for an abstract socket.
    pub fn connect(name: &str) -> io::Result<Self> {
        let addr = if let Some(abs) = name.strip_prefix('@') {
            use std::os::linux::net::SocketAddrExt;
            SocketAddr::from_abstract_name(abs.as_bytes())?
        } else if name.starts_with('/') {
            SocketAddr::from_pathname(name)?
        } else {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("NOTIFY_SOCKET {name:?}: neither an absolute path nor an @abstract name"),
            ));
        };
        let socket = UnixDatagram::unbound()?;
        Ok(Self { socket, addr })
    }

    /// Sends one message (`KEY=VALUE` lines) as a single datagram.
    pub fn send(&self, msg: &str) -> io::Result<()> {
        let n = self.socket.send_to_addr(msg.as_bytes(), &self.addr)?;
        if n != msg.len() {
            return Err(io::Error::new(
                io::ErrorKind::WriteZero,
                "short write to NOTIFY_SOCKET",
            ));
        }
        Ok(())
    }
}

/// The watchdog period systemd expects pings within: `$WATCHDOG_USEC`, if set, positive, and
/// meant for this process (`$WATCHDOG_PID` unset or equal to our pid).
pub fn watchdog_period() -> Option<Duration> {
    parse_watchdog(
        std::env::var("WATCHDOG_USEC").ok().as_deref(),
        std::env::var("WATCHDOG_PID").ok().as_deref(),
        std::process::id(),
    )
}

fn parse_watchdog(usec: Option<&str>, pid: Option<&str>, me: u32) -> Option<Duration> {
    if let Some(p) = pid {
        if p.trim().parse::<u32>().ok() != Some(me) {
            return None;
        }
    }
    let us: u64 = usec?.trim().parse().ok()?;
    (us > 0).then(|| Duration::from_micros(us))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn watchdog_period_is_read_only_for_this_process() {
        assert_eq!(
            parse_watchdog(Some("2000000"), None, 7),
            Some(Duration::from_secs(2))
        );
        assert_eq!(
            parse_watchdog(Some("500000"), Some("7"), 7),
            Some(Duration::from_millis(500))
        );
        assert_eq!(parse_watchdog(Some("500000"), Some("8"), 7), None);
        assert_eq!(parse_watchdog(Some("0"), None, 7), None);
        assert_eq!(parse_watchdog(Some("soon"), None, 7), None);
        assert_eq!(parse_watchdog(None, None, 7), None);
    }

    #[test]
    fn messages_reach_a_path_and_an_abstract_socket() {
        let dir = std::env::temp_dir().join(format!("rt-notify-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("notify.sock");
        let _ = std::fs::remove_file(&path);
        let server = UnixDatagram::bind(&path).unwrap();
        Notifier::connect(path.to_str().unwrap())
            .unwrap()
            .send("READY=1\nSTATUS=up")
            .unwrap();
        let mut buf = [0u8; 64];
        let n = server.recv(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"READY=1\nSTATUS=up");
        let _ = std::fs::remove_dir_all(&dir);

        use std::os::linux::net::SocketAddrExt;
        let name = format!("rt-notify-test-{}", std::process::id());
        let abs = SocketAddr::from_abstract_name(name.as_bytes()).unwrap();
        let server = UnixDatagram::bind_addr(&abs).unwrap();
        Notifier::connect(&format!("@{name}"))
            .unwrap()
            .send("WATCHDOG=1")
            .unwrap();
        let n = server.recv(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"WATCHDOG=1");
    }

    #[test]
    fn a_relative_name_is_refused() {
        assert!(Notifier::connect("notify.sock").is_err());
    }
}
