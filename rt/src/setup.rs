//! Asking the kernel for real-time treatment, and saying plainly what it refused.
//!
//! SCHED_FIFO and mlockall need privileges (CAP_SYS_NICE, RLIMIT_MEMLOCK) that a developer
//! machine or container often lacks. chaosd then still runs, warns once, and at least sets the
//! timer slack to its minimum so sleeps wake as close to the deadline as an ordinary thread can.

use serde::Serialize;

/// What to ask for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RtRequest {
    /// Core to pin the calling thread to.
    pub core: Option<usize>,
    /// SCHED_FIFO priority (1..=99); 0 keeps the normal scheduler.
    pub priority: u8,
    /// mlockall(MCL_CURRENT | MCL_FUTURE).
    pub lock_memory: bool,
}

/// What was granted.
#[derive(Clone, Debug, Default, Serialize, PartialEq, Eq)]
pub struct RtReport {
    pub pinned_core: Option<usize>,
    pub sched_fifo: Option<u8>,
    pub memory_locked: bool,
    pub timer_slack_ns: Option<u64>,
    pub warnings: Vec<String>,
}

impl RtReport {
    pub fn one_line(&self) -> String {
        format!(
            "core {}, {}, memory {}",
            self.pinned_core
                .map(|c| c.to_string())
                .unwrap_or_else(|| "unpinned".into()),
            self.sched_fifo
                .map(|p| format!("SCHED_FIFO {p}"))
                .unwrap_or_else(|| "SCHED_OTHER (timer slack 1 ns)".into()),
            if self.memory_locked {
                "locked"
            } else {
                "not locked"
            }
        )
    }
}

fn errno_text() -> String {
    std::io::Error::last_os_error().to_string()
}

/// Applies `req` to the calling thread (and, for mlockall, the process).
pub fn apply(req: RtRequest) -> RtReport {
    let mut r = RtReport::default();
    // Before the pin narrows it: what helper threads may use besides the loop's core.
    process_cpus();
    if let Some(core) = req.core {
        let ids = core_affinity::get_core_ids().unwrap_or_default();
        match ids.into_iter().find(|c| c.id == core) {
            Some(id) if core_affinity::set_for_current(id) => r.pinned_core = Some(core),
            Some(_) => r.warnings.push(format!("could not pin to core {core}")),
            None => r.warnings.push(format!(
                "core {core} does not exist or is not allowed; running unpinned"
            )),
        }
    }
    if req.priority > 0 {
        let param = libc::sched_param {
            sched_priority: i32::from(req.priority),
        };
        // SAFETY: valid param pointer; pid 0 is the calling thread.
        let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
        if rc == 0 {
            r.sched_fifo = Some(req.priority);
        } else {
            r.warnings.push(format!(
                "SCHED_FIFO priority {} refused ({}); running with the normal scheduler",
                req.priority,
                errno_text()
            ));
        }
    }
    if req.lock_memory {
        // SAFETY: plain syscall with flag arguments.
        let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
        if rc == 0 {
            r.memory_locked = true;
        } else {
            r.warnings.push(format!(
                "mlockall refused ({}); pages may fault in the loop",
                errno_text()
            ));
        }
    }
    if r.sched_fifo.is_none() {
        // SAFETY: PR_SET_TIMERSLACK takes an unsigned long; 1 ns is the minimum.
        let rc = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) };
        if rc == 0 {
            r.timer_slack_ns = Some(1);
        }
    }
    r
}

/// A loop setting out of range: `field` is the key inside its table (`rate_hz`, ...).
#[derive(Clone, Debug, PartialEq)]
pub struct Invalid {
    pub field: &'static str,
    pub value: String,
    pub expected: String,
}

/// Checks the settings every fixed-rate loop has (the daemon's and the plant's tables share
/// them): the rate within `rates` (Hz), the hybrid spin within one period, a SCHED_FIFO priority
/// and a plausible core.
pub fn check_loop(
    rate_hz: f64,
    rates: (f64, f64),
    spin_us: f64,
    priority: u8,
    core: Option<usize>,
) -> Result<(), Invalid> {
    let bad = |field, value: String, expected: String| {
        Err(Invalid {
            field,
            value,
            expected,
        })
    };
    if !(rate_hz.is_finite() && rate_hz >= rates.0 && rate_hz <= rates.1) {
        return bad(
            "rate_hz",
            rate_hz.to_string(),
            format!("must be between {} and {} Hz", rates.0, rates.1),
        );
    }
    let period_us = 1e6 / rate_hz;
    if !(spin_us.is_finite() && spin_us >= 0.0 && spin_us <= period_us) {
        return bad(
            "spin_us",
            spin_us.to_string(),
            format!("must be between 0 and the period ({period_us} µs)"),
        );
    }
    if priority > 99 {
        return bad(
            "priority",
            priority.to_string(),
            "must be 0 (normal scheduler) or a SCHED_FIFO priority 1..=99".into(),
        );
    }
    if let Some(c) = core {
        if c >= 1024 {
            return bad(
                "core",
                c.to_string(),
                "must be a CPU index below 1024".into(),
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loop_settings_are_checked() {
        assert!(check_loop(1000.0, (100.0, 10_000.0), 50.0, 50, Some(1)).is_ok());
        assert_eq!(
            check_loop(50.0, (100.0, 10_000.0), 0.0, 0, None)
                .unwrap_err()
                .field,
            "rate_hz"
        );
        assert_eq!(
            check_loop(f64::NAN, (100.0, 10_000.0), 0.0, 0, None)
                .unwrap_err()
                .field,
            "rate_hz"
        );
        assert_eq!(
            check_loop(1000.0, (100.0, 10_000.0), 2000.0, 0, None)
                .unwrap_err()
                .field,
            "spin_us"
        );
        assert_eq!(
            check_loop(1000.0, (100.0, 10_000.0), 0.0, 100, None)
                .unwrap_err()
                .field,
            "priority"
        );
        assert_eq!(
            check_loop(1000.0, (100.0, 10_000.0), 0.0, 0, Some(5000))
                .unwrap_err()
                .field,
            "core"
        );
    }
}

/// The CPUs the process was allowed when first asked (before [`apply`] pins the loop): the
/// unit's `CPUAffinity=`, a `taskset`, or every online CPU.
fn process_cpus() -> &'static [usize] {
    static CPUS: std::sync::OnceLock<Vec<usize>> = std::sync::OnceLock::new();
    CPUS.get_or_init(|| {
        // SAFETY: a zeroed cpu_set_t is the empty set; sched_getaffinity(0, …) fills it for the
        // calling thread; CPU_ISSET only reads inside it.
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            if libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
                return Vec::new();
            }
            (0..libc::CPU_SETSIZE as usize)
                .filter(|&c| libc::CPU_ISSET(c, &set))
                .collect()
        }
    })
}

/// Keeps the calling thread off `core` (the real-time loop's), on every other CPU the process
/// is allowed (never widening a unit's `CPUAffinity=` or a `taskset`). Helper threads
/// (reporter, cleanup) call this first, so they never take the loop's core even when they run at
/// the normal priority and the loop sleeps. Returns false, and changes nothing, when `core` is
/// `None`, when the loop's core is the only one allowed, or when the kernel refuses.
pub fn avoid_core(core: Option<usize>) -> bool {
    let Some(core) = core else { return false };
    let others: Vec<usize> = process_cpus()
        .iter()
        .copied()
        .filter(|&c| c != core)
        .collect();
    if others.is_empty() {
        return false;
    }
    // SAFETY: a zeroed cpu_set_t is the empty set; CPU_SET only writes inside it (every c came
    // from CPU_ISSET below CPU_SETSIZE), and sched_setaffinity(0, …) applies to the calling
    // thread.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        for c in others {
            libc::CPU_SET(c, &mut set);
        }
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0
    }
}

#[cfg(test)]
mod avoid_core_tests {
    #[test]
    fn a_helper_thread_leaves_the_loops_core_alone() {
        let allowed = std::thread::spawn(|| {
            let moved = super::avoid_core(Some(1));
            // SAFETY: as above; sched_getaffinity fills the set for the calling thread.
            let set = unsafe {
                let mut set: libc::cpu_set_t = std::mem::zeroed();
                libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set);
                set
            };
            // SAFETY: CPU_ISSET only reads inside the set.
            (moved, unsafe { libc::CPU_ISSET(1, &set) }, unsafe {
                libc::CPU_ISSET(0, &set)
            })
        })
        .join()
        .unwrap();
        // SAFETY: sysconf has no preconditions.
        if unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) } >= 2 {
            assert_eq!(allowed, (true, false, true));
        } else {
            assert!(!allowed.0);
        }
    }
}
