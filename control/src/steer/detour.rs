//! A detour the loop runs: the joint-space way onto a planned cycle for an arm that cannot
//! reach it tracking, as a fixed-size `Copy` table ([`crate::plan::detour`] searches for it).

use super::table::{CycleTable, Sample};
use super::SteerError;
use crate::basics::wrap_angle;

/// The most control points a detour may have.
pub const MAX_DETOUR: usize = 128;
/// How long the blend into the cycle takes (s).
pub const BLEND: f64 = 0.15;

/// A detour the loop can run: fixed size, `Copy`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetourTable {
    /// When it starts and how long the path takes (s).
    pub t_start: f64,
    pub duration: f64,
    /// When the arm is on the cycle and tracking resumes (s).
    pub t_arrive: f64,
    n: usize,
    c: [[f64; 3]; MAX_DETOUR],
}

fn smoothstep(x: f64) -> (f64, f64, f64) {
    let x = x.clamp(0.0, 1.0);
    let (x2, x3) = (x * x, x * x * x);
    (
        x3 * (10.0 - 15.0 * x + 6.0 * x2),
        30.0 * x2 * (1.0 - x) * (1.0 - x),
        60.0 * x * (1.0 - x) * (1.0 - 2.0 * x),
    )
}

impl DetourTable {
    /// The table of control points `c` (the first the arm's posture, the last the cycle's).
    pub fn new(
        t_start: f64,
        duration: f64,
        t_arrive: f64,
        c: &[[f64; 3]],
    ) -> Result<Self, SteerError> {
        let ok = (2..=MAX_DETOUR).contains(&c.len())
            && duration > 0.0
            && t_arrive >= t_start + duration
            && c.iter()
                .flatten()
                .chain([&t_start, &duration, &t_arrive])
                .all(|v| v.is_finite());
        if !ok {
            return Err(SteerError::Detour {
                max_points: MAX_DETOUR,
            });
        }
        let mut t = Self {
            t_start,
            duration,
            t_arrive,
            n: c.len(),
            c: [[0.0; 3]; MAX_DETOUR],
        };
        t.c[..c.len()].copy_from_slice(c);
        Ok(t)
    }

    /// The control points (as [`Self::new`] took them: a recording's copy).
    pub fn points(&self) -> &[[f64; 3]] {
        &self.c[..self.n]
    }

    /// Whether the detour still runs at `t` (tracking paused).
    #[inline]
    pub fn running(&self, t: f64) -> bool {
        t < self.t_arrive
    }

    /// The path alone at `t`: clamped B-spline under the quintic time scaling.
    #[inline]
    fn path(&self, t: f64) -> Sample {
        let span = (self.n + 1) as f64;
        let (s, sd, sdd) = smoothstep((t - self.t_start) / self.duration);
        let (ud, udd) = (
            span * sd / self.duration,
            span * sdd / (self.duration * self.duration),
        );
        let u = -1.0 + span * s;
        let k = (u.floor() as i64).clamp(-1, self.n as i64 - 1);
        let (b, db, ddb) = super::table::basis(u - k as f64);
        let mut out = Sample {
            q: [0.0; 3],
            qd: [0.0; 3],
            qdd: [0.0; 3],
        };
        for j in 0..4 {
            let p = self.c[(k - 1 + j as i64).clamp(0, self.n as i64 - 1) as usize];
            for i in 0..3 {
                out.q[i] += b[j] * p[i];
                let (d1, d2) = (db[j] * p[i], ddb[j] * p[i]);
                out.qd[i] += d1 * ud;
                out.qdd[i] += d2 * ud * ud + d1 * udd;
            }
        }
        out
    }

    /// The reference at `t`: the path, then (over the last [`BLEND`] s) a blend into `cycle`
    /// that hands over with the cycle's own posture, rate and acceleration at `t_arrive`.
    #[inline]
    pub fn sample(&self, t: f64, cycle: &CycleTable) -> Sample {
        let mut out = self.path(t);
        let from = self.t_arrive - BLEND;
        if t <= from {
            return out;
        }
        let (w, wd, wdd) = smoothstep((t - from) / BLEND);
        let (wd, wdd) = (wd / BLEND, wdd / (BLEND * BLEND));
        let c = cycle.sample(t);
        let end = self.c[self.n - 1];
        for i in 0..3 {
            let d = wrap_angle(c.q[i] - end[i]);
            out.q[i] += w * d;
            out.qd[i] += wd * d + w * c.qd[i];
            out.qdd[i] += wdd * d + 2.0 * wd * c.qd[i] + w * c.qdd[i];
        }
        out
    }
}
