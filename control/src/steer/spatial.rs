//! Steering a spatial arm onto its planned cycle: the planar [`crate::steer::Steer`]'s pull on
//! every joint, in a table as wide as the widest arm, so the law's parameter block stays one
//! `Copy` type whatever the arm.

use super::{Cycle, CycleTable};
use crate::arm::VecN;
use crate::basics::MAX_JOINTS;
use crate::safety::SafetyParams;
use nalgebra::SMatrix;

/// The share of a joint's acceleration limit the law with the pull may ask for.
pub const PULL_SHARE: f64 = 0.8;
/// The share of a joint's rate limit the pull closes in on the cycle at.
pub const APPROACH_SHARE: f64 = 0.2;

/// The planned cycle and the pull's gains (1/s², 1/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialSteer {
    pub cycle: CycleTable<MAX_JOINTS>,
    pub kp: f64,
    pub kd: f64,
}

impl SpatialSteer {
    /// The steering onto planned cycle `c` with a pull of natural frequency `hz`, critically
    /// damped.
    ///
    /// ```
    /// # use control::steer::{Cycle, SpatialSteer};
    /// let c = Cycle {
    ///     t0: 0.0, period: 2.0,
    ///     q: (0..8).map(|k| vec![0.1 * k as f64; 7]).collect(),
    ///     min_clearance: f64::INFINITY, max_rate: 0.0, filter_margin: f64::INFINITY,
    ///     unreachable: None, arm_off_path: false, detour: None,
    /// };
    /// let s = SpatialSteer::of(&c, 1.0).unwrap();
    /// assert!((s.cycle.sample(0.5).q[6] - 0.2).abs() < 1e-12); // the second phase's posture
    /// ```
    pub fn of(c: &Cycle, hz: f64) -> Result<Self, super::SteerError> {
        let w = std::f64::consts::TAU * hz;
        Ok(Self {
            cycle: CycleTable::new(c)?,
            kp: w * w,
            kd: 2.0 * w,
        })
    }

    /// The pull at task time `t` in the null space of the task rows `j`:
    /// (I − J⁺J)(q̈* + K_p(q* − q) + K_d(q̇* − q̇)), the cycle's acceleration fed forward.
    ///
    /// Two bounds make a cycle handed over far from the arm safe to reach, and leave the pull
    /// near the cycle as it is. The position error's pull is a closing speed K_p/K_d·(q* − q),
    /// capped at [`APPROACH_SHARE`] of each joint's rate limit: a fast self-motion drags the
    /// hand's drift J̇q̇ up with it, and the law's demand past the arm's limits. And the pull as
    /// a whole is scaled down (its direction kept) so that the law's `qdd` with it stays within
    /// [`PULL_SHARE`] of every acceleration limit, which the runaway guard would otherwise read
    /// as a runaway.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn pull<const N: usize, const M: usize>(
        &self,
        t: f64,
        q: &VecN<N>,
        qd: &VecN<N>,
        j: &SMatrix<f64, M, N>,
        jpinv: &SMatrix<f64, N, M>,
        qdd: &VecN<N>,
        limits: &SafetyParams,
    ) -> VecN<N> {
        let r = self.cycle.sample(t);
        let v = VecN::<N>::from_fn(|i, _| {
            let cap = APPROACH_SHARE * limits.qd_max[i];
            let closing = (self.kp / self.kd * (r.q[i] - q[i])).clamp(-cap, cap);
            r.qdd[i] + self.kd * (r.qd[i] + closing - qd[i])
        });
        let pull = v - jpinv * (j * v);
        let scale = (0..N)
            .map(|i| {
                let room = (PULL_SHARE * limits.qdd_max[i] - qdd[i].abs()).max(0.0);
                room / pull[i].abs()
            })
            .fold(1.0, f64::min);
        pull * scale
    }
}
