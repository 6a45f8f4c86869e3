//! The 0–1 test for chaos (Gottwald & Melbourne 2009), on a scalar series.
//!
//! The series drives a random-walk-like translation (p_c, q_c) at frequency c; its mean-square
//! displacement grows linearly when the series is chaotic and stays bounded when it is regular.
//! K_c is the correlation of the displacement with time, K the median over many c (a single c can
//! resonate with a periodic series). The oscillating term is subtracted (their "modified" test),
//! which makes K converge with far fewer samples: what a monitor that must answer within minutes
//! needs.
//!
//! Noise also gives K ≈ 1: the test separates chaos from periodicity, not from noise.

use std::f64::consts::PI;

/// How many frequencies c the median is taken over.
pub const FREQUENCIES: usize = 100;
/// Fewer samples than this give no K.
pub const MIN_SAMPLES: usize = 32;

/// K ∈ [−1, 1] (≈ 1 chaotic, ≈ 0 regular) for `phi`, or None for fewer than [`MIN_SAMPLES`].
/// A series without variation is regular (K = 0). `scratch` is reused between calls.
///
/// ```
/// use control::monitor::zero_one::k_statistic;
/// let mut scratch = Vec::new();
/// let periodic: Vec<f64> = (0..400).map(|j| (j as f64 * 2.1).sin()).collect();
/// assert!(k_statistic(&periodic, &mut scratch).unwrap() < 0.2);
/// let mut x = 0.3;
/// let logistic: Vec<f64> = (0..400).map(|_| { x = 3.97 * x * (1.0 - x); x }).collect();
/// assert!(k_statistic(&logistic, &mut scratch).unwrap() > 0.8);
/// ```
pub fn k_statistic(phi: &[f64], scratch: &mut Vec<f64>) -> Option<f64> {
    let n = phi.len();
    if n < MIN_SAMPLES {
        return None;
    }
    let mean = phi.iter().sum::<f64>() / n as f64;
    let var = phi.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64;
    if !var.is_finite() {
        return None;
    }
    if var <= 1e-24 * (1.0 + mean * mean) {
        return Some(0.0); // no variation: regular
    }
    let ncut = (n / 10).max(4);
    let mut ks = [0.0; FREQUENCIES];
    for (i, k) in ks.iter_mut().enumerate() {
        // Evenly spread over (π/5, 4π/5), away from the resonant ends.
        let c = PI / 5.0 + (i as f64 + 0.5) * (3.0 * PI / 5.0) / FREQUENCIES as f64;
        *k = k_at(phi, mean, c, ncut, scratch);
    }
    ks.sort_by(f64::total_cmp);
    Some(0.5 * (ks[FREQUENCIES / 2 - 1] + ks[FREQUENCIES / 2]))
}

/// K_c: the correlation of the modified mean-square displacement D_c(m) with m = 1..=ncut.
fn k_at(phi: &[f64], mean: f64, c: f64, ncut: usize, scratch: &mut Vec<f64>) -> f64 {
    let n = phi.len();
    scratch.clear();
    let (mut p, mut q) = (0.0, 0.0);
    for (j, v) in phi.iter().enumerate() {
        let a = (j + 1) as f64 * c;
        p += v * a.cos();
        q += v * a.sin();
        scratch.push(p);
        scratch.push(q);
    }
    let usable = n - ncut;
    let (mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for m in 1..=ncut {
        let mut msd = 0.0;
        for j in 0..usable {
            let dp = scratch[2 * (j + m)] - scratch[2 * j];
            let dq = scratch[2 * (j + m) + 1] - scratch[2 * j + 1];
            msd += dp * dp + dq * dq;
        }
        let osc = mean * mean * (1.0 - (m as f64 * c).cos()) / (1.0 - c.cos());
        let d = msd / usable as f64 - osc;
        let x = m as f64;
        sx += x;
        sy += d;
        sxx += x * x;
        syy += d * d;
        sxy += x * d;
    }
    let k = ncut as f64;
    let cov = sxy / k - sx * sy / (k * k);
    let vx = sxx / k - (sx / k).powi(2);
    let vy = syy / k - (sy / k).powi(2);
    if vy <= 0.0 {
        return 0.0;
    }
    cov / (vx * vy).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_and_short_series() {
        let mut s = Vec::new();
        assert_eq!(k_statistic(&[1.0; 10], &mut s), None);
        assert_eq!(k_statistic(&[0.7; 100], &mut s), Some(0.0));
        assert_eq!(k_statistic(&[f64::NAN; 100], &mut s), None);
    }

    #[test]
    fn quasi_periodic_is_regular_and_logistic_chaos_is_not() {
        let mut s = Vec::new();
        let quasi: Vec<f64> = (0..300)
            .map(|j| (j as f64 * 1.0).sin() + 0.5 * (j as f64 * 2f64.sqrt()).cos())
            .collect();
        let k = k_statistic(&quasi, &mut s).unwrap();
        assert!(k < 0.3, "quasi-periodic K = {k}");
        let mut x = 0.4;
        let chaos: Vec<f64> = (0..128)
            .map(|_| {
                x = 4.0 * x * (1.0 - x);
                x
            })
            .collect();
        let k = k_statistic(&chaos, &mut s).unwrap();
        assert!(k > 0.7, "logistic K = {k}");
    }
}
