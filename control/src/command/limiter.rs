//! Keeping a command stream continuous and inside the arm's limits, one tick at a time.
//!
//! A robot judges the stream, not the single command: successive positions imply a velocity,
//! an acceleration and a jerk, and any of them beyond its limit is a reflex stop. So the limiter
//! shapes the acceleration the law asks for as libfranka's `limitRate` does: clamp the jerk
//! against the last commanded acceleration, then the acceleration (with a bound that shrinks as
//! the velocity nears its limit, so the jerk limit can still level it off), then the velocity
//! (with a bound that shrinks near a position limit, so the arm can still stop before it), then
//! the position. Every limit is derated by a margin, and the velocity further by what three lost
//! packets at full acceleration would add (libfranka's assumption).
//!
//! With a jerk limit the commanded acceleration is continuous (see [`Limiter::step`]'s shaping):
//! each interval ramps from the last acceleration to the law's, because a robot sees a step in
//! acceleration as a jerk. A demand that continues the stream and stays inside every limit
//! passes bit for bit; without any limit (the planar arm) every demand passes unchanged, so the
//! planar results are untouched.

use super::limits::JointLimits;
use crate::arm::VecN;

/// The kinds of limit, in the order of a saturation table's columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LimitKind {
    Position,
    Velocity,
    Acceleration,
    Jerk,
    Torque,
    TorqueRate,
}

/// How many [`LimitKind`]s there are.
pub const LIMIT_KINDS: usize = 6;

impl LimitKind {
    pub const ALL: [LimitKind; LIMIT_KINDS] = [
        LimitKind::Position,
        LimitKind::Velocity,
        LimitKind::Acceleration,
        LimitKind::Jerk,
        LimitKind::Torque,
        LimitKind::TorqueRate,
    ];

    pub fn name(self) -> &'static str {
        match self {
            LimitKind::Position => "position",
            LimitKind::Velocity => "velocity",
            LimitKind::Acceleration => "acceleration",
            LimitKind::Jerk => "jerk",
            LimitKind::Torque => "torque",
            LimitKind::TorqueRate => "torque_rate",
        }
    }

    fn bit(self) -> u8 {
        1 << self as u8
    }
}

/// Ticks on which each joint's command was clamped, per [`LimitKind`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Saturations<const N: usize> {
    pub counts: [[u64; LIMIT_KINDS]; N],
}

impl<const N: usize> Default for Saturations<N> {
    fn default() -> Self {
        Self {
            counts: [[0; LIMIT_KINDS]; N],
        }
    }
}

impl<const N: usize> Saturations<N> {
    /// Adds one tick's clamps (a bit per [`LimitKind`] for each joint).
    pub fn add(&mut self, hits: &[u8; N]) {
        for (row, &h) in self.counts.iter_mut().zip(hits) {
            for (k, c) in row.iter_mut().enumerate() {
                *c += u64::from(h >> k & 1);
            }
        }
    }

    /// All joints' count for one kind.
    pub fn total(&self, kind: LimitKind) -> u64 {
        self.counts.iter().map(|r| r[kind as usize]).sum()
    }

    /// Every clamp of every kind.
    pub fn sum(&self) -> u64 {
        LimitKind::ALL.iter().map(|&k| self.total(k)).sum()
    }
}

/// A commanded motion: where the stream is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionState<const N: usize> {
    pub q: VecN<N>,
    pub qd: VecN<N>,
    /// The acceleration at the end of the last interval (the next one's jerk starts here).
    pub qdd: VecN<N>,
}

impl<const N: usize> MotionState<N> {
    pub fn at_rest(q: VecN<N>, qd: VecN<N>) -> Self {
        Self {
            q,
            qd,
            qdd: VecN::<N>::zeros(),
        }
    }
}

/// One interval of a limited stream.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step<const N: usize> {
    /// The motion at the end of the interval.
    pub end: MotionState<N>,
    /// The acceleration at its start and its rate over it (0 on a clamped joint).
    pub qdd: VecN<N>,
    pub qddd: VecN<N>,
    /// Which limits clamped each joint (bits of [`LimitKind`]).
    pub hits: [u8; N],
}

/// The derated limits and the period they are applied at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limiter<const N: usize> {
    l: JointLimits<N>,
    dt: f64,
    enabled: bool,
}

/// Lost packets the velocity margin allows for, at full acceleration (libfranka's value).
pub const LOST_PACKETS: f64 = 3.0;

impl<const N: usize> Limiter<N> {
    /// Limits derated by `margin` (a fraction, e.g. 0.02) at period `dt`; `enabled = false`
    /// passes every command unchanged (to show what the limiter prevents).
    pub fn new(limits: &JointLimits<N>, dt: f64, margin: f64, enabled: bool) -> Self {
        let k = 1.0 - margin;
        let mut l = *limits;
        for i in 0..N {
            let half = 0.5 * margin * (l.q_max[i] - l.q_min[i]);
            if half.is_finite() {
                l.q_min[i] += half;
                l.q_max[i] -= half;
            }
            l.qdd[i] *= k;
            l.jerk[i] *= k;
            l.qd[i] = l.qd[i] * k - LOST_PACKETS * dt * l.qdd[i];
            l.tau[i] *= k;
            l.tau_rate[i] *= k;
        }
        Self { l, dt, enabled }
    }

    /// The period the limits are applied at (s).
    pub fn dt(&self) -> f64 {
        self.dt
    }

    pub fn enabled(&self) -> bool {
        self.enabled
    }

    /// The derated limits in force.
    pub fn limits(&self) -> &JointLimits<N> {
        &self.l
    }

    /// The stream's next interval from `last`, asked to accelerate by `qdd + qddd·s`.
    pub fn step(&self, last: &MotionState<N>, qdd: &VecN<N>, qddd: &VecN<N>) -> Step<N> {
        let mut s = Step {
            end: *last,
            qdd: *qdd,
            qddd: *qddd,
            hits: [0; N],
        };
        for i in 0..N {
            if self.enabled {
                self.shape(i, last, &mut s);
            }
            let (a, r, h) = (s.qdd[i], s.qddd[i], self.dt);
            let v = last.qd[i];
            s.end.qd[i] = v + a * h + 0.5 * r * h * h;
            s.end.q[i] = last.q[i] + v * h + 0.5 * a * h * h + r * h * h * h / 6.0;
            s.end.qdd[i] = a + r * h;
            if self.enabled {
                self.keep_inside(i, last, &mut s);
            }
        }
        s
    }

    /// Jerk, then acceleration, then velocity, for joint `i`.
    ///
    /// With a jerk limit the acceleration is continuous: the interval starts at the last one and
    /// ramps to where the law wants it at the interval's end (`qdd + qddd·h`). A robot judges
    /// positions by finite differences, and to them a step in acceleration is a jerk as much
    /// as a ramp is: a stream that let the step and the ramp each take the whole jerk limit
    /// was stopped for twice it. On a continuous acceleration the finite differences are
    /// averages of the stream's own jerk, acceleration and velocity, so bounding those bounds
    /// what the robot sees. Without a jerk limit (the planar arm) the law's acceleration is
    /// taken as it is.
    fn shape(&self, i: usize, last: &MotionState<N>, s: &mut Step<N>) {
        let (l, h) = (&self.l, self.dt);
        let (v, a0) = (last.qd[i], last.qdd[i]);
        let mut clamp = |a: &mut f64, lo: f64, hi: f64, kind: LimitKind| {
            if *a > hi || *a < lo {
                *a = a.clamp(lo, hi.max(lo));
                s.hits[i] |= kind.bit();
            }
        };
        let (v_lo, v_hi) = self.velocity_bounds(i, last.q[i]);
        let (a_lo, a_hi) = self.acceleration_bounds(i, v, v_lo, v_hi);
        if !l.jerk[i].is_finite() {
            let mut a = s.qdd[i];
            clamp(&mut a, a_lo, a_hi, LimitKind::Acceleration);
            // The hard speed limit at the end of the interval with a constant `a`.
            let v_end = v + a * h;
            if v_end.abs() > l.qd[i] {
                a = (v_end.clamp(-l.qd[i], l.qd[i]) - v) / h;
                s.hits[i] |= LimitKind::Velocity.bit();
            }
            if a != s.qdd[i] {
                s.qdd[i] = a;
                s.qddd[i] = 0.0;
            }
            return;
        }
        let wanted = s.qdd[i] + s.qddd[i] * h;
        let mut e = wanted;
        let dj = l.jerk[i] * h;
        clamp(&mut e, a0 - dj, a0 + dj, LimitKind::Jerk);
        clamp(&mut e, a_lo, a_hi, LimitKind::Acceleration);
        // The hard speed limit at the end of the interval, the acceleration ramping a0 → e.
        let v_end = v + 0.5 * (a0 + e) * h;
        if v_end.abs() > l.qd[i] {
            e = 2.0 * (v_end.clamp(-l.qd[i], l.qd[i]) - v) / h - a0;
            s.hits[i] |= LimitKind::Velocity.bit();
        }
        // A demand that continues the stream and is inside every limit passes bit for bit.
        if !(s.qdd[i] == a0 && e == wanted) {
            s.qdd[i] = a0;
            s.qddd[i] = (e - a0) / h;
        }
    }

    /// The velocity range at position `q`: the speed limit, and no faster towards a position
    /// limit than the joint can still stop from at half its acceleration limit, allowing for
    /// the lag of the acceleration bound that follows it (`qdd / slope` seconds at full speed,
    /// see [`Self::slope`]).
    fn velocity_bounds(&self, i: usize, q: f64) -> (f64, f64) {
        let l = &self.l;
        let lag = if l.jerk[i].is_finite() && l.qd[i].is_finite() {
            l.qd[i] / self.slope(i)
        } else {
            0.0
        };
        let stop = |room: f64| (l.qdd[i] * (room - lag).max(0.0)).sqrt();
        let hi = l.qd[i].min(stop(l.q_max[i] - q));
        let lo = (-l.qd[i]).max(-stop(q - l.q_min[i]));
        (lo, hi)
    }

    /// How fast the acceleration bound falls with the velocity's room (1/s): two thirds of
    /// `jerk / qdd`. The bound moves as the velocity does (up to `qdd` per second) and as the
    /// velocity bound does near a position limit (up to `qdd / 2`, the stopping curve's
    /// deceleration): at `jerk / qdd`, libfranka's slope, it could fall by 1.5 jerk limits and
    /// the stream, whose jerk is limited, could not follow it.
    fn slope(&self, i: usize) -> f64 {
        self.l.jerk[i] / (1.5 * self.l.qdd[i])
    }

    /// The acceleration range at velocity `v`: the bound falls linearly to 0 as `v` nears its
    /// limit, at a slope the jerk limit can follow ([`Self::slope`]).
    fn acceleration_bounds(&self, i: usize, v: f64, v_lo: f64, v_hi: f64) -> (f64, f64) {
        let (a, j) = (self.l.qdd[i], self.l.jerk[i]);
        if !(a.is_finite() && j.is_finite()) {
            return (-a, a);
        }
        let slope = self.slope(i);
        (
            (-a).max(slope * (v_lo - v)).min(a),
            a.min(slope * (v_hi - v)).max(-a),
        )
    }

    /// The last resort: a position outside its limit is put back on it, at rest.
    fn keep_inside(&self, i: usize, last: &MotionState<N>, s: &mut Step<N>) {
        let (lo, hi) = (self.l.q_min[i], self.l.q_max[i]);
        let q = s.end.q[i];
        if q > hi || q < lo {
            s.end.q[i] = q.clamp(lo, hi).clamp(last.q[i].min(q), last.q[i].max(q));
            s.end.qd[i] = 0.0;
            s.end.qdd[i] = 0.0;
            s.qdd[i] = 0.0;
            s.qddd[i] = 0.0;
            s.hits[i] |= LimitKind::Position.bit();
        }
    }

    /// A torque command limited in rate (from `last`), then in size.
    pub fn torque(&self, last: &VecN<N>, tau: &VecN<N>, hits: &mut [u8; N]) -> VecN<N> {
        let mut out = *tau;
        if !self.enabled {
            return out;
        }
        for i in 0..N {
            let d = self.l.tau_rate[i] * self.dt;
            let t = out[i].clamp(last[i] - d, last[i] + d);
            if t != out[i] {
                hits[i] |= LimitKind::TorqueRate.bit();
            }
            let m = self.l.tau[i];
            out[i] = t.clamp(-m, m);
            if out[i] != t {
                hits[i] |= LimitKind::Torque.bit();
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::limits::PANDA;

    fn panda_limits() -> JointLimits<7> {
        let mut l = JointLimits::<7>::NONE;
        for i in 0..7 {
            l.q_min[i] = PANDA.q_min[i];
            l.q_max[i] = PANDA.q_max[i];
            l.qd[i] = PANDA.qd[i];
            l.qdd[i] = PANDA.qdd[i];
            l.jerk[i] = PANDA.jerk[i];
            l.tau[i] = PANDA.tau[i];
            l.tau_rate[i] = PANDA.tau_rate[i];
        }
        l
    }

    fn ready() -> MotionState<7> {
        MotionState::at_rest(
            VecN::<7>::from_column_slice(&crate::config::spatial::PANDA_READY),
            VecN::<7>::zeros(),
        )
    }

    #[test]
    fn values_inside_every_limit_pass_bit_for_bit() {
        let lim = Limiter::new(&panda_limits(), 1e-3, 0.02, true);
        let a = VecN::<7>::repeat(0.5);
        let r = VecN::<7>::repeat(2.0);
        // A demand that continues the stream's acceleration.
        let moving = MotionState { qdd: a, ..ready() };
        let s = lim.step(&moving, &a, &r);
        assert_eq!((s.qdd, s.qddd, s.hits), (a, r, [0; 7]));
        let off = Limiter::new(&panda_limits(), 1e-3, 0.02, false);
        assert_eq!(off.step(&moving, &a, &r).end, s.end);
        // From rest, the same demand is a ramp to where the law wants the acceleration at the
        // period's end: nothing is clamped, and the stream ends there.
        let s = lim.step(&ready(), &a, &r);
        assert_eq!((s.qdd, s.hits), (VecN::<7>::zeros(), [0; 7]));
        assert!((s.end.qdd - (a + r * 1e-3)).norm() < 1e-12, "{}", s.end.qdd);
        // Without any limit (the planar arm) nothing is ever clamped.
        let none = Limiter::new(&JointLimits::<7>::NONE, 1e-3, 0.02, true);
        let huge = VecN::<7>::repeat(1e6);
        assert_eq!(none.step(&ready(), &huge, &huge).hits, [0; 7]);
    }

    /// The limits a robot finds broken on a stream of commanded positions (finite differences,
    /// as it judges them), per joint: `Err` names the first.
    fn judge(l: &JointLimits<7>, dt: f64, qs: &[VecN<7>]) -> Result<(), String> {
        let max = |x: &[f64]| x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for i in 0..7 {
            let v: Vec<f64> = qs.windows(2).map(|w| (w[1][i] - w[0][i]) / dt).collect();
            let a: Vec<f64> = v.windows(2).map(|w| (w[1] - w[0]) / dt).collect();
            let j: Vec<f64> = a.windows(2).map(|w| (w[1] - w[0]) / dt).collect();
            if !qs.iter().all(|q| q[i] >= l.q_min[i] && q[i] <= l.q_max[i]) {
                return Err(format!("joint {i}: position"));
            }
            for (what, got, limit) in [
                ("velocity", max(&v), l.qd[i]),
                ("acceleration", max(&a), l.qdd[i] * 1.0001),
                ("jerk", max(&j), l.jerk[i] * 1.0001),
            ] {
                if got > limit {
                    return Err(format!("joint {i}: {what} {got:.1} > {limit:.1}"));
                }
            }
        }
        Ok(())
    }

    /// Drives each joint hard into every limit for 3 s and checks, on the stream itself as a
    /// robot would (finite differences of the commanded positions), that no limit is ever broken.
    /// The commanded positions and the clamps of `steps` periods from the ready posture at
    /// rest, each asked `demand(k, last)` = (q̈, q⃛), through the Panda's limiter (margin 0.02).
    fn drive(
        steps: usize,
        mut demand: impl FnMut(usize, &MotionState<7>) -> (VecN<7>, VecN<7>),
    ) -> (Vec<VecN<7>>, Saturations<7>) {
        let lim = Limiter::new(&panda_limits(), 1e-3, 0.02, true);
        let mut m = ready();
        let mut qs = vec![m.q];
        let mut sat = Saturations::<7>::default();
        for k in 0..steps {
            let (qdd, qddd) = demand(k, &m);
            let s = lim.step(&m, &qdd, &qddd);
            sat.add(&s.hits);
            m = s.end;
            qs.push(m.q);
        }
        (qs, sat)
    }

    #[test]
    fn a_violent_demand_gives_a_stream_inside_every_limit() {
        let (qs, sat) = drive(3000, |k, _| {
            // Full speed towards the upper limits, then a sudden reversal.
            let sign = if k < 1500 { 1.0 } else { -1.0 };
            (VecN::<7>::repeat(sign * 1e4), VecN::<7>::zeros())
        });
        judge(&panda_limits(), 1e-3, &qs).unwrap();
        assert!(sat.total(LimitKind::Jerk) > 0 && sat.total(LimitKind::Acceleration) > 0);
    }

    /// A law that asks for an acceleration within reach of the last one and a steep ramp on top
    /// (as after a hold, when the law catches the path again): the step to the acceleration and
    /// the ramp over the period are one jerk to the robot, and together they must stay inside
    /// its limit (a stream that let each take the whole limit was stopped for twice the jerk).
    #[test]
    fn a_step_and_a_ramp_together_stay_inside_the_jerk_limit() {
        let (l, dt) = (panda_limits(), 1e-3);
        let mut uniform = crate::basics::rng::uniform(7);
        let (qs, sat) = drive(20_000, |_, m| {
            let mut qdd = VecN::<7>::zeros();
            let mut qddd = VecN::<7>::zeros();
            for i in 0..7 {
                // Within one jerk-limited step of the last acceleration, and a ramp of up to
                // twice the jerk limit, either way.
                qdd[i] = m.qdd[i] + uniform() * l.jerk[i] * dt;
                qddd[i] = uniform() * 2.0 * l.jerk[i];
            }
            (qdd, qddd)
        });
        judge(&l, dt, &qs).unwrap();
        // The walk pressed on the jerk and the acceleration bounds, and came near a position
        // limit (where the acceleration bound moves fastest, and the jerk must still follow it).
        for kind in [LimitKind::Acceleration, LimitKind::Jerk] {
            assert!(sat.total(kind) > 0, "{kind:?}: {sat:?}");
        }
        let near = |i: usize| {
            qs.iter()
                .any(|q| q[i] - l.q_min[i] < 0.2 || l.q_max[i] - q[i] < 0.2)
        };
        assert!((0..7).filter(|&i| near(i)).count() >= 3);
    }

    #[test]
    fn torque_is_limited_in_rate_then_size() {
        let lim = Limiter::new(&panda_limits(), 1e-3, 0.0, true);
        let mut hits = [0u8; 7];
        let t = lim.torque(&VecN::zeros(), &VecN::repeat(50.0), &mut hits);
        assert_eq!(t[0], 1.0);
        assert_eq!(hits[0], LimitKind::TorqueRate.bit());
        let mut hits = [0u8; 7];
        let t = lim.torque(&VecN::repeat(11.9), &VecN::repeat(50.0), &mut hits);
        assert_eq!((t[0], t[6]), (12.9, 12.0));
        assert_ne!(hits[6] & LimitKind::Torque.bit(), 0);
    }
}
