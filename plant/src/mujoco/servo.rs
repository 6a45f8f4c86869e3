//! The joint servo's gains on MuJoCo's arm: each joint's natural frequency on the inertia it
//! meets, then no more than the physics step can hold.
//!
//! A gain set from the joint-space inertia's diagonal M_ii (as the rigid-body plant sets it)
//! assumes the other joints hold still; when they move with it, the joint meets only
//! 1/(M⁻¹)_ii, and on example-robot-data's Panda the servo then chattered at its torque limits
//! on every step. So the gains use 1/(M⁻¹)_ii, and are scaled down as a whole where the
//! coupled arm's fastest mode would still outrun the step: λ(M⁻¹K_d)·h ≤ 0.5 and
//! λ(M⁻¹K_p)·h² ≤ 0.1, the rigid-body plant's margins.

use mujoco_rs::mujoco_c::{mjData, mjModel, mj_fullM};
use nalgebra::DMatrix;

/// The inverse joint-space inertia (with armature) over `dofs` at the data's pose.
pub fn inverse_inertia(m: &mjModel, d: &mjData, dofs: &[usize]) -> DMatrix<f64> {
    let nv = m.nv as usize;
    let mut full = vec![0.0; nv * nv];
    // SAFETY: `full` has nv² entries; qM is current after a forward pass.
    unsafe { mj_fullM(m, d, full.as_mut_ptr()) };
    let whole = DMatrix::from_row_slice(nv, nv, &full);
    let inv = whole
        .try_inverse()
        .unwrap_or_else(|| DMatrix::identity(nv, nv));
    DMatrix::from_fn(dofs.len(), dofs.len(), |r, c| inv[(dofs[r], dofs[c])])
}

/// (K_p, K_d) per joint for natural frequency `w` (rad/s) and damping ratio `zeta` at step `h`.
pub fn gains(minv: &DMatrix<f64>, w: f64, zeta: f64, h: f64) -> (Vec<f64>, Vec<f64>) {
    let n = minv.nrows();
    let m_eff: Vec<f64> = (0..n).map(|i| 1.0 / minv[(i, i)].max(1e-12)).collect();
    let mut kp: Vec<f64> = m_eff.iter().map(|m| m * w * w).collect();
    let mut kd: Vec<f64> = m_eff.iter().map(|m| 2.0 * zeta * w * m).collect();
    let fastest = |k: &[f64]| {
        // The eigenvalues of M⁻¹K are those of K^½ M⁻¹ K^½, which is symmetric.
        let s = DMatrix::from_fn(n, n, |r, c| k[r].sqrt() * minv[(r, c)] * k[c].sqrt());
        s.symmetric_eigenvalues().max()
    };
    let ld = fastest(&kd) * h;
    if ld > 0.5 {
        kd.iter_mut().for_each(|k| *k *= 0.5 / ld);
    }
    let lp = fastest(&kp) * h * h;
    if lp > 0.1 {
        kp.iter_mut().for_each(|k| *k *= 0.1 / lp);
    }
    (kp, kd)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_coupled_light_joint_gets_the_gain_of_the_inertia_it_meets_and_no_more_than_the_step_holds()
    {
        // M = [[1, 0.9], [0.9, 1]]: each joint alone weighs 1, but moving with the other 0.19.
        let m = DMatrix::from_row_slice(2, 2, &[1.0, 0.9, 0.9, 1.0]);
        let minv = m.try_inverse().unwrap();
        let w = std::f64::consts::TAU * 50.0;
        let (kp, kd) = gains(&minv, w, 1.0, 1e-6);
        let m_eff = 1.0 / minv[(0, 0)];
        assert!((m_eff - 0.19).abs() < 1e-12);
        assert!((kp[0] - m_eff * w * w).abs() < 1e-6 && (kd[1] - 2.0 * w * m_eff).abs() < 1e-9);
        // At a coarse step the fastest coupled mode caps them.
        let h = 1e-3;
        let (kp, kd) = gains(&minv, w, 1.0, h);
        let fastest = |k: &[f64]| {
            let s = DMatrix::from_fn(2, 2, |r, c| k[r].sqrt() * minv[(r, c)] * k[c].sqrt());
            s.symmetric_eigenvalues().max()
        };
        assert!(fastest(&kd) * h <= 0.5 + 1e-12, "{kd:?}");
        assert!(fastest(&kp) * h * h <= 0.1 + 1e-12, "{kp:?}");
    }
}
