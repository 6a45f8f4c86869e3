//! A joint-space detour onto the planned cycle, for an arm that cannot reach it with its hand
//! on the path.
//!
//! With the hand held on the circle the 3-link arm has one degree of freedom left, and an
//! obstacle can stand across it: the clean cycle is on the obstacle's other side, and no
//! motion that keeps tracking gets there (an arm that starts off its path can land there too).
//! Without the hand's constraint the arm has three degrees of freedom and can usually go
//! round. So the detour pauses tracking, moves the joints along a collision-free path to the
//! cycle's posture at some phase, waits there for that phase to come round, and blends into the
//! cycle so that, at the hand-over, posture, rate and acceleration are the cycle's own: the law
//! resumes tracking with the arm on a clean cycle.
//!
//! The path is an A* search over a grid of the joint torus (64 cells a turn), centred on the
//! arm, each cell checked lazily for clearance (breadth-first search visited most of the
//! torus' 262 144 cells, and took 100 ms); the cells become the control
//! points of a clamped cubic B-spline run under a quintic time scaling, so the reference is C²
//! and starts at rest. The finished reference is checked densely for clearance, rate and
//! acceleration before it is offered. Off the loop: it allocates; the loop reads a `Copy`
//! [`DetourTable`].

use super::planar::PlanarProblem;
use crate::basics::wrap_angle;
use crate::steer::detour::{BLEND, MAX_DETOUR};
use crate::steer::{CycleTable, DetourTable};
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::f64::consts::TAU;

/// Cells per turn of each joint.
const GRID: usize = 64;
/// Clearances (m) the search keeps beyond the filter's, tried in turn, roomiest first: an arm
/// that lags its reference near an obstacle meets the filter's barrier, which holds it there
/// while the pull drags it sideways, and the spline through the cells cuts corners.
const SEARCH_MARGINS: [f64; 3] = [0.1, 0.05, 0.02];
/// The fastest a joint moves on the way (rad/s, roughly: the time scaling's peak).
const SPEED: f64 = 4.0;

/// Grid cell of a posture's offset from `centre`, if it is on the grid.
fn cell_of(q: &[f64; 3], centre: &[f64; 3]) -> [usize; 3] {
    let h = TAU / GRID as f64;
    let mut c = [0; 3];
    for i in 0..3 {
        let off = (wrap_angle(q[i] - centre[i]) / h).round() as i64 + (GRID / 2) as i64;
        c[i] = off.rem_euclid(GRID as i64) as usize;
    }
    c
}

fn index(c: [usize; 3]) -> usize {
    (c[0] * GRID + c[1]) * GRID + c[2]
}

fn unindex(i: usize) -> [usize; 3] {
    [i / (GRID * GRID), (i / GRID) % GRID, i % GRID]
}

/// The search: cells reached from the arm's, to the first cell of a cycle posture.
struct Search<'a> {
    p: &'a PlanarProblem,
    centre: [f64; 3],
    /// The arm's own clearance: an arm that starts inside a margin may leave it nearby.
    start_clearance: f64,
    margin: f64,
    /// 0 unknown, 1 free, 2 blocked.
    free: Vec<u8>,
    /// Joints without limits wrap round the torus.
    wraps: [bool; 3],
}

/// Cells round the arm's in which it may stay as close as it starts (to get out of a margin).
const ESCAPE_CELLS: usize = 6;

impl Search<'_> {
    fn angles(&self, c: [usize; 3]) -> [f64; 3] {
        let h = TAU / GRID as f64;
        let mut q = [0.0; 3];
        for i in 0..3 {
            q[i] = self.centre[i] + (c[i] as f64 - (GRID / 2) as f64) * h;
        }
        q
    }

    fn is_free(&mut self, c: [usize; 3]) -> bool {
        let i = index(c);
        if self.free[i] == 0 {
            let q = self.angles(c);
            let near = c.iter().all(|&v| v.abs_diff(GRID / 2) <= ESCAPE_CELLS);
            let clear = self.p.clearance_of(&q).0;
            let ok = self.p.within_limits(&q, 0.0)
                && (clear >= self.p.clearance + self.margin
                    || near && clear >= self.start_clearance - 1e-3);
            self.free[i] = if ok { 1 } else { 2 };
        }
        self.free[i] == 1
    }

    /// Neighbours of `c`, one joint one cell at a time (a joint with limits does not wrap),
    /// as (neighbour, joint, direction).
    fn neighbours(&self, c: [usize; 3], out: &mut Vec<([usize; 3], usize, f64)>) {
        out.clear();
        for i in 0..3 {
            for d in [-1i64, 1] {
                let v = c[i] as i64 + d;
                let mut n = c;
                if (0..GRID as i64).contains(&v) {
                    n[i] = v as usize;
                } else if self.wraps[i] {
                    n[i] = v.rem_euclid(GRID as i64) as usize;
                } else {
                    continue;
                }
                out.push((n, i, d as f64));
            }
        }
    }

    /// Whether the midpoint of the step from `c` along joint `i` is clear too: a step of joint
    /// 1 swings the hand 0.3 m, and a diagonal step could jump a small obstacle.
    fn midpoint_clear(&self, c: [usize; 3], i: usize, d: f64) -> bool {
        let mut mid = self.angles(c);
        mid[i] += d * 0.5 * TAU / GRID as f64;
        let near = c.iter().all(|&v| v.abs_diff(GRID / 2) <= ESCAPE_CELLS);
        let floor = if near {
            self.p.clearance.min(self.start_clearance - 1e-3)
        } else {
            self.p.clearance
        };
        self.p.clearance_of(&mid).0 >= floor
    }

    /// Steps (cells) from `c` to the nearest goal cell with no obstacle in the way: A*'s
    /// estimate, never above the true count, so the path found is as short as breadth-first
    /// search's while far fewer cells are visited.
    fn estimate(&self, c: [usize; 3], goals: &[[usize; 3]]) -> u32 {
        let apart = |a: usize, b: usize, wraps: bool| {
            let d = a.abs_diff(b);
            if wraps {
                d.min(GRID - d)
            } else {
                d
            }
        };
        goals
            .iter()
            .map(|g| {
                (0..3)
                    .map(|i| apart(c[i], g[i], self.wraps[i]))
                    .sum::<usize>()
            })
            .min()
            .unwrap_or(0) as u32
    }
}

/// Why no joint-space detour onto the cycle was found: the reason of the last search margin
/// tried (the planner adds it to the `Blocked` it reports).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DetourError {
    #[error("no joint-space path keeps clear of the obstacles either")]
    NoPath,
    #[error("the joint-space path needs {steps} steps (at most {max})")]
    TooLong { steps: usize, max: usize },
    #[error(
        "the joint-space path comes {clearance:.3} m from an obstacle at {at:.2} s of {of:.2} s"
    )]
    TooClose { clearance: f64, at: f64, of: f64 },
    #[error("the joint-space path breaks a joint limit")]
    JointLimit,
    #[error(transparent)]
    Table(#[from] crate::steer::SteerError),
}

/// Plans a detour from posture `q_now` at `t_start` onto `cycle`: the control points, the
/// path's duration and the arrival time, checked densely; or why there is none.
pub fn plan(
    p: &PlanarProblem,
    cycle: &CycleTable,
    q_now: [f64; 3],
    t_start: f64,
) -> Result<DetourTable, DetourError> {
    let mut last = Err(DetourError::NoPath);
    for margin in SEARCH_MARGINS {
        last = plan_with(p, cycle, q_now, t_start, margin);
        if last.is_ok() {
            break;
        }
    }
    last
}

fn plan_with(
    p: &PlanarProblem,
    cycle: &CycleTable,
    q_now: [f64; 3],
    t_start: f64,
    margin: f64,
) -> Result<DetourTable, DetourError> {
    let rows = cycle.rows();
    let phases = rows.len();
    // An arm inside a margin first backs out along its clearance's gradient, slowly.
    let escape = escape(p, q_now, p.clearance + margin / 2.0);
    let q_now = *escape.last().expect("an escape starts at the arm");
    let mut goal = vec![u8::MAX; GRID * GRID * GRID];
    let mut goals: Vec<[usize; 3]> = rows.iter().map(|q| cell_of(q, &q_now)).collect();
    for (k, &c) in goals.iter().enumerate() {
        goal[index(c)] = k as u8;
    }
    goals.sort_unstable();
    goals.dedup();
    let mut s = Search {
        p,
        centre: q_now,
        start_clearance: p.clearance_of(&q_now).0,
        margin,
        free: vec![0; GRID * GRID * GRID],
        wraps: [0, 1, 2].map(|i| p.q_min[i] == f64::NEG_INFINITY && p.q_max[i] == f64::INFINITY),
    };
    let start = [GRID / 2; 3];
    let mut parent = vec![u32::MAX; GRID * GRID * GRID];
    let mut steps = vec![u32::MAX; GRID * GRID * GRID];
    parent[index(start)] = index(start) as u32;
    steps[index(start)] = 0;
    // Fewest steps plus the estimate first; of equals, the one farthest along.
    let mut open = BinaryHeap::from([Reverse((
        s.estimate(start, &goals),
        Reverse(0u32),
        index(start) as u32,
    ))]);
    let mut next = Vec::with_capacity(6);
    let mut reached = None;
    while let Some(Reverse((_, Reverse(g), i))) = open.pop() {
        let i = i as usize;
        if g > steps[i] {
            continue; // reached by a shorter way since it was queued
        }
        let c = unindex(i);
        if goal[i] != u8::MAX {
            reached = Some(c);
            break;
        }
        s.neighbours(c, &mut next);
        for &(n, joint, d) in &next {
            let j = index(n);
            if g + 1 < steps[j]
                && (goal[j] != u8::MAX || s.is_free(n))
                && s.midpoint_clear(c, joint, d)
            {
                steps[j] = g + 1;
                parent[j] = i as u32;
                open.push(Reverse((
                    g + 1 + s.estimate(n, &goals),
                    Reverse(g + 1),
                    j as u32,
                )));
            }
        }
    }
    let end = reached.ok_or(DetourError::NoPath)?;
    let k = goal[index(end)] as usize;
    // The cells back to the arm, as continuous joint angles.
    let mut cells = vec![end];
    while let Some(&c) = cells.last().filter(|c| **c != start) {
        cells.push(unindex(parent[index(c)] as usize));
    }
    cells.reverse();
    let mut pts: Vec<[f64; 3]> = cells.iter().map(|&c| s.angles(c)).collect();
    for j in 1..pts.len() {
        for i in 0..3 {
            pts[j][i] = pts[j - 1][i] + wrap_angle(pts[j][i] - pts[j - 1][i]);
        }
    }
    pts[0] = q_now;
    let pts = shortcut(p, &pts, p.clearance + margin);
    let mut pts: Vec<[f64; 3]> = escape[..escape.len() - 1]
        .iter()
        .copied()
        .chain(pts)
        .collect();
    let last = pts.len() - 1;
    let before = if last > 0 { pts[last - 1] } else { q_now };
    for i in 0..3 {
        pts[last][i] = before[i] + wrap_angle(rows[k][i] - before[i]);
    }
    if pts.len() < 2 {
        pts.push(pts[0]);
    }
    if pts.len() > MAX_DETOUR {
        return Err(DetourError::TooLong {
            steps: pts.len(),
            max: MAX_DETOUR,
        });
    }
    let h = TAU / GRID as f64;
    let duration = (1.875 * (pts.len() + 1) as f64 * h / SPEED).max(0.5);
    // Arrive when the cycle is at phase k, with time to blend.
    let dt = cycle.period / phases as f64;
    let phase_t = cycle.t0 + k as f64 * dt;
    let earliest = t_start + duration + BLEND;
    let periods = ((earliest - phase_t) / cycle.period).ceil();
    let t_arrive = phase_t + periods * cycle.period;
    let table = DetourTable::new(t_start, duration, t_arrive, &pts)?;
    check(p, &table, cycle, margin)?;
    Ok(table)
}

/// How far (m) the escape's reference moves the nearest link out per control point: at the
/// detour's pace, about the filter's push-out speed, so the arm can follow.
const ESCAPE_STEP: f64 = 0.01;

/// Postures from `q` out along the clearance's gradient until it reaches `target` (m): `q`
/// alone when it is already there (or the gradient vanishes).
fn escape(p: &PlanarProblem, q: [f64; 3], target: f64) -> Vec<[f64; 3]> {
    let mut out = vec![q];
    let mut q = q;
    for _ in 0..60 {
        let c = p.clearance_of(&q).0;
        if c >= target {
            break;
        }
        let h = 1e-6;
        let mut g = [0.0; 3];
        for i in 0..3 {
            let mut a = q;
            a[i] += h;
            g[i] = (p.clearance_of(&a).0 - c) / h;
        }
        let g2: f64 = g.iter().map(|v| v * v).sum();
        if g2 < 1e-12 {
            break;
        }
        for i in 0..3 {
            q[i] += g[i] / g2 * ESCAPE_STEP;
        }
        out.push(q);
    }
    out
}

/// Whether the straight joint-space segment a–b keeps `floor` (m) everywhere (sampled finely
/// enough that no link moves more than a centimetre or so between samples).
fn segment_clear(p: &PlanarProblem, a: &[f64; 3], b: &[f64; 3], floor: f64) -> bool {
    let span = (0..3).map(|i| (b[i] - a[i]).abs()).fold(0.0, f64::max);
    let n = (span / 0.004).ceil().max(1.0) as usize;
    (0..=n).all(|k| {
        let f = k as f64 / n as f64;
        let q = [0, 1, 2].map(|i| a[i] + f * (b[i] - a[i]));
        p.clearance_of(&q).0 >= floor
    })
}

/// The grid's staircase straightened: from each kept point, the farthest later one in plain
/// sight, the segment between resampled at the grid's step (the spline then takes it at the
/// same pace). The first point may be inside the margin (it is where the escape ended).
fn shortcut(p: &PlanarProblem, pts: &[[f64; 3]], floor: f64) -> Vec<[f64; 3]> {
    let h = TAU / GRID as f64;
    let mut out = vec![pts[0]];
    let mut i = 0;
    while i + 1 < pts.len() {
        let mut j = i + 1;
        for cand in (i + 2..pts.len()).rev() {
            if segment_clear(p, &pts[i], &pts[cand], floor) {
                j = cand;
                break;
            }
        }
        let (a, b) = (pts[i], pts[j]);
        let span = (0..3).map(|k| (b[k] - a[k]).abs()).fold(0.0, f64::max);
        let n = (span / h).ceil().max(1.0) as usize;
        for s in 1..=n {
            let f = s as f64 / n as f64;
            out.push([0, 1, 2].map(|k| a[k] + f * (b[k] - a[k])));
        }
        i = j;
    }
    out
}

/// How much deeper than it starts the reference of an arm that starts inside a margin may
/// dip on its way out (m): the spline cuts the grid's corners. The filter runs on the detour's
/// commands too, and its barrier does not let the arm itself go deeper.
const ESCAPE_SLACK: f64 = 0.02;

/// Samples the whole detour: the filter's clearance once it has it (an arm that starts inside
/// goes barely deeper), within joint limits and rates.
fn check(
    p: &PlanarProblem,
    d: &DetourTable,
    cycle: &CycleTable,
    margin: f64,
) -> Result<(), DetourError> {
    let steps = ((d.t_arrive - d.t_start) / 0.002).ceil() as usize;
    let mut floor = p
        .clearance
        .min(p.clearance_of(&d.points()[0]).0 - ESCAPE_SLACK);
    for j in 0..=steps {
        let t = d.t_start + (d.t_arrive - d.t_start) * j as f64 / steps as f64;
        let r = d.sample(t, cycle);
        let (c, _) = p.clearance_of(&r.q);
        if c >= p.clearance + margin / 2.0 {
            floor = p.clearance + margin / 2.0;
        }
        if c < floor {
            return Err(DetourError::TooClose {
                clearance: c,
                at: t - d.t_start,
                of: d.t_arrive - d.t_start,
            });
        }
        if (0..3).any(|i| r.qd[i].abs() > p.qd_max[i]) || !p.within_limits(&r.q, 0.0) {
            return Err(DetourError::JointLimit);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cycle() -> CycleTable {
        let rows: Vec<[f64; 3]> = (0..64)
            .map(|k| {
                let a = TAU * k as f64 / 64.0;
                [0.3 * a.sin(), 1.0 + 0.2 * a.cos(), -0.5]
            })
            .collect();
        CycleTable::from_rows(0.0, 1.0, &rows).unwrap()
    }

    #[test]
    fn a_detour_starts_at_rest_and_hands_over_on_the_cycle() {
        let c = cycle();
        let pts = [
            [2.0, -1.0, 0.5],
            [1.5, -0.5, 0.2],
            [1.0, 0.0, 0.0],
            c.rows()[16],
        ];
        let d = DetourTable::new(3.0, 2.0, 5.25, &pts).unwrap();
        let s = d.sample(3.0, &c);
        assert!((0..3).all(|i| (s.q[i] - pts[0][i]).abs() < 1e-12 && s.qd[i].abs() < 1e-12));
        // At arrival: the cycle's own posture, rate and acceleration.
        let (a, b) = (d.sample(5.25, &c), c.sample(5.25));
        for i in 0..3 {
            assert!(wrap_angle(a.q[i] - b.q[i]).abs() < 1e-9, "{a:?} {b:?}");
            assert!((a.qd[i] - b.qd[i]).abs() < 1e-9 && (a.qdd[i] - b.qdd[i]).abs() < 1e-6);
        }
        assert!(d.running(5.2) && !d.running(5.25));
        // The rate is the posture's derivative, on the path and in the blend.
        for t in [3.7, 5.2] {
            let h = 1e-6;
            let (l, m, r) = (d.sample(t - h, &c), d.sample(t, &c), d.sample(t + h, &c));
            assert!((0..3).all(|i| ((r.q[i] - l.q[i]) / (2.0 * h) - m.qd[i]).abs() < 1e-5));
            assert!((0..3).all(|i| ((r.qd[i] - l.qd[i]) / (2.0 * h) - m.qdd[i]).abs() < 1e-3));
        }
    }

    #[test]
    fn a_bad_detour_is_refused() {
        let p = [[0.0; 3], [1.0; 3]];
        assert!(DetourTable::new(0.0, 1.0, 2.0, &p[..1]).is_err());
        assert!(DetourTable::new(0.0, 0.0, 2.0, &p).is_err());
        assert!(DetourTable::new(0.0, 3.0, 2.0, &p).is_err());
        assert!(DetourTable::new(f64::NAN, 1.0, 2.0, &p).is_err());
    }
}
