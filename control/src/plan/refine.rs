//! Refining a planned cycle until the safety filter has nothing to do on it.
//!
//! The grid search finds a cycle that keeps every clearance at every phase, but the filter does
//! not judge postures: it judges each barrier's condition ḧ + k₁ḣ + k₀h ≥ 0 (and the joints'
//! rate and acceleration rows) at every instant. A grid walk has kinks between phases, and a
//! link that sweeps towards an obstacle faster than the barrier allows is braked off the cycle
//! even where it keeps its distance; the arm then rides the barrier, centimetres off its path,
//! instead of following the cycle. So the cycle is refined as the filter will see it: the loop's
//! own spline through the phases ([`super::CycleTable`]), sampled between phases, every row of
//! the filter ([`crate::safety::rows`]) evaluated on the spline's posture, rate and acceleration.
//!
//! Each phase's posture may slide along the arm's self-motion (the hand stays on its target).
//! Gauss–Newton with Levenberg damping lowers the rows' shortfall below a margin plus a little
//! acceleration (so the cycle stays smooth); a posture's slide changes the spline only near its
//! phase, so each column of the Jacobian costs a few phases' samples. Off the loop: it allocates.

use super::planar::PlanarProblem;
use super::{Cycle, CycleTable};
use crate::arm::{ArmModel, FixedArm, Kinematics, Vec2, VecN};
use crate::safety::rows::{self, PointMotion, Points};
use crate::safety::SafetyParams;
use nalgebra::{DMatrix, DVector};

/// How the refinement samples and weighs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefineSettings {
    /// Samples of the spline per phase.
    pub samples: usize,
    /// How far above its bound every row is asked to stay (the rows' units: m/s² for an
    /// obstacle, rad/s² for a joint; k₀ · 2 cm is 2 m/s² at the default gains).
    pub margin: f64,
    /// The weight of the cycle's acceleration against the rows' shortfall.
    pub smooth: f64,
    /// Gauss–Newton steps at most.
    pub iterations: usize,
}

impl Default for RefineSettings {
    fn default() -> Self {
        Self {
            samples: 6,
            margin: 2.0,
            smooth: 1e-6,
            iterations: 40,
        }
    }
}

/// A refined cycle and how well the filter's rows hold on it.
#[derive(Clone, Debug, PartialEq)]
pub struct Refined {
    pub cycle: Cycle,
    /// The row that comes closest to its bound over the sampled cycle.
    pub worst: Worst,
}

/// The row of the filter nearest its bound: how far above (negative: the filter acts), when,
/// and which row (`rows::visit`'s order: link j against obstacle o is row 3·o + j; then the
/// joints' own rows).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Worst {
    pub value: f64,
    pub t: f64,
    pub row: usize,
}

impl Worst {
    const NONE: Self = Self {
        value: f64::INFINITY,
        t: 0.0,
        row: 0,
    };

    fn min(self, o: Self) -> Self {
        if o.value < self.value {
            o
        } else {
            self
        }
    }

    /// The obstacle and link (0-based) of an obstacle row; None for a joint's own row.
    pub fn obstacle_link(&self, obstacles: usize) -> Option<(usize, usize)> {
        (self.row < 3 * obstacles).then_some((self.row / 3, self.row % 3))
    }
}

/// Phases on either side of a posture whose spline it moves (the interpolating spline's
/// influence falls by 0.27 a phase: beyond four, under 1 %).
const REACH: usize = 4;

struct Refiner<'a> {
    p: &'a PlanarProblem,
    safety: SafetyParams,
    model: ArmModel<3>,
    hands: Vec<Vec2>,
    base: Vec<[f64; 3]>,
    dirs: Vec<[f64; 3]>,
    dt: f64,
    s: RefineSettings,
    /// Residuals per sample: one per row (padded), then three for the acceleration.
    per_sample: usize,
}

impl<'a> Refiner<'a> {
    fn new(p: &'a PlanarProblem, safety: SafetyParams, c: &Cycle, s: RefineSettings) -> Self {
        let model = ArmModel::Fixed(FixedArm::new(p.links));
        let n = c.q.len();
        let dt = c.period / n as f64;
        let hands = (0..n)
            .map(|k| p.task.at_xy(c.t0 + k as f64 * dt).0)
            .collect();
        let base: Vec<[f64; 3]> = c.q.iter().map(|q| [q[0], q[1], q[2]]).collect();
        let mut r = Self {
            p,
            safety,
            model,
            hands,
            dirs: Vec::new(),
            base,
            dt,
            s,
            per_sample: 3 * p.obstacles.len() + 6 + 3,
        };
        r.dirs = r.base.iter().map(|q| r.null_dir(q)).collect();
        r
    }

    fn kin(&self, q: &[f64; 3]) -> Kinematics<3> {
        let mut kin = Kinematics::default();
        self.model
            .kinematics(0.0, &VecN::from(*q), &VecN::zeros(), &mut kin);
        kin
    }

    fn null_dir(&self, q: &[f64; 3]) -> [f64; 3] {
        let kin = self.kin(q);
        crate::safety::solve::null_vector(&kin.j).map_or([0.0; 3], |v| [v[0], v[1], v[2]])
    }

    /// Posture `k` slid by `x` along the self-motion, its hand put back on target.
    fn knot(&self, k: usize, x: f64) -> [f64; 3] {
        let mut q = [0.0; 3];
        for i in 0..3 {
            q[i] = self.base[k][i] + x * self.dirs[k][i];
        }
        for _ in 0..4 {
            let kin = self.kin(&q);
            let (jpinv, _, _) = crate::resolve::damped_pinv(&kin.j, 1e-3, 1e-3);
            let dq = jpinv * (self.hands[k] - kin.p);
            for i in 0..3 {
                q[i] += dq[i];
            }
        }
        q
    }

    fn table(&self, c: &Cycle, knots: &[[f64; 3]]) -> CycleTable {
        CycleTable::from_rows(c.t0, c.period, knots)
            .expect("a refined cycle has the planner's size")
    }

    /// The residuals of phase `k`'s samples into `out` (length `samples · per_sample`); returns
    /// the smallest row value above its bound.
    fn phase(&self, table: &CycleTable, k: usize, out: &mut [f64]) -> Worst {
        let mut worst = Worst::NONE;
        let w_smooth = self.s.smooth.sqrt();
        let obstacles = &self.p.obstacles;
        for j in 0..self.s.samples {
            let t = table.t0 + (k as f64 + j as f64 / self.s.samples as f64) * self.dt;
            let r = table.sample(t);
            let (q, qd, qdd) = (VecN::from(r.q), VecN::from(r.qd), VecN::from(r.qdd));
            let mut kin = Kinematics::<3>::default();
            self.model.kinematics(0.0, &q, &qd, &mut kin);
            let mut pts: Points<3> = [PointMotion::default(); crate::basics::MAX_JOINTS + 1];
            rows::point_motions(&self.model, &kin, 0.0, &q, &qd, &mut pts);
            let block = &mut out[j * self.per_sample..(j + 1) * self.per_sample];
            block.fill(0.0);
            let mut m = 0;
            let rows_len = self.per_sample - 3;
            rows::visit(
                &self.safety,
                obstacles,
                &pts,
                &q,
                &qd,
                &mut |a: &VecN<3>, b: f64| {
                    let above = a.dot(&qdd) - b;
                    worst = worst.min(Worst {
                        value: above,
                        t,
                        row: m,
                    });
                    if m < rows_len {
                        block[m] = (self.s.margin - above).max(0.0);
                    }
                    m += 1;
                },
            );
            for i in 0..3 {
                block[rows_len + i] = w_smooth * r.qdd[i];
            }
        }
        worst
    }

    fn block_len(&self) -> usize {
        self.s.samples * self.per_sample
    }

    /// Every phase's residuals, and the smallest row value.
    fn all(&self, table: &CycleTable, n: usize) -> (Vec<f64>, Worst) {
        let b = self.block_len();
        let mut out = vec![0.0; n * b];
        let mut worst = Worst::NONE;
        for k in 0..n {
            worst = worst.min(self.phase(table, k, &mut out[k * b..(k + 1) * b]));
        }
        (out, worst)
    }
}

impl Refiner<'_> {
    /// The refined cycle's clearance and fastest joint, measured on the spline as it runs.
    fn measure(&self, c: &mut Cycle) {
        let table = CycleTable::new(c).expect("a refined cycle has the planner's size");
        let n = c.q.len();
        let (mut clearance, mut rate) = (f64::INFINITY, 0.0f64);
        for i in 0..n * self.s.samples {
            let r = table.sample(c.t0 + i as f64 * self.dt / self.s.samples as f64);
            clearance = clearance.min(self.p.clearance_of(&r.q).0);
            rate = r.qd.iter().fold(rate, |m, v| m.max(v.abs()));
        }
        (c.min_clearance, c.max_rate) = (clearance, rate);
    }
}

fn cost(r: &[f64]) -> f64 {
    r.iter().map(|v| v * v).sum()
}

/// Refines planner's cycle `c` for `p` against the filter `safety`, or returns it unchanged
/// when refining does not lower its cost.
pub fn refine(p: &PlanarProblem, safety: &SafetyParams, c: &Cycle, s: &RefineSettings) -> Refined {
    let n = c.q.len();
    let rf = Refiner::new(p, *safety, c, *s);
    let b = rf.block_len();
    let mut x = vec![0.0; n];
    let knots_of = |x: &[f64]| -> Vec<[f64; 3]> { (0..n).map(|k| rf.knot(k, x[k])).collect() };
    let mut knots = knots_of(&x);
    let (mut r, mut worst) = rf.all(&rf.table(c, &knots), n);
    let mut f = cost(&r);
    let mut lambda = 1e-3;
    let window = |k: usize| (0..2 * REACH).map(move |d| (k + n + d - REACH) % n);
    let mut scratch = vec![0.0; b];
    for _ in 0..s.iterations {
        // Done when every row keeps its margin: the rest of the cost is smoothness alone.
        if n < 2 * REACH + 1 || worst.value >= s.margin {
            break;
        }
        // Jacobian columns: posture k's slide, over the phases it moves.
        let eps = 1e-5;
        let now = rf.table(c, &knots);
        let cols: Vec<Vec<f64>> = (0..n)
            .map(|k| {
                let moved = rf.knot(k, x[k] + eps);
                let table = now.nudged(k, &std::array::from_fn(|i| moved[i] - knots[k][i]));
                let mut col = vec![0.0; 2 * REACH * b];
                for (w, ph) in window(k).enumerate() {
                    rf.phase(&table, ph, &mut scratch);
                    for i in 0..b {
                        col[w * b + i] = (scratch[i] - r[ph * b + i]) / eps;
                    }
                }
                col
            })
            .collect();
        let mut jtj = DMatrix::<f64>::zeros(n, n);
        let mut jtr = DVector::<f64>::zeros(n);
        for k in 0..n {
            for (w, ph) in window(k).enumerate() {
                let ck = &cols[k][w * b..(w + 1) * b];
                jtr[k] += ck
                    .iter()
                    .zip(&r[ph * b..(ph + 1) * b])
                    .map(|(a, v)| a * v)
                    .sum::<f64>();
            }
            for d in 0..=(2 * REACH) {
                let l = (k + d) % n;
                if d > 0 && l == k {
                    break;
                }
                let mut v = 0.0;
                for (w, ph) in window(k).enumerate() {
                    if let Some(wl) = window(l).position(|q| q == ph) {
                        let (a, bb) =
                            (&cols[k][w * b..(w + 1) * b], &cols[l][wl * b..(wl + 1) * b]);
                        v += a.iter().zip(bb).map(|(u, t)| u * t).sum::<f64>();
                    }
                }
                jtj[(k, l)] = v;
                jtj[(l, k)] = v;
            }
        }
        let mut improved = false;
        for _ in 0..8 {
            let mut m = jtj.clone();
            for k in 0..n {
                m[(k, k)] += lambda * (1.0 + jtj[(k, k)]);
            }
            let Some(step) = m.cholesky().map(|ch| ch.solve(&(-&jtr))) else {
                lambda *= 10.0;
                continue;
            };
            let trial: Vec<f64> = x
                .iter()
                .zip(step.iter())
                .map(|(a, d)| a + d.clamp(-0.3, 0.3))
                .collect();
            let tk = knots_of(&trial);
            let (tr, tm) = rf.all(&rf.table(c, &tk), n);
            let tf = cost(&tr);
            if tf < f {
                (x, knots, r, worst, f) = (trial, tk, tr, tm, tf);
                lambda = (lambda * 0.3).max(1e-9);
                improved = true;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    let mut cycle = c.clone();
    cycle.q = knots.iter().map(|q| q.to_vec()).collect();
    cycle.filter_margin = worst.value;
    rf.measure(&mut cycle);
    Refined { cycle, worst }
}
