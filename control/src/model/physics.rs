//! Whether a chain's dynamics can carry what a torque-driven run asks of them.
//!
//! A URDF link without `<inertial>` weighs nothing. That is harmless for kinematics, but when a
//! movable joint moves no mass at all the mass matrix is singular: forward dynamics divide by
//! zero and every torque-driven simulation fills with NaN. An effort limit below the arm's own
//! gravity load means it cannot even hold its start posture. Both are asked here, at start-up,
//! so that the answer names the joint and the numbers instead of surfacing later as a NaN or a
//! runaway-guard FAULT.

use super::chain::Chain;
use super::fixed::{Model, VecN};
use crate::basics::PhysicsError;

impl Chain {
    /// The first joint that moves neither mass nor inertia (it and every body after it are
    /// empty), or `None`. `remedy` ends the message (", or …"; "" for none).
    ///
    /// ```
    /// # use control::model::{builtin, Chain};
    /// let mut chain = Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap();
    /// assert!(chain.massless_joint("").is_none());
    /// chain.joints[6].body = control::model::Body::EMPTY;
    /// let e = chain.massless_joint("").unwrap().to_string();
    /// assert!(e.starts_with("joint 7 (\"panda_joint7\") moves no mass or inertia"), "{e}");
    /// ```
    pub fn massless_joint(&self, remedy: &'static str) -> Option<PhysicsError> {
        let empty = |i: usize| {
            let b = &self.joints[i].body;
            b.mass == 0.0 && b.inertia.iter().all(|&x| x == 0.0)
        };
        let first = (0..self.dof()).find(|&i| (i..self.dof()).all(empty))?;
        let j = &self.joints[first];
        Some(PhysicsError::Massless {
            index: first + 1,
            joint: j.name.clone(),
            link: j.links.first().cloned().unwrap_or_default(),
            remedy,
        })
    }

    /// The unit of joint `i`'s effort (0-based): a force for a prismatic joint, else a torque.
    pub fn effort_unit(&self, i: usize) -> &'static str {
        if self.joints[i].kind.is_prismatic() {
            "N"
        } else {
            "N·m"
        }
    }

    /// The first joint whose effort limit (`tau_max`, the tighter of the URDF's and any
    /// table's) is below the gravity load of `model` (the arm as simulated, payload included)
    /// at posture `q`, or `None`.
    pub fn gravity_beyond_effort<const N: usize>(
        &self,
        model: &Model<N>,
        q: &VecN<N>,
        tau_max: &VecN<N>,
        remedy: &'static str,
    ) -> Option<PhysicsError> {
        let g = model.gravity_torques(q);
        let i = (0..N).find(|&i| g[i].abs() > tau_max[i])?;
        Some(PhysicsError::GravityBeyondEffort {
            index: i + 1,
            joint: self.joints[i].name.clone(),
            load: g[i].abs(),
            limit: tau_max[i],
            unit: self.effort_unit(i),
            remedy,
        })
    }
}
