//! The live-control contract: requests a client sends to a running daemon, the answers, and the
//! telemetry stream.
//!
//! Requests are typed (an [`Op`] and a short text of arguments such as `mu 1.5 tau 1.0`); the
//! daemon parses and validates the arguments itself, so a client cannot put it in a state the
//! start-up validation would refuse. Answers carry a status and a UTF-8 body (JSON or TOML): they
//! are read by people and scripts, are rare, and never touch the real-time loop. Everything is
//! still fixed-size plain data, as iceoryx2 requires; the sizes below bound what fits.

use core::fmt::Debug;
use iceoryx2::node::Node;
use iceoryx2::prelude::ZeroCopySend;
use iceoryx2::service::port_factory::{publish_subscribe, request_response};

use crate::names::ServiceNames;
use crate::qos::{open_pubsub, service_name, Channel, PubSubQos, ServiceError};
use crate::MAX_JOINTS;

/// Longest argument text of a request (bytes).
pub const MAX_ARGS: usize = 1024;
/// Longest body of a response (bytes).
pub const MAX_BODY: usize = 16 * 1024;

/// What a client asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Op {
    /// Mode, time, parameters, counters, recent tracking and timing (JSON).
    Status = 1,
    /// The effective configuration (TOML).
    GetConfig = 2,
    /// `KEY VALUE… [KEY VALUE…]`: change parameters, all or nothing.
    Set = 3,
    /// `X Y RADIUS [MARGIN]`.
    ObstacleAdd = 4,
    /// `INDEX`.
    ObstacleRemove = 5,
    ObstacleList = 6,
    /// Feedback on now (t_on = now) or off.
    DfcOn = 7,
    DfcOff = 8,
    /// Percentiles of the latency histograms (JSON).
    HistSnapshot = 9,
    HistReset = 10,
    /// `[NAME]`: record the state and command streams to NAME inside the output directory.
    RecordStart = 11,
    RecordStop = 12,
    Shutdown = 13,
    /// Leave FAULT (the runaway guard tripped) and control again.
    Resume = 14,
    /// `MS`: stall the control loop for MS milliseconds (1..=10000), to check that a
    /// deployment's watchdog restarts a stuck loop. The plant brakes on its command timeout.
    DebugStall = 15,
}

impl TryFrom<u32> for Op {
    type Error = u32;
    fn try_from(v: u32) -> Result<Self, u32> {
        Ok(match v {
            1 => Op::Status,
            2 => Op::GetConfig,
            3 => Op::Set,
            4 => Op::ObstacleAdd,
            5 => Op::ObstacleRemove,
            6 => Op::ObstacleList,
            7 => Op::DfcOn,
            8 => Op::DfcOff,
            9 => Op::HistSnapshot,
            10 => Op::HistReset,
            11 => Op::RecordStart,
            12 => Op::RecordStop,
            13 => Op::Shutdown,
            14 => Op::Resume,
            15 => Op::DebugStall,
            other => return Err(other),
        })
    }
}

/// A request to the daemon.
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("chaosd::ControlRequest.v1")]
#[repr(C)]
pub struct ControlRequest {
    /// Chosen by the client; echoed in the response.
    pub id: u64,
    /// An [`Op`] as `u32`.
    pub op: u32,
    /// Bytes of `args` in use.
    pub len: u32,
    pub args: [u8; MAX_ARGS],
}

/// The daemon's verdict.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Status {
    /// Done; `body` holds the result.
    Ok = 0,
    /// Not done, nothing changed; `body` says why (an out-of-range value, an unknown key...).
    Refused = 1,
}

/// The daemon's answer.
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("chaosd::ControlResponse.v1")]
#[repr(C)]
pub struct ControlResponse {
    pub id: u64,
    /// A [`Status`] as `u32`.
    pub status: u32,
    /// Bytes of `body` in use.
    pub len: u32,
    pub body: [u8; MAX_BODY],
}

/// Copies as much of `text` as fits, cutting at a character boundary. Returns the length used.
fn fill(dst: &mut [u8], text: &str) -> u32 {
    let mut n = text.len().min(dst.len());
    while !text.is_char_boundary(n) {
        n -= 1;
    }
    dst[..n].copy_from_slice(&text.as_bytes()[..n]);
    n as u32
}

fn read(src: &[u8], len: u32) -> Result<&str, &'static str> {
    let n = len as usize;
    if n > src.len() {
        return Err("length field larger than the buffer");
    }
    core::str::from_utf8(&src[..n]).map_err(|_| "text is not UTF-8")
}

/// A request whose arguments do not fit in one sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("arguments are {len} bytes; at most {MAX_ARGS} fit in a request")]
pub struct ArgsTooLong {
    pub len: usize,
}

impl ControlRequest {
    /// A request; arguments longer than [`MAX_ARGS`] are refused.
    pub fn new(id: u64, op: Op, args: &str) -> Result<Self, ArgsTooLong> {
        if args.len() > MAX_ARGS {
            return Err(ArgsTooLong { len: args.len() });
        }
        let mut r = Self {
            id,
            op: op as u32,
            len: 0,
            args: [0; MAX_ARGS],
        };
        r.len = fill(&mut r.args, args);
        Ok(r)
    }
    pub fn op(&self) -> Result<Op, u32> {
        Op::try_from(self.op)
    }
    pub fn args(&self) -> Result<&str, &'static str> {
        read(&self.args, self.len)
    }
}

impl ControlResponse {
    /// A response; a body longer than [`MAX_BODY`] is cut and says so.
    pub fn new(id: u64, status: Status, body: &str) -> Self {
        let mut r = Self {
            id,
            status: status as u32,
            len: 0,
            body: [0; MAX_BODY],
        };
        if body.len() <= MAX_BODY {
            r.len = fill(&mut r.body, body);
        } else {
            const CUT: &str = "\n[response truncated]";
            r.len = fill(&mut r.body[..MAX_BODY - CUT.len()], body);
            let end = r.len as usize;
            r.body[end..end + CUT.len()].copy_from_slice(CUT.as_bytes());
            r.len += CUT.len() as u32;
        }
        r
    }
    pub fn is_ok(&self) -> bool {
        self.status == Status::Ok as u32
    }
    pub fn body(&self) -> Result<&str, &'static str> {
        read(&self.body, self.len)
    }
}

/// The kinds of [`TelemetrySample::limit_breaches`], in order (the metrics' `kind` label).
pub const LIMIT_BREACH_KINDS: [&str; 5] = ["position", "speed", "acceleration", "jerk", "effort"];

/// One telemetry sample, published by the daemon at `daemon.telemetry_hz`.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("chaosd::TelemetrySample.v9")]
#[repr(C)]
pub struct TelemetrySample {
    pub seq: u64,
    /// CLOCK_MONOTONIC of publication.
    pub stamp_ns: u64,
    /// Controller time (s) of the newest tick summarised.
    pub t: f64,
    /// A `Mode` as u32.
    pub mode: u32,
    /// 1 if the feedback switch is on, 0 if off.
    pub feedback_on: u32,
    /// 1 if the delayed term was applied on the newest tick.
    pub feedback_active: u32,
    pub n: u32,
    pub mu: f64,
    pub tau: f64,
    pub t_on: f64,
    /// RMS tracking error over the interval since the previous sample (m).
    pub tracking_error: f64,
    /// Mean |q̇(t) − q̇(t − τ)| over the interval (rad/s).
    pub period_residual: f64,
    /// Smallest obstacle clearance over the interval (m; +∞ without obstacles).
    pub clearance: f64,
    /// Total time spent inside an obstacle's safety zone (s).
    pub time_in_contact: f64,
    /// Wake-up lateness over the interval (µs).
    pub lateness_p50_us: f64,
    pub lateness_p99_us: f64,
    pub lateness_max_us: f64,
    pub ticks: u64,
    pub overruns: u64,
    pub telemetry_dropped: u64,
    pub rejected: u64,
    pub holds: u64,
    /// The newest state used.
    pub state_seq: u64,
    pub phi: f64,
    pub q: [f64; MAX_JOINTS],
    pub qd: [f64; MAX_JOINTS],
    /// Runaway-guard trips, plant restarts seen, ticks the safety filter acted on, ticks with the
    /// tracking error above `track_loss` (totals since start, like `ticks`).
    pub faults: u64,
    pub plant_restarts: u64,
    pub safety_active: u64,
    pub track_lost: u64,
    /// Distributions over the last complete metrics window (`window_s` long, `window_ticks`
    /// ticks; the window under way until the first one completes), for monitoring: wake-up
    /// lateness, compute per tick and state age at the tick, each as p50, p99, p99.9 and max (µs).
    pub window_s: f64,
    pub window_ticks: u64,
    pub lateness_us: [f64; 4],
    pub compute_us: [f64; 4],
    pub state_age_us: [f64; 4],
    /// The command interface sent (`crate::interface`), and the device's status on the newest
    /// state (`crate::DeviceStatus` code; 0 while it runs).
    pub interface: u32,
    pub device: u32,
    /// Joint-ticks the limiter clamped since start, per kind: position, velocity,
    /// acceleration, jerk, torque, torque rate.
    pub saturations: [u64; 6],
    /// 0: not blocked; blocked (no clean cycle, or a trap) and 1: holding, 2: best-effort.
    pub blocked: u32,
    /// 1 while the self-motion is steered onto a planned clean cycle.
    pub steering: u32,
    /// The chaos monitor's verdict (`control::monitor::Verdict::code`: 0 unknown, 1 chaotic,
    /// 2 converging, 3 periodic, 4 regular), and 1 if μ adapts (`feedback.mu = "auto"`).
    pub chaos: u32,
    pub mu_auto: u32,
    /// Its evidence: the finite-time Lyapunov estimate (1/s) and the 0–1 test's K (NaN: none yet).
    pub lyapunov: f64,
    pub k01: f64,
    /// Limit breaches since start, per kind ([`LIMIT_BREACH_KINDS`]): states past a position
    /// limit, states past a speed limit, commands past an acceleration, a jerk and an effort
    /// limit.
    pub limit_breaches: [u64; 5],
    /// The gain the daemon chose from its model for `mu = "auto"` (NaN until it has
    /// chosen one, and without "auto").
    pub mu_model: f64,
}

/// Control service settings: one daemon serves; several clients may ask at once, one request
/// in flight each.
pub const CONTROL_MAX_CLIENTS: usize = 16;

pub type ControlService<S> =
    request_response::PortFactory<S, ControlRequest, (), ControlResponse, ()>;
pub type TelemetryService<S> = publish_subscribe::PortFactory<S, TelemetrySample, ()>;

/// Telemetry: history 1 so a new `watch` sees the latest sample at once; several watchers.
pub const TELEMETRY_QOS: PubSubQos = PubSubQos {
    history_size: 1,
    subscriber_max_buffer_size: 16,
    subscriber_max_borrowed_samples: 2,
    max_publishers: 1,
    max_subscribers: 16,
    max_nodes: 32,
    safe_overflow: true,
};

fn control_builder<S: iceoryx2::service::Service>(
    node: &Node<S>,
    names: &ServiceNames,
) -> Result<
    iceoryx2::service::builder::request_response::Builder<
        ControlRequest,
        (),
        ControlResponse,
        (),
        S,
    >,
    ServiceError,
> {
    Ok(node
        .service_builder(&service_name(names.control(), Channel::Control)?)
        .request_response::<ControlRequest, ControlResponse>()
        .max_servers(1)
        .max_clients(CONTROL_MAX_CLIENTS)
        .max_active_requests_per_client(1)
        .max_response_buffer_size(1)
        .max_nodes(CONTROL_MAX_CLIENTS + 4)
        .enable_fire_and_forget_requests(false))
}

/// The daemon's side: creates or opens the control service.
pub fn serve_control_service<S: iceoryx2::service::Service>(
    node: &Node<S>,
    names: &ServiceNames,
) -> Result<ControlService<S>, ServiceError> {
    control_builder(node, names)?
        .open_or_create()
        .map_err(|source| ServiceError::RequestResponse {
            channel: Channel::Control,
            source,
        })
}

/// A client's side: opens the service, or says no daemon is running.
pub fn open_control_service<S: iceoryx2::service::Service>(
    node: &Node<S>,
    names: &ServiceNames,
) -> Result<ControlService<S>, ServiceError> {
    use iceoryx2::service::builder::request_response::RequestResponseOpenError as E;
    control_builder(node, names)?.open().map_err(|e| match e {
        E::DoesNotExist => ServiceError::NotRunning {
            channel: Channel::Control,
        },
        // Anything else (another wire version, no permission, ...) is not "not running": say it.
        other => ServiceError::RequestResponseOpen {
            channel: Channel::Control,
            source: other,
        },
    })
}

pub fn open_telemetry_service<S: iceoryx2::service::Service>(
    node: &Node<S>,
    names: &ServiceNames,
) -> Result<TelemetryService<S>, ServiceError> {
    open_pubsub(node, names.telemetry(), Channel::Telemetry, &TELEMETRY_QOS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texts_round_trip_and_are_bounded() {
        let r = ControlRequest::new(7, Op::Set, "mu 1.5 tau 1").unwrap();
        assert_eq!(
            (r.id, r.op(), r.args()),
            (7, Ok(Op::Set), Ok("mu 1.5 tau 1"))
        );
        assert!(ControlRequest::new(1, Op::Set, &"x".repeat(MAX_ARGS + 1)).is_err());
        let long = "é".repeat(MAX_BODY); // 2 bytes each: must be cut at a boundary
        let resp = ControlResponse::new(3, Status::Ok, &long);
        let body = resp.body().unwrap();
        assert!(body.ends_with("[response truncated]") && body.len() <= MAX_BODY);
        let mut bad = ControlResponse::new(1, Status::Refused, "no");
        assert!(!bad.is_ok());
        bad.len = MAX_BODY as u32 + 1;
        assert!(bad.body().is_err());
        assert_eq!(Op::try_from(99), Err(99));
        for v in 1..=13 {
            assert_eq!(Op::try_from(v).unwrap() as u32, v);
        }
    }

    /// The telemetry layout carries per-joint arrays of `MAX_JOINTS`; if this test fails, the
    /// layout changed: bump the version in its `type_name`.
    #[test]
    fn telemetry_layout_is_pinned() {
        use core::mem::{align_of, offset_of, size_of};
        assert_eq!(MAX_JOINTS, 12);
        assert_eq!(size_of::<TelemetrySample>(), 648);
        assert_eq!(align_of::<TelemetrySample>(), 8);
        assert_eq!(offset_of!(TelemetrySample, phi), 168);
        assert_eq!(offset_of!(TelemetrySample, q), 176);
        assert_eq!(offset_of!(TelemetrySample, qd), 272);
        assert_eq!(offset_of!(TelemetrySample, faults), 368);
        assert_eq!(offset_of!(TelemetrySample, state_age_us), 480);
        assert_eq!(offset_of!(TelemetrySample, interface), 512);
        assert_eq!(offset_of!(TelemetrySample, saturations), 520);
        assert_eq!(offset_of!(TelemetrySample, blocked), 568);
        assert_eq!(offset_of!(TelemetrySample, chaos), 576);
        assert_eq!(offset_of!(TelemetrySample, lyapunov), 584);
        assert_eq!(offset_of!(TelemetrySample, steering), 572);
        assert_eq!(offset_of!(TelemetrySample, limit_breaches), 600);
        // SAFETY: type_name only returns the string set by #[type_name].
        assert_eq!(
            unsafe { <TelemetrySample as ZeroCopySend>::type_name() },
            "chaosd::TelemetrySample.v9"
        );
    }
}
