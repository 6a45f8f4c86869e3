//! Judging a relaxed cycle as the loop will run it: the postures themselves with the margins,
//! then the loop's own spline between them against the filter's hard limits, then the law
//! itself, steered along the cycle for a period. A barrier row the cycle violates need not
//! take the hand off its path (the filter first tries the null space), so the law, not the
//! rows, decides: a cycle the filter brakes off the path is a trap by another name, and does
//! not count.

use super::SpatialProblem;
use crate::arm::spatial::CapsulePoints;
use crate::arm::spatial::SpatialKinematics;
use crate::arm::spatial::VecN;
use crate::plan::PlanSettings;
use crate::safety::rows::segment_row;
use crate::sim::Simulation;
use crate::steer::CycleTable;

/// Spline samples per span between two phases.
const SAMPLES: usize = 4;
/// The hand may miss the path at a phase by this much (m and rad): rounding, after the polish.
const PATH_TOL: f64 = 1e-6;
/// The steered law's check: its pull (Hz) and the tracking error it must keep (m).
const LAW_CHECK_HZ: f64 = 1.0;
const LAW_TRACK_TOL: f64 = 1e-4;

/// What keeps a cycle from being clean.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Fault {
    /// A link too near a sphere (0-based).
    Sphere { sphere: usize, link: usize },
    /// A joint too near its limit.
    Limit { joint: usize },
    /// A joint faster than the rate bound.
    Rate { joint: usize },
    /// The hand off its path (the relaxation did not converge).
    Path,
    /// The law, steered along the cycle, left its path: the filter braked it off (at the link
    /// and sphere nearest then), or the steering could not follow.
    Braked { sphere: usize, link: usize },
}

/// The worst shortfall of a cycle: what, by how much (in its own unit: m, rad, rad/s, m/s²;
/// > 0), and at what task time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shortfall {
    pub fault: Fault,
    pub by: f64,
    pub t: f64,
}

/// A cycle's numbers and its worst shortfall (None: clean).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Verdict {
    pub worst: Option<Shortfall>,
    pub min_clearance: f64,
    pub max_rate: f64,
    pub filter_margin: f64,
}

impl Verdict {
    fn note(&mut self, fault: Fault, by: f64, t: f64) {
        // Compared across units on purpose: any shortfall fails; the largest is the story.
        if by > 0.0 && self.worst.is_none_or(|w| by > w.by) {
            self.worst = Some(Shortfall { fault, by, t });
        }
    }
}

impl<const N: usize> SpatialProblem<N> {
    /// The rate bound a cycle keeps (rad/s): the settings' and a share of each joint's limit.
    pub(super) fn rate_bound(&self, s: &PlanSettings, i: usize) -> f64 {
        s.max_rate
            .min(s.rate_share * self.law.core.safety.qd_max[i])
    }

    /// Judges the postures `cycle` (one per phase) and the spline through them.
    pub fn check<const M: usize>(&self, cycle: &[VecN<N>], s: &PlanSettings) -> Verdict {
        let mut v = Verdict {
            worst: None,
            min_clearance: f64::INFINITY,
            max_rate: 0.0,
            filter_margin: f64::INFINITY,
        };
        let n = cycle.len();
        let dt = self.law.task.path.period / n as f64;
        let need = self.law.core.safety.clearance + s.margin;
        let mut kin = SpatialKinematics::<N>::default();
        for (k, q) in cycle.iter().enumerate() {
            let t = self.phase_time(k, n);
            let mut on = *q;
            v.note(
                Fault::Path,
                self.project::<M>(t, &mut on, 0, 0.0) - PATH_TOL,
                t,
            );
            self.kin(q, &mut kin);
            let near = self.nearest(&kin);
            let fault = Fault::Sphere {
                sphere: near.sphere,
                link: near.link,
            };
            v.note(fault, need - near.clearance, t);
            for i in 0..N {
                let lo = self.law.core.safety.q_min[i] + s.joint_margin;
                let hi = self.law.core.safety.q_max[i] - s.joint_margin;
                v.note(Fault::Limit { joint: i }, (lo - q[i]).max(q[i] - hi), t);
                let rate = (cycle[(k + 1) % n][i] - q[i]).abs() / dt;
                v.note(Fault::Rate { joint: i }, rate - self.rate_bound(s, i), t);
            }
        }
        let rows: Vec<[f64; N]> = cycle.iter().map(|q| (*q).into()).collect();
        match CycleTable::<N>::from_rows(self.t0, self.law.task.path.period, &rows) {
            Ok(table) => {
                self.check_spline(&table, &mut v);
                if v.worst.is_none() {
                    self.check_law(&rows, &mut v);
                }
            }
            Err(_) => v.note(Fault::Path, f64::INFINITY, self.t0),
        }
        v
    }

    /// Runs the law, steered along the cycle from its own state, for a period: the hand stays
    /// on the path (to 0.1 mm), or the cycle is no way out. The filter may leave the null space
    /// on the way: the barrier of the hand's own link, which no posture moves, can brake the
    /// hand a little where the path swings fast past a sphere. Without the delayed feedback,
    /// which vanishes on the cycle but not on the start's made-up history.
    fn check_law(&self, rows: &[[f64; N]], v: &mut Verdict) {
        let period = self.law.task.path.period;
        let wide: Vec<Vec<f64>> = rows.iter().map(|r| r.to_vec()).collect();
        let cycle = self.cycle_of(&wide, v);
        let Ok(steer) = super::SpatialSteer::of(&cycle, LAW_CHECK_HZ) else {
            return v.note(Fault::Path, f64::INFINITY, self.t0);
        };
        let mut law = self.law;
        law.steer = Some(steer);
        law.core.feedback = false;
        law.core.pause = false;
        let s = steer.cycle.sample(0.0);
        let (q0, qd0) = (
            VecN::<N>::from_fn(|i, _| s.q[i]),
            VecN::<N>::from_fn(|i, _| s.qd[i]),
        );
        let mut sim = Simulation::spatial(self.arm, law, self.dt, q0, qd0, law.core.tau);
        let mut kin = SpatialKinematics::<N>::default();
        for _ in 0..(period / self.dt).ceil() as u64 {
            let t = sim.time();
            let out = sim.step();
            if out.tracking_error > LAW_TRACK_TOL || !sim.state().is_finite() {
                self.kin(&sim.state().q, &mut kin);
                let near = self.nearest(&kin);
                let fault = Fault::Braked {
                    sphere: near.sphere,
                    link: near.link,
                };
                return v.note(fault, out.tracking_error.max(LAW_TRACK_TOL), t);
            }
        }
    }

    /// The loop's spline between the phases: the filter's hard limits and its barrier rows.
    fn check_spline(&self, table: &CycleTable<N>, v: &mut Verdict) {
        let n = table.rows().len();
        let dt = table.period / (n * SAMPLES) as f64;
        let mut kin = SpatialKinematics::<N>::default();
        let mut points = CapsulePoints::<N>::default();
        let gains = self.law.core.safety.gains();
        for k in 0..n * SAMPLES {
            let t = table.t0 + k as f64 * dt;
            let r = table.sample(t);
            let (q, qd, qdd) = (
                VecN::<N>::from(r.q),
                VecN::<N>::from(r.qd),
                VecN::<N>::from(r.qdd),
            );
            self.arm.kinematics(&q, &qd, &mut kin);
            let near = self.nearest(&kin);
            v.min_clearance = v.min_clearance.min(near.clearance);
            let fault = Fault::Sphere {
                sphere: near.sphere,
                link: near.link,
            };
            v.note(fault, self.law.core.safety.clearance - near.clearance, t);
            for i in 0..N {
                let out = (self.law.core.safety.q_min[i] - q[i])
                    .max(q[i] - self.law.core.safety.q_max[i]);
                v.note(Fault::Limit { joint: i }, out, t);
                v.max_rate = v.max_rate.max(qd[i].abs());
                v.note(
                    Fault::Rate { joint: i },
                    qd[i].abs() - self.law.core.safety.qd_max[i],
                    t,
                );
            }
            let links = self.arm.capsule_points(&kin, &qd, &mut points);
            for sphere in self.law.spheres.as_slice() {
                for j in 0..N {
                    let reach = sphere.radius + self.arm.radii[j] + self.law.core.safety.clearance;
                    let (a, b) = links.link(j);
                    let row = segment_row(a, b, sphere.center, reach, gains);
                    if let Some((_, a, b)) = row {
                        v.filter_margin = v.filter_margin.min(a.dot(&qdd) - b);
                    }
                }
            }
        }
    }
}
