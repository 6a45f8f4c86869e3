//! The planned cycle as the loop reads it: a fixed-size, `Copy` table of postures, evaluated as
//! a periodic cubic spline.
//!
//! Steering needs the cycle's acceleration, not only its posture: a pull that only chases a
//! posture lags behind a cycle that sweeps at several rad/s, and a lagging arm rides the safety
//! filter's barrier instead of the cycle the planner checked. Straight lines between the phases
//! have no acceleration to feed forward (and an infinite one at each phase), so the table is a
//! uniform cubic B-spline that passes through every planned posture: C² and periodic, with its
//! rate and acceleration in closed form. The spline is fitted off the loop, once; evaluating it
//! reads four control points.

use super::SteerError;
use crate::basics::wrap_angle;

/// The most phases a cycle handed to the loop may have.
pub const MAX_PHASES: usize = 64;

/// A cycle of `N` joints in a fixed-size, `Copy` table: what the control law steers towards
/// (`N` = 3 on the planar arm, [`crate::basics::MAX_JOINTS`] on a spatial one, whose unused
/// joints stay zero). Built off the loop from a [`super::Cycle`]; read on the loop without
/// allocating.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CycleTable<const N: usize = 3> {
    pub t0: f64,
    pub period: f64,
    n: usize,
    /// The planned postures, one per phase (a recording keeps these).
    q: [[f64; N]; MAX_PHASES],
    /// The spline's control points, less the ramp `turns · k / n` (periodic).
    c: [[f64; N]; MAX_PHASES],
    /// Whole turns each joint makes once round the cycle (rad: a multiple of 2π).
    turns: [f64; N],
}

/// The uniform cubic B-spline's four weights at `u` ∈ [0, 1) of a span, and their first and
/// second derivatives in `u`.
#[inline]
pub(super) fn basis(u: f64) -> ([f64; 4], [f64; 4], [f64; 4]) {
    let (u2, u3, v) = (u * u, u * u * u, 1.0 - u);
    (
        [
            v * v * v / 6.0,
            (3.0 * u3 - 6.0 * u2 + 4.0) / 6.0,
            (-3.0 * u3 + 3.0 * u2 + 3.0 * u + 1.0) / 6.0,
            u3 / 6.0,
        ],
        [
            -v * v / 2.0,
            (3.0 * u2 - 4.0 * u) / 2.0,
            (-3.0 * u2 + 2.0 * u + 1.0) / 2.0,
            u2 / 2.0,
        ],
        [v, 3.0 * u - 2.0, -3.0 * u + 1.0, u],
    )
}

/// The planned posture, rate and acceleration at one task time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample<const N: usize = 3> {
    pub q: [f64; N],
    pub qd: [f64; N],
    pub qdd: [f64; N],
}

impl<const N: usize> CycleTable<N> {
    /// The table of a cycle of at most [`MAX_PHASES`] phases and at most `N` joints (the
    /// joints past the cycle's stay zero).
    pub fn new(c: &super::Cycle) -> Result<Self, SteerError> {
        let joints = c.q.first().map_or(0, Vec::len);
        let bad = c.q.iter().any(|q| q.len() != joints) || joints == 0 || joints > N;
        if c.q.is_empty() || c.q.len() > MAX_PHASES || bad {
            return Err(SteerError::CycleShape {
                max_phases: MAX_PHASES,
                max_joints: N,
                phases: c.q.len(),
                joints,
            });
        }
        let rows: Vec<[f64; N]> =
            c.q.iter()
                .map(|p| std::array::from_fn(|i| p.get(i).copied().unwrap_or(0.0)))
                .collect();
        Self::from_rows(c.t0, c.period, &rows)
    }

    /// The table of `rows` postures (as [`Self::rows`] gives them back: a recording's copy).
    pub fn from_rows(t0: f64, period: f64, rows: &[[f64; N]]) -> Result<Self, SteerError> {
        let n = rows.len();
        if n == 0 || n > MAX_PHASES {
            return Err(SteerError::Phases {
                max_phases: MAX_PHASES,
                phases: n,
            });
        }
        let mut q = [[0.0; N]; MAX_PHASES];
        // Unwrapped along the cycle, so the spline never jumps by a turn between phases.
        q[0] = rows[0];
        for k in 1..n {
            for i in 0..N {
                q[k][i] = q[k - 1][i] + wrap_angle(rows[k][i] - q[k - 1][i]);
            }
        }
        let mut turns = [0.0; N];
        for (i, t) in turns.iter_mut().enumerate() {
            *t = q[n - 1][i] + wrap_angle(q[0][i] - q[n - 1][i]) - q[0][i];
        }
        let mut table = Self {
            t0,
            period,
            n,
            q: [[0.0; N]; MAX_PHASES],
            c: [[0.0; N]; MAX_PHASES],
            turns,
        };
        table.q[..n].copy_from_slice(rows);
        table.fit(&q);
        Ok(table)
    }

    /// Control points that interpolate the unwrapped postures `q`: (c₋₁ + 4c₀ + c₊₁)/6 = q, a
    /// cyclic, diagonally dominant system, solved by Gauss–Seidel sweeps (each halves the error
    /// at least: 60 reach the last bit). The ramp is taken out first, as a B-spline reproduces
    /// straight lines, so the system is periodic.
    fn fit(&mut self, q: &[[f64; N]; MAX_PHASES]) {
        let n = self.n;
        let ramp = |i: usize, k: usize| self.turns[i] * k as f64 / n as f64;
        let mut target = [[0.0; N]; MAX_PHASES];
        for k in 0..n {
            for i in 0..N {
                target[k][i] = q[k][i] - ramp(i, k);
            }
        }
        let mut c = target;
        for _ in 0..60 {
            for k in 0..n {
                let (a, b) = ((k + n - 1) % n, (k + 1) % n);
                for i in 0..N {
                    c[k][i] = (6.0 * target[k][i] - c[a][i] - c[b][i]) / 4.0;
                }
            }
        }
        self.c = c;
    }

    /// This table with posture `k` moved by `delta` (small: no joint wraps), without a new fit.
    /// The fit is linear and the same at every phase, so a move of one posture moves every
    /// control point by `delta` times the cyclic system's response to a unit at `k`,
    /// √3 (rᵈ + rⁿ⁻ᵈ)/(1 − rⁿ) at distance d with r = √3 − 2. The refinement nudges each
    /// posture of each step this way: one fit a nudge was 40 % of its time.
    ///
    /// ```
    /// use control::steer::CycleTable;
    /// let rows: Vec<[f64; 3]> = (0..16).map(|k| [0.1 * k as f64, (0.4 * k as f64).sin(), 0.0]).collect();
    /// let t = CycleTable::from_rows(0.0, 1.0, &rows).unwrap();
    /// let mut moved = rows.clone();
    /// moved[5][1] += 1e-3;
    /// let (a, b) = (t.nudged(5, &[0.0, 1e-3, 0.0]), CycleTable::from_rows(0.0, 1.0, &moved).unwrap());
    /// for s in 0..40 {
    ///     let (x, y) = (a.sample(s as f64 / 40.0), b.sample(s as f64 / 40.0));
    ///     assert!((0..3).all(|i| (x.qdd[i] - y.qdd[i]).abs() < 1e-9));
    /// }
    /// ```
    pub fn nudged(&self, k: usize, delta: &[f64; N]) -> Self {
        let n = self.n;
        let mut out = *self;
        let r = 3f64.sqrt() - 2.0;
        let scale = 3f64.sqrt() / (1.0 - r.powi(n as i32));
        for j in 0..n {
            let d = (j + n - k % n) % n;
            let g = scale * (r.powi(d as i32) + r.powi((n - d) as i32));
            for i in 0..N {
                out.c[j][i] += g * delta[i];
            }
        }
        for i in 0..N {
            out.q[k % n][i] += delta[i];
        }
        out
    }

    /// The postures, one per phase.
    pub fn rows(&self) -> &[[f64; N]] {
        &self.q[..self.n]
    }

    /// Control point `k` (any integer: periodic, plus the turns made on the way).
    #[inline]
    fn control(&self, k: i64) -> [f64; N] {
        let n = self.n as i64;
        let base = &self.c[k.rem_euclid(n) as usize];
        let mut out = [0.0; N];
        for i in 0..N {
            out[i] = base[i] + self.turns[i] * k as f64 / n as f64;
        }
        out
    }

    /// The planned posture, rate and acceleration at task time `t` (periodic).
    #[inline]
    pub fn sample(&self, t: f64) -> Sample<N> {
        let dt = self.period / self.n as f64;
        let x = (t - self.t0).rem_euclid(self.period) / dt;
        let k = (x.floor() as i64).min(self.n as i64 - 1);
        let (b, db, ddb) = basis(x - k as f64);
        let mut s = Sample {
            q: [0.0; N],
            qd: [0.0; N],
            qdd: [0.0; N],
        };
        for j in 0..4 {
            let c = self.control(k - 1 + j as i64);
            for i in 0..N {
                s.q[i] += b[j] * c[i];
                s.qd[i] += db[j] * c[i] / dt;
                s.qdd[i] += ddb[j] * c[i] / (dt * dt);
            }
        }
        s
    }

    /// The planned posture and rate at task time `t`.
    #[inline]
    pub fn at(&self, t: f64) -> ([f64; N], [f64; N]) {
        let s = self.sample(t);
        (s.q, s.qd)
    }
}
