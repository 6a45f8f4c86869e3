//! The leading Floquet multipliers of the loop *with* its delayed feedback (docs/science.md,
//! "Stability of the controlled loop").
//!
//! With μ ≠ 0 the closed loop is a delay equation: its state at t is (q, q̇) and the q̇ history
//! over [t − τ, t]. On a period-T orbit the one-period map of that state has a derivative, the
//! monodromy operator, whose leading eigenvalues decide the orbit's stability and how fast the
//! feedback pulls the arm onto it (λ = ln|ρ| / T). Benettin's λ_max gives only the largest, from
//! a long average, and only for one μ at a time; the multipliers give the whole leading spectrum
//! from one period's linearisation.
//!
//! The operator is the simulation's own, discretised: the history is the delay line's stored
//! samples (the semi-discretisation of the history at the integrator's step, so the map is the
//! one the loop really runs and its spectrum converges to the delay equation's as dt shrinks).
//! That makes it large (2N + h·N with h = τ/dt, 14 014 for the Panda at 1 ms), so it is never
//! formed: Arnoldi's method needs only its products with vectors, each one period of the
//! simulation from a perturbed state (a forward difference). The leading multipliers of a
//! retarded delay equation are few and well separated from the rest, which accumulate at 0, so a
//! few dozen products give them.

use crate::basics::wrap_angle;
use crate::sim::{ClosedLoopLaw, Simulation};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// Why the multipliers could not be had.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FloquetError {
    /// The loop is not one whose period map this computes (the message says why).
    #[error("{0}")]
    Invalid(String),
    #[error("the trajectory diverged (non-finite state)")]
    Diverged,
}

/// How the leading multipliers are computed.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FloquetSpec {
    /// How many leading multipliers are wanted (and must have converged).
    pub count: usize,
    /// The most Arnoldi steps (period maps) spent.
    pub max_krylov: usize,
    /// Converged when no leading Ritz value moved by more than this over the last check.
    pub tol: f64,
    /// Size of the perturbation of a unit direction, for the forward difference.
    pub fd_step: f64,
}

impl Default for FloquetSpec {
    fn default() -> Self {
        Self {
            count: 6,
            max_krylov: 150,
            tol: 1e-6,
            fd_step: 1e-6,
        }
    }
}

/// The leading multipliers of the delayed loop's one-period map.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DelayMultipliers {
    /// Largest modulus first, as (re, im); complex ones come in conjugate pairs.
    pub multipliers: Vec<[f64; 2]>,
    /// ln|ρ₁| / T (1/s): the rate at which the slowest mode decays (< 0) or grows.
    pub exponent: f64,
    /// Dimension of the discretised state: 2N + h·N.
    pub dimension: usize,
    /// Arnoldi steps taken (one period of simulation each).
    pub krylov: usize,
    /// Largest move of a leading Ritz value over the last check: the accuracy reached.
    pub change: f64,
    pub converged: bool,
}

/// The leading multipliers of the loop `sim` runs, over the next `steps` steps (one period T =
/// steps · dt), linearised about the trajectory from where `sim` stands. For the orbit's
/// multipliers `sim` must stand on the orbit at a whole number of periods, with the feedback on
/// and at least τ of the orbit's own history in its delay line. μ is taken as it stands: a law
/// that adapts μ must not do so here.
pub fn delay_multipliers<const N: usize, L: ClosedLoopLaw<N>>(
    sim: &Simulation<N, L>,
    steps: u64,
    spec: &FloquetSpec,
) -> Result<DelayMultipliers, FloquetError> {
    let map = PeriodMap::new(sim, steps, spec.fd_step)?;
    let dim = map.dimension();
    let (ritz, krylov, change) = arnoldi(|v| map.derivative(v), dim, spec)?;
    let period = steps as f64 * sim.dt();
    let converged = change <= spec.tol;
    let multipliers: Vec<[f64; 2]> = ritz.into_iter().take(spec.count).collect();
    let exponent = multipliers
        .first()
        .map(|z| z[0].hypot(z[1]).ln() / period)
        .unwrap_or(f64::NAN);
    Ok(DelayMultipliers {
        multipliers,
        exponent,
        dimension: dim,
        krylov,
        change,
        converged,
    })
}

/// The measured counterpart of the leading multiplier: the rate (1/s) at which a small offset of
/// q̇ from the trajectory `sim` runs shrinks or grows, on the section x(kT), over `duration` s.
/// The slope of ln|δx(kT)| against t, fitted from the third period on (the fastest modes gone)
/// while the offset stays between round-off and the linear range. None when fewer than three
/// periods qualify.
pub fn section_rate<const N: usize, L: ClosedLoopLaw<N>>(
    sim: &Simulation<N, L>,
    steps: u64,
    duration: f64,
) -> Option<f64> {
    const START: f64 = 1e-6;
    // Below this the two runs differ by round-off as much as by the offset.
    const FLOOR: f64 = 1e-12;
    let (mut a, mut b) = (sim.clone(), sim.clone());
    let dir = start_vector(N);
    b.state_mut().qd += nalgebra::SVector::<f64, N>::from_fn(|i, _| dir[i] * START);
    let period = steps as f64 * sim.dt();
    let periods = (duration / period).floor().max(0.0) as u64;
    let mut points = Vec::new();
    for k in 1..=periods {
        for _ in 0..steps {
            a.step();
            b.step();
        }
        let (x, y) = (a.state(), b.state());
        let d = ((y.q - x.q).map(wrap_angle).norm_squared() + (y.qd - x.qd).norm_squared()).sqrt();
        if !(d > FLOOR && d < 1e-3) {
            break;
        }
        if k >= 3 {
            points.push((k as f64 * period, d.ln()));
        }
    }
    slope(&points)
}

/// Least-squares slope of (t, y), with at least three points.
fn slope(points: &[(f64, f64)]) -> Option<f64> {
    if points.len() < 3 {
        return None;
    }
    let n = points.len() as f64;
    let (mt, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), (t, y)| (a + t / n, b + y / n));
    let (num, den) = points.iter().fold((0.0, 0.0), |(a, b), (t, y)| {
        (a + (t - mt) * (y - my), b + (t - mt) * (t - mt))
    });
    Some(num / den)
}

/// The one-period map of the discretised delay state, about `base`'s trajectory.
struct PeriodMap<'a, const N: usize, L: ClosedLoopLaw<N>> {
    base: &'a Simulation<N, L>,
    steps: u64,
    /// History samples in the state: the grid indices k − h … k − 1 before the k-th step.
    h: usize,
    fd_step: f64,
    image: DVector<f64>,
}

impl<'a, const N: usize, L: ClosedLoopLaw<N>> PeriodMap<'a, N, L> {
    fn new(base: &'a Simulation<N, L>, steps: u64, fd_step: f64) -> Result<Self, FloquetError> {
        let fb = base.law.loop_feedback();
        if base.law.is_floating() {
            return Err(FloquetError::Invalid(
                "Floquet multipliers need the fixed-base model: the floating base's attitude \
                 drifts, so its motion does not close after one period"
                    .into(),
            ));
        }
        if !fb.delay_is_state {
            return Err(FloquetError::Invalid(
                "the delayed feedback is off (or μ = 0): the loop is an ordinary differential \
                 equation, whose multipliers `orbits` computes at μ = 0"
                    .into(),
            ));
        }
        if steps == 0 || !(fd_step > 0.0 && fd_step.is_finite()) {
            return Err(FloquetError::Invalid(format!(
                "one period must be at least one step ({steps}) and the difference step positive \
                 ({fd_step})"
            )));
        }
        // The RK4 stages of step k read q̇ at grid times k − τ/dt … k + 1 − τ/dt, interpolated:
        // the samples from ⌊k − τ/dt⌋ on (the newest, k, is pushed from the state itself).
        let h = ((fb.tau / base.dt()) - 1e-9).ceil().max(1.0) as usize;
        let k = base.step_index();
        let held = (k as usize) >= h && base.delay().stored(k - h as u64).is_some();
        if !held {
            return Err(FloquetError::Invalid(format!(
                "the delay line holds {} of the {h} samples of history the delayed loop's state \
                 needs: run at least τ + dt with the feedback's history first",
                base.delay().filled()
            )));
        }
        let mut map = Self {
            base,
            steps,
            h,
            fd_step,
            image: DVector::zeros(0),
        };
        map.image = map.run(None);
        if !map.image.iter().all(|v| v.is_finite()) {
            return Err(FloquetError::Diverged);
        }
        Ok(map)
    }

    fn dimension(&self) -> usize {
        (2 + self.h) * N
    }

    /// The state a period after `base` (perturbed by `by`, when given).
    fn run(&self, by: Option<&DVector<f64>>) -> DVector<f64> {
        let mut sim = self.base.clone();
        let k = sim.step_index();
        if let Some(v) = by {
            let x = sim.state_mut();
            for i in 0..N {
                x.q[i] += v[i];
                x.qd[i] += v[N + i];
            }
            for s in 0..self.h {
                let index = k - (self.h - s) as u64;
                let sample = sim.delay_mut().stored_mut(index).expect("checked in new");
                for i in 0..N {
                    sample[i] += v[(2 + s) * N + i];
                }
            }
        }
        for _ in 0..self.steps {
            sim.step();
        }
        self.read(&sim)
    }

    fn read(&self, sim: &Simulation<N, L>) -> DVector<f64> {
        let k = sim.step_index();
        let x = sim.state();
        let mut out = DVector::zeros(self.dimension());
        for i in 0..N {
            out[i] = x.q[i];
            out[N + i] = x.qd[i];
        }
        for s in 0..self.h {
            let index = k - (self.h - s) as u64;
            let sample = sim.delay().stored(index).unwrap_or(x.qd);
            for i in 0..N {
                out[(2 + s) * N + i] = sample[i];
            }
        }
        out
    }

    /// The monodromy operator applied to `v`, by a forward difference along it.
    fn derivative(&self, v: &DVector<f64>) -> DVector<f64> {
        let eps = self.fd_step / v.norm().max(f64::MIN_POSITIVE);
        let moved = self.run(Some(&(v * eps)));
        let mut d = (moved - &self.image) / eps;
        for i in 0..N {
            // Angles compared modulo 2π (the perturbation is tiny; this only guards a wrap).
            d[i] = wrap_angle(d[i] * eps) / eps;
        }
        d
    }
}

/// Arnoldi's method on `apply` (an operator on R^dim): the Ritz values of the Krylov space from a
/// fixed pseudo-random start, largest modulus first, with the steps taken and the last change.
fn arnoldi(
    apply: impl Fn(&DVector<f64>) -> DVector<f64>,
    dim: usize,
    spec: &FloquetSpec,
) -> Result<(Vec<[f64; 2]>, usize, f64), FloquetError> {
    let max = spec.max_krylov.min(dim).max(1);
    let mut basis: Vec<DVector<f64>> = vec![start_vector(dim)];
    let mut h = DMatrix::<f64>::zeros(max + 1, max);
    let mut previous: Vec<[f64; 2]> = Vec::new();
    let mut change = f64::INFINITY;
    for j in 0..max {
        let mut w = apply(&basis[j]);
        if !w.iter().all(|v| v.is_finite()) {
            return Err(FloquetError::Diverged);
        }
        // Modified Gram–Schmidt, twice: one pass loses orthogonality on a non-normal operator.
        for _ in 0..2 {
            for (i, b) in basis.iter().enumerate() {
                let c = b.dot(&w);
                h[(i, j)] += c;
                w.axpy(-c, b, 1.0);
            }
        }
        let beta = w.norm();
        h[(j + 1, j)] = beta;
        let m = j + 1;
        let exhausted = beta <= 1e-13 * h.view((0, 0), (m, m)).norm() || m == max;
        if m >= spec.count && (m % 5 == 0 || exhausted) {
            let ritz = multipliers(&h.view((0, 0), (m, m)).into_owned())?;
            if !previous.is_empty() {
                change = moved(&ritz[..spec.count.min(ritz.len())], &previous);
            }
            previous = ritz;
            if change <= spec.tol {
                return Ok((previous, m, change));
            }
        }
        if exhausted {
            if beta <= 1e-13 * h.view((0, 0), (m, m)).norm() {
                // An invariant subspace: its Ritz values are exact eigenvalues.
                change = 0.0;
            }
            return Ok((previous, m, change));
        }
        basis.push(w / beta);
    }
    Ok((previous, max, change))
}

/// A fixed, well-spread start (the same every run, so the result is reproducible).
fn start_vector(dim: usize) -> DVector<f64> {
    let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
    let v = DVector::from_fn(dim, |_, _| {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    });
    let n = v.norm();
    v / n
}

/// Floquet multipliers (the eigenvalues of a monodromy matrix), largest modulus first.
pub fn multipliers(m: &DMatrix<f64>) -> Result<Vec<[f64; 2]>, FloquetError> {
    if !m.iter().all(|v| v.is_finite()) {
        return Err(FloquetError::Diverged);
    }
    let mut ev: Vec<[f64; 2]> = m
        .complex_eigenvalues()
        .iter()
        .map(|c| [c.re, c.im])
        .collect();
    ev.sort_by(|a, b| b[0].hypot(b[1]).total_cmp(&a[0].hypot(a[1])));
    Ok(ev)
}

/// How far the values `now` lie from `before`: for each, the distance to the nearest of `before`
/// (so a reordering of equal moduli is no change).
fn moved(now: &[[f64; 2]], before: &[[f64; 2]]) -> f64 {
    now.iter()
        .map(|a| {
            before
                .iter()
                .map(|b| (a[0] - b[0]).hypot(a[1] - b[1]))
                .fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arnoldi_finds_the_leading_eigenvalues_of_a_known_operator() {
        // A block-diagonal operator: a rotation scaled by 0.9 (ρ = 0.9 e^{±0.3i}), then 0.7,
        // then a tail 0.5^k that accumulates at 0, as a delay equation's spectrum does.
        let dim = 60;
        let mut a = DMatrix::<f64>::zeros(dim, dim);
        let (c, s) = (0.9 * 0.3f64.cos(), 0.9 * 0.3f64.sin());
        a[(0, 0)] = c;
        a[(0, 1)] = -s;
        a[(1, 0)] = s;
        a[(1, 1)] = c;
        a[(2, 2)] = 0.7;
        for k in 3..dim {
            a[(k, k)] = 0.5f64.powi(k as i32 - 2);
            a[(k, k - 1)] = 0.3; // non-normal
        }
        let spec = FloquetSpec {
            count: 3,
            ..FloquetSpec::default()
        };
        let (ritz, krylov, change) = arnoldi(|v| &a * v, dim, &spec).unwrap();
        assert!(change <= 1e-6, "change {change} after {krylov}");
        assert!((ritz[0][0].hypot(ritz[0][1]) - 0.9).abs() < 1e-8);
        assert!((ritz[0][1].abs() - 0.9 * 0.3f64.sin()).abs() < 1e-8);
        assert!((ritz[2][0] - 0.7).abs() < 1e-8 && ritz[2][1].abs() < 1e-12);
    }

    #[test]
    fn moved_ignores_order_among_equal_moduli() {
        let a = [[0.0, 1.0], [0.0, -1.0]];
        let b = [[0.0, -1.0], [0.0, 1.0]];
        assert_eq!(moved(&a, &b), 0.0);
        assert!((moved(&[[0.5, 0.0]], &[[0.4, 0.0]]) - 0.1).abs() < 1e-15);
    }
}
