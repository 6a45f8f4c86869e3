//! The deterministic in-process simulation: plant model and control law coupled by the
//! conventions of docs/science.md, "Time, integration and determinism".
//!
//! The plant here is the kinematic one of the paper: the commanded q̈ is the joint acceleration,
//! and for the floating base φ follows φ̇ = −H_b⁻¹H_bm q̇. The control law is evaluated at every RK4
//! stage, reading q̇(s − τ) from the delay line, which holds q̇ at every grid time. Time is always
//! `step_index · dt`, never accumulated, so two runs with the same inputs are bit-identical and a
//! run is reproducible from its config alone.

pub mod law;

pub use law::{ClosedLoopLaw, LoopFeedback};

use crate::arm::VecN;
use crate::basics::flags;
use crate::delay::DelayLine;
use crate::law::LawParams;
use crate::resolve::ControlOutput;
use crate::steer::Steering;

/// A state an explicit Runge-Kutta method can combine.
pub trait OdeState: Copy {
    /// self + h·k
    fn add_scaled(&self, k: &Self, h: f64) -> Self;
}

/// One classical RK4 step of size `dt`. `f(c, x)` is the derivative at stage fraction c ∈ {0, ½, 1}.
#[inline]
pub fn rk4_step<S: OdeState>(x: &S, dt: f64, mut f: impl FnMut(f64, &S) -> S) -> S {
    let k1 = f(0.0, x);
    let k2 = f(0.5, &x.add_scaled(&k1, 0.5 * dt));
    let k3 = f(0.5, &x.add_scaled(&k2, 0.5 * dt));
    let k4 = f(1.0, &x.add_scaled(&k3, dt));
    x.add_scaled(&k1, dt / 6.0)
        .add_scaled(&k2, dt / 3.0)
        .add_scaled(&k3, dt / 3.0)
        .add_scaled(&k4, dt / 6.0)
}

/// Joint angles, joint rates and (floating base) the base attitude.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ArmState<const N: usize> {
    pub q: VecN<N>,
    pub qd: VecN<N>,
    pub phi: f64,
}

impl<const N: usize> OdeState for ArmState<N> {
    #[inline(always)]
    fn add_scaled(&self, k: &Self, h: f64) -> Self {
        Self {
            q: self.q + k.q * h,
            qd: self.qd + k.qd * h,
            phi: self.phi + k.phi * h,
        }
    }
}

impl<const N: usize> ArmState<N> {
    pub fn is_finite(&self) -> bool {
        self.phi.is_finite() && self.q.iter().chain(self.qd.iter()).all(|v| v.is_finite())
    }
}

/// The time derivative of the kinematic plant under a commanded acceleration.
#[inline]
pub fn plant_derivative<const N: usize>(
    x: &ArmState<N>,
    qdd: &VecN<N>,
    base_rate: f64,
) -> ArmState<N> {
    ArmState {
        q: x.qd,
        qd: *qdd,
        phi: base_rate,
    }
}

/// A closed-loop simulation of any arm's law ([`ClosedLoopLaw`]): the daemon's
/// [`crate::tick_law::TickLaw`] (its constructors `new` for the planar arm and `spatial` for a
/// URDF chain are there), or a user's own law. Owns its delay line (sized once) and scratch;
/// `step` allocates nothing.
#[derive(Clone, Debug)]
pub struct Simulation<const N: usize, L: ClosedLoopLaw<N>> {
    /// The arm and its law's parameters; a change takes effect at the next step.
    pub law: L,
    dt: f64,
    delay: DelayLine<N>,
    step_index: u64,
    state: ArmState<N>,
    scratch: L::Scratch,
}

impl<const N: usize, L: ClosedLoopLaw<N>> Simulation<N, L> {
    /// `law` from `initial`; the delay line holds `max_tau` (at least the law's τ).
    pub fn of(law: L, dt: f64, initial: ArmState<N>, max_tau: f64) -> Self {
        let max_tau = max_tau.max(law.loop_feedback().tau);
        Self {
            law,
            dt,
            delay: DelayLine::new(max_tau / dt, initial.qd),
            step_index: 0,
            state: initial,
            scratch: L::Scratch::default(),
        }
    }

    pub fn dt(&self) -> f64 {
        self.dt
    }
    pub fn step_index(&self) -> u64 {
        self.step_index
    }
    pub fn time(&self) -> f64 {
        self.step_index as f64 * self.dt
    }
    pub fn state(&self) -> &ArmState<N> {
        &self.state
    }
    pub fn state_mut(&mut self) -> &mut ArmState<N> {
        &mut self.state
    }
    pub fn delay(&self) -> &DelayLine<N> {
        &self.delay
    }
    pub fn delay_mut(&mut self) -> &mut DelayLine<N> {
        &mut self.delay
    }

    /// Makes the delay line hold `max_tau` (s) before the first step, for a run whose τ will
    /// grow mid-way (an edit): its history is still the start's alone, so a longer line changes
    /// nothing else. False once the run has stepped (the line keeps its size).
    pub fn reserve_delay(&mut self, max_tau: f64) -> bool {
        if self.step_index != 0 {
            return false;
        }
        if max_tau / self.dt > self.delay.max_delay_steps() {
            self.delay = DelayLine::new(max_tau / self.dt, self.state.qd);
        }
        true
    }

    /// Advances one step of dt. Returns the control output at the start of the step (time t_k).
    pub fn step(&mut self) -> ControlOutput<N> {
        let k = self.step_index as f64;
        self.delay.push(self.state.qd);
        let tau_steps = self.law.loop_feedback().tau / self.dt;
        let (dt, law, delay) = (self.dt, &self.law, &self.delay);
        let scratch = &mut self.scratch;
        let mut first = None;
        self.state = rk4_step(&self.state, dt, |c, x| {
            let s = (k + c) * dt;
            let delayed = delay.sample(k + c - tau_steps);
            // Only the first stage's output is returned: the others need q̈ alone.
            let (qdd, base_rate) = if first.is_none() {
                let out = law.evaluate(s, x, &delayed, scratch);
                first = Some(out);
                (out.qdd, out.base_rate)
            } else {
                law.acceleration(s, x, &delayed, scratch)
            };
            plant_derivative(x, &qdd, base_rate)
        });
        self.step_index += 1;
        let out = first.expect("rk4 evaluates stage 1");
        self.law.adapt(&out, dt);
        out
    }
}

/// Runs `sim` for `duration` s, calling `each(t, state, output)` every step, and summarises.
pub fn run<const N: usize, L: ClosedLoopLaw<N>>(
    sim: &mut Simulation<N, L>,
    duration: f64,
    transient: f64,
    mut each: impl FnMut(f64, &ArmState<N>, &ControlOutput<N>),
) -> Summary {
    run_steering(sim, duration, transient, |t, x, o| {
        each(t, x, o);
        None
    })
}

/// [`run`], where `each` may hand the law a steering (a cycle planned after a trap, as the
/// daemon does): it takes effect from the next step. A run whose state stops being finite
/// stops there, its summary's `finite` false.
pub fn run_steering<const N: usize, L: ClosedLoopLaw<N>>(
    sim: &mut Simulation<N, L>,
    duration: f64,
    transient: f64,
    each: impl FnMut(f64, &ArmState<N>, &ControlOutput<N>) -> Option<Steering>,
) -> Summary {
    let mut summaries = run_steering_at(sim, &[duration], transient, each);
    summaries.remove(0)
}

/// [`run_steering`] for the longest of `ends` (s), with the summary a run of each of them
/// would give: its last ten periods, its peaks and its margins over its own steps. One run
/// answers "where is it at 60 s, and at 120 s?" as two runs would, the longer one's first
/// steps being the shorter one's.
pub fn run_steering_at<const N: usize, L: ClosedLoopLaw<N>>(
    sim: &mut Simulation<N, L>,
    ends: &[f64],
    transient: f64,
    mut each: impl FnMut(f64, &ArmState<N>, &ControlOutput<N>) -> Option<Steering>,
) -> Vec<Summary> {
    let setup = sim.law.stats_setup();
    let (dt, x0) = (sim.dt(), *sim.state());
    let mut stats: Vec<RunStats<N>> = ends
        .iter()
        .map(|&end| RunStats::of(setup, dt, end, transient, &x0))
        .collect();
    let ends: Vec<u64> = ends.iter().map(|end| (end / dt).round() as u64).collect();
    let steps = ends.iter().copied().max().unwrap_or(0);
    let mut diverged_at = None;
    for _ in 0..steps {
        let (k, t, x) = (sim.step_index(), sim.time(), *sim.state());
        let out = sim.step();
        if let Some(steer) = each(t, &x, &out) {
            sim.law.set_steering(Some(steer));
        }
        for (s, &end) in stats.iter_mut().zip(&ends) {
            if k < end {
                s.record(k, &x, &out);
            }
        }
        if !sim.state().is_finite() {
            diverged_at = Some(k);
            break;
        }
    }
    stats
        .iter()
        .zip(&ends)
        .map(|(s, &end)| Summary {
            finite: diverged_at.is_none_or(|k| k >= end),
            ..s.summary()
        })
        .collect()
}

/// Windowed statistics of a run, accumulated step by step without allocation.
#[derive(Clone, Debug)]
pub struct RunStats<const N: usize> {
    period: f64,
    dt: f64,
    transient: f64,
    t_on: f64,
    end: f64,
    feedback_used: bool,
    history: DelayLine<N>,
    pub steps_after_transient: u64,
    sq_err: f64,
    pub max_tracking_error: f64,
    pub track_lost_steps: u64,
    pub first_track_loss: Option<f64>,
    pub singular_steps: u64,
    pub out_of_reach_steps: u64,
    pub nonfinite_steps: u64,
    pub min_clearance: f64,
    pub safety_zone_steps: u64,
    /// The clearance the safety filter requires (m), `safety.clearance`.
    required_clearance: f64,
    has_obstacles: bool,
    safety_enabled: bool,
    /// Steps with clearance < 0 (a link inside an obstacle).
    pub contact_steps: u64,
    /// Steps with clearance < the required clearance.
    pub inside_clearance_steps: u64,
    /// Clearance at the first recorded step (NaN before it).
    pub start_clearance: f64,
    /// First time (s) the clearance reached the required clearance.
    pub first_clear: Option<f64>,
    /// The minimum clearance and the contact steps from `first_clear` on.
    pub min_clearance_after_clear: f64,
    pub contact_steps_after_clear: u64,
    /// Smallest distance (rad) to a joint position limit (+∞ without limits).
    pub min_joint_margin: f64,
    /// Steps on which the safety filter changed the command, left the null space, was infeasible.
    pub safety_active_steps: u64,
    pub safety_left_null_space_steps: u64,
    pub safety_infeasible_steps: u64,
    /// Largest orientation error after the transient (rad; 0 without a pose task).
    pub max_orientation_error: f64,
    /// Largest |q̇_i| and largest |q̇_i| / q̇_max,i over the run, each with its joint (1-based).
    pub max_joint_speed: f64,
    pub max_joint_speed_joint: usize,
    pub max_speed_ratio: f64,
    pub max_speed_ratio_joint: usize,
    /// Largest |q̈_i| / q̈_max,i and |Δq̈_i / dt| / jerk_max,i of the law's command over the run.
    pub max_accel_ratio: f64,
    pub max_jerk_ratio: f64,
    qd_max: [f64; crate::basics::MAX_JOINTS],
    qdd_max: [f64; crate::basics::MAX_JOINTS],
    jerk_max: [f64; crate::basics::MAX_JOINTS],
    /// The last recorded command (None before the first step).
    last_qdd: Option<VecN<N>>,
    before: (f64, u64),
    after: (f64, u64),
    strobe: [Option<ArmState<N>>; 2],
    next_strobe: u64,
}

/// The human summary of a run (docs/science.md's units: m, rad, s).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Summary {
    pub duration: f64,
    pub transient: f64,
    pub rms_tracking_error: f64,
    pub max_tracking_error: f64,
    pub track_lost_fraction: f64,
    pub first_track_loss: Option<f64>,
    pub singular_fraction: f64,
    pub out_of_reach_fraction: f64,
    pub nonfinite_steps: u64,
    /// Mean |q̇(t) − q̇(t − T)| over the 10 periods before feedback switches on, or without
    /// feedback over the first 10 after the transient (None if the run is too short).
    pub period_residual_before: Option<f64>,
    /// The same over the last 10 periods of the run.
    pub period_residual_final: Option<f64>,
    /// |x(kT) − x((k−1)T)| at the last two stroboscopic samples.
    pub strobe_return: Option<f64>,
    /// Smallest clearance (m) between a link and an obstacle's surface over the whole run
    /// (negative: inside); None without obstacles.
    pub min_clearance: Option<f64>,
    /// Time (s) some link was inside an obstacle's safety zone r + margin (the paper's potential).
    pub time_in_safety_zone: f64,
    /// The clearance the safety filter requires, `safety.clearance` (m; whether or not it is on).
    pub required_clearance: f64,
    /// Time (s) some link was inside an obstacle (clearance < 0); None without obstacles.
    pub time_in_contact: Option<f64>,
    /// Time (s) the clearance was below the required clearance; None without obstacles.
    pub time_inside_clearance: Option<f64>,
    /// Whether the run started with a link inside an obstacle; None without obstacles.
    pub start_in_contact: Option<bool>,
    /// First time (s) the clearance reached the required clearance (0 for a start that is clear);
    /// None if it never did or there are no obstacles.
    pub first_clear: Option<f64>,
    /// Minimum clearance (m) and time in contact (s) from `first_clear` on.
    pub min_clearance_after_clear: Option<f64>,
    pub time_in_contact_after_clear: Option<f64>,
    /// Smallest distance (rad) to a joint position limit over the run (negative: beyond it);
    /// None without limits.
    pub min_joint_margin: Option<f64>,
    /// Whether the safety filter ran (`safety.enabled`).
    pub safety_enabled: bool,
    /// Time (s) the filter changed the command (some limit or clearance was binding).
    pub safety_active_time: f64,
    /// Steps (and their time, s) on which the null space could not keep every limit, so the
    /// filter changed the task motion: tracking gave way to safety.
    pub safety_left_null_space_steps: u64,
    pub safety_left_null_space_time: f64,
    /// Steps on which no acceleration within the limits met every barrier condition.
    pub safety_infeasible_steps: u64,
    /// |q(kT) − q((k−1)T)| at the last two stroboscopic samples: the joint drift per period.
    #[serde(default)]
    pub drift_per_period: Option<f64>,
    /// Largest orientation error after the transient (rad; 0 without a pose task).
    #[serde(default)]
    pub max_orientation_error: f64,
    /// Largest joint speed (rad/s) and largest speed / limit over the run (above 1: a rate
    /// limit was exceeded; 0 without rate limits).
    #[serde(default)]
    pub max_joint_speed: f64,
    /// The joint of `max_joint_speed` (1-based; 0 before any step).
    #[serde(default)]
    pub max_joint_speed_joint: usize,
    #[serde(default)]
    pub max_speed_ratio: f64,
    /// The joint of `max_speed_ratio` (1-based; 0 without rate limits): not always the fastest.
    #[serde(default)]
    pub max_speed_ratio_joint: usize,
    /// Largest |q̈_i| / q̈_max,i and step-to-step |Δq̈_i| / (dt · jerk_max,i) of the commanded
    /// acceleration over the run (above 1: that limit was exceeded; 0 without such limits).
    #[serde(default)]
    pub max_accel_ratio: f64,
    #[serde(default)]
    pub max_jerk_ratio: f64,
    /// Whether the state stayed finite to the end (a run that diverged stops there).
    #[serde(default = "yes")]
    pub finite: bool,
}

fn yes() -> bool {
    true
}

/// What a run's statistics need to know of the law, whatever the arm: the planar law's
/// ([`StatsSetup::planar`]) or a spatial one's (`StatsSetup::spatial`), so that one
/// [`RunStats`] and one [`Summary`] describe every arm's run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StatsSetup {
    /// The task period T (s): the residual's delay and the strobe's step.
    pub period: f64,
    /// When the feedback switches on (s), and whether it is used at all (on, μ ≠ 0).
    pub t_on: f64,
    pub feedback_used: bool,
    /// The clearance the safety filter requires (m), `safety.clearance`.
    pub required_clearance: f64,
    pub has_obstacles: bool,
    pub safety_enabled: bool,
    /// The joints' rate, acceleration and jerk limits (+∞ where there is none).
    pub qd_max: [f64; crate::basics::MAX_JOINTS],
    pub qdd_max: [f64; crate::basics::MAX_JOINTS],
    pub jerk_max: [f64; crate::basics::MAX_JOINTS],
}

impl StatsSetup {
    /// A spatial law's: its path's period, its feedback, its spheres and its filter.
    pub fn spatial(p: &crate::law::spatial::SpatialParams) -> Self {
        Self::of(&p.core, p.task.path.period, !p.spheres.is_empty())
    }

    /// The planar law's.
    pub fn planar(params: &LawParams) -> Self {
        Self::of(
            &params.core,
            params.task.period,
            !params.obstacles.is_empty(),
        )
    }

    /// Any arm's: its law's core, its task's period, whether it has obstacles.
    pub fn of(core: &crate::law::LawCore, period: f64, has_obstacles: bool) -> Self {
        let s = &core.safety;
        Self {
            period,
            t_on: core.t_on,
            feedback_used: core.feedback && core.mu != 0.0,
            required_clearance: s.clearance,
            has_obstacles,
            safety_enabled: s.enabled,
            qd_max: s.qd_max,
            qdd_max: s.qdd_max,
            jerk_max: s.jerk_max,
        }
    }
}

impl<const N: usize> RunStats<N> {
    /// Statistics for a run of the planar law of `duration` s whose transient lasts
    /// `transient` s.
    pub fn new(
        params: &LawParams,
        dt: f64,
        duration: f64,
        transient: f64,
        initial: &ArmState<N>,
    ) -> Self {
        Self::of(StatsSetup::planar(params), dt, duration, transient, initial)
    }

    /// Statistics for a run of any arm's law (`setup`) of `duration` s whose transient lasts
    /// `transient` s.
    pub fn of(
        setup: StatsSetup,
        dt: f64,
        duration: f64,
        transient: f64,
        initial: &ArmState<N>,
    ) -> Self {
        let period = setup.period;
        Self {
            period,
            dt,
            transient,
            t_on: setup.t_on,
            end: duration,
            feedback_used: setup.feedback_used,
            history: DelayLine::new(period / dt, initial.qd),
            steps_after_transient: 0,
            sq_err: 0.0,
            max_tracking_error: 0.0,
            track_lost_steps: 0,
            first_track_loss: None,
            singular_steps: 0,
            out_of_reach_steps: 0,
            nonfinite_steps: 0,
            min_clearance: f64::INFINITY,
            safety_zone_steps: 0,
            required_clearance: setup.required_clearance,
            has_obstacles: setup.has_obstacles,
            safety_enabled: setup.safety_enabled,
            contact_steps: 0,
            inside_clearance_steps: 0,
            start_clearance: f64::NAN,
            first_clear: None,
            min_clearance_after_clear: f64::INFINITY,
            contact_steps_after_clear: 0,
            min_joint_margin: f64::INFINITY,
            safety_active_steps: 0,
            safety_left_null_space_steps: 0,
            safety_infeasible_steps: 0,
            max_orientation_error: 0.0,
            max_joint_speed: 0.0,
            max_joint_speed_joint: 0,
            max_speed_ratio: 0.0,
            max_speed_ratio_joint: 0,
            max_accel_ratio: 0.0,
            max_jerk_ratio: 0.0,
            qd_max: setup.qd_max,
            qdd_max: setup.qdd_max,
            jerk_max: setup.jerk_max,
            last_qdd: None,
            before: (0.0, 0),
            after: (0.0, 0),
            strobe: [None, None],
            next_strobe: 0,
        }
    }

    /// Records the state at grid step `k` (time k·dt) and the control output computed there.
    pub fn record(&mut self, k: u64, x: &ArmState<N>, out: &ControlOutput<N>) {
        let t = k as f64 * self.dt;
        self.history.push(x.qd);
        let back = self.history.sample(k as f64 - self.period / self.dt);
        let resid = (x.qd - back).norm();
        let w = 10.0 * self.period;
        if t >= self.period {
            // Before the feedback: the 10 periods before it switches on or, without it, the
            // first 10 after the transient.
            let before_end = if self.feedback_used {
                self.t_on
            } else {
                self.transient + w
            };
            if t < before_end && t >= before_end - w {
                self.before.0 += resid;
                self.before.1 += 1;
            }
            if t >= self.end - w {
                self.after.0 += resid;
                self.after.1 += 1;
            }
        }
        if (k as f64) * self.dt >= self.next_strobe as f64 * self.period {
            self.strobe = [self.strobe[1], Some(*x)];
            self.next_strobe += 1;
        }
        for i in 0..N {
            let (speed, ratio) = (x.qd[i].abs(), x.qd[i].abs() / self.qd_max[i]);
            if speed > self.max_joint_speed {
                (self.max_joint_speed, self.max_joint_speed_joint) = (speed, i + 1);
            }
            if ratio > self.max_speed_ratio {
                (self.max_speed_ratio, self.max_speed_ratio_joint) = (ratio, i + 1);
            }
        }
        self.record_command(&out.qdd);
        self.min_clearance = self.min_clearance.min(out.clearance);
        if out.flags & flags::IN_SAFETY_ZONE != 0 {
            self.safety_zone_steps += 1;
        }
        self.record_clearance(t, out.clearance);
        self.min_joint_margin = self.min_joint_margin.min(out.joint_margin);
        self.safety_active_steps += u64::from(out.flags & flags::SAFETY_ACTIVE != 0);
        self.safety_left_null_space_steps +=
            u64::from(out.flags & flags::SAFETY_LEFT_NULL_SPACE != 0);
        self.safety_infeasible_steps += u64::from(out.flags & flags::SAFETY_INFEASIBLE != 0);
        if out.flags & flags::NONFINITE != 0 {
            self.nonfinite_steps += 1;
        }
        if t < self.transient {
            return;
        }
        self.steps_after_transient += 1;
        self.sq_err += out.tracking_error * out.tracking_error;
        self.max_tracking_error = self.max_tracking_error.max(out.tracking_error);
        self.max_orientation_error = self.max_orientation_error.max(out.orientation_error);
        if out.flags & flags::TRACK_LOST != 0 {
            self.track_lost_steps += 1;
            self.first_track_loss.get_or_insert(t);
        }
        if out.flags & flags::SINGULAR != 0 {
            self.singular_steps += 1;
        }
        if out.flags & flags::OUT_OF_REACH != 0 {
            self.out_of_reach_steps += 1;
        }
    }

    /// The command's acceleration and jerk against their limits (a non-finite command is
    /// counted by its flag, not here).
    fn record_command(&mut self, qdd: &VecN<N>) {
        if !qdd.iter().all(|v| v.is_finite()) {
            return;
        }
        let accel = (0..N)
            .map(|i| qdd[i].abs() / self.qdd_max[i])
            .fold(0.0, f64::max);
        self.max_accel_ratio = self.max_accel_ratio.max(accel);
        if let Some(last) = self.last_qdd {
            let jerk = (0..N)
                .map(|i| (qdd[i] - last[i]).abs() / self.dt / self.jerk_max[i])
                .fold(0.0, f64::max);
            self.max_jerk_ratio = self.max_jerk_ratio.max(jerk);
        }
        self.last_qdd = Some(*qdd);
    }

    /// Contact and clearance bookkeeping of one step (the clearance is +∞ without obstacles).
    fn record_clearance(&mut self, t: f64, clearance: f64) {
        if self.start_clearance.is_nan() {
            self.start_clearance = clearance;
        }
        let contact = clearance < 0.0;
        self.contact_steps += u64::from(contact);
        self.inside_clearance_steps += u64::from(clearance < self.required_clearance);
        if self.first_clear.is_none() && clearance >= self.required_clearance {
            self.first_clear = Some(t);
        }
        if self.first_clear.is_some() {
            self.min_clearance_after_clear = self.min_clearance_after_clear.min(clearance);
            self.contact_steps_after_clear += u64::from(contact);
        }
    }

    pub fn summary(&self) -> Summary {
        let n = self.steps_after_transient.max(1) as f64;
        let mean = |(s, c): (f64, u64)| if c > 0 { Some(s / c as f64) } else { None };
        let obstacles = self.has_obstacles;
        let (strobe_return, drift_per_period) = match self.strobe {
            [Some(a), Some(b)] => {
                let dq = b.q - a.q;
                let dqd = b.qd - a.qd;
                let both = (dq.norm_squared() + dqd.norm_squared()).sqrt();
                (Some(both), Some(dq.norm()))
            }
            _ => (None, None),
        };
        Summary {
            duration: self.end,
            transient: self.transient,
            rms_tracking_error: (self.sq_err / n).sqrt(),
            max_tracking_error: self.max_tracking_error,
            track_lost_fraction: self.track_lost_steps as f64 / n,
            first_track_loss: self.first_track_loss,
            singular_fraction: self.singular_steps as f64 / n,
            out_of_reach_fraction: self.out_of_reach_steps as f64 / n,
            nonfinite_steps: self.nonfinite_steps,
            period_residual_before: mean(self.before),
            period_residual_final: mean(self.after),
            strobe_return,
            min_clearance: self.min_clearance.is_finite().then_some(self.min_clearance),
            time_in_safety_zone: self.safety_zone_steps as f64 * self.dt,
            required_clearance: self.required_clearance,
            time_in_contact: obstacles.then_some(self.contact_steps as f64 * self.dt),
            time_inside_clearance: obstacles
                .then_some(self.inside_clearance_steps as f64 * self.dt),
            start_in_contact: (obstacles && !self.start_clearance.is_nan())
                .then_some(self.start_clearance < 0.0),
            first_clear: self.first_clear.filter(|_| obstacles),
            min_clearance_after_clear: self
                .min_clearance_after_clear
                .is_finite()
                .then_some(self.min_clearance_after_clear)
                .filter(|_| obstacles),
            time_in_contact_after_clear: (obstacles && self.first_clear.is_some())
                .then_some(self.contact_steps_after_clear as f64 * self.dt),
            min_joint_margin: self
                .min_joint_margin
                .is_finite()
                .then_some(self.min_joint_margin),
            safety_enabled: self.safety_enabled,
            safety_active_time: self.safety_active_steps as f64 * self.dt,
            safety_left_null_space_steps: self.safety_left_null_space_steps,
            safety_left_null_space_time: self.safety_left_null_space_steps as f64 * self.dt,
            safety_infeasible_steps: self.safety_infeasible_steps,
            drift_per_period,
            max_orientation_error: self.max_orientation_error,
            max_joint_speed: self.max_joint_speed,
            max_joint_speed_joint: self.max_joint_speed_joint,
            max_speed_ratio: self.max_speed_ratio,
            max_speed_ratio_joint: self.max_speed_ratio_joint,
            max_accel_ratio: self.max_accel_ratio,
            max_jerk_ratio: self.max_jerk_ratio,
            finite: true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    fn output(clearance: f64, joint_margin: f64, flags: u32) -> ControlOutput<3> {
        ControlOutput {
            qdd: VecN::<3>::zeros(),
            p: nalgebra::Vector3::zeros(),
            p_desired: nalgebra::Vector3::zeros(),
            tracking_error: 0.0,
            orientation_error: 0.0,
            sigma_min: 1.0,
            damping: 0.0,
            secondary_value: 0.0,
            period_residual: 0.0,
            null_residual: 0.0,
            clearance,
            joint_margin,
            demand: 0.0,
            base_rate: 0.0,
            flags,
        }
    }

    #[test]
    fn one_run_summarises_each_end_as_a_run_of_that_length_would() {
        let cfg = Config::preset("demo").unwrap();
        let sim = || {
            let law = cfg.tick_law::<3>();
            Simulation::of(law, 1e-3, cfg.initial_state::<3>(), 1.0)
        };
        let at = run_steering_at(&mut sim(), &[0.1, 3.0, 5.0], 1.0, |_, _, _| None);
        for (end, got) in [0.1, 3.0, 5.0].into_iter().zip(&at) {
            let alone = run_steering(&mut sim(), end, 1.0, |_, _, _| None);
            assert_eq!(&alone, got, "end {end}");
        }
        assert!(at[1].period_residual_final.is_some() && at[1] != at[2]);
    }

    #[test]
    fn clearance_and_filter_statistics() {
        let cfg = Config::preset("paper-obstacle").unwrap();
        let p = cfg.law_params();
        let x = cfg.initial_state::<3>();
        let mut s = RunStats::new(&p, 0.5, 4.0, 0.0, &x);
        let active = flags::SAFETY_ACTIVE;
        let left = active | flags::SAFETY_LEFT_NULL_SPACE;
        // Starts inside (−0.1), gets clear at t = 1 (0.06 ≥ 0.05), dips to 0.03, then touches.
        let steps = [
            (-0.1, 0.4, left),
            (0.06, 0.3, active),
            (0.03, -0.2, flags::SAFETY_INFEASIBLE | left),
            (-0.02, 0.1, 0),
        ];
        for (k, &(c, m, f)) in steps.iter().enumerate() {
            s.record(k as u64, &x, &output(c, m, f));
        }
        let sum = s.summary();
        assert_eq!(sum.start_in_contact, Some(true));
        assert_eq!(sum.first_clear, Some(0.5));
        assert_eq!(sum.time_in_contact, Some(1.0));
        assert_eq!(sum.time_in_contact_after_clear, Some(0.5));
        assert_eq!(sum.time_inside_clearance, Some(1.5));
        assert_eq!(sum.min_clearance, Some(-0.1));
        assert_eq!(sum.min_clearance_after_clear, Some(-0.02));
        assert_eq!(sum.min_joint_margin, Some(-0.2));
        assert_eq!(sum.safety_active_time, 1.5);
        assert_eq!(sum.safety_left_null_space_steps, 2);
        assert_eq!(sum.safety_left_null_space_time, 1.0);
        assert_eq!(sum.safety_infeasible_steps, 1);
        assert_eq!(sum.required_clearance, 0.05);

        // Without obstacles or joint limits the obstacle fields are absent, not zero.
        let free = Config::preset("paper").unwrap();
        let mut s = RunStats::new(&free.law_params(), 0.5, 1.0, 0.0, &x);
        s.record(0, &x, &output(f64::INFINITY, f64::INFINITY, 0));
        let sum = s.summary();
        assert_eq!(sum.time_in_contact, None);
        assert_eq!(sum.start_in_contact, None);
        assert_eq!(sum.first_clear, None);
        assert_eq!(sum.min_joint_margin, None);
        assert!(!sum.safety_enabled);
    }
}
