//! The reporter thread: everything the tick must not do.
//!
//! The loop hands one small `Copy` record per tick to this thread through a bounded crossbeam
//! channel with `try_send`, and counts a drop if the queue is full: it never waits. Here the
//! records become HdrHistograms (wake-up lateness, compute time, state age), per-second windows of
//! tracking error and period residual, live status lines, the telemetry stream, recordings and,
//! at exit, the files a person or a tool reads: `.hgrm` percentile text, a V2 `.hlog` and
//! `daemon-summary.json`.
//!
//! This thread also serves the control service. It keeps the running [`Config`]; a change is
//! validated in [`crate::requests`] and sent to the loop as a whole `LawParams` block, which the
//! loop swaps in between two ticks. So a request can never stall the loop: the loop only ever
//! does a `try_recv`.

use crate::config::DaemonConfig;
use crate::controller::Counters;
use anyhow::anyhow;
use control::{Config, LawParams};
use hdrhistogram::Histogram;
use protocol::{
    CommandSample, ControlRequest, ControlResponse, Mode, Op, ServiceNames, StateSample, Status,
    TelemetrySample,
};
use rt::hist::{self, Percentiles};
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

/// What the control service hands the loop (through a bounded channel the loop `try_recv`s).
// Not boxed: the loop would free the box, and the tick does no heap work at all.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug)]
pub enum LoopRequest {
    /// A validated parameter block, swapped in between two ticks.
    Params(LawParams),
    /// Leave FAULT (`chaosctl resume`).
    Resume,
    /// The handshake's verdict on one plant start (`crate::handshake`).
    Plant { plant_id: u64, agreed: bool },
}

/// One tick, as the loop saw it.
#[derive(Clone, Copy, Debug)]
pub struct TickRecord {
    /// Controller time (s).
    pub t: f64,
    pub lateness_ns: u64,
    pub compute_ns: u64,
    pub state_age_ns: Option<u64>,
    pub mode: Mode,
    /// The runaway guard tripped on this tick.
    pub fault: Option<crate::guard::FaultReason>,
    /// Whether the law ran (a fresh state arrived).
    pub ran_law: bool,
    pub law_flags: u32,
    pub tracking_error: f64,
    pub period_residual: f64,
    pub clearance: f64,
    pub mu: f64,
    pub tau: f64,
    pub t_on: f64,
    pub feedback_on: bool,
    pub feedback_active: bool,
    pub counters: Counters,
    /// The state the law used, if a fresh one arrived.
    pub state: Option<StateSample>,
    /// The command published, if any.
    pub command: Option<CommandSample>,
}

/// What the reporter learnt over the run.
#[derive(Clone, Debug, Serialize)]
pub struct DaemonSummary {
    pub namespace: String,
    pub rate_hz: f64,
    pub wait: String,
    pub realtime: rt::setup::RtReport,
    pub duration_s: f64,
    pub counters: Counters,
    pub lateness: Percentiles,
    pub compute: Percentiles,
    pub state_age: Percentiles,
    /// State stamp → command sent (state age + compute), for each state answered.
    pub state_to_command: Percentiles,
    /// Share of answered states whose command left within one period of the state's stamp.
    pub answered_within_period: Option<f64>,
    /// RMS tracking error over ticks after the first 2 s (m).
    pub tracking_rms_m: Option<f64>,
    /// Mean |q̇(t) − q̇(t − τ)| while the feedback was off (after the first 2 s).
    pub period_residual_before: Option<f64>,
    /// The same over the last 5 s with the feedback on.
    pub period_residual_after: Option<f64>,
    pub feedback_on_at_s: Option<f64>,
    pub min_clearance_m: Option<f64>,
    pub time_in_safety_zone_s: f64,
    pub files: Vec<PathBuf>,
}

/// An open recording.
struct Recording {
    path: PathBuf,
    file: crate::rotate::RotatingWriter,
    rows: u64,
    n: usize,
}

/// Accumulates one telemetry interval.
#[derive(Default)]
struct Interval {
    sq_track: f64,
    n_track: u64,
    resid: f64,
    n_resid: u64,
    min_clearance: f64,
}

pub struct Reporter {
    names: ServiceNames,
    daemon: DaemonConfig,
    /// The running configuration: the only copy that changes.
    cfg: Config,
    params_tx: crossbeam::channel::Sender<LoopRequest>,
    rt_rx: crossbeam::channel::Receiver<rt::setup::RtReport>,
    min_tau: f64,
    report_every: Option<Duration>,
    realtime: rt::setup::RtReport,
    lateness: Histogram<u64>,
    compute: Histogram<u64>,
    state_age: Histogram<u64>,
    /// State → command, and (answered, answered within one period).
    state_to_command: Histogram<u64>,
    answered: (u64, u64),
    window_lateness: Histogram<u64>,
    tel_lateness: Histogram<u64>,
    /// Lateness, compute, state age since start or the last reset, for `hist`.
    snap: [Histogram<u64>; 3],
    snap_since: Instant,
    tel: Interval,
    tel_seq: u64,
    residuals: crate::residual::Residuals,
    sq_track: f64,
    n_track: u64,
    feedback_on_at: Option<f64>,
    min_clearance: f64,
    safety_ticks: u64,
    last: Option<TickRecord>,
    /// The newest state the law used (ticks without a fresh state have none).
    last_state: Option<StateSample>,
    /// Whether the delayed term was applied the last time the law ran.
    last_feedback_active: bool,
    window_track: (f64, u64),
    window_resid: (f64, u64),
    recording: Option<Recording>,
    recording_error: Option<String>,
    /// Why the daemon is in FAULT (controller time, reason), while it is.
    fault: Option<(f64, crate::guard::FaultReason)>,
    /// Controller time a restarted daemon resumed from (until the first record).
    t_start: f64,
    /// When the live state was last saved, and whether a failure to save was reported.
    saved_at: Option<Instant>,
    save_error_said: bool,
    /// Why the handshake refuses the current plant, if it does.
    handshake: crate::handshake::Refusal,
}

impl Reporter {
    pub fn new(
        cfg: Config,
        daemon: DaemonConfig,
        params_tx: crossbeam::channel::Sender<LoopRequest>,
        rt_rx: crossbeam::channel::Receiver<rt::setup::RtReport>,
    ) -> anyhow::Result<Self> {
        let names =
            ServiceNames::new(&daemon.namespace).map_err(|e| anyhow!("daemon.namespace: {e}"))?;
        Ok(Self {
            names,
            report_every: (daemon.report_every_s > 0.0)
                .then(|| Duration::from_secs_f64(daemon.report_every_s)),
            min_tau: 1.0 / daemon.rate_hz,
            daemon,
            cfg,
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
            snap: [hist::new_ns(), hist::new_ns(), hist::new_ns()],
            snap_since: Instant::now(),
            tel: Interval {
                min_clearance: f64::INFINITY,
                ..Default::default()
            },
            tel_seq: 0,
            residuals: Default::default(),
            sq_track: 0.0,
            n_track: 0,
            feedback_on_at: None,
            min_clearance: f64::INFINITY,
            safety_ticks: 0,
            last: None,
            last_state: None,
            last_feedback_active: false,
            window_track: (0.0, 0),
            window_resid: (0.0, 0),
            recording: None,
            recording_error: None,
            fault: None,
            t_start: 0.0,
            saved_at: None,
            save_error_said: false,
            handshake: Default::default(),
        })
    }

    /// Starts from a restarted daemon's saved state: its controller time and any FAULT.
    pub fn resuming(mut self, live: Option<&crate::persist::LiveState>) -> Self {
        if let Some(l) = live {
            self.t_start = l.t;
            if l.fault.is_some() {
                self.fault = Some((l.t, crate::guard::FaultReason::Restored));
            }
        }
        self
    }

    /// Shows the handshake's refusal, if any, in `status`.
    pub fn with_handshake(mut self, refusal: crate::handshake::Refusal) -> Self {
        self.handshake = refusal;
        self
    }

    /// Saves the live configuration, controller time and FAULT for a restart (see `persist`).
    fn save_live_state(&mut self) {
        let mut system = self.cfg.clone();
        system.daemon = None;
        system.plant = None;
        let state = crate::persist::LiveState {
            t: self.last.map_or(self.t_start, |r| r.t),
            saved_unix_s: crate::persist::unix_now(),
            fault: self.fault.map(|(t, f)| format!("at t = {t:.3} s: {f}")),
            system,
        };
        self.saved_at = Some(Instant::now());
        match crate::persist::save(&self.daemon.output_dir, &state) {
            Ok(()) => self.save_error_said = false,
            Err(e) if !self.save_error_said => {
                self.save_error_said = true;
                eprintln!(
                    "chaosd: warning: cannot save the live state to {}: {e} (a restart would lose live changes)",
                    crate::persist::path(&self.daemon.output_dir).display()
                );
            }
            Err(_) => {}
        }
    }

    fn record(&mut self, r: &TickRecord) {
        if let Some(f) = r.fault {
            // Said once, when it trips; `status` keeps saying it while the daemon is in FAULT.
            eprintln!(
                "chaosd: FAULT at t = {:.3} s: {f}; the plant is braking; `chaosctl resume` to control again",
                r.t
            );
            self.fault = Some((r.t, f));
            self.saved_at = None; // save at once: a FAULT must survive a crash right after it
        } else if r.mode != Mode::Fault && self.fault.is_some() {
            self.fault = None;
            self.saved_at = None;
        }
        self.lateness.saturating_record(r.lateness_ns.max(1));
        self.window_lateness.saturating_record(r.lateness_ns.max(1));
        self.tel_lateness.saturating_record(r.lateness_ns.max(1));
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
            if r.t >= 2.0 {
                self.sq_track += r.tracking_error * r.tracking_error;
                self.n_track += 1;
            }
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
            self.tel.min_clearance = self.tel.min_clearance.min(r.clearance);
            if r.law_flags & control::law::flags::IN_SAFETY_ZONE != 0 {
                self.safety_ticks += 1;
            }
        }
        if let (Some(rec), Some(st)) = (self.recording.as_mut(), r.state.as_ref()) {
            if let Err(e) = write_row(rec, r, st) {
                // Do not go on pretending: close it and say so in `status` and `record stop`.
                self.recording_error = Some(format!(
                    "recording to {} stopped after {} rows: {e}",
                    rec.path.display(),
                    rec.rows
                ));
                self.recording = None;
            }
        }
        if r.state.is_some() {
            self.last_state = r.state;
        }
        if r.ran_law {
            self.last_feedback_active = r.feedback_active;
        }
        self.last = Some(*r);
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
            n: self.cfg.n() as u32,
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
    fn resume(&mut self) -> Result<String, String> {
        let Some((t, why)) = self.fault else {
            return Err("the daemon is not in FAULT: nothing to resume".into());
        };
        self.params_tx.try_send(LoopRequest::Resume).map_err(|_| {
            "the control loop has not taken the previous request yet; try again".to_string()
        })?;
        Ok(format!(
            "resuming: HOLD until the next fresh state, then RUN with a fresh history (the fault at t = {t:.3} s was: {why})"
        ))
    }

    /// Sends a validated configuration to the loop and adopts it.
    fn commit(&mut self, new: Config) -> Result<String, String> {
        self.params_tx
            .try_send(LoopRequest::Params(new.law_params()))
            .map_err(|_| {
                "the control loop has not taken the previous change yet; try again".to_string()
            })?;
        self.cfg = new;
        self.save_live_state();
        let f = &self.cfg.feedback;
        let c = &self.cfg.control;
        Ok(serde_json::json!({
            "applied": "at the next tick",
            "mu": f.mu, "tau": f.tau, "t_on": f.t_on, "feedback": f.enabled,
            "kp": c.kp, "kv": c.kv, "alpha": c.alpha, "secondary": c.secondary,
            "obstacles": c.obstacles.len(),
            "task": self.cfg.task,
        })
        .to_string())
    }

    /// Percentiles since start or the last `hist --reset` (the exit files always cover the run).
    fn percentiles(&self) -> serde_json::Value {
        serde_json::json!({
            "since_s": self.snap_since.elapsed().as_secs_f64(),
            "lateness": Percentiles::of(&self.snap[0]),
            "compute": Percentiles::of(&self.snap[1]),
            "state_age": Percentiles::of(&self.snap[2]),
        })
    }

    /// Answered states whose command left within one period of the state's stamp.
    fn answered_share(&self) -> Option<f64> {
        let (all, in_time) = self.answered;
        (all > 0).then(|| in_time as f64 / all as f64)
    }

    fn status(&self) -> String {
        let r = self.last;
        let tr = self.window_track;
        serde_json::json!({
            "namespace": self.names.namespace(),
            "pid": std::process::id(),
            "rate_hz": self.daemon.rate_hz,
            "wait": self.daemon.wait,
            "mode": r.map(|r| format!("{:?}", r.mode)),
            "handshake": self.handshake.lock().ok().and_then(|g| g.clone()),
            "fault": self.fault.map(|(t, f)| format!("at t = {t:.3} s: {f}")),
            "safety": self.cfg.safety.enabled,
            "t": r.map(|r| r.t),
            "mu": r.map(|r| r.mu),
            "tau": r.map(|r| r.tau),
            "t_on": r.map(|r| r.t_on),
            "feedback": r.map(|r| r.feedback_on),
            "feedback_active": self.last_feedback_active,
            "kp": self.cfg.control.kp,
            "kv": self.cfg.control.kv,
            "alpha": self.cfg.control.alpha,
            "secondary": self.cfg.control.secondary,
            "obstacles": self.cfg.control.obstacles.len(),
            "max_tau": self.cfg.feedback.max_tau,
            "tracking_error_recent": if tr.1 > 0 { Some((tr.0 / tr.1 as f64).sqrt()) } else { None },
            "counters": r.map(|r| r.counters),
            "histograms": self.percentiles(),
            "recording": self.recording.as_ref().map(|r| r.path.display().to_string()),
            "recording_error": self.recording_error,
            "realtime": self.realtime,
            "trigger": self.daemon.trigger,
            "phase_offset_us": self.daemon.phase_offset_us,
            "state_to_command": Percentiles::of(&self.state_to_command),
            "answered_within_period": self.answered_share(),
        })
        .to_string()
    }

    /// Answers one request. Refusals leave everything unchanged.
    fn handle(&mut self, req: &ControlRequest) -> ControlResponse {
        let args = match req.args() {
            Ok(a) => a,
            Err(e) => {
                return ControlResponse::new(
                    req.id,
                    Status::Refused,
                    &format!("malformed request: {e}"),
                )
            }
        };
        let op = match req.op() {
            Ok(op) => op,
            Err(v) => {
                return ControlResponse::new(
                    req.id,
                    Status::Refused,
                    &format!("unknown operation {v}"),
                )
            }
        };
        let now = self.last.map_or(0.0, |r| r.t);
        let result: Result<String, String> = match op {
            Op::Status => Ok(self.status()),
            Op::GetConfig => {
                let mut c = self.cfg.clone();
                c.daemon = toml::Table::try_from(&self.daemon).ok();
                Ok(c.to_toml_string())
            }
            Op::Set => crate::requests::apply_set(&self.cfg, args, self.min_tau).and_then(|c| self.commit(c)),
            Op::DfcOn => crate::requests::apply_dfc(&self.cfg, true, now).and_then(|c| self.commit(c)),
            Op::DfcOff => crate::requests::apply_dfc(&self.cfg, false, now).and_then(|c| self.commit(c)),
            Op::ObstacleAdd => crate::requests::apply_obstacle_add(&self.cfg, args).and_then(|c| self.commit(c)),
            Op::ObstacleRemove => crate::requests::apply_obstacle_remove(&self.cfg, args).and_then(|c| self.commit(c)),
            Op::ObstacleList => Ok(serde_json::json!(self
                .cfg
                .control
                .obstacles
                .iter()
                .enumerate()
                .map(|(i, o)| serde_json::json!({"index": i, "center": o.center, "radius": o.radius, "margin": o.margin}))
                .collect::<Vec<_>>())
            .to_string()),
            Op::HistSnapshot => Ok(self.percentiles().to_string()),
            Op::HistReset => {
                for h in &mut self.snap {
                    h.reset();
                }
                self.snap_since = Instant::now();
                Ok("histograms reset (the files written at exit still cover the whole run)".into())
            }
            Op::RecordStart => self.start_recording(args),
            Op::RecordStop => match self.recording.take() {
                None if self.recording_error.is_some() => Err(self.recording_error.take().unwrap_or_default()),
                Some(mut r) => r
                    .file
                    .flush()
                    .map(|_| serde_json::json!({"path": r.path, "rows": r.rows, "rotations": r.file.rotations(), "last_file": r.file.current_path()}).to_string())
                    .map_err(|e| format!("cannot finish {}: {e}", r.path.display())),
                None => Err("not recording".into()),
            },
            Op::Shutdown => {
                rt::signal::request_stop();
                Ok("shutting down".into())
            }
            Op::Resume => self.resume(),
        };
        match result {
            Ok(body) => ControlResponse::new(req.id, Status::Ok, &body),
            Err(why) => ControlResponse::new(req.id, Status::Refused, &why),
        }
    }

    fn start_recording(&mut self, args: &str) -> Result<String, String> {
        if let Some(r) = &self.recording {
            return Err(format!("already recording to {}", r.path.display()));
        }
        let name = if args.trim().is_empty() {
            let secs = SystemTime::now()
                .duration_since(SystemTime::UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0);
            format!("recording-{secs}.csv")
        } else {
            args.trim().to_string()
        };
        let path = crate::requests::recording_path(&self.daemon.output_dir, &name)?;
        if let Some(dir) = path.parent() {
            rt::files::create_dir_all(dir)
                .map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
        }
        let n = self.cfg.n();
        let mut h = String::from("t,state_seq,state_stamp_ns,phi");
        for p in ["q", "qd"] {
            for i in 1..=n {
                h.push_str(&format!(",{p}{i}"));
            }
        }
        h.push_str(",command_seq,mode");
        for i in 1..=n {
            h.push_str(&format!(",qdd{i}"));
        }
        h.push_str(",tracking_error,period_residual\n");
        // Rotates at `record_max_bytes`, keeping `record_keep` old files (see `rotate`).
        let file =
            crate::rotate::RotatingWriter::create(&path, h.as_bytes(), self.daemon.record_limit())
                .map_err(|e| format!("cannot create {}: {e}", path.display()))?;
        self.recording = Some(Recording {
            path: path.clone(),
            file,
            rows: 0,
            n,
        });
        Ok(serde_json::json!({"path": path}).to_string())
    }

    /// Drains records until the loop closes the channel, serving requests and telemetry on the
    /// way, then writes the files.
    pub fn run(
        mut self,
        rx: crossbeam::channel::Receiver<TickRecord>,
        mut on_line: impl FnMut(&str),
    ) -> anyhow::Result<DaemonSummary> {
        let start = Instant::now();
        let wall_start = SystemTime::now();
        let node = match crate::service::node("chaosd-control") {
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
                self.realtime = r;
            }
            while let Ok(Some(active)) = server.receive() {
                let req = *active.payload();
                let resp = self.handle(&req);
                let _ = active.send_copy(resp);
            }
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
        if let Some(mut r) = self.recording.take() {
            let _ = r.file.flush();
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
        let mode = match r.mode {
            Mode::Run => "RUN ",
            Mode::Hold => "HOLD",
            Mode::Brake => "BRAKE",
            Mode::Fault => "FAULT",
        };
        Some(format!(
            "[{:7.1} s] {mode} μ={:.2} feedback {}  track {:.1e} m  residual {:.2e} rad/s  late p99 {:.1} µs max {:.1} µs  overruns {}  rejected {}  holds {}  drops {}",
            r.t,
            r.mu,
            if r.feedback_active { "on " } else { "off" },
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

        let (residual_before, residual_after) = self.residuals.means();
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
            tracking_rms_m: (self.n_track > 0)
                .then(|| (self.sq_track / self.n_track as f64).sqrt()),
            period_residual_before: residual_before,
            period_residual_after: residual_after,
            feedback_on_at_s: self.feedback_on_at,
            min_clearance_m: self.min_clearance.is_finite().then_some(self.min_clearance),
            time_in_safety_zone_s: self.safety_ticks as f64 / self.daemon.rate_hz,
            files: Vec::new(),
        };
        files.push(out_dir.join(SUMMARY_FILE));
        Ok(DaemonSummary { files, ..summary })
    }
}

/// Name of the JSON summary in the output directory.
pub const SUMMARY_FILE: &str = "daemon-summary.json";

/// Writes the summary once the loop has added what only it knows (the real-time set-up).
pub fn write_summary(summary: &DaemonSummary, dir: &Path) -> anyhow::Result<()> {
    let json = dir.join(SUMMARY_FILE);
    rt::files::write(&json, serde_json::to_string_pretty(summary)?)
        .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", json.display()))
}

fn write_row(rec: &mut Recording, r: &TickRecord, s: &StateSample) -> std::io::Result<()> {
    let n = rec.n;
    let f = &mut rec.file;
    write!(f, "{:.6},{},{},{:.12e}", r.t, s.seq, s.stamp_ns, s.phi)?;
    for v in s.q[..n].iter().chain(&s.qd[..n]) {
        write!(f, ",{v:.12e}")?;
    }
    match &r.command {
        Some(c) => {
            write!(f, ",{},{}", c.seq, c.mode)?;
            for v in &c.qdd[..n] {
                write!(f, ",{v:.12e}")?;
            }
        }
        None => {
            write!(f, ",,")?;
            for _ in 0..n {
                write!(f, ",")?;
            }
        }
    }
    writeln!(f, ",{:.9e},{:.9e}", r.tracking_error, r.period_residual)?;
    rec.rows += 1;
    Ok(())
}
