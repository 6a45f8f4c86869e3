//! The planar 3-link arm's cycle planner: dynamic programming on the cylinder of task phase ×
//! self-motion coordinate, closed by the cycle's periodicity.
//!
//! With the hand on the circle at phase s, the arm keeps one degree of freedom: the absolute
//! angle ψ of its last link. Given (s, ψ), the wrist sits at p_d(s) − l₃(cos ψ, sin ψ) and the
//! first two links reach it in two ways (elbow left or right), so a grid over ψ and both branches
//! covers every posture, the branches meeting where the elbow stretches or folds. A node is a
//! posture that keeps every clearance and joint limit with margin; an edge joins postures of
//! consecutive phases whose joints move at most `max_rate · Δt`, measured in joint space, so a
//! path may change branch where the two meet. A clean cycle is a closed walk once round the
//! phases.
//!
//! Existence is exact on the grid and cheap: bit sets of the starts that reach each node,
//! propagated once round (a start closes a cycle when it reaches itself). The cycle chosen is
//! then the cheapest closed walk, by dynamic programming from the closing starts nearest the arm's
//! posture: joint motion squared, plus a penalty for clearance below twice the margin, so it
//! is smooth, slow and roomy.

use super::{Blocked, Cycle, PlanOutcome, PlanSettings};
use crate::arm::Vec2;
use crate::basics::wrap_angle;
use crate::secondary::ObstacleSet;
use crate::task::Path;
use std::f64::consts::TAU;

/// What the planar planner needs: the arm, the task, the obstacles and the limits.
#[derive(Clone, Debug)]
pub struct PlanarProblem {
    pub links: [f64; 3],
    pub task: Path,
    pub obstacles: ObstacleSet,
    /// Required distance (m) from every link to every obstacle's surface.
    pub clearance: f64,
    pub q_min: [f64; 3],
    pub q_max: [f64; 3],
    /// The filter's joint rate limits (rad/s): [`super::PlanSettings::limits_only`] plans
    /// within them.
    pub qd_max: [f64; 3],
    /// The task time of the cycle's first phase (s): the arm's phase now.
    pub t0: f64,
    /// The arm's posture now, if known: the cycle is chosen near it.
    pub q_now: Option<[f64; 3]>,
}

/// One grid posture: joint angles (each wrapped into (−π, π]) and its smallest clearance.
#[derive(Clone, Copy, Debug)]
struct Node {
    q: [f64; 3],
    clearance: f64,
}

/// Distance from `c` to the segment a–b.
fn segment_distance(a: Vec2, b: Vec2, c: Vec2) -> f64 {
    let d = b - a;
    let l2 = d.norm_squared();
    let t = if l2 > 0.0 {
        ((c - a).dot(&d) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + d * t - c).norm()
}

impl PlanarProblem {
    /// The posture at hand position `p` with last-link angle `psi` on elbow `branch` (±1).
    fn posture(&self, p: Vec2, psi: f64, branch: f64) -> Option<[f64; 3]> {
        let [l1, l2, l3] = self.links;
        let w = p - Vec2::new(psi.cos(), psi.sin()) * l3;
        let r2 = w.norm_squared();
        let c2 = (r2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
        if !(-1.0..=1.0).contains(&c2) {
            return None;
        }
        let q2 = branch * c2.acos();
        let q1 = w.y.atan2(w.x) - (l2 * q2.sin()).atan2(l1 + l2 * q2.cos());
        let q3 = psi - q1 - q2;
        Some([wrap_angle(q1), wrap_angle(q2), wrap_angle(q3)])
    }

    /// The smallest clearance of posture `q`, and where it is.
    pub(super) fn clearance_of(&self, q: &[f64; 3]) -> (f64, Option<(usize, usize)>) {
        let mut pts = [Vec2::zeros(); 4];
        let mut theta = 0.0;
        for j in 0..3 {
            theta += q[j];
            pts[j + 1] = pts[j] + Vec2::new(theta.cos(), theta.sin()) * self.links[j];
        }
        let mut best = (f64::INFINITY, None);
        for (k, o) in self.obstacles.as_slice().iter().enumerate() {
            for j in 0..3 {
                let c = segment_distance(pts[j], pts[j + 1], o.center) - o.radius;
                if c < best.0 {
                    best = (c, Some((k, j)));
                }
            }
        }
        best
    }

    pub(super) fn within_limits(&self, q: &[f64; 3], margin: f64) -> bool {
        (0..3).all(|i| q[i] >= self.q_min[i] + margin && q[i] <= self.q_max[i] - margin)
    }
}

/// Joint-space step between two wrapped postures (the largest joint's).
fn step(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (0..3)
        .map(|i| wrap_angle(b[i] - a[i]).abs())
        .fold(0.0, f64::max)
}

/// Whether moving from `a` to `b` in `dt` closes in on the nearest obstacle no faster than
/// `approach` times the clearance left at `b` (always, without obstacles).
fn approach_ok(p: &PlanarProblem, s: &PlanSettings, a: &Node, b: &Node, dt: f64) -> bool {
    if !b.clearance.is_finite() || s.approach == f64::INFINITY {
        return true;
    }
    let left = b.clearance - p.clearance;
    (b.clearance - a.clearance) / dt + s.approach * left >= 0.0
}

/// The grid: `layers[k]` holds every posture at phase k (infeasible ones as `None`), and
/// `edges[k][i]` the postures of phase k + 1 (cyclically) that posture i may move to.
struct Grid {
    layers: Vec<Vec<Option<Node>>>,
    edges: Vec<Vec<Vec<u32>>>,
    dt: f64,
}

fn build(p: &PlanarProblem, s: &PlanSettings) -> Grid {
    let dt = p.task.period / s.phases as f64;
    let layers: Vec<Vec<Option<Node>>> = (0..s.phases)
        .map(|k| {
            let hand = p.task.at_xy(p.t0 + k as f64 * dt).0;
            (0..2 * s.angles)
                .map(|n| {
                    let psi = TAU * (n % s.angles) as f64 / s.angles as f64;
                    let branch = if n < s.angles { 1.0 } else { -1.0 };
                    let q = p.posture(hand, psi, branch)?;
                    if !p.within_limits(&q, s.joint_margin) {
                        return None;
                    }
                    let (clearance, _) = p.clearance_of(&q);
                    (clearance >= p.clearance + s.margin).then_some(Node { q, clearance })
                })
                .collect()
        })
        .collect();
    let max_step = s.max_rate * dt;
    let n = layers.len();
    let edges = (0..n)
        .map(|k| {
            let next = &layers[(k + 1) % n];
            layers[k]
                .iter()
                .map(|a| match a {
                    None => Vec::new(),
                    Some(a) => next
                        .iter()
                        .enumerate()
                        .filter(|(_, b)| {
                            b.is_some_and(|b| {
                                step(&a.q, &b.q) <= max_step && approach_ok(p, s, a, &b, dt)
                            })
                        })
                        .map(|(j, _)| j as u32)
                        .collect(),
                })
                .collect()
        })
        .collect();
    Grid { layers, edges, dt }
}

impl Grid {
    /// The nodes of layer `k + 1` (cyclically) that node `i` of layer `k` may move to.
    fn successors(&self, k: usize, i: usize) -> impl Iterator<Item = usize> + '_ {
        self.edges[k][i].iter().map(|&j| j as usize)
    }

    /// Which layer-0 starts close a walk once round: bit sets of the starts reaching each
    /// node, propagated over the layers.
    fn closing_starts(&self) -> Vec<usize> {
        let width = self.layers[0].len();
        let words = width.div_ceil(64);
        let mut reach: Vec<Vec<u64>> = (0..width)
            .map(|i| {
                let mut b = vec![0u64; words];
                if self.layers[0][i].is_some() {
                    b[i / 64] |= 1 << (i % 64);
                }
                b
            })
            .collect();
        for k in 0..self.layers.len() {
            let mut next = vec![vec![0u64; words]; width];
            for i in 0..width {
                if reach[i].iter().all(|w| *w == 0) {
                    continue;
                }
                for j in self.successors(k, i) {
                    for w in 0..words {
                        next[j][w] |= reach[i][w];
                    }
                }
            }
            reach = next;
        }
        (0..width)
            .filter(|&i| reach[i][i / 64] >> (i % 64) & 1 == 1)
            .collect()
    }

    /// The layer-0 nodes reachable from layer-0 node `from` after one to `periods` whole
    /// periods: where the arm can go while its hand tracks the path and it keeps clean.
    fn reachable(&self, from: usize, periods: usize) -> Vec<bool> {
        let width = self.layers[0].len();
        let mut at = vec![false; width];
        at[from] = true;
        let mut seen = vec![false; width];
        for _ in 0..periods {
            for k in 0..self.layers.len() {
                let mut next = vec![false; width];
                for i in (0..width).filter(|&i| at[i]) {
                    for j in self.successors(k, i) {
                        next[j] = true;
                    }
                }
                at = next;
            }
            for (s, a) in seen.iter_mut().zip(&at) {
                *s |= *a;
            }
        }
        seen
    }

    /// The cheapest closed walk from layer-0 node `start`: joint motion squared per unit time,
    /// plus a penalty on clearance below `roomy`. Returns the node indices per layer and cost.
    fn cheapest_cycle(&self, start: usize, roomy: f64) -> Option<(Vec<usize>, f64)> {
        let (n, width) = (self.layers.len(), self.layers[0].len());
        let penalty = |c: f64| {
            let short = (roomy - c).max(0.0) / roomy.max(1e-9);
            short * short
        };
        let mut cost = vec![vec![f64::INFINITY; width]; n + 1];
        let mut from = vec![vec![usize::MAX; width]; n + 1];
        cost[0][start] = 0.0;
        for k in 0..n {
            for i in 0..width {
                let c = cost[k][i];
                let Some(a) = self.layers[k][i].filter(|_| c.is_finite()) else {
                    continue;
                };
                for j in self.successors(k, i) {
                    let b = self.layers[(k + 1) % n][j].expect("successors are feasible");
                    let d: f64 = (0..3).map(|m| wrap_angle(b.q[m] - a.q[m]).powi(2)).sum();
                    let total = c + d / self.dt + self.dt * penalty(b.clearance);
                    if total < cost[k + 1][j] {
                        cost[k + 1][j] = total;
                        from[k + 1][j] = i;
                    }
                }
            }
        }
        if !cost[n][start].is_finite() {
            return None;
        }
        let mut path = vec![start; n];
        let mut at = start;
        for k in (1..=n).rev() {
            at = from[k][at];
            path[k - 1] = at;
        }
        (path[0] == start).then_some((path, cost[n][start]))
    }
}

/// Whole periods the arm may take to reach a cycle from its posture.
const REACH_PERIODS: usize = 4;

/// The clean layer-0 node the arm's posture `q` is at: the nearest, if it is within one
/// phase's motion (an arm off its path, or inside a margin, is at none).
fn arm_node(q: &[f64; 3], s: &PlanSettings, grid: &Grid) -> Option<usize> {
    let q = q.map(wrap_angle);
    grid.layers[0]
        .iter()
        .enumerate()
        .filter_map(|(i, n)| n.map(|n| (i, step(&q, &n.q))))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .filter(|(_, d)| *d <= s.max_rate.min(1e3) * grid.dt)
        .map(|(i, _)| i)
}

/// Plans a clean periodic cycle for the planar 3-link arm, or says why there is none.
///
/// When the arm's posture is on the grid, only cycles it can reach while tracking count: a
/// cycle on the other side of an obstacle is no way out for an arm that must keep its hand on
/// the path.
pub fn plan(p: &PlanarProblem, s: &PlanSettings) -> PlanOutcome {
    let grid = build(p, s);
    let mut starts = grid.closing_starts();
    if starts.is_empty() {
        return PlanOutcome::Blocked(blocked(p, s, &grid));
    }
    // Cycles the arm cannot reach with its hand on the path are kept (a detour in joint space
    // may reach them: `super::detour`), marked with why.
    let (mut unreached, mut off) = (None, false);
    if let Some(q) = p.q_now {
        match arm_node(&q, s, &grid) {
            Some(a) => {
                let reach = grid.reachable(a, REACH_PERIODS);
                let kept: Vec<usize> = starts.iter().copied().filter(|&i| reach[i]).collect();
                if kept.is_empty() {
                    unreached = Some(unreachable(p, s, &grid, a));
                } else {
                    starts = kept;
                }
            }
            None => (unreached, off) = (Some(off_path(p, &q)), true),
        }
    }
    let start_q = |i: usize| grid.layers[0][i].expect("a start is feasible").q;
    let mut ranked = starts.clone();
    if let Some(q) = p.q_now {
        let q = q.map(wrap_angle);
        ranked.sort_by(|&a, &b| step(&q, &start_q(a)).total_cmp(&step(&q, &start_q(b))));
    }
    let roomy = 2.0 * (p.clearance + s.margin);
    let best = ranked
        .iter()
        .take(s.candidates)
        .filter_map(|&i| grid.cheapest_cycle(i, roomy))
        .min_by(|a, b| a.1.total_cmp(&b.1));
    match best {
        Some((path, _)) => PlanOutcome::Found(Cycle {
            unreachable: unreached,
            arm_off_path: off,
            ..cycle(p, &grid, &path)
        }),
        None => PlanOutcome::Blocked(blocked(p, s, &grid)),
    }
}

/// The walk as joint angles, unwrapped along the cycle and placed nearest the arm's posture.
fn cycle(p: &PlanarProblem, grid: &Grid, path: &[usize]) -> Cycle {
    let node = |k: usize| grid.layers[k][path[k]].expect("a walk visits feasible nodes");
    let mut q = vec![node(0).q; path.len()];
    if let Some(now) = p.q_now {
        // The same posture, by whole turns, nearest the arm's own joint angles.
        for i in 0..3 {
            q[0][i] = now[i] + wrap_angle(q[0][i] - now[i]);
        }
    }
    for k in 1..path.len() {
        for i in 0..3 {
            q[k][i] = q[k - 1][i] + wrap_angle(node(k).q[i] - node(k - 1).q[i]);
        }
    }
    let min_clearance = (0..path.len())
        .map(|k| node(k).clearance)
        .fold(f64::INFINITY, f64::min);
    let max_rate = (0..path.len())
        .map(|k| step(&node(k).q, &node((k + 1) % path.len()).q) / grid.dt)
        .fold(0.0, f64::max);
    Cycle {
        t0: p.t0,
        period: p.task.period,
        q: q.into_iter().map(|a| a.to_vec()).collect(),
        min_clearance,
        max_rate,
        filter_margin: f64::INFINITY,
        unreachable: None,
        arm_off_path: false,
        detour: None,
    }
}

/// Why an arm at posture `q` reaches no cycle with its hand on the path: it is not on the grid
/// (its hand off the path, or a link inside a margin).
fn off_path(p: &PlanarProblem, q: &[f64; 3]) -> Blocked {
    let (c, at) = p.clearance_of(q);
    Blocked {
        reason: "the arm is off its path or inside a clearance margin, so no cycle can be \
                 reached with its hand on the path"
            .into(),
        best_clearance: c,
        obstacle: at.map(|w| w.0),
        link: at.map(|w| w.1),
        task_time: p.t0,
    }
}

/// Why the arm at layer-0 node `a` reaches no clean cycle: the obstacle nearest to it. (With
/// no obstacle, only the rate bound and the grid's resolution stand between: near a fold of
/// the self-motion the grid can miss a way the arm has.)
fn unreachable(p: &PlanarProblem, s: &PlanSettings, grid: &Grid, a: usize) -> Blocked {
    let q = grid.layers[0][a].expect("the arm's node is clean").q;
    let (c, at) = p.clearance_of(&q);
    let between = at.map_or(String::new(), |(o, l)| {
        format!(
            ": an obstacle stands between (nearest: link {} {c:.3} m from obstacle {})",
            l + 1,
            o + 1
        )
    });
    Blocked {
        reason: format!(
            "clean cycles exist, but none the arm can reach from its posture with its hand on \
             the path and joint rates within {:.1} rad/s{between}",
            s.max_rate
        ),
        best_clearance: c,
        obstacle: at.map(|w| w.0),
        link: at.map(|w| w.1),
        task_time: p.t0,
    }
}

/// Why no cycle exists: the phase with the fewest clean postures, and there the best posture's
/// smallest clearance and where it is.
fn blocked(p: &PlanarProblem, s: &PlanSettings, grid: &Grid) -> Blocked {
    let feasible = |k: usize| grid.layers[k].iter().flatten().count();
    let k = (0..grid.layers.len())
        .min_by_key(|&k| feasible(k))
        .unwrap_or(0);
    let t = p.t0 + k as f64 * grid.dt;
    // Every posture at that phase, clean or not: the roomiest one says how close it came.
    let hand = p.task.at_xy(t).0;
    let roomiest = (0..2 * s.angles)
        .filter_map(|n| {
            let psi = TAU * (n % s.angles) as f64 / s.angles as f64;
            let branch = if n < s.angles { 1.0 } else { -1.0 };
            let q = p.posture(hand, psi, branch)?;
            p.within_limits(&q, s.joint_margin)
                .then(|| p.clearance_of(&q))
        })
        .max_by(|a, b| a.0.total_cmp(&b.0));
    let required = p.clearance + s.margin;
    let reason = match (feasible(k), roomiest) {
        (0, Some((c, Some((o, l))))) => format!(
            "at task time {t:.3} s no posture keeps {required:.3} m from every obstacle: the best \
             leaves link {} {c:.3} m from obstacle {}",
            l + 1,
            o + 1
        ),
        (0, _) => format!(
            "at task time {t:.3} s the hand's target is out of reach or every posture breaks a \
             joint limit"
        ),
        _ => format!(
            "clean postures exist at every phase, but none links round the period with joint \
             rates within {:.1} rad/s",
            s.max_rate
        ),
    };
    Blocked {
        reason,
        best_clearance: roomiest.map_or(f64::NEG_INFINITY, |r| r.0),
        obstacle: roomiest.and_then(|r| r.1).map(|w| w.0),
        link: roomiest.and_then(|r| r.1).map(|w| w.1),
        task_time: t,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::secondary::Obstacle;

    fn paper(obstacles: &[(f64, f64, f64)]) -> PlanarProblem {
        let mut set = ObstacleSet::new();
        for &(x, y, r) in obstacles {
            set.push(Obstacle {
                center: Vec2::new(x, y),
                radius: r,
                margin: 0.1,
            })
            .unwrap();
        }
        PlanarProblem {
            links: [1.0; 3],
            task: Path::in_the_plane(crate::task::Shape::Circle, [1.0, 2.0], 0.5, 1.0),
            obstacles: set,
            clearance: 0.05,
            q_min: [f64::NEG_INFINITY; 3],
            q_max: [f64::INFINITY; 3],
            qd_max: [20.0; 3],
            t0: 0.0,
            q_now: Some([
                0.0,
                std::f64::consts::FRAC_PI_2,
                std::f64::consts::FRAC_PI_2,
            ]),
        }
    }

    fn hand(links: &[f64; 3], q: &[f64]) -> Vec2 {
        let (mut p, mut th) = (Vec2::zeros(), 0.0);
        for j in 0..3 {
            th += q[j];
            p += Vec2::new(th.cos(), th.sin()) * links[j];
        }
        p
    }

    /// The cycle tracks the path, keeps its clearance and rate bound, and closes.
    fn check(p: &PlanarProblem, s: &PlanSettings, c: &Cycle) {
        let n = c.q.len();
        let dt = c.period / n as f64;
        for (k, q) in c.q.iter().enumerate() {
            let want = p.task.at_xy(c.t0 + k as f64 * dt).0;
            assert!((hand(&p.links, q) - want).norm() < 1e-9, "phase {k}");
            let qa: [f64; 3] = [q[0], q[1], q[2]];
            assert!(p.clearance_of(&qa).0 >= p.clearance + s.margin, "phase {k}");
            let next = &c.q[(k + 1) % n];
            let stepped = (0..3)
                .map(|i| wrap_angle(next[i] - q[i]).abs())
                .fold(0.0, f64::max);
            assert!(stepped <= s.max_rate * dt + 1e-12, "phase {k}: {stepped}");
        }
        assert!(c.min_clearance >= p.clearance + s.margin);
        assert!(c.max_rate <= s.max_rate + 1e-9);
    }

    #[test]
    fn without_obstacles_a_cycle_near_the_arm_is_found() {
        let (mut p, s) = (paper(&[]), PlanSettings::default());
        // An arm on the path at t = 0, its last link at 1.3 rad, elbow right.
        let now = p.posture(p.task.at_xy(0.0).0, 1.3, -1.0).unwrap();
        p.q_now = Some(now);
        let PlanOutcome::Found(c) = plan(&p, &s) else {
            panic!("no cycle without obstacles")
        };
        check(&p, &s, &c);
        assert_eq!(c.min_clearance, f64::INFINITY);
        // It starts near the arm's posture (within a few grid steps of ψ).
        let d = (0..3)
            .map(|i| wrap_angle(c.q[0][i] - now[i]).abs())
            .fold(0.0, f64::max);
        assert!(d < 0.3, "{:?} vs {now:?}", c.q[0]);
    }

    #[test]
    fn round_the_obstacle_that_traps_the_filter_there_is_a_clean_cycle() {
        // The layout a user's `chaosctl obstacle add 0.9 1.1 0.15` made: the filter held the arm
        // 0.2 m off its path; a clean cycle exists.
        let (p, s) = (paper(&[(0.9, 1.1, 0.15)]), PlanSettings::default());
        let PlanOutcome::Found(c) = plan(&p, &s) else {
            panic!("no cycle round (0.9, 1.1)")
        };
        check(&p, &s, &c);
        assert!(c.min_clearance.is_finite());
    }

    #[test]
    fn an_obstacle_on_the_path_blocks_and_the_reason_names_it() {
        // A disc over the circle's right-hand point: the hand must pass through it.
        let p = paper(&[(3.0, 3.0, 0.3), (1.5, 2.0, 0.2)]);
        let PlanOutcome::Blocked(b) = plan(&p, &PlanSettings::default()) else {
            panic!("a cycle through an obstacle")
        };
        assert_eq!(b.obstacle, Some(1), "{b:?}");
        assert_eq!(b.link, Some(2), "{b:?}");
        assert!(b.best_clearance < 0.07, "{b:?}");
        assert!(b.reason.contains("obstacle 2"), "{}", b.reason);
        assert!(
            b.task_time.abs() < 0.1 || (b.task_time - 1.0).abs() < 0.1,
            "{b:?}"
        );
    }

    #[test]
    fn joint_rates_bound_the_cycle() {
        // The task alone moves the joints at a few rad/s: a bound below that leaves no cycle,
        // and the reason says it is the rate, not the room.
        let p = paper(&[]);
        let s = PlanSettings {
            max_rate: 0.5,
            ..PlanSettings::default()
        };
        let PlanOutcome::Blocked(b) = plan(&p, &s) else {
            panic!("a cycle at 0.5 rad/s")
        };
        assert!(b.reason.contains("joint rates"), "{}", b.reason);
    }

    #[test]
    fn the_cycle_passes_through_its_phases_smoothly_and_periodically() {
        let (p, s) = (paper(&[]), PlanSettings::default());
        let PlanOutcome::Found(c) = plan(&p, &s) else {
            panic!()
        };
        let table = super::super::CycleTable::<3>::new(&c).unwrap();
        let dt = c.period / c.q.len() as f64;
        for k in [0, 3, 17, 63] {
            let q = table.sample(c.t0 + k as f64 * dt).q;
            assert!(
                (0..3).all(|i| wrap_angle(q[i] - c.q[k][i]).abs() < 1e-12),
                "{k}"
            );
        }
        // C²: rate and acceleration agree either side of a phase.
        let (a, b) = (
            table.sample(c.t0 + 5.0 * dt - 1e-9),
            table.sample(c.t0 + 5.0 * dt + 1e-9),
        );
        assert!(
            (0..3).all(|i| (a.qd[i] - b.qd[i]).abs() < 1e-5 && (a.qdd[i] - b.qdd[i]).abs() < 1e-3)
        );
        // The rate is the posture's derivative.
        let h = 1e-6;
        let (m, l, r) = (
            table.sample(c.t0 + 3.3 * dt),
            table.sample(c.t0 + 3.3 * dt - h),
            table.sample(c.t0 + 3.3 * dt + h),
        );
        assert!((0..3).all(|i| (wrap_angle(r.q[i] - l.q[i]) / (2.0 * h) - m.qd[i]).abs() < 1e-5));
        assert!((0..3).all(|i| ((r.qd[i] - l.qd[i]) / (2.0 * h) - m.qdd[i]).abs() < 1e-3));
        // Periodic: a period later, the same posture, rate and acceleration.
        let (x, y) = (
            table.sample(c.t0 + 3.5 * dt),
            table.sample(c.t0 + 3.5 * dt + c.period),
        );
        assert!((0..3).all(|i| wrap_angle(x.q[i] - y.q[i]).abs() < 1e-9
            && (x.qd[i] - y.qd[i]).abs() < 1e-9
            && (x.qdd[i] - y.qdd[i]).abs() < 1e-6));
    }
}
