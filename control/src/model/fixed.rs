//! The chain as fixed-size arrays, for the per-tick algorithms.
//!
//! A [`Chain`] keeps names and vectors for people; a [`Model`] keeps only what the recursions
//! read, in arrays sized by the joint count as a type, so that every loop is unrolled and every
//! buffer lives on the stack (pinocchio's `Model`, with its size in the type).

use super::chain::{Body, Chain};
use super::pose::Pose;
use super::ModelError;
use nalgebra::{Matrix3, SVector, Vector3};

pub type VecN<const N: usize> = SVector<f64, N>;

/// What the kinematics and dynamics read of a chain, sized for `N` joints.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Model<const N: usize> {
    /// Joint i translates (else it rotates), along or about its frame's z.
    pub prismatic: [bool; N],
    /// Joint i's frame in body i−1's frame (the base's for i = 0).
    pub placement: [Pose; N],
    /// Body i in joint i's frame.
    pub body: [Body; N],
    /// The tip in body N−1's frame.
    pub tip: Pose,
    /// Gravity in the base frame.
    pub gravity: Vector3<f64>,
    /// How joint i's frame was turned to put its axis on z (see [`Frames::link`]).
    pub turn: [Matrix3<f64>; N],
}

impl Chain {
    /// The fixed-size model; `N` must be [`Chain::dof`].
    ///
    /// ```
    /// # use control::model::{builtin, Chain};
    /// let chain = Chain::from_urdf(builtin("planar3").unwrap(), None, None).unwrap();
    /// assert!(chain.model::<3>().is_ok());
    /// assert!(chain.model::<7>().is_err());
    /// ```
    pub fn model<const N: usize>(&self) -> Result<Model<N>, ModelError> {
        if self.dof() != N {
            return Err(ModelError::Dof {
                chain: self.dof(),
                asked: N,
            });
        }
        Ok(Model {
            prismatic: std::array::from_fn(|i| self.joints[i].kind.is_prismatic()),
            placement: std::array::from_fn(|i| self.joints[i].placement),
            body: std::array::from_fn(|i| self.joints[i].body),
            tip: self.tip_placement,
            gravity: self.gravity,
            turn: std::array::from_fn(|i| self.joints[i].turn),
        })
    }
}

/// Every body frame and the tip, in the base frame, at one configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frames<const N: usize> {
    pub body: [Pose; N],
    pub tip: Pose,
}

impl<const N: usize> Default for Frames<N> {
    fn default() -> Self {
        Self {
            body: [Pose::IDENTITY; N],
            tip: Pose::IDENTITY,
        }
    }
}

impl<const N: usize> Frames<N> {
    /// Joint i's child link frame as the URDF defines it (pinocchio's joint frame). The body
    /// frames share its origin but are turned so that the joint axis is z.
    pub fn link(&self, model: &Model<N>, i: usize) -> Pose {
        Pose {
            rot: self.body[i].rot * model.turn[i].transpose(),
            pos: self.body[i].pos,
        }
    }
}

impl<const N: usize> Model<N> {
    /// Forward kinematics: the pose of every body frame (joint i's frame moved by q_i) and of
    /// the tip. Joint i's axis in the base frame is `out.body[i].rot` column 2 and its origin
    /// `out.body[i].pos`.
    #[inline]
    pub fn frames(&self, q: &VecN<N>, out: &mut Frames<N>) {
        let sines = self.sines(q);
        let mut pose = Pose::IDENTITY;
        for i in 0..N {
            pose = self.body_pose(i, &pose, q[i], sines[i]);
            out.body[i] = pose;
        }
        out.tip = pose.then(&self.tip);
    }

    /// Body i's frame from body i−1's (`parent`; the base's, the identity, for i = 0): one step
    /// of [`Model::frames`], for the recursions that need each pose only once. `sc` is
    /// `sin_cos(q_i)` (unused for a prismatic joint), from [`Model::sines`].
    #[inline(always)]
    pub fn body_pose(&self, i: usize, parent: &Pose, qi: f64, sc: (f64, f64)) -> Pose {
        let pl = &self.placement[i];
        let mut f = if i == 0 { *pl } else { parent.then(pl) };
        if self.prismatic[i] {
            f.pos += f.rot.column(2) * qi;
        } else {
            rotate_about_z(&mut f, sc);
        }
        f
    }

    /// `sin_cos(q_i)` of every joint, for [`Model::body_pose`]. Taken all at once before the
    /// poses: seven independent calls the processor runs side by side, where one call per step
    /// of the chain of poses made each wait for the last (CRBA 11 % faster, bit for bit the
    /// same; the sines are a quarter of its time).
    #[inline(always)]
    pub fn sines(&self, q: &VecN<N>) -> [(f64, f64); N] {
        std::array::from_fn(|i| q[i].sin_cos())
    }
}

/// `f · Rz(angle)` from the angle's (sin, cos): only the first two columns change.
#[inline(always)]
fn rotate_about_z(f: &mut Pose, (s, c): (f64, f64)) {
    let c0 = f.rot.column(0).into_owned();
    let c1 = f.rot.column(1).into_owned();
    f.rot.set_column(0, &(c0 * c + c1 * s));
    f.rot.set_column(1, &(c1 * c - c0 * s));
}
