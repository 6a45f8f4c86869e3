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

/// How a series was sampled and how its pairs are formed. A stroboscopic series of a periodic
/// system compares states at the same phase of the path only: a sample's neighbour is at the
/// same phase (an index a whole number of `phases` away) and at least `apart` samples away; the
/// pair's distance is followed over `horizon` samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sampling {
    /// Samples a period (1: one return a period).
    pub phases: usize,
    /// The least index distance between neighbours (a multiple of `phases` is the natural one).
    pub apart: usize,
    /// Steps the divergence is followed over (at most [`MAX_HORIZON`]), each `stride` samples:
    /// a whole period (`stride = phases`) steps over the stretching and folding inside a period,
    /// which a stable orbit has too.
    pub horizon: usize,
    pub stride: usize,
    /// Fewer samples than this give no estimate.
    pub min_samples: usize,
}

/// The longest horizon [`lyapunov_per_sample`] follows (its sums are a fixed array).
pub const MAX_HORIZON: usize = 16;

/// One return a period: [`HORIZON`], [`THEILER`], [`MIN_RETURNS`].
pub const ONCE_A_PERIOD: Sampling = Sampling {
    phases: 1,
    apart: THEILER + 1,
    horizon: HORIZON,
    stride: 1,
    min_samples: MIN_RETURNS,
};

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
    lyapunov_per_sample(returns, &ONCE_A_PERIOD)
}

/// λ per step of `stride` samples of a series sampled as `s` says (multiply by
/// `phases`/(`stride`·τ) for per second), or None as for [`lyapunov_per_step`].
pub fn lyapunov_per_sample<const D: usize>(samples: &[[f64; D]], s: &Sampling) -> Option<f64> {
    let n = samples.len();
    let h = s.horizon.clamp(1, MAX_HORIZON);
    let span = h * s.stride.max(1);
    if n < s.min_samples.max(span + 2) {
        return None;
    }
    let last = n - span; // a pair's successors must exist
    let mut sum = [0.0; MAX_HORIZON + 1];
    let mut pairs = 0usize;
    for i in 0..last {
        let Some(j) = nearest(samples, i, last, s) else {
            continue;
        };
        let mut logs = [0.0; MAX_HORIZON + 1];
        let ok = (0..=h).all(|k| {
            let d = distance(&samples[i + k * s.stride], &samples[j + k * s.stride]);
            logs[k] = d.ln();
            d > FLOOR && d.is_finite()
        });
        if ok {
            for (s, l) in sum.iter_mut().zip(logs).take(h + 1) {
                *s += l;
            }
            pairs += 1;
        }
    }
    (pairs > 0).then(|| {
        let mut mean = [0.0; MAX_HORIZON + 1];
        for (m, s) in mean.iter_mut().zip(sum).take(h + 1) {
            *m = s / pairs as f64;
        }
        slope(&mean[..=h])
    })
}

/// The index of the nearest other sample at the same phase among `0..last`, at least `apart`
/// away and at a non-zero distance.
fn nearest<const D: usize>(
    samples: &[[f64; D]],
    i: usize,
    last: usize,
    s: &Sampling,
) -> Option<usize> {
    let phases = s.phases.max(1);
    (i % phases..last)
        .step_by(phases)
        .filter(|&j| i.abs_diff(j) >= s.apart)
        .map(|j| (j, distance(&samples[i], &samples[j])))
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

    /// The logistic map at r = 4 (λ = ln 2 a step) seen at four phases of each step, each phase
    /// a different (scaled, shifted) picture of the same iterate.
    fn phased_logistic(steps: usize) -> Vec<[f64; 2]> {
        let mut x = 0.3;
        let mut out = Vec::new();
        for _ in 0..steps {
            x = 4.0 * x * (1.0 - x);
            for p in 0..4 {
                out.push([x * (1.0 + p as f64), p as f64]);
            }
        }
        out
    }

    #[test]
    fn phases_pool_pairs_at_the_same_phase_and_follow_them_a_period_at_a_time() {
        let s = Sampling {
            phases: 4,
            apart: 4,
            horizon: 2,
            stride: 4,
            min_samples: 16,
        };
        // 60 steps: a steady estimate. 6 steps: the few pairs of four phases still see growth.
        let l = lyapunov_per_sample(&phased_logistic(60), &s).unwrap();
        assert!((l - 2f64.ln()).abs() < 0.25, "{l}");
        assert!(lyapunov_per_sample(&phased_logistic(6), &s).unwrap() > 0.3);
        assert_eq!(lyapunov_per_sample(&phased_logistic(3), &s), None);
    }
}
