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
