//! Waiting for a datagram without a wake-up on the path from state to answer.
//!
//! Why: a thread woken from a blocking wait (here `ppoll`) pays the kernel's and the host's
//! wake-up latency, tens of µs on a VM and more in its tail, and then runs on cold caches. A
//! device-clocked exchange knows when the next datagram is due: the device's state one period
//! after the last, the controller's answer right after the state went out. So both sides poll
//! without blocking (`MSG_DONTWAIT`) through a [`Window`] around that time, and block in `ppoll`
//! only outside it, where nothing is expected and a late arrival is already a fault.

use protocol::monotonic_ns;
pub use rt::trigger::Window;

/// Calls `take` (a non-blocking receive) until it yields or `until_ns` passes: in a tight loop
/// inside `window` (see [`Window::around`]), and after a `ppoll` for readability outside it.
/// Allocates nothing.
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
    use rt::WaitStrategy;
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
        let never = Window::around(WaitStrategy::Sleep, 0, 0);
        for w in [Window::ALWAYS, never] {
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
        let w = Window::around(WaitStrategy::Hybrid, now + 3_000_000, 1_000_000);
        let until = now + 5_000_000;
        let (mut before, mut inside, mut woke) = (0u32, 0u32, None);
        let got = poll_datagram(b.as_raw_fd(), until, w, || {
            let t = monotonic_ns();
            if t < w.from_ns {
                before += 1;
            } else {
                woke.get_or_insert(t);
                inside += u32::from(t < w.to_ns);
            }
            take(&b)
        });
        assert_eq!(got, None);
        assert!(monotonic_ns() >= until);
        // Before the window: the one poll on entry, then a block (no spinning).
        assert_eq!(
            before, 1,
            "it polled {before} times before the window opened"
        );
        // Inside it, a tight loop. (The host may hold this vCPU for 1-2 ms; only a wake-up with
        // half a millisecond of window left is held to it.)
        let woke = woke.expect("it polled again once the window opened");
        if woke + 500_000 < w.to_ns {
            assert!(inside > 10, "{inside} polls in the window");
        }
    }
}
