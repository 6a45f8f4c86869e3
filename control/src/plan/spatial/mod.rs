//! The planner for a spatial arm: a clean periodic posture cycle for a URDF chain with several
//! redundant joints, found by optimisation in the null space.
//!
//! The planar arm's self-motion is one angle, so its planner can grid the whole (phase × angle)
//! cylinder and prove that no cycle exists. A 7-joint arm on a position task has four redundant
//! joints: no grid reaches that, so this planner samples and optimises. It rolls a cycle from a
//! start posture once round the path (the smallest joint motion at each phase), then relaxes it
//! ([`relax`]): each phase slides along its own self-motion, away from the spheres and the joint
//! limits and towards its neighbours, so the cycle closes and keeps its rates low. Starts are
//! the arm's own posture first, then postures spread over the joint box and put on the path.
//! The first cycle that passes [`check`] (margins at the phases, the filter's limits and
//! barrier rows on the loop's spline between them) is the plan.
//!
//! What this cannot do is prove that no cycle exists: `Blocked` here means that none of the
//! starts relaxed into a clean cycle, with the shortfall of the best one, unless the path
//! itself runs through a sphere, which it says as such. Like the planar planner it allocates
//! and takes milliseconds, off the loop.

mod check;
mod cost;
mod relax;

pub use check::{Fault, Shortfall, Verdict};
pub use cost::Nearest;

use super::{PlanOutcome, PlanSettings, Planned};
use crate::arm::spatial::SpatialArm;
use crate::arm::spatial::VecN;
use crate::basics::MAX_JOINTS;
use crate::law::spatial::SpatialParams;
use crate::steer::{Blocked, Cycle, CycleTable, SpatialSteer};

/// Sweeps of the relaxation per start, at most, and how often the cycle is judged.
const SWEEPS: usize = 400;
const JUDGE_EVERY: usize = 20;
/// Tool-path samples for the check that the path itself clears every sphere.
const PATH_SAMPLES: usize = 256;

/// What the spatial planner plans round: the arm and its law (the task, the spheres, the
/// filter's limits), run at step `dt`, from task time `t0` near posture `q_now`.
#[derive(Clone, Copy, Debug)]
pub struct SpatialProblem<const N: usize> {
    pub arm: SpatialArm<N>,
    pub law: SpatialParams,
    pub dt: f64,
    pub t0: f64,
    pub q_now: Option<VecN<N>>,
    /// The cycle the arm is steered along now, if it is: the first start, so that an edit's
    /// cycle is the nearest deformation of it that clears the new layout, and the arm, on the
    /// old cycle, is near the new one everywhere but where the layout changed.
    pub following: Option<CycleTable<MAX_JOINTS>>,
}

/// Where a relaxation starts.
#[derive(Clone, Debug)]
enum Start<const N: usize> {
    /// A cycle rolled once round the path from this posture.
    Posture(VecN<N>),
    /// The cycle the arm follows now.
    Following(Box<CycleTable<MAX_JOINTS>>),
}

/// Starts after the arm's own posture: postures spread over the joint box (a fixed sequence,
/// so a plan is the same every time).
fn spread<const N: usize>(p: &SpatialProblem<N>, count: usize) -> Vec<VecN<N>> {
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..count)
        .map(|_| {
            VecN::<N>::from_fn(|i, _| {
                let (lo, hi) = (
                    p.law.core.safety.q_min[i].max(-3.0),
                    p.law.core.safety.q_max[i].min(3.0),
                );
                let mid = 0.5 * (lo + hi);
                mid + (uniform() - 0.5) * 0.7 * (hi - lo)
            })
        })
        .collect()
}

impl<const N: usize> SpatialProblem<N> {
    /// How near the path itself comes to a sphere: the hand's link is on it wherever the arm
    /// is, so no cycle keeps more clearance than this. Returns (clearance (m), sphere, task
    /// time), None without spheres.
    fn path_clearance(&self) -> Option<(f64, usize, f64)> {
        let period = self.law.task.path.period;
        let reach = self.arm.radii[N - 1];
        let mut worst: Option<(f64, usize, f64)> = None;
        for k in 0..PATH_SAMPLES {
            let t = self.t0 + period * k as f64 / PATH_SAMPLES as f64;
            let x = self.law.task.path.position(t);
            for (i, s) in self.law.spheres.as_slice().iter().enumerate() {
                let c = (x - s.center).norm() - s.radius - reach;
                if worst.is_none_or(|w| c < w.0) {
                    worst = Some((c, i, t));
                }
            }
        }
        worst
    }

    /// No cycle at all: the path runs within the filter's clearance of a sphere.
    fn path_blocked(&self) -> Option<Blocked> {
        let (c, i, t) = self.path_clearance()?;
        let need = self.law.core.safety.clearance;
        (c < need).then(|| Blocked {
            reason: format!(
                "the path runs through obstacle {}: at task time {t:.3} s the hand's link {} \
                 would be {c:.3} m from it, and the filter keeps {need} m",
                i + 1,
                N,
            ),
            best_clearance: c,
            obstacle: Some(i),
            link: Some(N - 1),
            task_time: t,
        })
    }

    /// The settings' margin, less where the path itself leaves less (the hand cannot keep more
    /// than the path does: only the rest of the arm keeps the whole margin).
    fn margin_within_path(&self, s: &PlanSettings) -> PlanSettings {
        let room = self.path_clearance().map_or(f64::INFINITY, |(c, _, _)| {
            c - self.law.core.safety.clearance
        });
        PlanSettings {
            margin: s.margin.min(0.9 * room).max(0.0),
            ..*s
        }
    }

    /// The cycle a start gives before relaxing: rolled from a posture, or the cycle followed
    /// now, at this plan's phases and put on the path; None when it does not reach the path.
    fn initial<const M: usize>(&self, start: &Start<N>, phases: usize) -> Option<Vec<VecN<N>>> {
        match start {
            Start::Posture(q) => {
                let mut q0 = *q;
                if self.project::<M>(self.t0, &mut q0, 50, 1e-9) > 1e-6 {
                    return None;
                }
                self.roll_out::<M>(&q0, phases)
            }
            Start::Following(table) => (0..phases)
                .map(|k| {
                    let t = self.phase_time(k, phases);
                    let r = table.sample(t);
                    let mut q = VecN::<N>::from_fn(|i, _| r.q[i]);
                    (self.project::<M>(t, &mut q, 30, 1e-9) <= 1e-6).then_some(q)
                })
                .collect(),
        }
    }

    /// Relaxes the cycle `start` gives; returns the postures and their verdict.
    fn relax_from<const M: usize>(
        &self,
        start: &Start<N>,
        s: &PlanSettings,
    ) -> Option<(Vec<VecN<N>>, Verdict)> {
        let mut cycle = self.initial::<M>(start, s.phases)?;
        let mut verdict = self.check::<M>(&cycle, s);
        for sweep in 1..=SWEEPS {
            self.sweep::<M>(&mut cycle, s);
            if sweep % JUDGE_EVERY == 0 || sweep == SWEEPS {
                for (k, q) in cycle.iter_mut().enumerate() {
                    self.project::<M>(self.phase_time(k, s.phases), q, 5, 1e-12);
                }
                verdict = self.check::<M>(&cycle, s);
                if verdict.worst.is_none() {
                    break;
                }
            }
        }
        Some((cycle, verdict))
    }

    /// The starts near the arm (the cycle it follows, its posture), or the ones spread over
    /// the joint box.
    fn starts(&self, near: bool, s: &PlanSettings) -> Vec<Start<N>> {
        if near {
            let following = self.following.map(|c| Start::Following(Box::new(c)));
            following
                .into_iter()
                .chain(self.q_now.map(Start::Posture))
                .collect()
        } else {
            spread(self, s.candidates.max(1))
                .into_iter()
                .map(Start::Posture)
                .collect()
        }
    }

    /// Plans with settings `s` (their margin already within the path's,
    /// [`Self::margin_within_path`]) from the `near` starts or the others: the first clean
    /// cycle, or why there is none.
    fn plan<const M: usize>(&self, s: &PlanSettings, near: bool) -> PlanOutcome {
        let starts = self.starts(near, s);
        let mut best: Option<Shortfall> = None;
        let mut tried = 0;
        for start in &starts {
            let Some((cycle, verdict)) = self.relax_from::<M>(start, s) else {
                continue;
            };

            tried += 1;
            match verdict.worst {
                None => {
                    let q: Vec<Vec<f64>> = cycle.iter().map(|p| p.as_slice().to_vec()).collect();
                    return PlanOutcome::Found(self.cycle_of(&q, &verdict));
                }
                Some(w) if best.is_none_or(|b| w.by < b.by) => best = Some(w),
                Some(_) => {}
            }
        }
        PlanOutcome::Blocked(self.no_cycle(best, tried, starts.len()))
    }

    /// The planned cycle of postures `q` (one per phase) with verdict `v`'s numbers.
    fn cycle_of(&self, q: &[Vec<f64>], v: &Verdict) -> Cycle {
        Cycle {
            t0: self.t0,
            period: self.law.task.path.period,
            q: q.to_vec(),
            min_clearance: v.min_clearance,
            max_rate: v.max_rate,
            filter_margin: v.filter_margin,
            unreachable: None,
            arm_off_path: false,
            detour: None,
        }
    }

    /// Why none of the starts gave a clean cycle, in words: the best one's shortfall.
    fn no_cycle(&self, best: Option<Shortfall>, tried: usize, starts: usize) -> Blocked {
        let Some(w) = best else {
            return Blocked {
                reason: format!("none of {starts} starts puts the hand on the path"),
                best_clearance: f64::NAN,
                obstacle: None,
                link: None,
                task_time: self.t0,
            };
        };
        let (what, obstacle, link) = match w.fault {
            Fault::Sphere { sphere, link } => (
                format!(
                    "link {} comes {:.3} m too near obstacle {}",
                    link + 1,
                    w.by,
                    sphere + 1
                ),
                Some(sphere),
                Some(link),
            ),
            Fault::Braked { sphere, link } => (
                format!(
                    "the safety filter brakes the hand off its path (by {:.1e} m), link {} \
                     nearest obstacle {} (a slower task helps)",
                    w.by,
                    link + 1,
                    sphere + 1,
                ),
                Some(sphere),
                Some(link),
            ),
            Fault::Limit { joint } => (
                format!(
                    "joint {} comes {:.3} rad too near its limit",
                    joint + 1,
                    w.by
                ),
                None,
                None,
            ),
            Fault::Rate { joint } => (
                format!("joint {} moves {:.2} rad/s too fast", joint + 1, w.by),
                None,
                None,
            ),
            Fault::Path => ("the hand does not stay on the path".into(), None, None),
        };
        let mut kin = Default::default();
        let clearance = self.q_now.map_or(f64::NAN, |q| {
            self.kin(&q, &mut kin);
            self.nearest(&kin).clearance
        });
        Blocked {
            reason: format!(
                "no clean cycle found from {tried} starts on the path: the best one's worst \
                 point, at task time {:.3} s: {what}",
                w.t
            ),
            best_clearance: clearance,
            obstacle,
            link,
            task_time: w.t,
        }
    }
}

/// Plans for a spatial set-up from task time `t0` near posture `q_now` (joint values; more than
/// the arm's are ignored): with the default settings, then with the physical limits alone, as
/// the planar [`super::plan_config`] does.
pub fn plan_system(
    sys: &crate::system::SpatialSystem,
    t0: f64,
    q_now: Option<&[f64]>,
) -> Result<Planned, super::PlanError> {
    plan_system_with(sys, t0, q_now, None, &PlanSettings::default())
}

/// [`plan_system`] starting from the cycle the arm follows now, if it follows one
/// ([`SpatialProblem::following`]), with settings of one's own for the first try.
pub fn plan_system_with(
    sys: &crate::system::SpatialSystem,
    t0: f64,
    q_now: Option<&[f64]>,
    following: Option<&CycleTable<MAX_JOINTS>>,
    settings: &PlanSettings,
) -> Result<Planned, super::PlanError> {
    let dof = sys.chain.dof();
    if !(2..=crate::basics::MAX_JOINTS).contains(&dof) {
        return Err(super::PlanError::Joints(dof));
    }
    Ok(crate::with_dof!(dof, N => {
        let set = sys.config.setup::<N>(&sys.chain)?;
        let q = q_now.filter(|q| q.len() >= N).map(|q| VecN::<N>::from_fn(|i, _| q[i]));
        plan_setup(&set, t0, q, following, settings)
    }))
}

/// Plans for a built set-up (its arm, law and step) from task time `t0` near posture `q_now`.
pub fn plan_setup<const N: usize>(
    set: &crate::config::spatial::SpatialSetup<N>,
    t0: f64,
    q_now: Option<VecN<N>>,
    following: Option<&CycleTable<MAX_JOINTS>>,
    settings: &PlanSettings,
) -> Planned {
    // The cycle is one of the periodic loop: the path's start-up ramp is not part of it.
    let mut law = set.params;
    law.task.path = law.task.path.with_ramp(0.0);
    let problem = SpatialProblem::<N> {
        arm: set.arm,
        law,
        dt: set.dt,
        t0,
        q_now,
        following: following.copied(),
    };
    let (outcome, limits_only) =
        crate::with_task_rows!(problem.law.task.kind, |M| problem.plan_twice::<M>(settings));
    Planned {
        outcome,
        limits_only,
    }
}

impl<const N: usize> SpatialProblem<N> {
    /// The settings' plan, or failing that the plan within the physical limits alone (the
    /// strict plan's reason when neither finds one): from the starts near the arm first, then
    /// from the others. A cycle near the arm with less margin beats a far one with more: the
    /// arm gets to it without crossing the layout.
    fn plan_twice<const M: usize>(&self, s: &PlanSettings) -> (PlanOutcome, bool) {
        if let Some(b) = self.path_blocked() {
            return (PlanOutcome::Blocked(b), true);
        }
        let rate = (0..N)
            .map(|i| self.law.core.safety.qd_max[i])
            .fold(f64::INFINITY, f64::min);
        let loose = PlanSettings {
            candidates: s.candidates,
            ..PlanSettings::limits_only(rate.max(s.max_rate))
        };
        let (s, loose) = (&self.margin_within_path(s), self.margin_within_path(&loose));
        let mut first = None;
        for near in [true, false] {
            if near && self.following.is_none() && self.q_now.is_none() {
                continue;
            }
            for (settings, limits_only) in [(s, false), (&loose, true)] {
                match self.plan::<M>(settings, near) {
                    found @ PlanOutcome::Found(_) => return (found, limits_only),
                    blocked => {
                        first.get_or_insert(blocked);
                    }
                }
            }
        }
        (first.expect("one plan at least"), true)
    }
}
