//! What one rate of `e2e` measured and how it was wired, apart from the runs that produce it,
//! so the tables built from results (`late`) need not import the runs.

use serde_json::Value;
use std::path::PathBuf;

/// How the plant side and the daemon are wired.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Free-running loops (`trigger = "clock"`), today's default.
    Clock,
    /// Clock-triggered, the daemon's deadlines phase-locked to the plant's stamps
    /// (`phase_offset_us`, see [`phase_offset_us`](super::phase_offset_us)).
    Phase,
    /// State-triggered over iceoryx2, with the fast lane (`protocol::board`, the default).
    State,
    /// State-triggered over iceoryx2 pub-sub alone (`fast_lane = false`).
    PubSub,
    /// State-triggered through chaosd-bridge and chaosd-fakebot over UDP, the device placed
    /// beside the bridge ([`DEVICE_ARGS`](super::DEVICE_ARGS)).
    Udp,
    /// The same, the device unpinned at the normal scheduler and polling for its answers: the
    /// placement it had before, kept beside `Udp` to show what the placement is worth.
    UdpFree,
}

impl Mode {
    pub const ALL: [Mode; 6] = [
        Mode::Clock,
        Mode::Phase,
        Mode::PubSub,
        Mode::State,
        Mode::Udp,
        Mode::UdpFree,
    ];

    /// Through the UDP bridge, with chaosd-fakebot as the device.
    pub fn is_udp(self) -> bool {
        matches!(self, Mode::Udp | Mode::UdpFree)
    }

    pub fn name(self) -> &'static str {
        match self {
            Mode::Clock => "free-running (iceoryx2)",
            Mode::Phase => "phase-locked clock (iceoryx2)",
            Mode::State => "state-triggered (iceoryx2, fast lane)",
            Mode::PubSub => "state-triggered (iceoryx2 pub-sub only)",
            Mode::Udp => "state-triggered (UDP bridge)",
            Mode::UdpFree => "state-triggered (UDP bridge, device unpinned)",
        }
    }

    pub(super) fn slug(self) -> &'static str {
        match self {
            Mode::Clock => "",
            Mode::Phase => "-phase",
            Mode::State => "-state",
            Mode::PubSub => "-pubsub",
            Mode::Udp => "-udp",
            Mode::UdpFree => "-udp-free",
        }
    }
}

/// What one rate measured.
#[derive(Debug, Clone)]
pub struct RateResult {
    pub rate_hz: f64,
    pub mode: Mode,
    /// The UDP device's summary (chaosd-fakebot), in the UDP mode.
    pub device: Option<Value>,
    /// Status requests answered during the run, when a client hammered the control service.
    pub requests: Option<u64>,
    /// Scrape latencies (ns, sorted), when a Prometheus scraper polled `chaosctl exporter`.
    pub scrapes: Option<Vec<u64>>,
    /// Live-view messages a Foxglove viewer received, when one was attached.
    pub viewed: Option<u64>,
    pub daemon: Value,
    pub plant: Value,
    pub cpu_daemon: f64,
    pub cpu_plant: f64,
    /// Each CPU's steal over the run (ms): the host running something else on that vCPU. Empty
    /// if `/proc/stat` could not be read.
    pub steal_ms: Vec<f64>,
    pub dir: PathBuf,
}
