//! The control service: `chaosctl` requests, answered on the reporter thread.
//!
//! The reporter keeps the running [`System`]; a change is validated in [`crate::requests`] (one
//! path for every arm) and sent to the loop as a whole parameter block, which the loop swaps in
//! between two ticks. A request can never stall the loop: the loop only
//! ever does a `try_recv`.

use crate::recording::Recording;
use crate::reporter::Reporter;
use crate::telemetry::LoopRequest;
use control::System;
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
    fn commit(&mut self, new: System) -> Result<String, String> {
        self.params_tx
            .try_send(LoopRequest::Params(new.param_block()))
            .map_err(|_| {
                "the control loop has not taken the previous change yet; try again".to_string()
            })?;
        let answer = crate::change::describe(&self.system, &new);
        self.system = new;
        let t = self.last.map_or(self.t_start, |r| r.t);
        let q_now = self.last_state.map(|s| s.q[..self.system.n()].to_vec());
        self.deadlock.edited(&self.system, t, q_now);
        self.gains.edited(&self.system, crate::gains::Why::Edit);
        self.limits.set_limits(*self.system.param_block().safety());
        if let Some(log) = self.replay.as_mut() {
            log.committed(&self.system);
        }
        self.save_live_state();
        Ok(answer)
    }

    /// Hands the gain the model chose to the loop (see `gains`): not an edit, so neither the
    /// planner nor the monitor starts over. Tried again on the next pass while the loop has
    /// not taken the previous block.
    pub(crate) fn adopt_gain(&mut self, t: f64) {
        let Some(c) = self.gains.poll() else {
            return;
        };
        let Some(new) = self.system.with_model_gain(c.choice.mu, c.choice.gamma) else {
            return;
        };
        if self
            .params_tx
            .try_send(LoopRequest::Params(new.param_block()))
            .is_err()
        {
            return;
        }
        self.system = new;
        self.chaos.gain_only();
        self.gains.handed_over(t);
        if let Some(Ok(target)) = &c.target {
            self.deadlock.target(target, t, self.system.period());
        }
        if let Some(log) = self.replay.as_mut() {
            log.committed(&self.system);
        }
        self.save_live_state();
    }

    /// The monitor calls the arm chaotic again after the model's gain came: something (a
    /// stall, a hold, a push) knocked it off its cycle, so it is steered back, as at the start,
    /// rather than left to the feedback to catch by chance ([`control::target::MAX_RETARGETS`]
    /// times until the next edit).
    pub(crate) fn retarget(&mut self, t: f64) {
        let Some(Ok(target)) = self.gains.chosen.as_ref().and_then(|c| c.target.clone()) else {
            return;
        };
        if self.deadlock.target.active() || !self.deadlock.target.may_retarget() {
            return;
        }
        tracing::warn!(
            "mu = \"auto\": the arm left the model's cycle (chaotic at t = {t:.3} s): steering it back"
        );
        self.deadlock.target(&target, t, self.system.period());
    }

    /// `status`'s `gains`: the model's gain and the steering onto its cycle.
    fn gains_json(&self) -> serde_json::Value {
        let mut g = self.gains.to_json();
        g["target"] = self.deadlock.target.to_json();
        g
    }

    /// The law's settings as `status` and a change's answer show them.
    fn law_settings(&self) -> serde_json::Value {
        let (fb, section, law) = (
            self.system.feedback(),
            self.system.feedback_section(),
            self.system.law_section(),
        );
        let mut v = serde_json::json!({
            "feedback": section.enabled, "projection": section.projection,
            "kp": law.kp, "kv": law.kv, "alpha": law.alpha, "secondary": law.secondary,
        });
        v["task"] = serde_json::json!(self.system.task());
        if let Some(id) = self.system.identity() {
            v["robot"] = id.name.into();
        }
        v["mu"] = fb.mu.into();
        v["tau"] = fb.tau.into();
        v["t_on"] = fb.t_on.into();
        v["max_tau"] = fb.max_tau.into();
        v["obstacles"] = self.system.safety().obstacles.into();
        v
    }

    /// Applies one change request to the running set-up (not yet committed).
    fn change(&self, op: Op, args: &str, now: f64) -> Result<System, String> {
        use crate::requests as p;
        let t = self.min_tau;
        let system = &self.system;
        match op {
            Op::DfcOn => p::apply_dfc(system, true, now, t),
            Op::DfcOff => p::apply_dfc(system, false, now, t),
            Op::ObstacleAdd => p::apply_obstacle_add(system, args, t),
            Op::ObstacleRemove => p::apply_obstacle_remove(system, args, t),
            _ => p::apply_set(system, args, t),
        }
    }

    /// Refuses a new obstacle that a link is already inside: the filter keeps links out of an
    /// obstacle and cannot bring one out, so the arm would run on inside it.
    fn outside_obstacles(&self, op: Op, new: System) -> Result<System, String> {
        let Some(s) = self.last_state.filter(|_| op == Op::ObstacleAdd) else {
            return Ok(new);
        };
        let q = &s.q[..self.system.n()];
        let (before, after) = (
            self.system.clearance_at(s.phi, q),
            new.clearance_at(s.phi, q),
        );
        if after < 0.0 && after < before {
            return Err(format!(
                "a link of the arm is {:.3} m inside that obstacle at its posture now: the safety filter keeps links out of an obstacle but cannot bring one out; place it clear of the arm",
                -after
            ));
        }
        Ok(new)
    }

    /// The obstacles as `obstacle ls` lists them (2-D circles or 3-D spheres).
    fn obstacles(&self) -> serde_json::Value {
        // Numbered from 1, as `obstacle rm`, Blocked and every other message number them.
        let rows: Vec<_> = self
            .system
            .obstacle_rows()
            .iter()
            .enumerate()
            .map(|(i, o)| serde_json::json!({"number": i + 1, "center": o.center, "radius": o.radius, "margin": o.margin}))
            .collect();
        serde_json::json!(rows)
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
        let law = self.law_settings();
        let mut v = serde_json::json!({
            "namespace": self.names.namespace(),
            "pid": std::process::id(),
            "rate_hz": self.daemon.rate_hz,
            "wait": self.daemon.wait,
            "mode": r.map(|r| format!("{:?}", r.mode)),
            "handshake": self.handshake.lock().ok().and_then(|g| g.clone()),
            "fault": self.fault.map(|(t, f)| format!("at t = {t:.3} s: {f}")),
            "arm": self.system.describe_arm(),
            "n": self.system.n(),
            "safety": self.system.safety().enabled,
            "t": r.map(|r| r.t),
            "mu": r.map(|r| r.mu),
            "tau": r.map(|r| r.tau),
            "t_on": r.map(|r| r.t_on),
            "feedback": r.map(|r| r.feedback_on),
            "feedback_active": self.last_feedback_active,
            "tracking_error_recent": if tr.1 > 0 { Some((tr.0 / tr.1 as f64).sqrt()) } else { None },
            "counters": r.map(|r| r.counters),
            "histograms": self.percentiles(),
            "recording": self.recording.as_ref().map(|r| r.path().display().to_string()),
            "recording_error": self.recording_error,
            "replay_recording": self.replay.as_ref().map(|r| r.path.display().to_string()),
            "replay_error": self.replay.as_ref().and_then(|r| r.stopped.clone()),
            "realtime": self.realtime,
            "trigger": self.daemon.trigger,
            "phase_offset_us": self.daemon.phase_offset_us,
            "state_to_command": Percentiles::of(&self.state_to_command),
            "answered_within_period": self.answered_share(),
            "command": self.saturations.to_json(),
            "device": protocol::DeviceStatus::from_code(self.device).map(|d| d.to_string()),
            "blocked": self.deadlock.blocked.as_ref().map(|b| b.to_json()),
            "plan": self.deadlock.plan_json(),
            "chaos": self.chaos.to_json(self.mu_auto()),
            "gains": self.gains_json(),
            "joint_limits": self.limits.seen(),
            "limit_breaches": self.limits.seen().breaches(),
        });
        for k in [
            "kp",
            "kv",
            "alpha",
            "secondary",
            "obstacles",
            "max_tau",
            "robot",
            "projection",
        ] {
            if let Some(x) = law.get(k) {
                v[k] = x.clone();
            }
        }
        v.to_string()
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
                let mut c = self.system.clone();
                *c.tables_mut().0 = toml::Table::try_from(&self.daemon).ok();
                Ok(c.to_toml())
            }
            Op::Set | Op::DfcOn | Op::DfcOff | Op::ObstacleAdd | Op::ObstacleRemove => self
                .change(op, args, now)
                .and_then(|c| self.outside_obstacles(op, c))
                .and_then(|c| self.commit(c)),
            Op::ObstacleList => Ok(self.obstacles().to_string()),
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
                None if self.recording_error.is_some() => {
                    Err(self.recording_error.take().unwrap_or_default())
                }
                Some(r) => r.finish(),
                None => Err("not recording".into()),
            },
            Op::Shutdown => {
                rt::signal::request_stop();
                Ok("shutting down".into())
            }
            Op::Resume => self.resume(),
            Op::DebugStall => crate::requests::parse_stall(args).and_then(|ms| {
                self.params_tx
                    .try_send(LoopRequest::Stall(ms))
                    .map_err(|_| {
                        "the control loop has not taken the previous request yet; try again"
                            .to_string()
                    })?;
                Ok(format!("stalling the control loop for {ms} ms"))
            }),
        };
        if result.is_ok() {
            self.note_change(op, args);
        }
        match result {
            Ok(body) => ControlResponse::new(req.id, Status::Ok, &body),
            Err(why) => ControlResponse::new(req.id, Status::Refused, &why),
        }
    }

    /// Puts an operator's accepted change into the recordings: an event in the operator's words,
    /// and the new scene when the configuration changed.
    fn note_change(&mut self, op: Op, args: &str) {
        let words = match op {
            Op::Set => "set",
            Op::ObstacleAdd => "obstacle add",
            Op::ObstacleRemove => "obstacle remove",
            Op::DfcOn => "dfc on",
            Op::DfcOff => "dfc off",
            Op::Resume => "resume",
            Op::Shutdown => "shutdown",
            _ => return,
        };
        let text = format!("chaosctl {words} {args}");
        let text = text.trim_end();
        let system = (!matches!(op, Op::Resume | Op::Shutdown)).then_some(&self.system);
        if let Some(rec) = self.recording.as_mut() {
            if let Err(e) = rec.note(text, system) {
                self.recording_error = Some(format!(
                    "recording to {} stopped after {} rows: {e}",
                    rec.path().display(),
                    rec.rows()
                ));
                self.recording = None;
            }
        }
        if let Some(live) = self.live.as_mut() {
            live.note(text, system);
        }
        if let Some(rec) = self.replay.as_mut().and_then(|l| l.mcap()) {
            if let Err(e) = rec.note(text, system) {
                tracing::warn!("replay recording {}: {e}", rec.path.display());
            }
        }
    }

    fn start_recording(&mut self, args: &str) -> Result<String, String> {
        if let Some(r) = &self.recording {
            return Err(format!("already recording to {}", r.path().display()));
        }
        let r = Recording::start(
            &self.daemon.output_dir,
            args,
            &self.system,
            self.daemon.rate_hz,
            self.daemon.record_limit(),
        )?;
        let answer = serde_json::json!({"path": r.path()}).to_string();
        self.recording = Some(r);
        Ok(answer)
    }
}
