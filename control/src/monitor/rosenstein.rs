//! The largest Lyapunov exponent from a short series of returns (Rosenstein, Collins & De Luca
//! 1993).
//!
//! Benettin's method ([`crate::analysis::lyapunov`]) needs a model to run a perturbed copy; a
//! monitor watching a real arm has only what the arm did. Rosenstein's method pairs each return
//! with its nearest neighbour among the others (not its own temporal neighbours), follows how far
//! apart the two pairs' successors drift over a few steps, and fits the mean log distance against
//! the step: the slope is λ per return. Robust with a few dozen points, which is what a window of
//! once-per-period returns holds.

/// Steps the divergence is followed over.
pub const HORIZON: usize = 4;
/// Returns at most this far apart in time are not neighbours.
pub const THEILER: usize = 2;
/// Fewer returns than this give no estimate.
pub const MIN_RETURNS: usize = 12;
/// Distances below this are round-off, not dynamics: an arm on its orbit returns to within
/// 1e-13 of itself, and the log of such distances is noise. Pairs that come this close are left
/// out (all of them: no estimate, the residual judges).
pub const FLOOR: f64 = 1e-10;

/// λ per return (multiply by 1/τ for per second), or None with too few returns or no pair
/// farther apart than [`FLOOR`] (every return the same: a fixed point, judged by the residual instead).
/// `returns` are equal-length state vectors, oldest first.
///
/// ```
/// use control::monitor::rosenstein::lyapunov_per_step;
/// // The logistic map at r = 4 has λ = ln 2 per step.
/// let mut x = 0.3;
/// let r: Vec<[f64; 1]> = (0..200).map(|_| { x = 4.0 * x * (1.0 - x); [x] }).collect();
/// let l = lyapunov_per_step(&r).unwrap();
/// assert!((l - 2f64.ln()).abs() < 0.25, "{l}");
/// ```
pub fn lyapunov_per_step<const D: usize>(returns: &[[f64; D]]) -> Option<f64> {
    let n = returns.len();
    if n < MIN_RETURNS {
        return None;
    }
    let last = n - HORIZON; // a pair's successors must exist
    let mut sum = [0.0; HORIZON + 1];
    let mut pairs = 0usize;
    for i in 0..last {
        let Some(j) = nearest(returns, i, last) else {
            continue;
        };
        let mut logs = [0.0; HORIZON + 1];
        let ok = (0..=HORIZON).all(|k| {
            let d = distance(&returns[i + k], &returns[j + k]);
            logs[k] = d.ln();
            d > FLOOR && d.is_finite()
        });
        if ok {
            for (s, l) in sum.iter_mut().zip(logs) {
                *s += l;
            }
            pairs += 1;
        }
    }
    (pairs > 0).then(|| slope(&sum.map(|s| s / pairs as f64)))
}

/// The index of the nearest other return among `0..last`, at a non-zero distance.
fn nearest<const D: usize>(returns: &[[f64; D]], i: usize, last: usize) -> Option<usize> {
    (0..last)
        .filter(|&j| i.abs_diff(j) > THEILER)
        .map(|j| (j, distance(&returns[i], &returns[j])))
        .filter(|&(_, d)| d > FLOOR)
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(j, _)| j)
}

fn distance<const D: usize>(a: &[f64; D], b: &[f64; D]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

/// Least-squares slope of y against its index.
fn slope(y: &[f64]) -> f64 {
    let n = y.len() as f64;
    let mx = (n - 1.0) / 2.0;
    let my = y.iter().sum::<f64>() / n;
    let (mut num, mut den) = (0.0, 0.0);
    for (k, v) in y.iter().enumerate() {
        let dx = k as f64 - mx;
        num += dx * (v - my);
        den += dx * dx;
    }
    num / den
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contraction_is_negative_and_too_few_is_none() {
        // A spiral into a fixed point: every distance shrinks by 0.8 a step.
        let r: Vec<[f64; 2]> = (0..40)
            .map(|k| {
                let (a, s) = (k as f64, 0.8f64.powi(k));
                [s * a.cos(), s * a.sin()]
            })
            .collect();
        let l = lyapunov_per_step(&r).unwrap();
        assert!((l - 0.8f64.ln()).abs() < 1e-9, "{l}");
        assert_eq!(lyapunov_per_step(&r[..5]), None);
        assert_eq!(lyapunov_per_step(&[[1.0, 2.0]; 30]), None);
    }
}
