//! The rules a real arm's controller applies to every command it receives (docs/science.md, "Commanding real arms"): the
//! stream must stay continuous and inside the joint limits, or the arm stops with a reflex
//! error naming the joint and the rule.
//!
//! Like a robot, the device judges the stream, not the one command: successive positions imply
//! a velocity, an acceleration and a jerk (finite differences at the device's period), and a
//! stream starts from the arm's measured position and velocity with zero acceleration, as
//! libfranka's motion generators do: the first command must continue the arm's motion, and its
//! acceleration and jerk are judged from there (a stream that starts with the law's full q̈ is
//! a jerk the arm refuses). The limits are the description's, undated (the daemon's limiter
//! keeps a margin below them), with a relative slack of 1e-6 for rounding.

use super::wire::DeviceCommand;
use control::command::JointLimits;
use protocol::{interface, DeviceStatus};

/// Rounding slack on every limit (relative).
const SLACK: f64 = 1e-6;

/// A broken rule: which, and on which joint (0-based).
pub type Breach = (DeviceStatus, usize);

/// The stream so far, per joint.
#[derive(Clone, Copy, Debug)]
struct Stream<const N: usize> {
    /// Commands seen since the stream started.
    count: u32,
    /// The device cycle of the state the last command answered.
    cycle: u64,
    /// The time the last two commands each covered (s), the latest first.
    spans: [f64; 2],
    q: [f64; N],
    qd: [f64; N],
    qdd: [f64; N],
    tau: [f64; N],
}

/// The checker: the device's limits, its period, and the stream it is judging.
#[derive(Clone, Debug)]
pub struct Rules<const N: usize> {
    limits: JointLimits<N>,
    dt: f64,
    stream: Option<Stream<N>>,
}

fn beyond(value: f64, limit: f64) -> bool {
    value.abs() > limit * (1.0 + SLACK) + 1e-12
}

impl<const N: usize> Rules<N> {
    pub fn new(limits: JointLimits<N>, dt: f64) -> Self {
        Self {
            limits,
            dt,
            stream: None,
        }
    }

    /// A new stream starts with the next command (after a start, a hold or a stop).
    pub fn restart(&mut self) {
        self.stream = None;
    }

    /// Judges one RUN command against the arm's measured (q, q̇) and applied torque; on a breach
    /// the stream is over (the device stops) until [`Rules::restart`]. `cycle` is the device
    /// cycle of the state the command answers: the stream's differences are taken over the
    /// cycles since the last command judged (one, or more after missed answers or the device's
    /// own overruns), the time the device moved on by. A stream's first command is one cycle
    /// ahead of the state it answers.
    pub fn check(
        &mut self,
        c: &DeviceCommand,
        q: &[f64],
        qd: &[f64],
        tau: &[f64],
        cycle: u64,
    ) -> Result<(), Breach> {
        let s = *self.stream.get_or_insert(Stream {
            count: 0,
            cycle: cycle.saturating_sub(1),
            spans: [self.dt; 2],
            q: std::array::from_fn(|i| q[i]),
            qd: std::array::from_fn(|i| qd[i]),
            qdd: [0.0; N],
            tau: std::array::from_fn(|i| tau[i]),
        });
        let cycles = cycle.saturating_sub(s.cycle).clamp(1, u64::from(u32::MAX));
        let h = self.dt * cycles as f64;
        let mut next = self.judge(c, &s, h)?;
        next.cycle = cycle;
        next.spans = [h, s.spans[0]];
        self.stream = Some(next);
        Ok(())
    }

    /// After missed answers the commands are unevenly spaced: the derivatives are divided
    /// differences over the times between the points they stand for (a position difference
    /// is the velocity at the middle of its span), exact for a cubic stream whatever the gaps,
    /// so a smooth stream that lost answers is judged as smooth.
    fn judge(&self, c: &DeviceCommand, s: &Stream<N>, h: f64) -> Result<Stream<N>, Breach> {
        let l = &self.limits;
        let [h1, h2] = s.spans;
        // The start (the measured state, at rest in acceleration) stands for the point one
        // period before it: every rule applies from the first command.
        let first = s.count == 0;
        let mut next = *s;
        next.count = s.count.saturating_add(1);
        for i in 0..N {
            let (v, a, jerk_span) = match c.interface {
                interface::POSITION => {
                    if c.q[i] < l.q_min[i] || c.q[i] > l.q_max[i] {
                        return Err((DeviceStatus::PositionLimit, i));
                    }
                    let v = (c.q[i] - s.q[i]) / h;
                    // The first command must be within one period's travel of the arm.
                    if first && beyond(v, l.qd[i]) {
                        return Err((DeviceStatus::Discontinuity, i));
                    }
                    next.q[i] = c.q[i];
                    (v, (v - s.qd[i]) / ((h + h1) / 2.0), (h + h1 + h2) / 3.0)
                }
                interface::VELOCITY => (c.qd[i], (c.qd[i] - s.qd[i]) / h, (h + h1) / 2.0),
                interface::ACCELERATION => (s.qd[i] + c.qdd[i] * h, c.qdd[i], h),
                _ => {
                    if beyond(c.tau[i], l.tau[i]) {
                        return Err((DeviceStatus::TorqueLimit, i));
                    }
                    if !first && beyond((c.tau[i] - s.tau[i]) / h, l.tau_rate[i]) {
                        return Err((DeviceStatus::TorqueRateLimit, i));
                    }
                    next.tau[i] = c.tau[i];
                    continue;
                }
            };
            if beyond(v, l.qd[i]) {
                return Err((DeviceStatus::VelocityLimit, i));
            }
            if beyond(a, l.qdd[i]) {
                return Err((DeviceStatus::AccelerationLimit, i));
            }
            if beyond((a - s.qdd[i]) / jerk_span, l.jerk[i]) {
                return Err((DeviceStatus::JerkLimit, i));
            }
            next.qd[i] = v;
            next.qdd[i] = a;
        }
        Ok(next)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::udp::wire::DeviceMode;

    fn limits() -> JointLimits<2> {
        let mut l = JointLimits::<2>::NONE;
        l.q_min = [-1.0; 2];
        l.q_max = [1.0; 2];
        l.qd = [2.0; 2];
        l.qdd = [10.0; 2];
        l.jerk = [5000.0; 2];
        l.tau = [50.0; 2];
        l.tau_rate = [1000.0; 2];
        l
    }

    fn position(q: f64) -> DeviceCommand {
        let mut c = DeviceCommand::still(2, 0, 0, DeviceMode::Run);
        c.interface = interface::POSITION;
        c.q[0] = q;
        c
    }

    #[test]
    fn a_smooth_stream_passes_and_each_rule_names_its_breach() {
        let (dt, z) = (1e-3, [0.0; 2]);
        let mut r = Rules::new(limits(), dt);
        // 1 rad/s² from rest for 0.2 s: well inside every limit.
        for k in 1..=200 {
            let t = k as f64 * dt;
            assert_eq!(
                r.check(&position(0.5 * t * t), &z, &z, &z, k),
                Ok(()),
                "tick {k}"
            );
        }
        // A jump: 1 mm more in one tick than the stream implies is a huge acceleration step.
        let mut r = Rules::new(limits(), dt);
        r.check(&position(0.0), &z, &z, &z, 1).unwrap();
        assert_eq!(
            r.check(&position(1e-3), &z, &z, &z, 2).unwrap_err().0,
            DeviceStatus::AccelerationLimit
        );
        // Out of range, and a first command that does not continue the arm.
        let mut r = Rules::new(limits(), dt);
        assert_eq!(
            r.check(&position(1.5), &z, &z, &z, 1),
            Err((DeviceStatus::PositionLimit, 0))
        );
        r.restart();
        assert_eq!(
            r.check(&position(0.01), &z, &z, &z, 1),
            Err((DeviceStatus::Discontinuity, 0))
        );
        // A first command that continues the arm's motion (1 rad/s) starts a stream.
        r.restart();
        assert_eq!(r.check(&position(0.001), &z, &[1.0, 0.0], &z, 1), Ok(()));
        // From rest, a stream starts at zero acceleration: 9 rad/s² at once (inside the
        // acceleration limit) is a jerk of 9000 rad/s³.
        r.restart();
        assert_eq!(
            r.check(&position(9e-6), &z, &z, &z, 1),
            Err((DeviceStatus::JerkLimit, 0))
        );
        // Torque: size, then rate.
        let mut r = Rules::new(limits(), dt);
        let mut c = DeviceCommand::still(2, 0, 0, DeviceMode::Run);
        c.interface = interface::TORQUE;
        c.tau[1] = 60.0;
        assert_eq!(
            r.check(&c, &z, &z, &z, 1),
            Err((DeviceStatus::TorqueLimit, 1))
        );
        c.tau[1] = 0.5;
        r.restart();
        r.check(&c, &z, &z, &z, 1).unwrap();
        c.tau[1] = 5.0;
        assert_eq!(
            r.check(&c, &z, &z, &z, 2),
            Err((DeviceStatus::TorqueRateLimit, 1))
        );
    }

    #[test]
    fn differences_span_the_cycles_the_device_moved_on_by() {
        let (dt, z, one) = (1e-3, [0.0; 2], [1.0, 0.0]);
        // 1 rad/s from the start; the answers to cycles 3 and 4 went missing.
        let mut r = Rules::new(limits(), dt);
        for k in [1, 2, 5, 6] {
            let q = k as f64 * dt;
            assert_eq!(r.check(&position(q), &z, &one, &z, k), Ok(()), "cycle {k}");
        }
        // Near the acceleration and jerk limits (9 rad/s² and 3600 rad/s³ peaks, of 10 and
        // 5000), answers lost here and there: judged over the true gaps, the stream is smooth.
        let mut r = Rules::new(limits(), dt);
        let q = |t: f64| 9.0 / 400.0_f64.powi(2) * (400.0 * t).sin();
        let qd0 = [9.0 / 400.0, 0.0];
        for k in (1..=60).filter(|k| k % 7 != 3 && k % 11 != 5) {
            let t = k as f64 * dt;
            assert_eq!(
                r.check(&position(q(t)), &z, &qd0, &z, k),
                Ok(()),
                "cycle {k}"
            );
        }
        // The same positions judged as if one cycle had passed: three periods of travel in one
        // is a velocity step the arm cannot make.
        let mut r = Rules::new(limits(), dt);
        r.check(&position(dt), &z, &one, &z, 1).unwrap();
        r.check(&position(2.0 * dt), &z, &one, &z, 2).unwrap();
        assert!(r.check(&position(5.0 * dt), &z, &one, &z, 3).is_err());
    }
}
