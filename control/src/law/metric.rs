//! The joint-space metric the task's pseudo-inverse minimises.
//!
//! The minimum-norm pseudo-inverse J⁺ = Jᵀ(JJᵀ)⁻¹ shares the task among the joints as if a
//! radian (or a metre) cost the same on every joint. On an arm whose joints are alike that is
//! harmless; on a chain with a slow joint it is not: TIAGo's torso lift (0.07 m/s) under a
//! 7-joint arm (about 2 rad/s) is handed a share of the circle's vertical motion it cannot
//! follow, the command limiter holds it back on most ticks, and the tool leaves the path by
//! centimetres. Measuring each joint's motion against its own speed limit, |D⁻¹q̇| with
//! D = diag(q̇_max) / max q̇_max, gives the weighted least-norm inverse
//! J⁺_W = D (J D)⁺ (Whitney 1969; Chan & Dubey 1995), which leaves the task to the joints that
//! can carry it; its null-space projector I − J⁺_W J is oblique but still keeps the task.
//!
//! `law.metric = "auto"` (the default) takes the speed metric only where the limits differ
//! by more than [`AUTO_SPEED_RATIO`]×, so every arm whose joints are alike (the Panda, the
//! planar arm) keeps its minimum-norm law bit for bit. The safety filter keeps the orthogonal
//! projector: its smallest correction must stay in J's null space, which only the
//! minimum-norm inverse's projector spans ([`crate::safety::solve`]).

use crate::basics::{invalid, ConfigError, MAX_JOINTS};
use crate::resolve::damped_pinv_m;
use crate::safety::SafetyParams;
use nalgebra::SMatrix;

/// "auto" weights the joints when the fastest's speed limit is more than this many times the
/// slowest's (the Panda's are 1.2× apart, the 7-joint arms of `tests/own_robot.rs` at most 2.7×;
/// TIAGo's torso lift under its arm, 65×).
pub const AUTO_SPEED_RATIO: f64 = 4.0;

/// The metric's names, for messages.
pub const NAMES: &str = "\"auto\", \"identity\" or \"speed\"";

/// The joint weights D for `metric` on an arm of `n` joints with `safety`'s speed limits
/// (each limit over the largest, so the fastest joint weighs 1); None for the identity.
pub fn weights(
    metric: &str,
    safety: &SafetyParams,
    n: usize,
) -> Result<Option<[f64; MAX_JOINTS]>, ConfigError> {
    let qd = &safety.qd_max[..n];
    let limited = qd.iter().all(|v| v.is_finite() && *v > 0.0);
    let (lo, hi) = qd.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &v| {
        (lo.min(v), hi.max(v))
    });
    let speed = match metric {
        "identity" => false,
        "auto" => limited && hi > AUTO_SPEED_RATIO * lo,
        "speed" if limited => true,
        "speed" => return Err(invalid(
            "law.metric",
            metric,
            "\"identity\" or \"auto\": the speed metric needs a finite speed limit on every joint",
        )),
        _ => return Err(invalid("law.metric", metric, NAMES)),
    };
    Ok(speed.then(|| {
        let mut d = [1.0; MAX_JOINTS];
        for (di, v) in d.iter_mut().zip(qd) {
            *di = v / hi;
        }
        d
    }))
}

/// The damped weighted pseudo-inverse J⁺_W = D (J D)⁺ for weights `d` (the first N used), with
/// (J D)⁺ damped as [`damped_pinv_m`] damps J⁺; returns (J⁺_W, σ_min(J D), λ).
///
/// ```
/// use nalgebra::SMatrix;
/// // Two joints move the tool along x alike; the second is ten times slower.
/// let j = SMatrix::<f64, 1, 2>::new(1.0, 1.0);
/// let mut d = [1.0; control::MAX_JOINTS];
/// d[1] = 0.1;
/// let (p, _, _) = control::law::metric::damped_pinv_weighted(&j, &d, 0.05, 0.05);
/// assert!(((j * p)[(0, 0)] - 1.0).abs() < 1e-12); // the task is met
/// assert!(p[(1, 0)] < 0.011 * p[(0, 0)]); // and the slow joint takes 1 % of it
/// ```
#[inline]
pub fn damped_pinv_weighted<const N: usize, const M: usize>(
    j: &SMatrix<f64, M, N>,
    d: &[f64; MAX_JOINTS],
    threshold: f64,
    lambda_max: f64,
) -> (SMatrix<f64, N, M>, f64, f64) {
    let jd = SMatrix::<f64, M, N>::from_fn(|r, c| j[(r, c)] * d[c]);
    let (p, smin, lambda) = damped_pinv_m(&jd, threshold, lambda_max);
    (SMatrix::from_fn(|r, c| d[r] * p[(r, c)]), smin, lambda)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits(qd: &[f64]) -> SafetyParams {
        let mut s = SafetyParams::off();
        s.qd_max[..qd.len()].copy_from_slice(qd);
        s
    }

    #[test]
    fn auto_weights_only_joints_whose_limits_differ_by_more_than_the_ratio() {
        let panda = limits(&[2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61]);
        assert_eq!(weights("auto", &panda, 7).unwrap(), None);
        let torso = limits(&[0.07, 2.7, 2.7, 3.66, 3.66, 4.58, 4.58, 4.58]);
        let d = weights("auto", &torso, 8).unwrap().unwrap();
        assert!((d[0] - 0.07 / 4.58).abs() < 1e-15 && d[5] == 1.0 && d[8] == 1.0);
        assert!(weights("speed", &panda, 7).unwrap().is_some());
        assert_eq!(weights("identity", &torso, 8).unwrap(), None);
        let unlimited = limits(&[f64::INFINITY, 1.0, 2.0]);
        assert_eq!(weights("auto", &unlimited, 3).unwrap(), None);
        let e = weights("speed", &unlimited, 3).unwrap_err().to_string();
        assert!(e.contains("law.metric") && e.contains("speed limit"), "{e}");
        let e = weights("fast", &panda, 7).unwrap_err().to_string();
        assert!(e.contains("\"identity\""), "{e}");
    }

    #[test]
    fn the_weighted_inverse_meets_the_task_and_its_projector_keeps_it() {
        let j = SMatrix::<f64, 2, 4>::new(1.0, 0.3, -0.2, 0.5, 0.1, 1.0, 0.4, -0.7);
        let mut d = [1.0; MAX_JOINTS];
        d[0] = 0.05;
        let (p, _, lambda) = damped_pinv_weighted(&j, &d, 0.05, 0.05);
        assert_eq!(lambda, 0.0);
        assert!((j * p - SMatrix::<f64, 2, 2>::identity()).norm() < 1e-12);
        let v = SMatrix::<f64, 4, 1>::new(0.3, -1.0, 2.0, 0.5);
        assert!((j * (v - p * (j * v))).norm() < 1e-12);
        // With equal weights it is the minimum-norm inverse.
        let (p1, _, _) = damped_pinv_weighted(&j, &[0.5; MAX_JOINTS], 0.01, 0.05);
        let (p0, _, _) = damped_pinv_m(&j, 0.01, 0.05);
        assert!((p1 - p0).norm() < 1e-12);
    }
}
