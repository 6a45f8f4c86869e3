//! The law's joint-space core, written once for every task dimension m (docs/science.md, "The control law" and "Spatial arms").
//!
//! The planar law (m = 2), the position task (m = 3) and the pose task (m = 6) differ only in
//! how they build the task acceleration and the m×n Jacobian; what turns those into q̈ (the
//! damped pseudo-inverse, the null-space projection of the secondary task, the Pyragas term) is
//! here, generic over both sizes, on the stack. For m = 2 the pseudo-inverse keeps the closed
//! form of [`crate::resolve::damped_pinv`] bit for bit, so the paper's numbers do not move.

use crate::arm::{Jac, VecN};
use nalgebra::{Matrix2, SMatrix, SVector, Vector3};

type Vec3 = Vector3<f64>;

/// Where the Pyragas term acts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Projection {
    /// −μ[q̇(t) − q̇(t−τ)] on every joint (the paper's form).
    #[default]
    Full,
    /// −(I − J⁺J) μ[q̇(t) − q̇(t−τ)]: only the self-motion, so tracking is never disturbed.
    NullSpace,
}

/// The command and what the controller learnt while computing it.
#[derive(Clone, Copy, Debug)]
pub struct ControlOutput<const N: usize> {
    pub qdd: VecN<N>,
    /// The end effector (tool point) and its target, in the base frame (z = 0 in the plane).
    pub p: Vec3,
    pub p_desired: Vec3,
    /// |p_d − p| (m).
    pub tracking_error: f64,
    /// |log(R_d Rᵀ)| (rad) for a pose task; 0 otherwise.
    pub orientation_error: f64,
    pub sigma_min: f64,
    /// The damping λ used (0 away from singularities).
    pub damping: f64,
    /// Secondary-task value: w for manipulability, h for obstacles, 0 otherwise.
    pub secondary_value: f64,
    /// |q̇(t) − q̇(t − τ)|: the Pyragas residual, whether or not the feedback is on.
    pub period_residual: f64,
    /// |(I − J⁺J)(q̇(t) − q̇(t − τ))|: the residual's self-motion part.
    pub null_residual: f64,
    /// Obstacle clearance (m, negative: penetration); +∞ without obstacles.
    pub clearance: f64,
    /// Distance (rad) to the nearest joint position limit; +∞ without limits, negative beyond.
    pub joint_margin: f64,
    /// max_i |q̈_i| / qdd_max_i of the law's command *before* the filter: above 1 the law asks
    /// for more than the joints may do (the daemon's runaway guard watches it).
    pub demand: f64,
    /// Base attitude rate (floating model).
    pub base_rate: f64,
    pub flags: u32,
}

/// Smallest singular value of a 2×n matrix from the 2×2 Gram matrix.
#[inline]
fn sigma_min(a: &Matrix2<f64>) -> f64 {
    let m = 0.5 * (a[(0, 0)] + a[(1, 1)]);
    let d = 0.5 * (a[(0, 0)] - a[(1, 1)]);
    let r = (d * d + a[(0, 1)] * a[(0, 1)]).sqrt();
    (m - r).max(0.0).sqrt()
}

/// The damped pseudo-inverse J⁺ = Jᵀ(JJᵀ + λ²I)⁻¹ with λ² = (1 − (σ_min/ε)²) λ_max² below the
/// threshold ε and 0 above it. Returns (J⁺, σ_min, λ). Finite for every finite J when λ_max > 0.
#[inline]
pub fn damped_pinv<const N: usize>(
    j: &Jac<N>,
    threshold: f64,
    lambda_max: f64,
) -> (SMatrix<f64, N, 2>, f64, f64) {
    let a = j * j.transpose();
    let smin = sigma_min(&a);
    let mut lambda2 = 0.0;
    if smin < threshold {
        let r = smin / threshold;
        lambda2 = (1.0 - r * r) * lambda_max * lambda_max;
    }
    let m = a + Matrix2::identity() * lambda2;
    let det = m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)];
    let minv = Matrix2::new(m[(1, 1)], -m[(0, 1)], -m[(1, 0)], m[(0, 0)]) / det;
    (j.transpose() * minv, smin, lambda2.sqrt())
}

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
    damped_pinv_deciding(j, threshold, lambda_max, true)
}

/// [`damped_pinv_m`], where σ_min may be wanted only to decide the damping (`smin_wanted`
/// false, the law's command alone): for a 3-row task whose JJᵀ = A has det(A)/Σ(principal 2×2
/// minors) ≥ (1.01 ε)², a lower bound of its smallest eigenvalue (λ₁ = det/(λ₂λ₃) and λ₂λ₃ is
/// one of the minors' terms), σ_min is surely above the threshold, λ = 0, and the eigenvalue
/// itself (an `acos` and a `cos`) is not computed: σ_min comes back NaN. J⁺ and λ are
/// [`damped_pinv_m`]'s bit for bit either way.
///
/// ```
/// use nalgebra::SMatrix;
/// let j = SMatrix::<f64, 3, 7>::from_fn(|r, c| if r == c { 2.0 } else { 0.0 });
/// let (p, smin, l) = control::resolve::damped_pinv_deciding(&j, 0.05, 0.05, false);
/// assert!(smin.is_nan() && l == 0.0); // far from singular: only the decision was made
/// assert_eq!(p, control::resolve::damped_pinv_m(&j, 0.05, 0.05).0);
/// ```
#[inline]
pub fn damped_pinv_deciding<const N: usize, const M: usize>(
    j: &SMatrix<f64, M, N>,
    threshold: f64,
    lambda_max: f64,
    smin_wanted: bool,
) -> (SMatrix<f64, N, M>, f64, f64) {
    if M == 2 {
        let j2 = Jac::<N>::from_fn(|r, c| j[(r, c)]);
        let (p, s, l) = damped_pinv(&j2, threshold, lambda_max);
        return (SMatrix::from_fn(|r, c| p[(r, c)]), s, l);
    }
    let a = j * j.transpose();
    let a3 = || SMatrix::<f64, 3, 3>::from_fn(|r, c| a[(r, c)]);
    let smin = if M == 3 && !smin_wanted && surely_above(&a3(), threshold) {
        f64::NAN
    } else if M == 3 {
        min_eigenvalue_3(&a3()).max(0.0).sqrt()
    } else {
        min_eigenvalue(a).max(0.0).sqrt()
    };
    let mut lambda2 = 0.0;
    // A NaN σ_min (not computed: surely above) takes no damping, as one above the threshold.
    if smin < threshold {
        let r = smin / threshold;
        lambda2 = (1.0 - r * r) * lambda_max * lambda_max;
    }
    let m = a + SMatrix::<f64, M, M>::identity() * lambda2;
    // (JJᵀ + λ²I)⁻¹J, transposed: one triangular solve per column instead of an inverse.
    let solved = if M == 3 {
        let m3 = SMatrix::<f64, 3, 3>::from_fn(|r, c| m[(r, c)]);
        let j3 = SMatrix::<f64, 3, N>::from_fn(|r, c| j[(r, c)]);
        cholesky_solve_3(&m3, &j3).map(|x| SMatrix::<f64, M, N>::from_fn(|r, c| x[(r, c)]))
    } else {
        m.cholesky().map(|c| c.solve(j))
    };
    let pinv_t = match solved {
        Some(x) => x,
        None => m.try_inverse().map_or_else(SMatrix::zeros, |inv| inv * j),
    };
    (pinv_t.transpose(), smin, lambda2.sqrt())
}

/// `m⁻¹ b` for a symmetric positive definite 3×3 `m` by its Cholesky factor, None where
/// nalgebra's `cholesky()` is None (a zero, negative or NaN pivot). The operations are nalgebra
/// 0.35's `Cholesky::new` and `solve` in their order, written out for three rows (so the results
/// are the same to the bit, `cholesky_3_is_nalgebras_to_the_bit`): the generic code's views and
/// loops were 8 % of a Panda simulation for some 60 flops.
#[inline]
fn cholesky_solve_3<const N: usize>(
    m: &SMatrix<f64, 3, 3>,
    b: &SMatrix<f64, 3, N>,
) -> Option<SMatrix<f64, 3, N>> {
    // nalgebra's pivot: not zero, then `try_sqrt` (not negative, not NaN): together v > 0.
    let root = |v: f64| (v > 0.0).then(|| v.sqrt());
    let l00 = root(m[(0, 0)])?;
    let (l10, l20) = (m[(1, 0)] / l00, m[(2, 0)] / l00);
    let l11 = root(-l10 * l10 + m[(1, 1)])?;
    let l21 = (-l10 * l20 + m[(2, 1)]) / l11;
    let l22 = root(-l21 * l21 + (-l20 * l20 + m[(2, 2)]))?;
    let mut x = *b;
    for c in 0..N {
        // L y = b, then Lᵀ x = y, as nalgebra's axpy and dot compute them.
        let y0 = x[(0, c)] / l00;
        let b1 = -y0 * l10 + x[(1, c)];
        let b2 = -y0 * l20 + x[(2, c)];
        let y1 = b1 / l11;
        let y2 = (-y1 * l21 + b2) / l22;
        let x2 = (y2 - 0.0) / l22;
        let x1 = (y1 - (0.0 + l21 * x2)) / l11;
        let x0 = (y0 - ((0.0 + l10 * x1) + l20 * x2)) / l00;
        x[(0, c)] = x0;
        x[(1, c)] = x1;
        x[(2, c)] = x2;
    }
    Some(x)
}

/// Whether the symmetric positive semi-definite `a`'s smallest eigenvalue is surely above
/// `threshold`², with a margin of 1 % in σ for the rounding: det(a) / Σ(principal 2×2 minors)
/// bounds it from below. False when the bound cannot tell (a singular or indefinite `a`, NaN).
#[inline]
fn surely_above(a: &SMatrix<f64, 3, 3>, threshold: f64) -> bool {
    let m = |r: usize, c: usize| a[(r, r)] * a[(c, c)] - a[(r, c)] * a[(c, r)];
    let minors = m(0, 1) + m(0, 2) + m(1, 2);
    let det = a.determinant();
    det > 0.0 && minors > 0.0 && det >= minors * (1.0201 * threshold * threshold)
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

/// The smallest eigenvalue of a symmetric 3×3 matrix in closed form (the trigonometric solution
/// of the characteristic cubic): a tenth of the Jacobi sweeps' cost, accurate to ~1e-16·|A| in
/// absolute terms, which is all the damping's threshold test needs.
pub fn min_eigenvalue_3(a: &SMatrix<f64, 3, 3>) -> f64 {
    let p1 = a[(0, 1)].powi(2) + a[(0, 2)].powi(2) + a[(1, 2)].powi(2);
    let q = a.trace() / 3.0;
    let p2 = (a[(0, 0)] - q).powi(2) + (a[(1, 1)] - q).powi(2) + (a[(2, 2)] - q).powi(2) + 2.0 * p1;
    if p2 <= 1e-300 {
        return q;
    }
    let p = (p2 / 6.0).sqrt();
    let b = (a - SMatrix::<f64, 3, 3>::identity() * q) / p;
    let r = (0.5 * b.determinant()).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos()
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The written-out 3×3 Cholesky solve against nalgebra's, bit for bit, on J Jᵀ + λ²I of
    /// random 3×7 Jacobians from well conditioned to nearly singular (one row scaled down to
    /// 1e-9), undamped and damped, with ±0 and large entries; and None exactly where nalgebra's
    /// factorisation is None (a singular, an indefinite and a NaN matrix).
    #[test]
    fn cholesky_3_is_nalgebras_to_the_bit() {
        let mut rnd = crate::basics::rng::uniform(0xc401u64);
        for k in 0..20_000 {
            let mut j = SMatrix::<f64, 3, 7>::from_fn(|_, _| rnd() * 10f64.powf(2.0 * rnd()));
            let scale = [1.0, 1e-3, 1e-9][k % 3];
            for c in 0..7 {
                j[(2, c)] *= scale;
            }
            if k % 7 == 0 {
                j[(1, 3)] = -0.0;
            }
            let lambda2 = [0.0, 2.5e-3, 1e-12][(k / 3) % 3];
            let m = j * j.transpose() + SMatrix::<f64, 3, 3>::identity() * lambda2;
            let ours = cholesky_solve_3(&m, &j);
            let theirs = m.cholesky().map(|c| c.solve(&j));
            match (ours, theirs) {
                (Some(a), Some(b)) => {
                    for (x, y) in a.iter().zip(b.iter()) {
                        assert_eq!(x.to_bits(), y.to_bits(), "case {k}: {a} vs {b}");
                    }
                }
                (None, None) => {}
                (a, b) => panic!("case {k}: {a:?} vs {b:?}"),
            }
        }
        let b = SMatrix::<f64, 3, 7>::repeat(1.0);
        for m in [
            SMatrix::<f64, 3, 3>::zeros(),
            SMatrix::<f64, 3, 3>::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0),
            SMatrix::<f64, 3, 3>::repeat(f64::NAN),
        ] {
            assert!(cholesky_solve_3(&m, &b).is_none() && m.cholesky().is_none());
        }
    }

    /// On random 3×7 Jacobians, far from singular and within the damping band alike (one row
    /// scaled down to σ_min around the threshold), deciding without σ_min gives J⁺ and λ bit for
    /// bit, and skips σ_min only where it is above the threshold; it does skip it where J is well
    /// conditioned.
    #[test]
    fn deciding_the_damping_alone_changes_nothing_and_skips_only_above_the_threshold() {
        let mut rnd = crate::basics::rng::uniform(9u64);
        let (threshold, lambda_max) = (0.05, 0.05);
        let mut skipped = 0;
        for k in 0..5000 {
            let mut j = SMatrix::<f64, 3, 7>::from_fn(|_, _| rnd());
            let scale = [1.0, 0.1, 0.05, 0.03, 0.01][k % 5] * (1.0 + 0.5 * rnd());
            for c in 0..7 {
                j[(2, c)] = j[(1, c)] + scale * j[(2, c)];
            }
            let (p, smin, l) = damped_pinv_m(&j, threshold, lambda_max);
            let (pd, sd, ld) = damped_pinv_deciding(&j, threshold, lambda_max, false);
            assert_eq!(p, pd, "J⁺ differs at {k}");
            assert_eq!(l.to_bits(), ld.to_bits(), "λ differs at {k}");
            if sd.is_nan() {
                skipped += 1;
                assert!(
                    smin >= threshold,
                    "skipped σ_min = {smin} below the threshold"
                );
            } else {
                assert_eq!(sd.to_bits(), smin.to_bits());
            }
        }
        assert!(skipped > 1000, "σ_min skipped {skipped} times");
    }
}
