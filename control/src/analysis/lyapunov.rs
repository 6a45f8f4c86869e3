//! Benettin's method for the largest Lyapunov exponent, generic over the system.
//!
//! A reference trajectory and a copy displaced by d₀ run side by side. Every renormalisation
//! interval the separation d is measured, ln(d/d₀) is recorded, and the copy is pulled back along
//! the separation to distance d₀. The exponent is the recorded log growth summed over a window
//! divided by the window's length; its uncertainty comes from block averages (the window is cut
//! into contiguous blocks, each block gives its own exponent, and the standard error of their
//! mean is reported), which tolerates the serial correlation of successive growth factors.
//!
//! The driver knows nothing about arms: anything that implements [`Trajectory`] can be plugged in.
//! The tests run the logistic map, the Lorenz system, a linear ODE and a linear delay equation
//! through exactly this code, and the arm ([`super::ArmFlow`]) uses it unchanged.
//!
//! For a delay differential equation the state is the whole history segment on [t − τ, t], so the
//! perturbation and the renormalisation must act on the stored history too; otherwise the copy's
//! history keeps an unrenormalised separation and the estimate is biased. [`history_distance2`] and
//! [`rescale_history`] do that for a [`DelayLine`], with the norm of docs/science.md, "Measuring chaos":
//! norm² = |δq|² + |δq̇|² + mean over the stored history of |δq̇_hist|².

use crate::arm::VecN;
use crate::delay::DelayLine;
use serde::Serialize;

/// A trajectory of a deterministic system that Benettin's method can follow as a pair.
pub trait Trajectory: Clone {
    /// The current time (seconds for flows, iterations for maps).
    fn time(&self) -> f64;
    /// Advances to time `t` (nearest point of the system's own time grid). No-op if already there.
    fn advance_to(&mut self, t: f64);
    /// Whether every state variable is finite.
    fn is_finite(&self) -> bool;
    /// Squared distance to another trajectory of the same system, in the phase-space norm.
    fn distance2(&self, other: &Self) -> f64;
    /// `other ← self + factor · (other − self)`, for every state variable (history included).
    fn rescale(&self, other: &mut Self, factor: f64);
    /// A partner trajectory displaced from this one by a small amount of order `eps` along a
    /// fixed, generic direction. The driver normalises the separation afterwards. The partner
    /// need not carry observers (statistics, recorders) of the reference.
    fn perturbed(&self, eps: f64) -> Self;
}

/// Why an exponent could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LyapunovError {
    #[error("invalid Lyapunov set-up: {0}")]
    Invalid(String),
    #[error("the trajectory diverged (non-finite state) by t = {t}")]
    Diverged { t: f64 },
    #[error("the separation became {d} at t = {t}: the pair collapsed (d0 too small for the state's precision?)")]
    Degenerate { t: f64, d: f64 },
    #[error("the window {start}..{end} holds {intervals} complete renormalisation intervals; at least 4 are needed")]
    WindowTooShort {
        start: f64,
        end: f64,
        intervals: usize,
    },
}

/// ln(d(t1)/d₀) over one renormalisation interval [t0, t1].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Growth {
    pub t0: f64,
    pub t1: f64,
    pub log_growth: f64,
}

/// λ_max over a window, with its convergence estimate.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LyapunovEstimate {
    /// Σ ln(d/d₀) / Σ Δt over the window (1/time unit).
    pub lambda_max: f64,
    /// Standard error of λ from the spread of the block estimates.
    pub stderr: f64,
    /// The window actually averaged: from the first to the end of the last complete interval.
    pub window: [f64; 2],
    /// Renormalisation intervals in the window.
    pub intervals: usize,
    /// λ of each contiguous block, in time order (their drift shows whether λ has converged).
    pub blocks: Vec<f64>,
}

/// A reference/perturbed pair that renormalises as it advances.
#[derive(Clone, Debug)]
pub struct Benettin<S> {
    reference: S,
    perturbed: S,
    d0: f64,
    interval: f64,
    start: f64,
    renorms: u64,
    last_renorm_time: f64,
    growth: Vec<Growth>,
}

impl<S: Trajectory> Benettin<S> {
    /// Starts a pair at the reference's current time, with separation exactly `d0`, renormalising
    /// every `interval`.
    pub fn new(reference: S, d0: f64, interval: f64) -> Result<Self, LyapunovError> {
        if !(d0.is_finite() && d0 > 0.0) {
            return Err(LyapunovError::Invalid(format!(
                "d0 = {d0}: must be a finite number > 0"
            )));
        }
        if !(interval.is_finite() && interval > 0.0) {
            return Err(LyapunovError::Invalid(format!(
                "renormalisation interval {interval}: must be a finite number > 0"
            )));
        }
        let t = reference.time();
        let mut perturbed = reference.perturbed(d0);
        let d = reference.distance2(&perturbed).sqrt();
        if !(d.is_finite() && d > 0.0) {
            return Err(LyapunovError::Degenerate { t, d });
        }
        reference.rescale(&mut perturbed, d0 / d);
        Ok(Self {
            reference,
            perturbed,
            d0,
            interval,
            start: t,
            renorms: 0,
            last_renorm_time: t,
            growth: Vec::new(),
        })
    }

    pub fn reference(&self) -> &S {
        &self.reference
    }
    pub fn perturbed(&self) -> &S {
        &self.perturbed
    }
    pub fn into_reference(self) -> S {
        self.reference
    }
    pub fn growth(&self) -> &[Growth] {
        &self.growth
    }
    pub fn d0(&self) -> f64 {
        self.d0
    }
    pub fn interval(&self) -> f64 {
        self.interval
    }

    /// Advances both trajectories to `t`, renormalising at every interval boundary on the way.
    pub fn advance_to(&mut self, t: f64) -> Result<(), LyapunovError> {
        // Boundaries are start + k·interval, computed by multiplication so they never drift.
        let tol = 1e-9 * self.interval;
        loop {
            let next = self.start + (self.renorms + 1) as f64 * self.interval;
            if next > t + tol {
                break;
            }
            self.move_both(next)?;
            self.renormalise()?;
        }
        if t > self.reference.time() {
            self.move_both(t)?;
        }
        Ok(())
    }

    fn move_both(&mut self, t: f64) -> Result<(), LyapunovError> {
        self.reference.advance_to(t);
        self.perturbed.advance_to(t);
        if !(self.reference.is_finite() && self.perturbed.is_finite()) {
            return Err(LyapunovError::Diverged {
                t: self.reference.time(),
            });
        }
        Ok(())
    }

    fn renormalise(&mut self) -> Result<(), LyapunovError> {
        let t = self.reference.time();
        let d = self.reference.distance2(&self.perturbed).sqrt();
        if !(d.is_finite() && d > 0.0) {
            return Err(LyapunovError::Degenerate { t, d });
        }
        self.growth.push(Growth {
            t0: self.last_renorm_time,
            t1: t,
            log_growth: (d / self.d0).ln(),
        });
        self.reference.rescale(&mut self.perturbed, self.d0 / d);
        self.last_renorm_time = t;
        self.renorms += 1;
        Ok(())
    }

    /// λ_max averaged over the intervals lying inside `[start, end]`, with `blocks` blocks for the
    /// standard error (fewer if the window is short, never fewer than 2).
    pub fn estimate(
        &self,
        start: f64,
        end: f64,
        blocks: usize,
    ) -> Result<LyapunovEstimate, LyapunovError> {
        estimate(&self.growth, start, end, blocks)
    }
}

/// λ_max from recorded growth over `[start, end]`; see [`Benettin::estimate`].
pub fn estimate(
    growth: &[Growth],
    start: f64,
    end: f64,
    blocks: usize,
) -> Result<LyapunovEstimate, LyapunovError> {
    let eps = 1e-9 * (1.0 + start.abs().max(end.abs()));
    let inside: Vec<&Growth> = growth
        .iter()
        .filter(|g| g.t0 >= start - eps && g.t1 <= end + eps)
        .collect();
    let n = inside.len();
    if n < 4 {
        return Err(LyapunovError::WindowTooShort {
            start,
            end,
            intervals: n,
        });
    }
    let nb = blocks.clamp(2, n / 2);
    let rate = |gs: &[&Growth]| {
        let (sum, dur) = gs.iter().fold((0.0, 0.0), |(s, d), g| {
            (s + g.log_growth, d + (g.t1 - g.t0))
        });
        sum / dur
    };
    let lambda_max = rate(&inside);
    let block_values: Vec<f64> = (0..nb)
        .map(|b| rate(&inside[b * n / nb..(b + 1) * n / nb]))
        .collect();
    let mean = block_values.iter().sum::<f64>() / nb as f64;
    let var = block_values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (nb - 1) as f64;
    Ok(LyapunovEstimate {
        lambda_max,
        stderr: (var / nb as f64).sqrt(),
        window: [inside[0].t0, inside[n - 1].t1],
        intervals: n,
        blocks: block_values,
    })
}

/// Mean over the stored history segment of |δq̇_hist|² between two delay lines that have seen the
/// same number of pushes (so their slots hold the same grid times).
pub fn history_distance2<const N: usize>(reference: &DelayLine<N>, other: &DelayLine<N>) -> f64 {
    debug_assert_eq!(reference.len(), other.len(), "history pair out of step");
    let (a, b) = (reference.slots(), other.slots());
    let sum: f64 = a.iter().zip(b).map(|(x, y)| (y - x).norm_squared()).sum();
    sum / a.len() as f64
}

/// `other ← reference + factor · (other − reference)` for every stored sample and for the history
/// before the first sample (the line's initial value, read back as the sample at grid time −1).
pub fn rescale_history<const N: usize>(
    reference: &DelayLine<N>,
    other: &mut DelayLine<N>,
    factor: f64,
) {
    debug_assert_eq!(reference.len(), other.len(), "history pair out of step");
    let ref_initial = reference.sample(-1.0);
    let (slots, initial) = other.history_mut();
    for (y, x) in slots.iter_mut().zip(reference.slots()) {
        *y = x + (*y - x) * factor;
    }
    *initial = ref_initial + (*initial - ref_initial) * factor;
}

/// Adds `delta` to every stored sample and to the initial history.
pub fn shift_history<const N: usize>(line: &mut DelayLine<N>, delta: &VecN<N>) {
    let (slots, initial) = line.history_mut();
    for y in slots.iter_mut() {
        *y += delta;
    }
    *initial += delta;
}

/// A fixed, generic unit-scale direction of length `n` (all components distinct and non-zero), so
/// that the initial perturbation has a component along every direction of a generic system.
pub fn generic_direction(n: usize) -> impl Iterator<Item = f64> {
    (0..n).map(|i| 0.5 + 0.5 * ((i as f64 + 1.0) * 1.618_033_988_749_895).fract())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// x ↦ a x: λ = ln|a| exactly, a one-line check of the bookkeeping.
    #[derive(Clone)]
    struct Scale {
        a: f64,
        x: f64,
        n: u64,
    }
    impl Trajectory for Scale {
        fn time(&self) -> f64 {
            self.n as f64
        }
        fn advance_to(&mut self, t: f64) {
            while (self.n as f64) < t.round() {
                self.x *= self.a;
                self.n += 1;
            }
        }
        fn is_finite(&self) -> bool {
            self.x.is_finite()
        }
        fn distance2(&self, o: &Self) -> f64 {
            (self.x - o.x).powi(2)
        }
        fn rescale(&self, o: &mut Self, f: f64) {
            o.x = self.x + (o.x - self.x) * f;
        }
        fn perturbed(&self, eps: f64) -> Self {
            Self {
                x: self.x + eps,
                ..self.clone()
            }
        }
    }

    #[test]
    fn linear_map_gives_log_of_its_factor() {
        for a in [0.5, 3.0, -2.0] {
            // The reference sits at the fixed point 0 so large |a|^n cannot swamp d0 in rounding.
            let mut b = Benettin::new(Scale { a, x: 0.0, n: 0 }, 1e-8, 2.0).unwrap();
            b.advance_to(100.0).unwrap();
            let e = b.estimate(10.0, 100.0, 5).unwrap();
            assert!(
                (e.lambda_max - a.abs().ln()).abs() < 1e-12,
                "a = {a}: {e:?}"
            );
            assert!(e.stderr < 1e-12);
            assert_eq!(e.intervals, 45);
            assert_eq!(e.window, [10.0, 100.0]);
        }
    }

    #[test]
    fn short_window_and_bad_set_up_are_errors() {
        let mut b = Benettin::new(
            Scale {
                a: 2.0,
                x: 1.0,
                n: 0,
            },
            1e-8,
            1.0,
        )
        .unwrap();
        b.advance_to(10.0).unwrap();
        assert!(matches!(
            b.estimate(8.0, 10.0, 4),
            Err(LyapunovError::WindowTooShort { intervals: 2, .. })
        ));
        assert!(Benettin::new(
            Scale {
                a: 2.0,
                x: 1.0,
                n: 0
            },
            0.0,
            1.0
        )
        .is_err());
        assert!(Benettin::new(
            Scale {
                a: 2.0,
                x: 1.0,
                n: 0
            },
            1e-8,
            -1.0
        )
        .is_err());
        let mut zero = Benettin::new(
            Scale {
                a: 0.0,
                x: 1.0,
                n: 0,
            },
            1e-8,
            1.0,
        )
        .unwrap();
        assert!(matches!(
            zero.advance_to(3.0),
            Err(LyapunovError::Degenerate { .. })
        ));
    }

    #[test]
    fn history_rescaling_is_affine_about_the_reference() {
        use nalgebra::Vector2;
        let mut a = DelayLine::<2>::new(5.0, Vector2::new(1.0, 2.0));
        let mut b = a.clone();
        shift_history(&mut b, &Vector2::new(0.5, -0.5));
        for k in 0..3 {
            a.push(Vector2::new(k as f64, 0.0));
            b.push(Vector2::new(k as f64 + 2.0, 0.0));
        }
        // 3 slots differ by (2, 0), 4 unfilled slots by (0.5, −0.5): mean |δ|² = (12 + 2)/7.
        assert!((history_distance2(&a, &b) - 2.0).abs() < 1e-12);
        rescale_history(&a, &mut b, 0.25);
        assert!((history_distance2(&a, &b) - 2.0 / 16.0).abs() < 1e-12);
        assert!((b.sample(-1.0) - Vector2::new(1.125, 1.875)).norm() < 1e-12);
        assert!((b.sample(2.0) - Vector2::new(2.5, 0.0)).norm() < 1e-12);
    }
}
