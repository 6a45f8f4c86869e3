//! The reporter thread: everything the tick must not do.
//!
//! The loop hands one small `Copy` record per tick to this thread through a bounded crossbeam
//! channel with `try_send`, and counts a drop if the queue is full: it never waits. Here the
//! records become HdrHistograms (wake-up lateness, compute time, state age), per-second windows of
//! tracking error and period residual, live status lines, the telemetry stream, recordings and,
//! at exit, the files a person or a tool reads: `.hgrm` percentile text, a V2 `.hlog` and
//! `daemon-summary.json`.
//!
//! This thread also serves the control service ([`crate::control_service`]) and writes
//! recordings ([`crate::recording`]).

use crate::config::DaemonConfig;
use crate::recording::Recording;
use crate::telemetry::{DaemonSummary, LoopRequest, TickRecord, SUMMARY_FILE};
use anyhow::anyhow;
use control::System;
use hdrhistogram::Histogram;
use protocol::{Mode, ServiceNames, StateSample, TelemetrySample};
use rt::hist::{self, Percentiles};
use std::time::{Duration, Instant, SystemTime};

/// Accumulates one telemetry interval.
#[derive(Default)]
pub(crate) struct Interval {
    sq_track: f64,
    n_track: u64,
    resid: f64,
    n_resid: u64,
    min_clearance: f64,
}

pub struct Reporter {
    pub(crate) names: ServiceNames,
    pub(crate) daemon: DaemonConfig,
    /// The running configuration: the only copy that changes.
    pub(crate) system: System,
    pub(crate) params_tx: crossbeam::channel::Sender<LoopRequest>,
    pub(crate) rt_rx: crossbeam::channel::Receiver<rt::setup::RtReport>,
    pub(crate) min_tau: f64,
    pub(crate) report_every: Option<Duration>,
    pub(crate) realtime: rt::setup::RtReport,
    pub(crate) lateness: Histogram<u64>,
    pub(crate) compute: Histogram<u64>,
    pub(crate) state_age: Histogram<u64>,
    /// State → command, and (answered, answered within one period).
    pub(crate) state_to_command: Histogram<u64>,
    pub(crate) answered: (u64, u64),
    pub(crate) window_lateness: Histogram<u64>,
    pub(crate) tel_lateness: Histogram<u64>,
    /// Distributions over the last complete 10 s, for monitoring (see `window`).
    pub(crate) metrics: crate::window::MetricsWindow,
    /// Lateness, compute, state age since start or the last reset, for `hist`.
    pub(crate) snap: [Histogram<u64>; 3],
    pub(crate) snap_since: Instant,
    pub(crate) tel: Interval,
    pub(crate) tel_seq: u64,
    pub(crate) residuals: crate::residual::Residuals,
    pub(crate) tracking: crate::tracking::TrackingStats,
    pub(crate) feedback_on_at: Option<f64>,
    pub(crate) min_clearance: f64,
    pub(crate) safety_ticks: u64,
    pub(crate) last: Option<TickRecord>,
    /// The newest state the law used (ticks without a fresh state have none).
    pub(crate) last_state: Option<StateSample>,
    /// Whether the delayed term was applied the last time the law ran.
    pub(crate) last_feedback_active: bool,
    /// Controller time of the newest [`crate::controller::Counters::arm_brakes`].
    last_arm_brake: Option<f64>,
    pub(crate) window_track: (f64, u64),
    pub(crate) window_resid: (f64, u64),
    pub(crate) recording: Option<Recording>,
    pub(crate) recording_error: Option<String>,
    /// The replay recording from the first tick (`chaosd run --record`), if any.
    pub(crate) replay: Option<crate::replay::ReplayLog>,
    /// Why the daemon is in FAULT (controller time, reason), while it is.
    pub(crate) fault: Option<(f64, crate::guard::FaultReason)>,
    /// Controller time a restarted daemon resumed from (until the first record).
    pub(crate) t_start: f64,
    /// The config file's settings this daemon started from (`persist::fingerprint`).
    file_fingerprint: Option<String>,
    /// When the live state was last saved, and whether a failure to save was reported.
    pub(crate) saved_at: Option<Instant>,
    pub(crate) save_error_said: bool,
    /// Why the handshake refuses the current plant, if it does.
    pub(crate) handshake: crate::handshake::Refusal,
    /// How close the arm came to its joint limits.
    pub(crate) limits: crate::limits::LimitWatch,
    /// How often the limiter clamped each joint's command, per kind of limit.
    pub(crate) saturations: crate::saturations::SaturationTable,
    /// The device status on the newest state received.
    pub(crate) device: u32,
    /// Reflex stops the device reported, and the first one (controller time, reason).
    pub(crate) device_stops: u64,
    pub(crate) first_device_stop: Option<String>,
    /// Planning, trap detection and the `Blocked` state (see `deadlock`).
    pub(crate) deadlock: crate::deadlock::Deadlock,
    /// Whether the self-motion is chaotic, converging or periodic (see `chaos`).
    pub(crate) chaos: crate::chaos::ChaosWatch,
    /// `mu = "auto"`: the gain from the model (see `gains`).
    pub(crate) gains: crate::gains::GainTuning,
    /// The Foxglove live view (`[daemon] foxglove`), if served.
    pub(crate) live: Option<crate::foxglove::Live>,
}

impl Reporter {
    pub fn new(
        system: System,
        daemon: DaemonConfig,
        params_tx: crossbeam::channel::Sender<LoopRequest>,
        rt_rx: crossbeam::channel::Receiver<rt::setup::RtReport>,
    ) -> anyhow::Result<Self> {
        let names =
            ServiceNames::new(&daemon.namespace).map_err(|e| anyhow!("daemon.namespace: {e}"))?;
        let limits = crate::limits::LimitWatch::new(
            *system.param_block().safety(),
            system.effort_limits(),
            system.n(),
        );
        let saturations = crate::saturations::SaturationTable::new(
            system.command_mode(),
            system.limiter_on(),
            system.n(),
        );
        let deadlock = crate::deadlock::Deadlock::new(&system, daemon.core);
        let chaos =
            crate::chaos::ChaosWatch::new(daemon.monitor(), system.feedback().tau, system.n());
        let live = crate::foxglove::Live::start(&system, &daemon)?;
        let mut gains = crate::gains::GainTuning::new(daemon.core);
        gains.edited(&system, crate::gains::Why::Start);
        Ok(Self {
            live,
            gains,
            deadlock,
            chaos,
            limits,
            saturations,
            device: 0,
            device_stops: 0,
            first_device_stop: None,
            names,
            report_every: (daemon.report_every_s > 0.0)
                .then(|| Duration::from_secs_f64(daemon.report_every_s)),
            min_tau: 1.0 / daemon.rate_hz,
            daemon,
            system,
            params_tx,
            rt_rx,
            realtime: Default::default(),
            lateness: hist::new_ns(),
            compute: hist::new_ns(),
            state_age: hist::new_ns(),
            state_to_command: hist::new_ns(),
            answered: (0, 0),
            window_lateness: hist::new_ns(),
            tel_lateness: hist::new_ns(),
            metrics: Default::default(),
            snap: [hist::new_ns(), hist::new_ns(), hist::new_ns()],
            snap_since: Instant::now(),
            tel: Interval {
                min_clearance: f64::INFINITY,
                ..Default::default()
            },
            tel_seq: 0,
            residuals: Default::default(),
            tracking: Default::default(),
            feedback_on_at: None,
            min_clearance: f64::INFINITY,
            safety_ticks: 0,
            last: None,
            last_state: None,
            last_feedback_active: false,
            last_arm_brake: None,
            window_track: (0.0, 0),
            window_resid: (0.0, 0),
            recording: None,
            recording_error: None,
            replay: None,
            fault: None,
            t_start: 0.0,
            file_fingerprint: None,
            saved_at: None,
            save_error_said: false,
            handshake: Default::default(),
        })
    }

    /// Shows the handshake's refusal, if any, in `status`.
    pub fn with_handshake(mut self, refusal: crate::handshake::Refusal) -> Self {
        self.handshake = refusal;
        self
    }

    /// Starts from a restarted daemon's saved state: its controller time and any FAULT.
    /// `file` is the fingerprint of the config file's settings, saved with every live state.
    pub fn resuming(mut self, live: Option<&crate::persist::LiveState>, file: String) -> Self {
        self.file_fingerprint = Some(file);
        if let Some(l) = live {
            self.t_start = l.t;
            if l.fault.is_some() {
                self.fault = Some((l.t, crate::guard::FaultReason::Restored));
            }
        }
        self
    }

    /// Writes every tick to a replay recording (see [`crate::replay`]).
    pub fn recording_replay(mut self, log: Option<crate::replay::ReplayLog>) -> Self {
        self.replay = log;
        self
    }

    /// Saves the live configuration, controller time and FAULT for a restart (see `persist`).
    pub(crate) fn save_live_state(&mut self) {
        self.saved_at = Some(Instant::now());
        let system = match crate::persist::SavedSystem::of(&self.system) {
            Ok(s) => s,
            Err(e) => return self.save_failed(&e),
        };
        let state = crate::persist::LiveState {
            t: self.last.map_or(self.t_start, |r| r.t),
            saved_unix_s: crate::persist::unix_now(),
            fault: self.fault.map(|(t, f)| format!("at t = {t:.3} s: {f}")),
            system,
            file: self.file_fingerprint.clone(),
            gain: self
                .system
                .feedback()
                .auto
                .map(|a| crate::persist::SavedGain {
                    mu: self.last.map_or(self.system.feedback().mu, |r| r.mu),
                    model: a.anchor,
                }),
        };
        match crate::persist::save(&self.daemon.output_dir, &state) {
            Ok(()) => self.save_error_said = false,
            Err(e) => self.save_failed(&e),
        }
    }

    /// Says once (until a save succeeds again) that the live state could not be saved.
    fn save_failed(&mut self, e: &dyn std::fmt::Display) {
        if !self.save_error_said {
            self.save_error_said = true;
            tracing::warn!(
                "cannot save the live state to {}: {e} (a restart would lose live changes)",
                crate::persist::path(&self.daemon.output_dir).display()
            );
        }
    }

    fn record(&mut self, r: &TickRecord) {
        if self
            .last
            .is_some_and(|l| r.counters.arm_brakes > l.counters.arm_brakes)
        {
            self.last_arm_brake = Some(r.t);
        }
        if let Some(f @ crate::guard::FaultReason::Device { .. }) = r.fault {
            self.device_stops += 1;
            self.first_device_stop
                .get_or_insert_with(|| format!("at t = {:.3} s: {f}", r.t));
        }
        if let Some(f) = r.fault {
            // Said once, when it trips; `status` keeps saying it while the daemon is in FAULT.
            tracing::error!(
                "FAULT at t = {:.3} s: {f}; the plant is braking; `chaosctl resume` to control again",
                r.t
            );
            self.fault = Some((r.t, f));
            self.saved_at = None; // save at once: a FAULT must survive a crash right after it
        } else if r.mode != Mode::Fault && self.fault.is_some() {
            self.fault = None;
            self.saved_at = None;
        }
        self.deadlock.observe(r, &self.system);
        self.gains.observe(r, self.system.period(), self.system.n());
        if self.daemon.monitor {
            let edge = self.chaos.observe(r, self.mu_auto());
            if edge.is_some_and(|e| e.to == control::monitor::Verdict::Chaotic) {
                self.retarget(r.t);
            }
        }
        self.lateness.saturating_record(r.lateness_ns.max(1));
        self.window_lateness.saturating_record(r.lateness_ns.max(1));
        self.tel_lateness.saturating_record(r.lateness_ns.max(1));
        self.metrics.record(r);
        self.compute.saturating_record(r.compute_ns.max(1));
        self.snap[0].saturating_record(r.lateness_ns.max(1));
        self.snap[1].saturating_record(r.compute_ns.max(1));
        if let Some(a) = r.state_age_ns {
            self.state_age.saturating_record(a.max(1));
            self.snap[2].saturating_record(a.max(1));
        }
        if let (Some(a), true, Some(_)) = (r.state_age_ns, r.ran_law, r.command) {
            let to_cmd = a + r.compute_ns;
            self.state_to_command.saturating_record(to_cmd.max(1));
            self.answered.0 += 1;
            self.answered.1 += u64::from(to_cmd < self.daemon.period_ns());
        }
        if r.ran_law {
            self.residuals
                .add(r.t, r.period_residual, r.feedback_active);
            if r.feedback_active && self.feedback_on_at.is_none() {
                self.feedback_on_at = Some(r.t);
            }
            self.tracking.observe(r.t, r.tracking_error);
            self.window_track.0 += r.tracking_error * r.tracking_error;
            self.window_track.1 += 1;
            self.window_resid.0 += r.period_residual;
            self.window_resid.1 += 1;
            self.tel.sq_track += r.tracking_error * r.tracking_error;
            self.tel.n_track += 1;
            self.tel.resid += r.period_residual;
            self.tel.n_resid += 1;
            if r.clearance.is_finite() {
                self.min_clearance = self.min_clearance.min(r.clearance);
            }
            if let Some(st) = &r.state {
                self.limits.observe_state(st);
            }
            if let Some(c) = &r.command {
                self.limits.observe_command(c);
            }
            self.saturations.observe(&r.limiter_hits);
            self.tel.min_clearance = self.tel.min_clearance.min(r.clearance);
            if r.law_flags & control::basics::flags::IN_SAFETY_ZONE != 0 {
                self.safety_ticks += 1;
            }
        }
        if let (Some(rec), Some(st), true) = (self.recording.as_mut(), r.state.as_ref(), r.ran_law)
        {
            let ctx = crate::view::TickContext {
                chaos: self.chaos.evidence().verdict,
                blocked: self.deadlock.blocked.as_ref().map(|b| b.reason.as_str()),
            };
            if let Err(e) = rec.tick(r, st, ctx) {
                // Do not go on pretending: close it and say so in `status` and `record stop`.
                self.recording_error = Some(format!(
                    "recording to {} stopped after {} rows: {e}",
                    rec.path().display(),
                    rec.rows()
                ));
                self.recording = None;
            }
        }
        if let (Some(live), Some(st), true) = (self.live.as_mut(), r.state.as_ref(), r.ran_law) {
            let ctx = crate::view::TickContext {
                chaos: self.chaos.evidence().verdict,
                blocked: self.deadlock.blocked.as_ref().map(|b| b.reason.as_str()),
            };
            live.tick(r, st, ctx);
        }
        if let Some(log) = self.replay.as_mut() {
            let was_running = log.stopped.is_none();
            let ctx = crate::view::TickContext {
                chaos: self.chaos.evidence().verdict,
                blocked: self.deadlock.blocked.as_ref().map(|b| b.reason.as_str()),
            };
            log.tick(r, ctx);
            if let (true, Some(why)) = (was_running, &log.stopped) {
                tracing::warn!("{why}");
            }
        }
        if r.ran_law && r.state.is_some() {
            self.last_state = r.state;
        }
        if let Some(st) = &r.state {
            self.device = st.device;
        }
        if r.ran_law {
            self.last_feedback_active = r.feedback_active;
        }
        self.last = Some(*r);
    }

    /// Whether μ adapts (`feedback.mu = "auto"`) in the running configuration.
    pub(crate) fn mu_auto(&self) -> bool {
        self.system.feedback().auto.is_some()
    }

    fn telemetry(&mut self) -> Option<TelemetrySample> {
        let r = self.last?;
        let c = &r.counters;
        let p = Percentiles::of(&self.tel_lateness);
        let i = std::mem::replace(
            &mut self.tel,
            Interval {
                min_clearance: f64::INFINITY,
                ..Default::default()
            },
        );
        self.tel_lateness.reset();
        let mut t = TelemetrySample {
            seq: self.tel_seq,
            stamp_ns: protocol::monotonic_ns(),
            t: r.t,
            mode: r.mode as u32,
            feedback_on: u32::from(r.feedback_on),
            feedback_active: u32::from(self.last_feedback_active),
            n: self.system.n() as u32,
            mu: r.mu,
            tau: r.tau,
            t_on: r.t_on,
            tracking_error: if i.n_track > 0 {
                (i.sq_track / i.n_track as f64).sqrt()
            } else {
                f64::NAN
            },
            period_residual: if i.n_resid > 0 {
                i.resid / i.n_resid as f64
            } else {
                f64::NAN
            },
            clearance: i.min_clearance,
            time_in_contact: self.safety_ticks as f64 / self.daemon.rate_hz,
            lateness_p50_us: p.p50_us,
            lateness_p99_us: p.p99_us,
            lateness_max_us: p.max_us,
            ticks: c.ticks,
            overruns: c.overruns,
            telemetry_dropped: c.telemetry_dropped,
            rejected: c.rejected(),
            holds: c.holds_entered,
            ..TelemetrySample::default()
        };
        self.metrics.fill(&mut t, c);
        t.blocked = self.deadlock.code();
        t.steering = u32::from(self.deadlock.steering());
        self.chaos.fill(&mut t, self.mu_auto());
        t.mu_model = self.gains.mu_model();
        t.interface = self.saturations.mode.code();
        t.device = self.device;
        for kind in control::command::LimitKind::ALL {
            t.saturations[kind as usize] = self.saturations.total(kind);
        }
        t.limit_breaches = self.limits.seen().by_kind();
        if let Some(s) = self.last_state {
            t.state_seq = s.seq;
            t.phi = s.phi;
            t.q = s.q;
            t.qd = s.qd;
        }
        self.tel_seq += 1;
        Some(t)
    }

    /// Asks the loop to leave FAULT; refused when it is not in FAULT.
    /// Drains records until the loop closes the channel, serving requests and telemetry on the
    /// way, then writes the files.
    pub fn run(
        mut self,
        rx: crossbeam::channel::Receiver<TickRecord>,
        mut on_line: impl FnMut(&str),
    ) -> anyhow::Result<DaemonSummary> {
        let start = Instant::now();
        let wall_start = SystemTime::now();
        let node = match crate::ipc::node("chaosd-control") {
            Ok(n) => n,
            Err(e) => {
                rt::signal::request_stop();
                while rx.recv().is_ok() {}
                return Err(e);
            }
        };
        let ports = (|| -> anyhow::Result<_> {
            let server = protocol::control::serve_control_service(&node, &self.names)?
                .server_builder()
                .create()
                .map_err(|e| {
                    anyhow!(
                        "cannot serve {}: {e:?} (another chaosd in this namespace?)",
                        self.names.control()
                    )
                })?;
            let telemetry = protocol::control::open_telemetry_service(&node, &self.names)?
                .publisher_builder()
                .create()
                .map_err(|e| anyhow!("cannot publish on {}: {e:?}", self.names.telemetry()))?;
            Ok((server, telemetry))
        })();
        let (server, telemetry) = match ports {
            Ok(p) => p,
            Err(e) => {
                rt::signal::request_stop();
                while rx.recv().is_ok() {}
                return Err(e);
            }
        };
        let tel_every = Duration::from_secs_f64(1.0 / self.daemon.telemetry_hz);
        let mut next_tel = start + tel_every;
        let mut next_report = self.report_every.map(|d| start + d);
        loop {
            // Never block on the channel: a parked receiver makes every `try_send` in the loop
            // take the channel's waker lock and wake this thread with a futex call. Polling keeps
            // the sender on its lock-free fast path.
            let mut closed = false;
            loop {
                match rx.try_recv() {
                    Ok(r) => self.record(&r),
                    Err(crossbeam::channel::TryRecvError::Empty) => break,
                    Err(crossbeam::channel::TryRecvError::Disconnected) => {
                        closed = true;
                        break;
                    }
                }
            }
            if closed {
                break;
            }
            if let Ok(r) = self.rt_rx.try_recv() {
                log_started(&self.daemon, &r);
                self.realtime = r;
            }
            while let Ok(Some(active)) = server.receive() {
                let req = *active.payload();
                let resp = self.handle(&req);
                let _ = active.send_copy(resp);
            }
            let t = self.last.map_or(self.t_start, |r| r.t);
            self.deadlock
                .poll(&self.system, t, &self.params_tx, self.replay.as_mut());
            self.adopt_gain(t);
            let now = Instant::now();
            if now >= next_tel {
                if let Some(t) = self.telemetry() {
                    let _ = telemetry.send_copy(t);
                }
                next_tel += tel_every;
                if next_tel < now {
                    next_tel = now + tel_every;
                }
            }
            if let (Some(at), Some(every)) = (next_report, self.report_every) {
                if now >= at {
                    if let Some(line) = self.status_line() {
                        on_line(&line);
                    }
                    next_report = Some(at + every);
                }
            }
            if self
                .saved_at
                .is_none_or(|at| now.duration_since(at) >= Duration::from_secs(1))
            {
                self.save_live_state();
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        self.save_live_state();
        if let Some(r) = self.recording.take() {
            let _ = r.finish();
        }
        if let Some(log) = self.replay.take() {
            match log.finish() {
                Ok(p) => tracing::info!("replay recording {}", p.display()),
                Err(e) => tracing::warn!("{e}"),
            }
        }
        self.finish(start.elapsed(), wall_start)
    }

    fn status_line(&mut self) -> Option<String> {
        let r = self.last?;
        let c = &r.counters;
        let p = Percentiles::of(&self.window_lateness);
        let track = if self.window_track.1 > 0 {
            (self.window_track.0 / self.window_track.1 as f64).sqrt()
        } else {
            f64::NAN
        };
        let resid = if self.window_resid.1 > 0 {
            self.window_resid.0 / self.window_resid.1 as f64
        } else {
            f64::NAN
        };
        self.window_lateness.reset();
        self.window_track = (0.0, 0);
        self.window_resid = (0.0, 0);
        let mode = match (r.mode, &self.deadlock.blocked) {
            (_, Some(_)) => "BLOCKED",
            (Mode::Run, None) => "RUN ",
            (Mode::Hold, None) => "HOLD",
            (Mode::Brake, None) => "BRAKE",
            (Mode::Fault, None) => "FAULT",
        };
        Some(format!(
            "[{:7.1} s] {mode} μ={:.2} feedback {}  track {:.1e} m  residual {:.2e} rad/s  late p99 {:.1} µs max {:.1} µs  overruns {}  rejected {}  holds {}  drops {}",
            r.t,
            r.mu,
            if self.last_feedback_active { "on " } else { "off" },
            track,
            resid,
            p.p99_us,
            p.max_us,
            c.overruns,
            c.rejected(),
            c.holds_entered,
            c.telemetry_dropped
        ))
    }

    fn finish(self, elapsed: Duration, wall_start: SystemTime) -> anyhow::Result<DaemonSummary> {
        let out_dir = self.daemon.output_dir.clone();
        rt::files::create_dir_all(&out_dir).map_err(|e| {
            anyhow::anyhow!("cannot create output directory {}: {e}", out_dir.display())
        })?;
        let mut files = Vec::new();
        for (name, h) in [
            ("lateness", &self.lateness),
            ("compute", &self.compute),
            ("state-age", &self.state_age),
        ] {
            let p = out_dir.join(format!("daemon-{name}.hgrm"));
            hist::save_hgrm(h, &p)
                .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", p.display()))?;
            files.push(p);
        }
        let hlog = out_dir.join("daemon.hlog");
        hist::save_hlog(
            &[
                ("lateness", &self.lateness),
                ("compute", &self.compute),
                ("state-age", &self.state_age),
            ],
            wall_start,
            elapsed,
            &hlog,
        )
        .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", hlog.display()))?;
        files.push(hlog);

        let (residual_before, residual_start, residual_after) = self.residuals.all_means();
        let counters = self.last.map(|r| r.counters).unwrap_or_default();
        let summary = DaemonSummary {
            namespace: self.names.namespace().to_string(),
            rate_hz: self.daemon.rate_hz,
            wait: self.daemon.wait.name().to_string(),
            realtime: self.realtime.clone(),
            duration_s: elapsed.as_secs_f64(),
            counters,
            lateness: Percentiles::of(&self.lateness),
            compute: Percentiles::of(&self.compute),
            state_age: Percentiles::of(&self.state_age),
            state_to_command: Percentiles::of(&self.state_to_command),
            answered_within_period: self.answered_share(),
            tracking_rms_m: self.tracking.rms(),
            tracking: self.tracking.spread(),
            tracking_whole_rms_m: self.tracking.whole_rms(),
            tracking_whole: self.tracking.whole_spread(),
            period_residual_before: residual_before,
            period_residual_after: residual_after,
            period_residual_start: residual_start,
            feedback_on_at_s: self.feedback_on_at,
            min_clearance_m: self.min_clearance.is_finite().then_some(self.min_clearance),
            joint_limits: self.limits.seen(),
            command: self.saturations,
            last_arm_brake_s: self.last_arm_brake,
            device_stops: self.device_stops,
            first_device_stop: self.first_device_stop.clone(),
            blocked_entered: self.deadlock.entered,
            first_blocked: self.deadlock.first.clone(),
            chaos: crate::telemetry::ChaosSummary {
                model_gain: self.gains.chosen.as_ref().map(|c| c.choice.why()),
                target: self.deadlock.target.last,
                ..self.chaos.summary()
            },
            time_in_safety_zone_s: self.safety_ticks as f64 / self.daemon.rate_hz,
            files: Vec::new(),
        };
        files.push(out_dir.join(SUMMARY_FILE));
        Ok(DaemonSummary { files, ..summary })
    }
}

/// The start-up lines, logged by the reporter thread once the loop reports its real-time set-up.
pub fn log_started(d: &crate::config::DaemonConfig, rt_report: &rt::setup::RtReport) {
    for w in &rt_report.warnings {
        tracing::warn!("{w}");
    }
    tracing::info!(
        "namespace {:?}, {} Hz, {} wait, {}",
        d.namespace,
        d.rate_hz,
        d.wait.name(),
        rt_report.one_line()
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::telemetry::TickRecord;

    /// A tick without a state runs no law and so has no feedback flag: the status line must
    /// still say what the law did on its last run (it said "feedback off" mid-run on the UDP
    /// bridge, where such ticks are common).
    #[test]
    fn the_status_line_says_the_feedback_of_the_last_law_run_not_of_a_tick_without_a_state() {
        let system = System::preset("paper", &control::system::builtin_robot).unwrap();
        let (params_tx, _params_rx) = crossbeam::channel::unbounded();
        let (_rt_tx, rt_rx) = crossbeam::channel::unbounded();
        let daemon = DaemonConfig {
            namespace: "reporter-status-line-test".into(),
            ..DaemonConfig::default()
        };
        let mut rep = Reporter::new(system, daemon, params_tx, rt_rx).unwrap();
        let ran = TickRecord {
            t: 1.0,
            ran_law: true,
            mu: 0.2,
            feedback_on: true,
            feedback_active: true,
            ..TickRecord::blank()
        };
        rep.record(&ran);
        let line = rep.status_line().unwrap();
        assert!(line.contains("feedback on"), "{line}");
        rep.record(&TickRecord {
            t: 1.001,
            ..TickRecord::blank()
        });
        let line = rep.status_line().unwrap();
        assert!(line.contains("feedback on"), "{line}");
        rep.record(&TickRecord {
            feedback_active: false,
            t: 1.002,
            ..ran
        });
        let line = rep.status_line().unwrap();
        assert!(line.contains("feedback off"), "{line}");
    }
}
