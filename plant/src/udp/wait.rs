//! Waiting for a datagram without a wake-up on the path from state to answer.
//!
//! Why: a thread woken from a blocking wait (here `ppoll`) pays the kernel's and the host's
//! wake-up latency, tens of µs on a VM and more in its tail, and then runs on cold caches. A
//! device-clocked exchange knows when the next datagram is due: the device's state one period
//! after the last, the controller's answer right after the state went out. So both sides poll
//! without blocking (`MSG_DONTWAIT`) through a [`Window`] around that time, and block in `ppoll`
//! only outside it, where nothing is expected and a late arrival is already a fault.

use protocol::monotonic_ns;
use rt::WaitStrategy;

/// When to poll without blocking: from `from_ns` (inclusive) to `to_ns` (exclusive).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    pub from_ns: u64,
    pub to_ns: u64,
}

impl Window {
    /// Always poll (a core given to the exchange).
    pub const ALWAYS: Window = Window {
        from_ns: 0,
        to_ns: u64::MAX,
    };
    /// Never poll: block in `ppoll` throughout.
    pub const NEVER: Window = Window {
        from_ns: u64::MAX,
        to_ns: u64::MAX,
    };

    /// The window a wait strategy gives around `expected_ns`: `Spin` always polls, `Hybrid`
    /// polls within `spin_ns` either side of it, `Sleep` never polls.
    ///
    /// ```
    /// use plant::udp::wait::Window;
    /// use rt::WaitStrategy;
    /// let w = Window::around(WaitStrategy::Hybrid, 1_000_000, 50_000);
    /// assert_eq!((w.from_ns, w.to_ns), (950_000, 1_050_000));
    /// assert_eq!(Window::around(WaitStrategy::Spin, 7, 0), Window::ALWAYS);
    /// assert_eq!(Window::around(WaitStrategy::Sleep, 7, 0), Window::NEVER);
    /// ```
    pub fn around(wait: WaitStrategy, expected_ns: u64, spin_ns: u64) -> Window {
        match wait {
            WaitStrategy::Spin => Window::ALWAYS,
            WaitStrategy::Hybrid => Window {
                from_ns: expected_ns.saturating_sub(spin_ns),
                to_ns: expected_ns.saturating_add(spin_ns),
            },
            WaitStrategy::Sleep => Window::NEVER,
        }
    }
}

/// Calls `take` (a non-blocking receive) until it yields or `until_ns` passes: in a tight loop
/// inside `window`, and after a `ppoll` for readability outside it. Allocates nothing.
pub fn poll_datagram<T>(
    fd: i32,
    until_ns: u64,
    window: Window,
    mut take: impl FnMut() -> Option<T>,
) -> Option<T> {
    loop {
        if let Some(v) = take() {
            return Some(v);
        }
        let now = monotonic_ns();
        if now >= until_ns {
            return None;
        }
        if now >= window.from_ns && now < window.to_ns {
            core::hint::spin_loop();
            continue;
        }
        // Outside the window: block until a datagram comes, the window opens, or time is up.
        let wake = if now < window.from_ns {
            window.from_ns.min(until_ns)
        } else {
            until_ns
        };
        wait_readable(fd, wake);
    }
}

/// Waits until the socket is readable or `until_ns` passes; true if readable.
pub fn wait_readable(fd: i32, until_ns: u64) -> bool {
    let now = monotonic_ns();
    if now >= until_ns {
        return false;
    }
    let rem = until_ns - now;
    let ts = libc::timespec {
        tv_sec: (rem / 1_000_000_000) as libc::time_t,
        tv_nsec: (rem % 1_000_000_000) as libc::c_long,
    };
    let mut p = libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    };
    // SAFETY: one valid pollfd, a valid timespec, no signal mask.
    unsafe { libc::ppoll(&mut p, 1, &ts, std::ptr::null()) > 0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::UdpSocket;
    use std::os::fd::AsRawFd;

    fn pair() -> (UdpSocket, UdpSocket) {
        let a = UdpSocket::bind("127.0.0.1:0").unwrap();
        let b = UdpSocket::bind("127.0.0.1:0").unwrap();
        b.set_nonblocking(true).unwrap();
        a.connect(b.local_addr().unwrap()).unwrap();
        (a, b)
    }

    fn take(b: &UdpSocket) -> Option<u8> {
        let mut buf = [0u8; 4];
        b.recv(&mut buf).ok().map(|_| buf[0])
    }

    #[test]
    fn every_window_gets_the_datagram_or_gives_up_on_time() {
        for w in [Window::ALWAYS, Window::NEVER] {
            let (a, b) = pair();
            let until = monotonic_ns() + 300_000;
            assert_eq!(poll_datagram(b.as_raw_fd(), until, w, || take(&b)), None);
            assert!(monotonic_ns() >= until, "{w:?} gave up early");
            let sender = std::thread::spawn(move || {
                std::thread::sleep(std::time::Duration::from_millis(2));
                a.send(&[42]).unwrap();
            });
            let far = monotonic_ns() + 2_000_000_000;
            assert_eq!(poll_datagram(b.as_raw_fd(), far, w, || take(&b)), Some(42));
            sender.join().unwrap();
        }
        // A window that opens later: blocks until then, then polls, and gives up at `until`.
        let (_a, b) = pair();
        let now = monotonic_ns();
        let w = Window::around(WaitStrategy::Hybrid, now + 1_000_000, 100_000);
        let until = now + 1_500_000;
        let mut polls_in_window = 0;
        let got = poll_datagram(b.as_raw_fd(), until, w, || {
            let t = monotonic_ns();
            polls_in_window += u32::from(t >= w.from_ns && t < w.to_ns);
            take(&b)
        });
        assert_eq!(got, None);
        assert!(monotonic_ns() >= until);
        assert!(
            polls_in_window > 10,
            "{polls_in_window} polls in the window"
        );
    }
}
