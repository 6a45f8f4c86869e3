//! The first seconds of the motion, rehearsed offline before the arm is asked for them.
//!
//! A start posture the arm can hold may still lead, within a second, to a motion that needs
//! more torque than a joint has. The start's gravity check cannot see it; the arm finds out by
//! saturating (the rigid-body plant's servo clamps, a real arm's reflex stops it) and the
//! tracking is lost by millimetres, the problem reported only after the fact. The kinematic
//! loop is cheap (milliseconds for seconds of motion), so at start-up the law runs offline from
//! the configured start over [`REHEARSAL_PERIODS`] periods of the path (at least
//! [`REHEARSAL_MIN_S`]), and the inverse dynamics of the controller's own model along it gives
//! each joint's torque. It checks the start's neighbourhood, not the whole run: the chaotic
//! self-motion may wander later, and the live limit watch reports what it finds there.

use crate::basics::{ConfigError, PhysicsError};
use crate::config::spatial::SpatialSetup;
use crate::config::Config;
use crate::model::Chain;

/// Path periods rehearsed.
pub const REHEARSAL_PERIODS: f64 = 2.0;
/// Shortest rehearsal (s): the transient from rest to the path takes about a second.
pub const REHEARSAL_MIN_S: f64 = 4.0;

/// The largest share of its effort limit any joint needs over the rehearsal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffortPeak {
    /// 0-based.
    pub joint: usize,
    /// |τ| needed (N·m or N) and the limit it is compared with.
    pub torque: f64,
    pub limit: f64,
    /// When, from the start (s), and how long the rehearsal ran.
    pub t: f64,
    pub span: f64,
}

impl EffortPeak {
    pub fn share(&self) -> f64 {
        self.torque / self.limit
    }
}

impl Config {
    /// Runs the law offline from the start for the rehearsal's span and returns the joint
    /// that comes closest to (or furthest past) its effort limit. `N` must be the chain's
    /// joint count.
    pub fn effort_peak<const N: usize>(&self, chain: &Chain) -> Result<EffortPeak, ConfigError> {
        let (setup, limits) = self.effort_setup::<N>(chain)?;
        self.rehearse(&setup, &limits)
    }

    /// The run and the effort limits the stream obeys (the description's, tightened).
    fn effort_setup<const N: usize>(
        &self,
        chain: &Chain,
    ) -> Result<(SpatialSetup<N>, [f64; N]), ConfigError> {
        let r = self.spatial_part();
        let setup = self.setup::<N>(chain)?;
        let limits = r.command.limits::<N>(chain, &r.robot.description)?.tau;
        Ok((setup, limits))
    }

    fn rehearse<const N: usize>(
        &self,
        setup: &SpatialSetup<N>,
        limits: &[f64; N],
    ) -> Result<EffortPeak, ConfigError> {
        let r = self.spatial_part();
        let span = (REHEARSAL_PERIODS * r.task.period).max(REHEARSAL_MIN_S);
        let steps = (span / setup.dt).ceil() as u64;
        let model = setup.arm.model;
        let mut peak = EffortPeak {
            joint: 0,
            torque: 0.0,
            limit: limits[0],
            t: 0.0,
            span,
        };
        let mut sim = setup.simulation();
        for _ in 0..steps {
            let (t, x) = (sim.time(), *sim.state());
            let out = sim.step();
            if !(x.is_finite() && out.qdd.iter().all(|v| v.is_finite())) {
                break;
            }
            let tau = model.rnea(&x.q, &x.qd, &out.qdd);
            for i in 0..N {
                if tau[i].abs() / limits[i] > peak.share() {
                    peak = EffortPeak {
                        joint: i,
                        torque: tau[i].abs(),
                        limit: limits[i],
                        t,
                        span,
                    };
                }
            }
        }
        Ok(peak)
    }

    /// Refuses a start the arm cannot hold, then one whose first seconds of motion need more
    /// than a joint's effort limit (the first is the plainer cause, so it is named first).
    pub fn check_motion_effort<const N: usize>(&self, chain: &Chain) -> Result<(), ConfigError> {
        let (setup, tau) = self.effort_setup::<N>(chain)?;
        let hold = chain.gravity_beyond_effort(&setup.arm.model, &setup.q0, &tau.into(), "");
        if let Some(e) = hold {
            return Err(e.into());
        }
        let p = self.rehearse(&setup, &tau)?;
        if p.torque <= p.limit {
            return Ok(());
        }
        Err(PhysicsError::MotionBeyondEffort {
            index: p.joint + 1,
            joint: chain.joints[p.joint].name.clone(),
            load: p.torque,
            limit: p.limit,
            unit: chain.effort_unit(p.joint),
            t: p.t,
            span: p.span,
        }
        .into())
    }
}

#[cfg(test)]
mod tests {
    use crate::command::CommandMode;
    use crate::system::{builtin_robot, System};

    fn panda(mode: CommandMode, torque: Option<Vec<f64>>) -> System {
        let mut s = System::preset("panda", &builtin_robot).unwrap();
        if let System::Spatial(sp) = &mut s {
            sp.own_mut().command.mode = mode;
            sp.own_mut().command.limits.torque = torque;
        }
        s
    }

    #[test]
    fn the_panda_preset_carries_its_motion_with_room_to_spare() {
        let System::Spatial(s) = panda(CommandMode::Torque, None) else {
            unreachable!()
        };
        let p = s.config.effort_peak::<7>(&s.chain).unwrap();
        // The shoulder holds the arm out: a real share of its 87 N·m, well inside it.
        assert!(p.share() > 0.05 && p.share() < 0.8, "{p:?}");
        assert_eq!(p.span, 4.0);
        assert!(panda(CommandMode::Torque, None)
            .check_motion_effort()
            .is_ok());
    }

    #[test]
    fn a_joint_too_weak_for_the_motion_is_named_with_its_numbers() {
        // Joint 2 limited to 5 N·m, less than the motion needs (but not refused for holding the
        // start alone: that check is the generator's, in torque mode only).
        let weak = Some(vec![87.0, 5.0, 87.0, 87.0, 12.0, 12.0, 12.0]);
        for mode in [
            CommandMode::Position,
            CommandMode::Velocity,
            CommandMode::Torque,
        ] {
            let e = panda(mode, weak.clone()).check_motion_effort().unwrap_err();
            let m = e.to_string();
            assert!(
                m.starts_with("joint 2 (\"panda_joint2\") cannot carry the motion from this start")
                    && m.contains("its effort limit is 5.00 N·m"),
                "{m}"
            );
        }
        // The ideal arm's interface is not asked.
        assert!(panda(CommandMode::Acceleration, weak)
            .check_motion_effort()
            .is_ok());
    }
}
