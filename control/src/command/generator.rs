//! The motion generator: the law's q̈ integrated into the reference a real arm follows, and the
//! command for the configured interface.
//!
//! Each tick the limited acceleration ramp (q̈ + q⃛·s, the law's first-order hold) advances the
//! reference (q_r, q̇_r) exactly over one period, as a motion generator on a robot does. Position
//! and velocity modes send the reference at the end of the period; torque mode sends computed
//! torque on the measured state, τ = M(q)q̈ + C(q,q̇)q̇ + g(q) (RNEA), plus a joint PD on the
//! reference error, limited in rate and size; acceleration mode sends the limited q̈ itself, with
//! the reference re-anchored on the measured state every tick (the plant integrates q̈ itself).
//!
//! The generator restarts from the measured state whenever the stream restarts (the first tick
//! of a run, after a HOLD or a FAULT), so the first command continues the arm's own motion.
//! [`MotionGenerator::next`] computes without changing anything (a rehearsal calls it);
//! [`MotionGenerator::commit`] makes a computed tick the stream's.

use super::limiter::{Limiter, MotionState, Saturations, Step};
use super::mode::CommandMode;
use crate::arm::VecN;
use crate::model::Model;

/// Torque mode's joint PD on (q_r − q, q̇_r − q̇), N·m/rad and N·m·s/rad, and velocity mode's
/// position correction on q_r − q: proportional (1/s) and integral (1/s²).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandGains<const N: usize> {
    pub kp: VecN<N>,
    pub kd: VecN<N>,
    pub kv: VecN<N>,
    pub ki: VecN<N>,
}

/// The most velocity mode's position correction adds to a joint's rate, as a share of its
/// velocity limit: an arm held back (by a collision, a brake, a weak motor) gets a bounded
/// push, not one that grows with its error.
pub const CORRECTION_SHARE: f64 = 0.05;

/// The most velocity mode's position correction changes in one period, as a share of the
/// joint's acceleration limit times the period: after a stall of the controller the arm is off
/// its reference by q̈·T²/2, and the pull's step would otherwise add that at once to the
/// acceleration the device sees, past a strict device's rule.
pub const PULL_SLEW_SHARE: f64 = 0.05;

/// Periods the pull's integral holds after a gap in the stream, per period missed.
pub const HOLD_OFF_PER_PERIOD: u32 = 10;

/// One tick's command in every interface's terms (the plant uses the one its mode names).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Command<const N: usize> {
    pub mode: CommandMode,
    /// The reference position at the end of the period.
    pub q: VecN<N>,
    /// The rate sent: the reference's at the end of the period, plus in velocity mode the
    /// position correction `kv·(q_r − q)` on the measured state.
    pub qd: VecN<N>,
    /// The limited acceleration ramp over the period.
    pub qdd: VecN<N>,
    pub qddd: VecN<N>,
    /// Torque mode's command (zero otherwise).
    pub tau: VecN<N>,
    /// Velocity mode's position correction: the rate added to the reference's (zero otherwise),
    /// and the integral of the reference error it has reached (rad·s).
    pub pull: Pull<N>,
    /// Which limits clamped each joint this tick (bits of `LimitKind`).
    pub hits: [u8; N],
    /// Where the stream's reference is at the end of the period (its next tick starts here).
    pub end: MotionState<N>,
}

impl<const N: usize> Command<N> {
    /// A command in interface `mode` that moves nothing (a HOLD's, a BRAKE's).
    pub fn still(mode: CommandMode) -> Self {
        let zero = VecN::<N>::zeros();
        Self {
            mode,
            q: zero,
            qd: zero,
            qdd: zero,
            qddd: zero,
            tau: zero,
            pull: Pull::default(),
            hits: [0; N],
            end: MotionState::at_rest(zero, zero),
        }
    }
}

/// Velocity mode's position correction as it stands after a tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pull<const N: usize> {
    /// The rate added to the reference's (rad/s).
    pub rate: VecN<N>,
    /// ∫(q_r − q)dt (rad·s), held while the pull is at its cap (no wind-up).
    pub integral: VecN<N>,
    /// Periods left during which the integral holds: a gap in the stream (a stall of the
    /// controller) leaves an error that is the stall's, not the servo's lag, and integrating
    /// it made the pull overshoot for a second after every long stall.
    pub hold_off: u32,
}

impl<const N: usize> Default for Pull<N> {
    fn default() -> Self {
        Self {
            rate: VecN::<N>::zeros(),
            integral: VecN::<N>::zeros(),
            hold_off: 0,
        }
    }
}

/// What a [`MotionGenerator`] remembers from tick to tick (see [`MotionGenerator::stream`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stream<const N: usize> {
    reference: MotionState<N>,
    last_tau: VecN<N>,
    pull: Pull<N>,
    saturations: Saturations<N>,
}

/// The generator's state and settings.
#[derive(Debug, Clone)]
pub struct MotionGenerator<const N: usize> {
    mode: CommandMode,
    limiter: Limiter<N>,
    gains: CommandGains<N>,
    /// The controller's model of the arm (torque mode's inverse dynamics).
    model: Option<Model<N>>,
    reference: MotionState<N>,
    last_tau: VecN<N>,
    pull: Pull<N>,
    pub saturations: Saturations<N>,
}

impl<const N: usize> MotionGenerator<N> {
    /// Torque mode needs `model`; the others ignore it.
    pub fn new(
        mode: CommandMode,
        limiter: Limiter<N>,
        gains: CommandGains<N>,
        model: Option<Model<N>>,
    ) -> Result<Self, &'static str> {
        if mode == CommandMode::Torque && model.is_none() {
            return Err("torque mode needs the robot's dynamic model (a [robot] description)");
        }
        Ok(Self {
            mode,
            limiter,
            gains,
            model,
            reference: MotionState::at_rest(VecN::<N>::zeros(), VecN::<N>::zeros()),
            last_tau: VecN::<N>::zeros(),
            pull: Pull::default(),
            saturations: Saturations::default(),
        })
    }

    /// A generator that passes q̈ through untouched: acceleration mode with no limits.
    pub fn passthrough(dt: f64) -> Self {
        let limiter = Limiter::new(&super::JointLimits::NONE, dt, 0.0, false);
        let gains = CommandGains {
            kp: VecN::<N>::zeros(),
            kd: VecN::<N>::zeros(),
            kv: VecN::<N>::zeros(),
            ki: VecN::<N>::zeros(),
        };
        Self::new(CommandMode::Acceleration, limiter, gains, None).expect("no model needed")
    }

    pub fn mode(&self) -> CommandMode {
        self.mode
    }

    pub fn limiter(&self) -> &Limiter<N> {
        &self.limiter
    }

    /// The reference the stream has reached.
    pub fn reference(&self) -> &MotionState<N> {
        &self.reference
    }

    /// The state the law runs on. Position and velocity modes run it on the reference, as a
    /// motion generator does (libfranka's `q_d`): the arm's servo lags the reference, and a law
    /// that closed its loop through that lag would see its own commands late and wind the
    /// reference up (tried: the Panda's self-motion then ran away within 3 s). The arm follows
    /// a reference that is itself a clean run of the law. Torque and acceleration modes act on
    /// the arm directly, so their law runs on the measured state.
    pub fn law_state(&self, q: &VecN<N>, qd: &VecN<N>) -> (VecN<N>, VecN<N>) {
        match self.mode {
            CommandMode::Position | CommandMode::Velocity => (self.reference.q, self.reference.qd),
            CommandMode::Acceleration | CommandMode::Torque => (*q, *qd),
        }
    }

    /// Starts the stream again from the measured state, at rest in acceleration.
    pub fn restart(&mut self, q: &VecN<N>, qd: &VecN<N>) {
        self.reference = MotionState::at_rest(*q, *qd);
        self.pull = Pull::default();
        self.last_tau = match &self.model {
            Some(m) if self.mode == CommandMode::Torque => m.rnea(q, qd, &VecN::<N>::zeros()),
            _ => VecN::<N>::zeros(),
        };
    }

    /// This tick's command on the measured (q, q̇) for the law's ramp q̈ + q⃛·s. Changes nothing.
    pub fn next(&self, q: &VecN<N>, qd: &VecN<N>, qdd: &VecN<N>, qddd: &VecN<N>) -> Command<N> {
        let from = match self.mode {
            CommandMode::Acceleration => MotionState {
                q: *q,
                qd: *qd,
                qdd: self.reference.qdd,
            },
            _ => self.reference,
        };
        let Step {
            end,
            qdd: a,
            qddd: r,
            mut hits,
        } = self.limiter.step(&from, qdd, qddd);
        let tau = match (&self.model, self.mode) {
            (Some(m), CommandMode::Torque) => {
                let e = from.q - q;
                let ed = from.qd - qd;
                let ff = m.rnea(q, qd, &a);
                let pd = self.gains.kp.component_mul(&e) + self.gains.kd.component_mul(&ed);
                self.limiter.torque(&self.last_tau, &(ff + pd), &mut hits)
            }
            _ => VecN::<N>::zeros(),
        };
        let (qd_sent, pull) = match self.mode {
            CommandMode::Velocity => {
                let pull = self.correction(&(from.q - q));
                (self.held_rate(&from, &end) + pull.rate, pull)
            }
            _ => (end.qd, Pull::default()),
        };
        Command {
            mode: self.mode,
            q: end.q,
            qd: qd_sent,
            qdd: a,
            qddd: r,
            tau,
            pull,
            hits,
            end,
        }
    }

    /// The one rate that, held over the period, moves the arm from the stream's start to its
    /// end: (q_end − q_start)/dt. A velocity interface holds each command for a period, so the
    /// end's rate (the reference's q̇ at the period's end) would carry the arm ½·q̈·dt² a period
    /// past the reference, a bias the pull below then holds at q̈·dt/(2·k_v) (about 0.3 mm at
    /// the Panda's tip with k_v = 5 /s); the mean rate leaves none. It lies between the
    /// period's start and end rates up to the jerk's ⅙·q⃛·dt², inside the limits the stream keeps.
    fn held_rate(&self, from: &MotionState<N>, end: &MotionState<N>) -> VecN<N> {
        (end.q - from.q) / self.limiter_dt()
    }

    /// Velocity mode's pull back to the reference: a velocity interface integrates what it is
    /// sent, so whatever the arm loses (a late or dropped command, its servo's lag, its own
    /// integration) would stay lost, and the tip would drift off the path.
    /// `kv·(q_r − q) + ki·∫(q_r − q)dt` on the measured state makes the arm's position, not only
    /// its rate, follow the reference (the velocity feed-forward plus PI of ros2_control's
    /// trajectory controller). Each joint's pull is capped at [`CORRECTION_SHARE`] of its
    /// velocity limit (the integral holds while it is: no wind-up), and changes by at most
    /// [`PULL_SLEW_SHARE`] of its acceleration limit over a period.
    fn correction(&self, error: &VecN<N>) -> Pull<N> {
        let l = self.limiter.limits();
        let dt = self.limiter_dt();
        let last = &self.pull;
        let mut next = *last;
        let integrate = last.hold_off == 0;
        next.hold_off = last.hold_off.saturating_sub(1);
        for i in 0..N {
            let (kv, ki) = (self.gains.kv[i], self.gains.ki[i]);
            let integral = last.integral[i] + error[i] * dt;
            let wanted = kv * error[i] + ki * integral;
            let cap = CORRECTION_SHARE * l.qd[i];
            let capped = if cap.is_finite() {
                wanted.clamp(-cap, cap)
            } else {
                wanted
            };
            if capped == wanted && integrate {
                next.integral[i] = integral;
            }
            let step = PULL_SLEW_SHARE * l.qdd[i] * dt;
            next.rate[i] = if step.is_finite() {
                capped.clamp(last.rate[i] - step, last.rate[i] + step)
            } else {
                capped
            };
        }
        next
    }

    /// [`Self::next`] for a command that comes `periods` periods after the last one (states
    /// went missing in between): the reference moves on over the whole time, as the device's
    /// own did. Over the first period it follows the law's ramp, limited; after it, the
    /// stream's acceleration at that period's end is held. The ramp is a one-period prediction:
    /// carried on over a gap of tens of periods at the jerk limit (a stiff law's ramp is
    /// steep), it took the reference off the path, and the law then asked for more than the
    /// arm can do. Changes nothing.
    pub fn next_over(
        &self,
        q: &VecN<N>,
        qd: &VecN<N>,
        qdd: &VecN<N>,
        qddd: &VecN<N>,
        periods: u32,
    ) -> Command<N> {
        if periods <= 1 || self.mode == CommandMode::Acceleration {
            return self.next(q, qd, qdd, qddd);
        }
        let mut g = self.clone();
        let mut hits = [0u8; N];
        let mut c = g.next(q, qd, qdd, qddd);
        let held = c.qdd + c.qddd * self.limiter_dt();
        for _ in 1..periods {
            hits.iter_mut().zip(&c.hits).for_each(|(h, x)| *h |= x);
            g.reference = c.end;
            c = g.next(q, qd, &held, &VecN::<N>::zeros());
        }
        hits.iter_mut().zip(&c.hits).for_each(|(h, x)| *h |= x);
        c.hits = hits;
        if self.mode == CommandMode::Velocity {
            c.pull.integral = self.pull.integral;
            c.pull.hold_off = c.pull.hold_off.max(HOLD_OFF_PER_PERIOD * periods);
        }
        c
    }

    /// Where the stream stands: all that [`Self::commit`] and [`Self::restart`] change, for a
    /// caller that runs a tick and undoes it ([`Self::set_stream`]).
    pub fn stream(&self) -> Stream<N> {
        Stream {
            reference: self.reference,
            last_tau: self.last_tau,
            pull: self.pull,
            saturations: self.saturations,
        }
    }

    /// Puts the stream back where [`Self::stream`] found it.
    pub fn set_stream(&mut self, s: Stream<N>) {
        self.reference = s.reference;
        self.last_tau = s.last_tau;
        self.pull = s.pull;
        self.saturations = s.saturations;
    }

    /// Makes `c` (computed by [`Self::next`] this tick) the stream's last command.
    pub fn commit(&mut self, c: &Command<N>) {
        self.reference = c.end;
        self.last_tau = c.tau;
        self.pull = c.pull;
        self.saturations.add(&c.hits);
    }

    fn limiter_dt(&self) -> f64 {
        self.limiter.dt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::{JointLimits, MakerTable};
    use crate::model::{builtin, Chain};

    fn panda(mode: CommandMode) -> (MotionGenerator<7>, Model<7>) {
        panda_with(mode, 0.0)
    }

    /// The Panda's generator with velocity mode's integral gain `ki`.
    fn panda_with(mode: CommandMode, ki: f64) -> (MotionGenerator<7>, Model<7>) {
        let chain = Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap();
        let model = chain.model::<7>().unwrap();
        let limits = JointLimits::<7>::described(&chain, MakerTable::for_robot("panda", 7));
        let gains = CommandGains {
            kp: VecN::<7>::repeat(100.0),
            kd: VecN::<7>::repeat(10.0),
            kv: VecN::<7>::repeat(20.0),
            ki: VecN::<7>::repeat(ki),
        };
        let g = MotionGenerator::new(
            mode,
            Limiter::new(&limits, 1e-3, 0.02, true),
            gains,
            Some(model),
        );
        (g.unwrap(), model)
    }

    #[test]
    fn position_mode_integrates_the_ramp_exactly() {
        let (mut g, _) = panda(CommandMode::Position);
        let q = VecN::<7>::from_column_slice(&crate::config::spatial::PANDA_READY);
        g.restart(&q, &VecN::zeros());
        let a = VecN::<7>::repeat(0.5);
        for _ in 0..100 {
            let c = g.next(&q, &VecN::zeros(), &a, &VecN::zeros());
            assert_eq!(c.hits, [0; 7]);
            g.commit(&c);
        }
        // From rest the first period ramps the acceleration up to 0.5 rad/s² (a robot sees a
        // step in it as a jerk); 0.1 s: q̇ = 0.5 (T − h/2), q = 0.5 (T²/2 − hT/2 + h²/6).
        let (t, h) = (0.1, 1e-3);
        let r = g.reference();
        let (qd, dq) = (
            0.5 * (t - h / 2.0),
            0.5 * (t * t / 2.0 - h * t / 2.0 + h * h / 6.0),
        );
        assert!((r.qd[0] - qd).abs() < 1e-12, "{}", r.qd[0]);
        assert!((r.q[0] - q[0] - dq).abs() < 1e-12, "{}", r.q[0] - q[0]);
    }

    #[test]
    fn over_a_gap_the_reference_holds_the_acceleration_the_first_period_reached() {
        let (mut g, _) = panda(CommandMode::Position);
        let q = VecN::<7>::from_column_slice(&crate::config::spatial::PANDA_READY);
        g.restart(&q, &VecN::zeros());
        // A steep ramp (2000 rad/s³, inside every joint's jerk limit), answered 20 periods late:
        // the first period ramps to 2 rad/s², and the rest of the gap holds it; carried on, the
        // ramp would have reached the acceleration limits.
        let ramp = VecN::<7>::repeat(2000.0);
        let c = g.next_over(&q, &VecN::zeros(), &VecN::zeros(), &ramp, 20);
        let end = c.qdd + c.qddd * 1e-3;
        assert!((end - VecN::<7>::repeat(2.0)).amax() < 1e-9, "{end}");
        assert_eq!(c.hits, [0; 7]);
    }

    #[test]
    fn velocity_mode_pulls_the_arm_back_to_the_reference_by_a_bounded_push() {
        let (mut g, _) = panda(CommandMode::Velocity);
        let q = VecN::<7>::from_column_slice(&crate::config::spatial::PANDA_READY);
        g.restart(&q, &VecN::zeros());
        let a = VecN::<7>::repeat(0.5);
        // On the reference: the rate that, held for the period, reaches the stream's end, and
        // the stream moves on by it alone.
        let on = g.next(&q, &VecN::zeros(), &a, &VecN::zeros());
        assert!((q + on.qd * 1e-3 - on.end.q).amax() < 1e-15, "{}", on.qd);
        assert!(
            on.qd[0] > 0.0 && on.qd[0] < on.end.qd[0],
            "between the start's and the end's"
        );
        // 1 mrad behind on joint 1, the reference at rest: the pull ramps at its slew to
        // 20 /s × 1e-3 = 0.02 rad/s and stays there, and the reference is not moved by it (the
        // push is the arm's, not the reference's).
        g.restart(&q, &VecN::zeros());
        let zero = VecN::<7>::zeros();
        let l = *g.limiter().limits();
        let step = PULL_SLEW_SHARE * l.qdd[0] * 1e-3;
        let mut behind = q;
        behind[0] -= 1e-3;
        let mut last = 0.0;
        for k in 0..100 {
            let c = g.next(&behind, &zero, &zero, &zero);
            assert!(
                c.qd[0] - last <= step + 1e-15,
                "tick {k}: {} after {last}",
                c.qd[0]
            );
            assert_eq!(c.qd[1], 0.0);
            last = c.qd[0];
            g.commit(&c);
        }
        assert!((last - 0.02).abs() < 1e-12, "{last}");
        assert_eq!(g.reference().q, q);
        // Far behind: the push stops at its share of the velocity limit.
        behind[0] -= 1.0;
        let cap = CORRECTION_SHARE * l.qd[0];
        for _ in 0..1000 {
            let c = g.next(&behind, &zero, &zero, &zero);
            last = c.qd[0];
            g.commit(&c);
        }
        assert!((last - cap).abs() < 1e-12, "{last} against {cap}");
    }

    #[test]
    fn velocity_modes_integral_takes_back_a_steady_lag_and_does_not_wind_up() {
        let (mut g, _) = panda_with(CommandMode::Velocity, 100.0);
        let limits = *g.limiter().limits();
        let q = VecN::<7>::from_column_slice(&crate::config::spatial::PANDA_READY);
        let zero = VecN::<7>::zeros();
        g.restart(&q, &zero);
        let run = |g: &mut MotionGenerator<7>, at: &VecN<7>, ticks: usize| {
            let mut c = g.next(at, &zero, &zero, &zero);
            for _ in 0..ticks {
                c = g.next(at, &zero, &zero, &zero);
                g.commit(&c);
            }
            c
        };
        // 0.1 mrad behind for 0.2 s: kv·e + ki·e·t = 2e-3 + 100·1e-4·0.2 = 4e-3 rad/s.
        let mut behind = q;
        behind[0] -= 1e-4;
        let c = run(&mut g, &behind, 200);
        assert!((c.qd[0] - 4e-3).abs() < 2e-5, "{}", c.qd[0]);
        // Held far behind for 2 s (a collision, a brake): the pull sits at its cap and the
        // integral stops growing there, so once the arm is back on its reference the pull is
        // no more than the cap's worth, not two seconds of error.
        g.restart(&q, &zero);
        behind[0] -= 0.5;
        let cap = CORRECTION_SHARE * limits.qd[0];
        let c = run(&mut g, &behind, 2000);
        assert!((c.qd[0] - cap).abs() < 1e-12, "{} against {cap}", c.qd[0]);
        assert!(c.pull.integral[0] * 100.0 <= cap, "{}", c.pull.integral[0]);
        let c = run(&mut g, &q, 200);
        assert!(c.qd[0].abs() <= cap, "{}", c.qd[0]);
    }

    #[test]
    fn after_a_gap_the_integral_holds_while_the_stall_s_error_is_taken_back() {
        let (mut g, _) = panda_with(CommandMode::Velocity, 100.0);
        let q = VecN::<7>::from_column_slice(&crate::config::spatial::PANDA_READY);
        let zero = VecN::<7>::zeros();
        g.restart(&q, &zero);
        let mut behind = q;
        behind[0] -= 1e-4;
        for _ in 0..10 {
            let c = g.next(&behind, &zero, &zero, &zero);
            g.commit(&c);
        }
        let before = g.stream().pull.integral[0];
        assert!(before > 0.0);
        // A command 20 periods late: the pull still pushes (P), the integral holds for
        // 10 periods per period missed, then integrates again.
        let c = g.next_over(&behind, &zero, &zero, &zero, 20);
        assert_eq!(c.pull.hold_off, HOLD_OFF_PER_PERIOD * 20);
        assert_eq!(c.pull.integral[0], before);
        g.commit(&c);
        for _ in 0..HOLD_OFF_PER_PERIOD * 20 {
            let c = g.next(&behind, &zero, &zero, &zero);
            g.commit(&c);
        }
        assert_eq!(g.stream().pull.integral[0], before);
        let c = g.next(&behind, &zero, &zero, &zero);
        assert!(c.pull.integral[0] > before);
    }

    #[test]
    fn torque_mode_is_inverse_dynamics_on_the_reference() {
        let (mut g, model) = panda(CommandMode::Torque);
        let q = VecN::<7>::from_column_slice(&crate::config::spatial::PANDA_READY);
        let qd = VecN::<7>::repeat(0.1);
        g.restart(&q, &qd);
        // On the reference, with a small q̈: RNEA alone, within the rate limit of the start, at
        // the stream's acceleration (which ramps from the restart's 0 to the law's q̈).
        let a = VecN::<7>::repeat(0.01);
        let c = g.next(&q, &qd, &a, &VecN::zeros());
        assert!(c.qdd.norm() == 0.0 && (c.qddd * 1e-3 - a).norm() < 1e-12);
        let expect = model.rnea(&q, &qd, &c.qdd);
        assert!((c.tau - expect).norm() < 1e-9, "{} vs {}", c.tau, expect);
        // A reference error adds the PD.
        let off = q + VecN::<7>::repeat(1e-3);
        let c = g.next(&off, &qd, &a, &VecN::zeros());
        let expect = model.rnea(&off, &qd, &c.qdd) - VecN::<7>::repeat(0.1);
        assert!((c.tau - expect).norm() < 1e-9);
        assert!(MotionGenerator::new(CommandMode::Torque, *g.limiter(), g.gains, None).is_err());
    }
}
