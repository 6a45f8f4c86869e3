//! The law's joint-space core, written once for every task dimension m (SCIENCE.md §2, §8).
//!
//! The planar law (m = 2), the position task (m = 3) and the pose task (m = 6) differ only in
//! how they build the task acceleration and the m×n Jacobian; what turns those into q̈ (the
//! damped pseudo-inverse, the null-space projection of the secondary task, the Pyragas term) is
//! here, generic over both sizes, on the stack. For m = 2 the pseudo-inverse keeps the closed
//! form of [`crate::law::damped_pinv`] bit for bit, so the paper's numbers do not move.

use crate::arm::{Jac, VecN};
use crate::law::{damped_pinv, Projection};
use nalgebra::{SMatrix, SVector};

/// J⁺ = Jᵀ(JJᵀ + λ²I)⁻¹ with λ² = (1 − (σ_min/ε)²) λ_max² below the threshold ε and 0 above it,
/// for an m×n Jacobian. Returns (J⁺, σ_min, λ); finite for every finite J when λ_max > 0.
///
/// ```
/// use nalgebra::SMatrix;
/// let j = SMatrix::<f64, 3, 7>::from_fn(|r, c| if r == c { 2.0 } else { 0.0 });
/// let (pinv, smin, lambda) = control::resolve::damped_pinv_m(&j, 0.05, 0.05);
/// assert!((smin - 2.0).abs() < 1e-12 && lambda == 0.0);
/// assert!(((j * pinv) - SMatrix::<f64, 3, 3>::identity()).norm() < 1e-12);
/// ```
#[inline]
pub fn damped_pinv_m<const N: usize, const M: usize>(
    j: &SMatrix<f64, M, N>,
    threshold: f64,
    lambda_max: f64,
) -> (SMatrix<f64, N, M>, f64, f64) {
    if M == 2 {
        let j2 = Jac::<N>::from_fn(|r, c| j[(r, c)]);
        let (p, s, l) = damped_pinv(&j2, threshold, lambda_max);
        return (SMatrix::from_fn(|r, c| p[(r, c)]), s, l);
    }
    let a = j * j.transpose();
    let smin = min_eigenvalue(a).max(0.0).sqrt();
    let mut lambda2 = 0.0;
    if smin < threshold {
        let r = smin / threshold;
        lambda2 = (1.0 - r * r) * lambda_max * lambda_max;
    }
    let m = a + SMatrix::<f64, M, M>::identity() * lambda2;
    let minv = match m.cholesky() {
        Some(c) => c.inverse(),
        None => m.try_inverse().unwrap_or_else(SMatrix::zeros),
    };
    (j.transpose() * minv, smin, lambda2.sqrt())
}

/// The smallest eigenvalue of a symmetric m×m matrix by cyclic Jacobi rotations: each sweep
/// zeroes every off-diagonal entry once, and a handful of sweeps reach machine precision for
/// the m ≤ 6 of a task (nalgebra's `SymmetricEigen` needs a dimension it can subtract one from,
/// which a const generic is not).
pub fn min_eigenvalue<const M: usize>(mut a: SMatrix<f64, M, M>) -> f64 {
    for _ in 0..12 {
        let off: f64 = (0..M)
            .flat_map(|p| (p + 1..M).map(move |q| (p, q)))
            .map(|(p, q)| a[(p, q)] * a[(p, q)])
            .sum();
        if off <= 1e-30 * (1.0 + a.diagonal().norm_squared()) {
            break;
        }
        for p in 0..M {
            for q in p + 1..M {
                let apq = a[(p, q)];
                if apq == 0.0 {
                    continue;
                }
                let theta = (a[(q, q)] - a[(p, p)]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..M {
                    let (akp, akq) = (a[(k, p)], a[(k, q)]);
                    a[(k, p)] = c * akp - s * akq;
                    a[(k, q)] = s * akp + c * akq;
                }
                for k in 0..M {
                    let (apk, aqk) = (a[(p, k)], a[(q, k)]);
                    a[(p, k)] = c * apk - s * aqk;
                    a[(q, k)] = s * apk + c * aqk;
                }
            }
        }
    }
    (0..M).map(|i| a[(i, i)]).fold(f64::INFINITY, f64::min)
}

/// What the law adds to the task motion J⁺ẍ in the null space and through the delayed term.
#[derive(Clone, Copy, Debug)]
pub struct NullTerms<const N: usize> {
    /// The secondary task's η (None: no secondary task).
    pub eta: Option<VecN<N>>,
    /// Its gain α.
    pub alpha: f64,
    /// q̇(t) − q̇(t − τ), and the gain μ when the feedback is on at this instant.
    pub diff: VecN<N>,
    pub mu: Option<f64>,
    pub projection: Projection,
}

/// q̈ = J⁺ẍ + α(I − J⁺J)η − μ P[q̇(t) − q̇(t − τ)], P = I or I − J⁺J. The projector is never
/// formed: (I − J⁺J)v = v − J⁺(Jv).
#[inline]
pub fn resolve<const N: usize, const M: usize>(
    j: &SMatrix<f64, M, N>,
    jpinv: &SMatrix<f64, N, M>,
    task_acc: &SVector<f64, M>,
    terms: &NullTerms<N>,
) -> VecN<N> {
    let mut qdd = jpinv * task_acc;
    if let Some(eta) = terms.eta {
        qdd += (eta - jpinv * (j * eta)) * terms.alpha;
    }
    if let Some(mu) = terms.mu {
        let diff = terms.diff;
        let term = match terms.projection {
            Projection::Full => diff,
            Projection::NullSpace => diff - jpinv * (j * diff),
        };
        qdd -= term * mu;
    }
    qdd
}
