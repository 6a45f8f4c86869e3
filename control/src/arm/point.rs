//! The motion of one point of an arm, in the plane (D = 2) or in space (D = 3): what the
//! barrier rows, the obstacle potential and the planners' clearance checks read, one type for
//! every arm so that each of them is written once.

use crate::basics::MAX_JOINTS;
use nalgebra::{SMatrix, SVector};

/// Position, Jacobian, velocity and drift (J̇q̇) of one point of the arm.
#[derive(Clone, Copy, Debug)]
pub struct PointMotion<const N: usize, const D: usize> {
    pub pos: SVector<f64, D>,
    pub jac: SMatrix<f64, D, N>,
    pub vel: SVector<f64, D>,
    pub drift: SVector<f64, D>,
}

impl<const N: usize, const D: usize> Default for PointMotion<N, D> {
    fn default() -> Self {
        Self {
            pos: SVector::zeros(),
            jac: SMatrix::zeros(),
            vel: SVector::zeros(),
            drift: SVector::zeros(),
        }
    }
}

/// The arm's N + 1 points P_0 … P_N (joints, then the end effector or tool point); link j runs
/// from P_j to P_(j+1).
pub type Points<const N: usize, const D: usize> = [PointMotion<N, D>; MAX_JOINTS + 1];

/// Where each link's capsule ends among an arm's points: a chain of N + 1 points whose link j
/// runs from point j to point j + 1 (the planar arm, and a robot's capsules about its joint
/// origins), or two rows of N whose link j runs from the first row's point j to the second's
/// (a robot's capsules with end points of their own, `robot.capsules`). The barrier rows, the
/// obstacle potential and the clearance read the links through this view, so both layouts share
/// every formula.
#[derive(Clone, Copy)]
pub struct Links<'a, const N: usize, const D: usize> {
    first: &'a Points<N, D>,
    /// None for a chain.
    second: Option<&'a Points<N, D>>,
}

impl<'a, const N: usize, const D: usize> Links<'a, N, D> {
    /// Link j from `points[j]` to `points[j + 1]`.
    pub fn chain(points: &'a Points<N, D>) -> Self {
        Self {
            first: points,
            second: None,
        }
    }

    /// Link j from `a[j]` to `b[j]`.
    pub fn pairs(a: &'a Points<N, D>, b: &'a Points<N, D>) -> Self {
        Self {
            first: a,
            second: Some(b),
        }
    }

    /// The indices of link j's two ends in [`Self::points`]' order.
    #[inline(always)]
    pub fn ends(&self, j: usize) -> (usize, usize) {
        match self.second {
            Some(_) => (j, N + j),
            None => (j, j + 1),
        }
    }

    /// Link j's two ends.
    #[inline(always)]
    pub fn link(&self, j: usize) -> (&'a PointMotion<N, D>, &'a PointMotion<N, D>) {
        match self.second {
            Some(b) => (&self.first[j], &b[j]),
            None => (&self.first[j], &self.first[j + 1]),
        }
    }

    /// The points the N links end on: N + 1 of a chain, then for pairs the N second ends.
    #[inline(always)]
    pub fn points(&self) -> impl Iterator<Item = &'a PointMotion<N, D>> {
        let (first, second): (usize, &'a [PointMotion<N, D>]) = match self.second {
            Some(b) => (N, &b[..N]),
            None => (N + 1, &[]),
        };
        self.first[..first].iter().chain(second)
    }
}
