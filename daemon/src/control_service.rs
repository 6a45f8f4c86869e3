//! The control service: `chaosctl` requests, answered on the reporter thread.
//!
//! The reporter keeps the running [`Config`]; a change is validated in [`crate::requests`] and
//! sent to the loop as a whole `LawParams` block, which the loop swaps in between two ticks. A
//! request can never stall the loop: the loop only ever does a `try_recv`.

use crate::recording::Recording;
use crate::reporter::Reporter;
use crate::telemetry::LoopRequest;
use control::Config;
use protocol::{ControlRequest, ControlResponse, Op, Status};
use rt::hist::Percentiles;
use std::time::Instant;

impl Reporter {
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
        if let Some(log) = self.replay.as_mut() {
            log.committed(&self.cfg);
        }
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
    pub(crate) fn answered_share(&self) -> Option<f64> {
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
            "replay_recording": self.replay.as_ref().map(|r| r.path.display().to_string()),
            "replay_error": self.replay.as_ref().and_then(|r| r.stopped.clone()),
            "realtime": self.realtime,
            "trigger": self.daemon.trigger,
            "phase_offset_us": self.daemon.phase_offset_us,
            "state_to_command": Percentiles::of(&self.state_to_command),
            "answered_within_period": self.answered_share(),
        })
        .to_string()
    }

    /// Answers one request. Refusals leave everything unchanged.
    pub(crate) fn handle(&mut self, req: &ControlRequest) -> ControlResponse {
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
                Some(r) => r.finish(),
                None => Err("not recording".into()),
            },
            Op::Shutdown => {
                rt::signal::request_stop();
                Ok("shutting down".into())
            }
            Op::Resume => self.resume(),
            Op::DebugStall => crate::requests::parse_stall(args).and_then(|ms| {
                self.params_tx.try_send(LoopRequest::Stall(ms)).map_err(|_| {
                    "the control loop has not taken the previous request yet; try again".to_string()
                })?;
                Ok(format!("stalling the control loop for {ms} ms"))
            }),
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
        let r = Recording::start(
            &self.daemon.output_dir,
            args,
            self.cfg.n(),
            self.daemon.record_limit(),
        )?;
        let answer = serde_json::json!({"path": r.path}).to_string();
        self.recording = Some(r);
        Ok(answer)
    }
}
