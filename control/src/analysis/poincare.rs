//! The stroboscopic Poincaré section and a classifier for what it shows.
//!
//! The arm is driven by a circle of period T, so sampling (q, q̇) at t = kT turns the flow into a
//! map: a period-p orbit is p points that repeat, quasi-periodic motion fills a closed curve, and
//! chaos scatters points over a fractal set.
//!
//! **The classification rule** (in this order; the first that applies wins):
//! 1. *Period-p* (p = 1..P): over the last W samples, every return distance
//!    |x_k − x_{k−p}| ≤ tol. The smallest such p is reported. Angles are compared modulo 2π.
//! 2. *Converging to period-p*: not yet within tol, but ln|x_k − x_{k−p}| falls linearly over the
//!    last half or the last quarter of the samples (least-squares slope < 0, a predicted drop of at
//!    least 10× over that stretch, R² ≥ 0.8), and the last return distance is already small
//!    (≤ `converge_max`, 1e-2). Stable orbits are approached geometrically; chaotic return
//!    distances do not line up like that for long, and a chaotic orbit that passes near a periodic
//!    one (stickiness) does not get close enough. A long transient (μ = 0.1 needs ~250 s from the paper's
//!    start) is thereby not mislabelled as quasi-periodic or chaotic.
//! 3. Otherwise the 0-1 test for chaos (Gottwald & Melbourne, SIAM J. Appl. Dyn. Syst. 8, 129-145,
//!    2009: the modified test with the correlation method, the median over 100 frequencies c in
//!    (π/5, 4π/5)) is applied to each velocity coordinate of the section; K is their median.
//!    K ≥ 0.5 is *irregular* (K → 1 for chaos), K < 0.5 *quasi-periodic* (K → 0 for regular
//!    motion). "Quasi-periodic" therefore means "bounded, regular, and not of period ≤ P within
//!    tol": it also covers periodic motion of period > P.
//!
//! With too few samples (fewer than `min_points`) the section is reported as too short instead of
//! being guessed at. The largest Lyapunov exponent, computed independently, is the cross-check:
//! λ > 0 should go with "irregular", λ ≈ 0 with "quasi-periodic", λ < 0 with "period-p".

use crate::basics::wrap_angle;
use serde::Serialize;
use std::f64::consts::PI;

/// Stroboscopic samples: `dim` coordinates per point, the first `angles` of which are angles.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Section {
    pub dim: usize,
    pub angles: usize,
    pub times: Vec<f64>,
    data: Vec<f64>,
}

impl Section {
    pub fn new(dim: usize, angles: usize) -> Self {
        assert!(angles <= dim && dim > 0, "bad section layout");
        Self {
            dim,
            angles,
            times: Vec::new(),
            data: Vec::new(),
        }
    }

    pub fn push(&mut self, t: f64, x: &[f64]) {
        assert_eq!(x.len(), self.dim, "section point of the wrong size");
        self.times.push(t);
        self.data.extend_from_slice(x);
    }

    pub fn len(&self) -> usize {
        self.times.len()
    }
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }
    pub fn point(&self, i: usize) -> &[f64] {
        &self.data[i * self.dim..(i + 1) * self.dim]
    }
    pub fn points(&self) -> impl Iterator<Item = &[f64]> {
        self.data.chunks_exact(self.dim)
    }
    /// Coordinate `c` of every point, in time order.
    pub fn coordinate(&self, c: usize) -> Vec<f64> {
        self.points().map(|p| p[c]).collect()
    }
    /// Euclidean distance with angle coordinates compared modulo 2π.
    pub fn distance(&self, a: &[f64], b: &[f64]) -> f64 {
        let mut d2 = 0.0;
        for c in 0..self.dim {
            let d = if c < self.angles {
                wrap_angle(b[c] - a[c])
            } else {
                b[c] - a[c]
            };
            d2 += d * d;
        }
        d2.sqrt()
    }

    /// |x_k − x_{k−p}| for k = p..len.
    pub fn return_distances(&self, p: usize) -> Vec<f64> {
        (p..self.len())
            .map(|k| self.distance(self.point(k - p), self.point(k)))
            .collect()
    }
}

/// Parameters of the classification rule (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ClassifyConfig {
    /// Largest period P tested.
    pub max_period: usize,
    /// Return-distance tolerance for "period-p".
    pub tol: f64,
    /// W: how many of the last samples must return within tol.
    pub window: usize,
    /// Largest last return distance that can count as "converging".
    pub converge_max: f64,
    /// K at or above which the 0-1 test calls the motion irregular.
    pub chaos_threshold: f64,
    /// Fewer samples than this are "too short".
    pub min_points: usize,
}

impl Default for ClassifyConfig {
    fn default() -> Self {
        Self {
            max_period: 8,
            tol: 1e-6,
            window: 20,
            converge_max: 1e-2,
            chaos_threshold: 0.5,
            min_points: 40,
        }
    }
}

/// What the section shows.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "class", rename_all = "kebab-case")]
pub enum Motion {
    /// Returns within tol after `period` samples; `residual` is the largest return distance.
    Periodic { period: usize, residual: f64 },
    /// Approaching a period-p orbit; the return distance shrinks by `contraction` per sample.
    Converging {
        period: usize,
        residual: f64,
        contraction: f64,
    },
    /// Regular (0-1 test K below the threshold) but not period ≤ P.
    QuasiPeriodic { k: f64 },
    /// Chaotic by the 0-1 test.
    Irregular { k: f64 },
    /// Not enough samples to judge.
    TooShort { points: usize },
}

impl Motion {
    /// A short human label: "period-1", "→ period-1", "quasi-periodic", "irregular".
    pub fn label(&self) -> String {
        match self {
            Motion::Periodic { period, .. } => format!("period-{period}"),
            Motion::Converging { period, .. } => format!("→ period-{period}"),
            Motion::QuasiPeriodic { .. } => "quasi-periodic".into(),
            Motion::Irregular { .. } => "irregular".into(),
            Motion::TooShort { .. } => "too short".into(),
        }
    }

    /// The period if the motion is (or converges to) period-p.
    pub fn period(&self) -> Option<usize> {
        match self {
            Motion::Periodic { period, .. } | Motion::Converging { period, .. } => Some(*period),
            _ => None,
        }
    }
}

/// The verdict and the evidence behind it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Classification {
    pub motion: Motion,
    /// max |x_k − x_{k−p}| over the last W samples, for p = 1..P.
    pub returns: Vec<f64>,
    /// The 0-1 test's K (None when a periodic verdict made it unnecessary).
    pub k: Option<f64>,
}

/// Classifies a section by the rule in the module docs.
pub fn classify(section: &Section, cfg: &ClassifyConfig) -> Classification {
    let m = section.len();
    let max_p = cfg.max_period.max(1);
    if m < cfg.min_points.max(max_p + 2) {
        return Classification {
            motion: Motion::TooShort { points: m },
            returns: Vec::new(),
            k: None,
        };
    }
    let window = cfg.window.max(1);
    let returns: Vec<f64> = (1..=max_p)
        .map(|p| {
            let d = section.return_distances(p);
            let w = window.min(d.len());
            d[d.len() - w..].iter().cloned().fold(0.0, f64::max)
        })
        .collect();
    if let Some((i, &r)) = returns.iter().enumerate().find(|(_, r)| **r <= cfg.tol) {
        return Classification {
            motion: Motion::Periodic {
                period: i + 1,
                residual: r,
            },
            returns,
            k: None,
        };
    }
    for p in 1..=max_p {
        let d = section.return_distances(p);
        // The last half catches slow contraction, the last quarter a late end of a chaotic transient.
        for n in [d.len() / 2, d.len() / 4] {
            let n = n.max(8).min(d.len());
            if let Some((slope, r2)) = log_slope(&d[d.len() - n..]) {
                let last = d[d.len() - 1];
                let drop = slope * (n - 1) as f64 <= -std::f64::consts::LN_10;
                if slope < 0.0 && drop && r2 >= 0.8 && last <= cfg.converge_max {
                    return Classification {
                        motion: Motion::Converging {
                            period: p,
                            residual: last,
                            contraction: slope.exp(),
                        },
                        returns,
                        k: None,
                    };
                }
            }
        }
    }
    let coords: Vec<usize> = if section.angles < section.dim {
        (section.angles..section.dim).collect()
    } else {
        (0..section.dim).collect()
    };
    let mut ks: Vec<f64> = coords
        .iter()
        .map(|&c| zero_one_k(&section.coordinate(c)))
        .filter(|k| k.is_finite())
        .collect();
    let k = median(&mut ks).unwrap_or(0.0);
    let motion = if k >= cfg.chaos_threshold {
        Motion::Irregular { k }
    } else {
        Motion::QuasiPeriodic { k }
    };
    Classification {
        motion,
        returns,
        k: Some(k),
    }
}

/// Least-squares slope of ln y against the index, and the fit's R². None if degenerate.
fn log_slope(y: &[f64]) -> Option<(f64, f64)> {
    let n = y.len();
    if n < 3 {
        return None;
    }
    let ly: Vec<f64> = y.iter().map(|v| v.max(1e-300).ln()).collect();
    let mx = (n - 1) as f64 / 2.0;
    let my = ly.iter().sum::<f64>() / n as f64;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (i, v) in ly.iter().enumerate() {
        let dx = i as f64 - mx;
        let dy = v - my;
        sxy += dx * dy;
        sxx += dx * dx;
        syy += dy * dy;
    }
    if sxx == 0.0 || syy == 0.0 || !syy.is_finite() {
        return None;
    }
    Some((sxy / sxx, sxy * sxy / (sxx * syy)))
}

fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

/// The 0-1 test for chaos on a scalar series: K ≈ 1 for chaotic, ≈ 0 for regular dynamics.
///
/// Gottwald & Melbourne (2009), modified mean square displacement D_c(n) = M_c(n) − V_osc(c, n)
/// with n ≤ N/10, K_c = corr(n, D_c(n)), K = median over c. The 100 values of c are evenly spaced
/// in (π/5, 4π/5), so the result is deterministic. NaN for fewer than 30 samples.
pub fn zero_one_k(phi: &[f64]) -> f64 {
    let n = phi.len();
    if n < 30 {
        return f64::NAN;
    }
    let ncut = n / 10;
    let mean = phi.iter().sum::<f64>() / n as f64;
    let count = 100;
    let mut kc = Vec::with_capacity(count);
    let mut p = vec![0.0; n + 1];
    let mut q = vec![0.0; n + 1];
    let mut d = vec![0.0; ncut];
    for i in 0..count {
        let c = PI / 5.0 + (i as f64 + 0.5) * (3.0 * PI / 5.0) / count as f64;
        for j in 0..n {
            let (s, co) = ((j + 1) as f64 * c).sin_cos();
            p[j + 1] = p[j] + phi[j] * co;
            q[j + 1] = q[j] + phi[j] * s;
        }
        let terms = n - ncut;
        for (m, dm) in d.iter_mut().enumerate() {
            let lag = m + 1;
            let mut acc = 0.0;
            for j in 1..=terms {
                let dp = p[j + lag] - p[j];
                let dq = q[j + lag] - q[j];
                acc += dp * dp + dq * dq;
            }
            let v_osc = mean * mean * (1.0 - (lag as f64 * c).cos()) / (1.0 - c.cos());
            *dm = acc / terms as f64 - v_osc;
        }
        kc.push(correlation_with_index(&d));
    }
    median(&mut kc).unwrap_or(f64::NAN)
}

/// Pearson correlation of (1, 2, …, n) with `y`; 0 if `y` is constant.
fn correlation_with_index(y: &[f64]) -> f64 {
    let n = y.len() as f64;
    let mx = (n + 1.0) / 2.0;
    let my = y.iter().sum::<f64>() / n;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (i, v) in y.iter().enumerate() {
        let dx = (i + 1) as f64 - mx;
        let dy = v - my;
        sxy += dx * dy;
        sxx += dx * dx;
        syy += dy * dy;
    }
    if syy <= 0.0 || !syy.is_finite() {
        return 0.0;
    }
    (sxy / (sxx * syy).sqrt()).clamp(-1.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn section_of(
        points: impl IntoIterator<Item = Vec<f64>>,
        dim: usize,
        angles: usize,
    ) -> Section {
        let mut s = Section::new(dim, angles);
        for (i, p) in points.into_iter().enumerate() {
            s.push(i as f64, &p);
        }
        s
    }

    fn logistic(n: usize) -> Vec<f64> {
        let mut x = 0.3;
        (0..n + 100)
            .map(|_| {
                x = 4.0 * x * (1.0 - x);
                x
            })
            .skip(100)
            .collect()
    }

    #[test]
    fn zero_one_test_separates_chaos_from_quasi_periodicity() {
        let chaos = zero_one_k(&logistic(300));
        assert!(chaos > 0.8, "logistic r = 4: K = {chaos}");
        let rho = (5f64.sqrt() - 1.0) / 2.0;
        let qp: Vec<f64> = (0..300)
            .map(|k| (2.0 * PI * rho * k as f64).cos() + 0.4 * (4.0 * PI * rho * k as f64).sin())
            .collect();
        let regular = zero_one_k(&qp);
        assert!(regular < 0.2, "irrational rotation: K = {regular}");
        assert!(zero_one_k(&qp[..20]).is_nan());
    }

    #[test]
    fn periodic_sections_get_their_period() {
        let cfg = ClassifyConfig::default();
        let p1 = section_of((0..100).map(|_| vec![0.3, 1.0]), 2, 1);
        let c = classify(&p1, &cfg);
        assert_eq!(
            c.motion,
            Motion::Periodic {
                period: 1,
                residual: 0.0
            }
        );
        // Period 2, with an angle that winds by 2π per sample (the same configuration).
        let p2 = section_of(
            (0..100).map(|k| {
                vec![
                    0.1 + 2.0 * PI * k as f64,
                    if k % 2 == 0 { 1.0 } else { -1.0 },
                ]
            }),
            2,
            1,
        );
        let c = classify(&p2, &cfg);
        assert!(
            matches!(c.motion, Motion::Periodic { period: 2, residual } if residual < 1e-9),
            "{c:?}"
        );
        assert!(c.returns[0] > 1.9);
        // The logistic map's superstable period-2 window would be period-2 too; r = 4 is not periodic.
        let chaos = section_of(logistic(200).into_iter().map(|x| vec![x]), 1, 0);
        assert!(matches!(
            classify(&chaos, &cfg).motion,
            Motion::Irregular { .. }
        ));
    }

    #[test]
    fn converging_and_quasi_periodic_and_short_sections() {
        let cfg = ClassifyConfig::default();
        let conv = section_of((0..80).map(|k| vec![1.0 + 0.5 * 0.85f64.powi(k)]), 1, 0);
        match classify(&conv, &cfg).motion {
            Motion::Converging {
                period: 1,
                contraction,
                ..
            } => assert!((contraction - 0.85).abs() < 1e-6),
            m => panic!("{m:?}"),
        }
        let rho = (5f64.sqrt() - 1.0) / 2.0;
        let circle = section_of(
            (0..300).map(|k| {
                let a = 2.0 * PI * rho * k as f64;
                vec![a.cos(), 2.0 * a.sin()]
            }),
            2,
            0,
        );
        assert!(matches!(
            classify(&circle, &cfg).motion,
            Motion::QuasiPeriodic { .. }
        ));
        let short = section_of((0..10).map(|_| vec![0.0]), 1, 0);
        assert_eq!(
            classify(&short, &cfg).motion,
            Motion::TooShort { points: 10 }
        );
    }
}
