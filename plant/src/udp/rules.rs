//! The rules a real arm's controller applies to every command it receives (SCIENCE.md §9): the
//! stream must stay continuous and inside the joint limits, or the arm stops with a reflex
//! error naming the joint and the rule.
//!
//! Like a robot, the device judges the stream, not the one command: successive positions imply
//! a velocity, an acceleration and a jerk (finite differences at the device's period), and the
//! first command of a stream must continue the arm's measured motion. The limits are the
//! description's, undated (the daemon's limiter keeps a margin below them), with a relative
//! slack of 1e-6 for rounding.

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
    /// the stream is over (the device stops) until [`Rules::restart`]. `cycles` is how many of
    /// the device's periods the command covers since the last one it judged (1, or more after
    /// missed answers: the stream's differences are taken over the time that passed).
    pub fn check(
        &mut self,
        c: &DeviceCommand,
        q: &[f64],
        qd: &[f64],
        tau: &[f64],
        cycles: u32,
    ) -> Result<(), Breach> {
        let s = *self.stream.get_or_insert(Stream {
            count: 0,
            q: std::array::from_fn(|i| q[i]),
            qd: std::array::from_fn(|i| qd[i]),
            qdd: [0.0; N],
            tau: std::array::from_fn(|i| tau[i]),
        });
        let next = self.judge(c, &s, self.dt * f64::from(cycles.max(1)))?;
        self.stream = Some(next);
        Ok(())
    }

    fn judge(&self, c: &DeviceCommand, s: &Stream<N>, h: f64) -> Result<Stream<N>, Breach> {
        let l = &self.limits;
        // A stream's velocity is defined from its first command, its acceleration from the
        // second, its jerk from the third: each rule applies once its quantity exists.
        let first = s.count == 0;
        let second = s.count == 1;
        let mut next = *s;
        next.count = s.count.saturating_add(1);
        for i in 0..N {
            let (v, a) = match c.interface {
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
                    if first {
                        next.qd[i] = v;
                        next.qdd[i] = 0.0;
                        continue;
                    }
                    (v, (v - s.qd[i]) / h)
                }
                interface::VELOCITY => {
                    let v = c.qd[i];
                    if first && beyond(v - s.qd[i], l.qdd[i] * h * 2.0) {
                        return Err((DeviceStatus::Discontinuity, i));
                    }
                    (v, (v - s.qd[i]) / h)
                }
                interface::ACCELERATION => (s.qd[i] + c.qdd[i] * h, c.qdd[i]),
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
            if !(first || second) && beyond((a - s.qdd[i]) / h, l.jerk[i]) {
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
        c.q = [q, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
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
                r.check(&position(0.5 * t * t), &z, &z, &z, 1),
                Ok(()),
                "tick {k}"
            );
        }
        // A jump: 1 mm more in one tick than the stream implies is a huge acceleration step.
        let mut r = Rules::new(limits(), dt);
        r.check(&position(0.0), &z, &z, &z, 1).unwrap();
        assert_eq!(
            r.check(&position(1e-3), &z, &z, &z, 1).unwrap_err().0,
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
        // The first command within one period's travel starts a stream.
        r.restart();
        assert_eq!(r.check(&position(0.001), &z, &z, &z, 1), Ok(()));
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
            r.check(&c, &z, &z, &z, 1),
            Err((DeviceStatus::TorqueRateLimit, 1))
        );
    }
}
