//! Relaxing a posture cycle in the null space: every phase slides along its task's self-motion
//! manifold, pushed off the spheres and joint limits and pulled towards its neighbours, and is
//! put back on the path by a Newton step after each slide.
//!
//! The neighbours' pull is the cycle's discrete Laplacian, periodic: it closes the cycle (a
//! posture rolled once round the path does not come back to itself on a redundant arm) and
//! keeps the joint rates low. Only the null-space part of each push is taken, so the hand never
//! leaves its path by more than one Newton step's residual, and the last sweeps polish that to
//! rounding.

use super::SpatialProblem;
use crate::arm::spatial::SpatialKinematics;
use crate::arm::spatial::VecN;
use crate::plan::PlanSettings;
use crate::resolve::damped_pinv_m;
use crate::task::pose::orientation_error;
use crate::task::Vec3;
use nalgebra::{SMatrix, SVector};

/// Gradient step per unit cost, and the longest slide a phase makes in one sweep (rad).
const STEP: f64 = 0.2;
const MAX_SLIDE: f64 = 0.05;
/// Weight of a joint step beyond the rate bound (per rad²), and the share of the bound the
/// relaxation aims at (the check allows all of it).
const RATE_WEIGHT: f64 = 4.0;
const RATE_AIM: f64 = 0.9;
/// The damped pseudo-inverse's threshold and largest damping for the Newton steps.
const DAMP_THRESHOLD: f64 = 0.02;
const DAMP_MAX: f64 = 0.05;

/// The task error at time `t` of the posture whose kinematics `kin` holds: M = 3 rows of
/// position, or 6 with the orientation's rotation vector.
fn task_error<const N: usize, const M: usize>(
    p: &SpatialProblem<N>,
    t: f64,
    kin: &SpatialKinematics<N>,
) -> SVector<f64, M> {
    let target = p.law.task.at(t);
    let ep = target.p - kin.p;
    let eo = if M == 6 {
        orientation_error(&target.rot, &kin.rot)
    } else {
        Vec3::zeros()
    };
    SVector::<f64, M>::from_fn(|r, _| if r < 3 { ep[r] } else { eo[r - 3] })
}

impl<const N: usize> SpatialProblem<N> {
    /// The kinematics of posture `q` at rest.
    pub(super) fn kin(&self, q: &VecN<N>, kin: &mut SpatialKinematics<N>) {
        self.arm.kinematics(q, &VecN::<N>::zeros(), kin);
    }

    /// Newton steps q ← q + J⁺e onto the task at time `t`, at most `steps`, until |e| ≤ `tol`.
    /// Returns |e| after the last.
    pub(super) fn project<const M: usize>(
        &self,
        t: f64,
        q: &mut VecN<N>,
        steps: usize,
        tol: f64,
    ) -> f64 {
        let mut kin = SpatialKinematics::<N>::default();
        for _ in 0..steps {
            self.kin(q, &mut kin);
            let e = task_error::<N, M>(self, t, &kin);
            if e.norm() <= tol {
                return e.norm();
            }
            let j: SMatrix<f64, M, N> = kin.jac.fixed_rows::<M>(0).into_owned();
            let (jp, _, _) = damped_pinv_m(&j, DAMP_THRESHOLD, DAMP_MAX);
            *q += jp * e;
        }
        self.kin(q, &mut kin);
        task_error::<N, M>(self, t, &kin).norm()
    }

    /// The posture at each phase, rolled from `q0` at the first one by the smallest joint
    /// motion (Newton steps from the phase before); None when the path leaves the arm's reach.
    pub(super) fn roll_out<const M: usize>(
        &self,
        q0: &VecN<N>,
        phases: usize,
    ) -> Option<Vec<VecN<N>>> {
        let mut cycle = Vec::with_capacity(phases);
        let mut q = *q0;
        for k in 0..phases {
            if self.project::<M>(self.phase_time(k, phases), &mut q, 30, 1e-9) > 1e-6 {
                return None;
            }
            cycle.push(q);
        }
        Some(cycle)
    }

    /// Task time of phase `k` of `phases`.
    pub(super) fn phase_time(&self, k: usize, phases: usize) -> f64 {
        self.t0 + self.law.task.path.period * k as f64 / phases as f64
    }

    /// The gradient of the cost of joint steps to the neighbouring phases beyond the rate
    /// bound.
    fn rate_gradient(
        &self,
        q: &VecN<N>,
        prev: &VecN<N>,
        next: &VecN<N>,
        s: &PlanSettings,
        dt: f64,
    ) -> VecN<N> {
        VecN::<N>::from_fn(|i, _| {
            let allowed = RATE_AIM * self.rate_bound(s, i) * dt;
            [q[i] - prev[i], q[i] - next[i]]
                .iter()
                .map(|d| RATE_WEIGHT * (d.abs() - allowed).max(0.0) * d.signum())
                .sum()
        })
    }

    /// One Gauss–Seidel sweep over the cycle: each phase slides along its self-motion by the
    /// null-space part of the cost's gradient, then steps back onto the path.
    pub(super) fn sweep<const M: usize>(&self, cycle: &mut [VecN<N>], s: &PlanSettings) {
        let n = cycle.len();
        let need = self.law.core.safety.clearance + s.margin;
        let dt = self.law.task.path.period / n as f64;
        let mut kin = SpatialKinematics::<N>::default();
        for k in 0..n {
            let (prev, next) = (cycle[(k + n - 1) % n], cycle[(k + 1) % n]);
            let q = &mut cycle[k];
            self.kin(q, &mut kin);
            let g = (*q * 2.0 - prev - next)
                + self.cost_gradient(&kin, q, need, s.joint_margin)
                + self.rate_gradient(q, &prev, &next, s, dt);
            let j: SMatrix<f64, M, N> = kin.jac.fixed_rows::<M>(0).into_owned();
            let (jp, _, _) = damped_pinv_m(&j, DAMP_THRESHOLD, DAMP_MAX);
            let mut slide = -(g - jp * (j * g)) * STEP;
            let len = slide.amax();
            if len > MAX_SLIDE {
                slide *= MAX_SLIDE / len;
            }
            *q += slide;
            self.project::<M>(self.phase_time(k, n), q, 2, 1e-12);
        }
    }
}
