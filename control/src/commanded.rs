//! The sampled-data loop through a command interface and a dynamic arm, offline.
//!
//! What the daemon and the plant do across two processes, in one: each period the law runs on
//! the measured state (first-order hold, delay line on the measured rates), the motion
//! generator turns its q̈ into the configured command through the limiter, and the device
//! (`rigid_body::Device`: servo, friction, payload, sensors) follows it for one period. It
//! answers "does this mode track, and does the feedback still work?" in seconds, and is what
//! the bench's acceptance table and the tests run; the live processes are checked separately.

use crate::arm::VecN;
use crate::basics::ConfigError;
use crate::command::{CommandMode, LimitKind, LIMIT_KINDS};
use crate::delay::DelayLine;
use crate::hold;
use crate::resolve::ControlOutput;
use crate::rigid_body::{Device, RigidBodyConfig};
use crate::sim::{ArmState, ClosedLoopLaw, RunStats, Summary};
use crate::system::System;
use crate::tick_law::LawScratch;

/// What a run showed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandedRun {
    pub mode: CommandMode,
    /// Tracking error after the transient: RMS and peak (m).
    pub tracking_rms: f64,
    pub tracking_max: f64,
    /// RMS of the period residual ‖q̇(t) − q̇(t − τ)‖ over the last τ before the feedback comes
    /// on, and over the run's last τ (rad/s).
    pub residual_before: f64,
    pub residual_after: f64,
    /// Limiter clamps (ticks × joints) per [`LimitKind`].
    pub saturations: [u64; LIMIT_KINDS],
    /// Plant substeps in which a torque hit the arm's limit.
    pub plant_torque_saturations: u64,
    /// Peak |q̇_i| / q̇_max,i (the description's limits).
    pub peak_speed_fraction: f64,
    /// Peak |q_r − q| (rad): how far the arm lags its reference.
    pub reference_lag: f64,
}

/// Runs `system` (spatial) for `duration` s at period `dt` against the dynamic arm `plant` in
/// `substeps` per period. `N` must be the chain's joint count.
pub fn run<const N: usize>(
    system: &System,
    plant: &RigidBodyConfig,
    dt: f64,
    substeps: u32,
    duration: f64,
    transient: f64,
) -> Result<CommandedRun, ConfigError> {
    let (run, _) = run_at::<N>(system, plant, dt, substeps, duration, transient, &[])?;
    Ok(run)
}

/// [`run`], with the summary of the plant's own motion up to each of `ends` (s, at most
/// `duration`), as [`crate::sim::run_steering_at`] gives the law's own model's: the arm's true
/// speeds, residual and distance to the position limits (not the sensors' noisy reading of
/// them), its own tracking error, and the law's commanded q̈ against the acceleration and jerk
/// limits. So a study judges a run on the plant by the same rules as a run on the model.
pub fn run_at<const N: usize>(
    system: &System,
    plant: &RigidBodyConfig,
    dt: f64,
    substeps: u32,
    duration: f64,
    transient: f64,
    ends: &[f64],
) -> Result<(CommandedRun, Vec<Summary>), ConfigError> {
    if let Some(&end) = ends.iter().find(|&&e| !(e > 0.0 && e <= duration)) {
        let expected = format!("a time in (0, {duration}] s: the run lasts {duration} s");
        return Err(crate::basics::invalid("a summary's end", end, &expected));
    }
    let System::Spatial(s) = system else {
        return Err(ConfigError::Spatial(
            "command interfaces need a robot model: use a [robot] set-up".into(),
        ));
    };
    let mut gen = s.config.generator::<N>(&s.chain, dt)?;
    let law = system.tick_law::<N>();
    let crate::tick_law::TickLaw::Spatial { arm: arm_model, .. } = &law else {
        unreachable!("a spatial system has a spatial law")
    };
    let arm_model = *arm_model;
    let described = s
        .own()
        .command
        .limits::<N>(&s.chain, &s.own().robot.description)?;
    let x0: ArmState<N> = system.initial_state();
    let tau_max = VecN::<N>::from_column_slice(&described.tau);
    let (arm, sensor) = plant.build::<N>(
        &s.chain,
        (x0.q, x0.qd),
        tau_max,
        dt / f64::from(substeps.max(1)),
        "plant.rigid_body",
    )?;
    let mut device = Device::new(arm, sensor);
    let fb = system.feedback();
    let mut delay = DelayLine::new(fb.max_tau.max(fb.tau) / dt, x0.qd);
    let mut scratch = LawScratch::default();
    gen.restart(&x0.q, &x0.qd);
    let steps = (duration / dt).round() as u64;
    let window = (fb.tau / dt).round().max(1.0) as u64;
    let t_on = (fb.t_on / dt).round() as u64;
    let mut out = CommandedRun {
        mode: gen.mode(),
        tracking_rms: 0.0,
        tracking_max: 0.0,
        residual_before: 0.0,
        residual_after: 0.0,
        saturations: [0; LIMIT_KINDS],
        plant_torque_saturations: 0,
        peak_speed_fraction: 0.0,
        reference_lag: 0.0,
    };
    let (mut tracked, mut before, mut after) = (0u64, 0u64, 0u64);
    let mut stats = Judged::new(&law, dt, transient, ends, &x0);
    for k in 0..steps {
        let t = k as f64 * dt;
        let m = device.measure();
        // The arm itself at the same instant, not the sensors' reading of it (noise, encoder
        // steps): what the summaries judge.
        let truth = ArmState {
            q: device.arm.state.q,
            qd: device.arm.state.qd,
            phi: 0.0,
        };
        let (q, qd) = gen.law_state(&m.q, &m.qd);
        let x = ArmState { q, qd, phi: 0.0 };
        delay.push(x.qd);
        let held = hold::command(
            &law,
            t,
            &x,
            dt,
            true,
            |at| delay.sample(at / dt),
            &mut scratch,
        );
        let o = held.output;
        out.reference_lag = out.reference_lag.max((gen.reference().q - m.q).amax());
        let c = gen.next(&m.q, &m.qd, &held.qdd, &held.qddd);
        gen.commit(&c);
        device.command(&c, dt, 0.0);
        device.advance(dt, substeps);
        // The arm's own error (the law's is its reference's in position and velocity modes).
        let e = (arm_model.tool_position(&m.q) - o.p_desired).norm();
        if stats.wanted() {
            let e = (arm_model.tool_position(&truth.q) - o.p_desired).norm();
            stats.record(k, &truth, &o, e);
        }
        if t >= transient {
            out.tracking_rms += e * e;
            out.tracking_max = out.tracking_max.max(e);
            tracked += 1;
        }
        if k + window >= t_on && k < t_on {
            out.residual_before += o.period_residual * o.period_residual;
            before += 1;
        }
        if k + window >= steps {
            out.residual_after += o.period_residual * o.period_residual;
            after += 1;
        }
        for i in 0..N {
            let f = m.qd[i].abs() / described.qd[i];
            out.peak_speed_fraction = out.peak_speed_fraction.max(f);
        }
    }
    out.tracking_rms = (out.tracking_rms / tracked.max(1) as f64).sqrt();
    out.residual_before = (out.residual_before / before.max(1) as f64).sqrt();
    out.residual_after = (out.residual_after / after.max(1) as f64).sqrt();
    for kind in LimitKind::ALL {
        out.saturations[kind as usize] = gen.saturations.total(kind);
    }
    out.plant_torque_saturations = device.arm.torque_saturations;
    Ok((out, stats.summaries()))
}

/// [`run_at`]'s summaries: one [`RunStats`] per end, fed the arm's true state.
struct Judged<const N: usize> {
    stats: Vec<RunStats<N>>,
    ends: Vec<u64>,
    safety: crate::safety::SafetyParams,
    diverged_at: Option<u64>,
}

impl<const N: usize> Judged<N> {
    fn new(
        law: &crate::tick_law::TickLaw<N>,
        dt: f64,
        transient: f64,
        ends: &[f64],
        x0: &ArmState<N>,
    ) -> Self {
        let setup = law.stats_setup();
        Self {
            stats: ends
                .iter()
                .map(|&end| RunStats::of(setup, dt, end, transient, x0))
                .collect(),
            ends: ends.iter().map(|end| (end / dt).round() as u64).collect(),
            safety: law.core().safety,
            diverged_at: None,
        }
    }

    /// Whether any summary was asked for ([`run`] asks none, and pays nothing for them).
    fn wanted(&self) -> bool {
        !self.stats.is_empty()
    }

    /// Step `k`: the arm's state, the law's output and the arm's own tracking error.
    fn record(&mut self, k: u64, x: &ArmState<N>, o: &ControlOutput<N>, error: f64) {
        if self.diverged_at.is_none() && !x.is_finite() {
            self.diverged_at = Some(k);
        }
        let judged = ControlOutput {
            tracking_error: error,
            joint_margin: self.safety.joint_margin(&x.q),
            ..*o
        };
        for (s, &end) in self.stats.iter_mut().zip(&self.ends) {
            if k < end {
                s.record(k, x, &judged);
            }
        }
    }

    fn summaries(&self) -> Vec<Summary> {
        self.stats
            .iter()
            .zip(&self.ends)
            .map(|(s, &end)| Summary {
                finite: self.diverged_at.is_none_or(|k| k >= end),
                ..s.summary()
            })
            .collect()
    }
}
