//! One analysed closed-loop run: the trajectory, optionally its Lyapunov partner, the
//! stroboscopic section and the run statistics, in a single pass.
//!
//! Every offline analysis (a λ_max estimate, a sweep cell, a basin cell, a Poincaré plot) is this
//! same run with different options, so they cannot disagree about what "the run" was.

use super::closed_loop::ArmFlow;
use super::lyapunov::{Benettin, Growth, LyapunovError, LyapunovEstimate, Trajectory};
use super::poincare::{classify, Classification, ClassifyConfig, Section};
use crate::arm::{ArmModel, Kinematics};
use crate::law::LawParams;
use crate::sim::{ArmState, ClosedLoopLaw, Summary};
use serde::Serialize;

/// Why an analysis could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum AnalysisError {
    #[error("{0}")]
    Invalid(String),
    #[error(
        "task unreachable: the circle spans {near:.3}..{far:.3} m from joint 1, but the arm reaches only \
         {inner:.3}..{outer:.3} m (links sum to {outer:.3} m)"
    )]
    Unreachable {
        near: f64,
        far: f64,
        inner: f64,
        outer: f64,
    },
    #[error("the simulation diverged (non-finite state) by t = {t} s")]
    Diverged { t: f64 },
    #[error(transparent)]
    Lyapunov(#[from] LyapunovError),
    #[error(transparent)]
    Config(#[from] crate::basics::ConfigError),
}

/// How to estimate λ_max during a run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LyapunovSpec {
    /// Initial (and renormalised) separation d₀.
    pub d0: f64,
    /// Renormalisation interval (s).
    pub renorm: f64,
    /// Averaging window [start, end] (s).
    pub window: [f64; 2],
    /// Blocks for the standard error.
    pub blocks: usize,
}

impl Default for LyapunovSpec {
    fn default() -> Self {
        Self {
            d0: 1e-8,
            renorm: 1.0,
            window: [100.0, 300.0],
            blocks: 10,
        }
    }
}

/// What to do in one run.
#[derive(Clone, Debug, PartialEq)]
pub struct RunSpec {
    /// Simulated time (s).
    pub duration: f64,
    /// The section records samples at t = kT ≥ this (s), and statistics start here.
    pub transient: f64,
    pub lyapunov: Option<LyapunovSpec>,
    pub classify: ClassifyConfig,
}

/// Everything one run measured.
#[derive(Clone, Debug, Serialize)]
pub struct RunAnalysis {
    pub lyapunov: Option<LyapunovEstimate>,
    /// ln(d/d₀) of every renormalisation interval of the whole run (empty without a pair).
    #[serde(skip)]
    pub growth: Vec<Growth>,
    pub classification: Classification,
    #[serde(skip)]
    pub section: Section,
    pub summary: Summary,
    /// The final state's coordinates: [φ (floating)], q, q̇.
    pub final_coords: Vec<f64>,
}

/// The number of integration steps in one task period; the section needs a whole number.
pub fn period_steps(period: f64, dt: f64) -> Result<u64, AnalysisError> {
    let r = period / dt;
    if !(r.is_finite() && r >= 1.0 && (r - r.round()).abs() <= 1e-6 * r) {
        return Err(AnalysisError::Invalid(format!(
            "the task period T = {period} s is not a whole number of steps of dt = {dt} s; \
             stroboscopic sampling at t = kT needs one"
        )));
    }
    Ok(r.round() as u64)
}

/// Checks that the task circle lies inside the annular workspace around joint 1 at the start.
pub fn check_reachable<const N: usize>(
    model: &ArmModel<N>,
    params: &LawParams,
    initial: &ArmState<N>,
) -> Result<(), AnalysisError> {
    let mut kin = Kinematics::default();
    model.kinematics(initial.phi, &initial.q, &initial.qd, &mut kin);
    let d = (params.task.center.xy() - kin.points[0]).norm();
    let (near, far) = ((d - params.task.radius).max(0.0), d + params.task.radius);
    let (inner, outer) = (model.inner_reach(), model.reach());
    if far < outer && near > inner {
        Ok(())
    } else {
        Err(AnalysisError::Unreachable {
            near,
            far,
            inner,
            outer,
        })
    }
}

impl RunSpec {
    /// Checks the spec against a period and step before anything runs.
    pub fn validate(&self, period: f64, dt: f64) -> Result<(), AnalysisError> {
        let bad = |m: String| Err(AnalysisError::Invalid(m));
        if !(self.duration.is_finite() && self.duration > 0.0) {
            return bad(format!(
                "duration {} s: must be a finite number > 0",
                self.duration
            ));
        }
        if !(self.transient.is_finite() && self.transient >= 0.0 && self.transient < self.duration)
        {
            return bad(format!(
                "transient {} s: must be in [0, duration = {} s)",
                self.transient, self.duration
            ));
        }
        period_steps(period, dt)?;
        if let Some(l) = &self.lyapunov {
            let [a, b] = l.window;
            if !(a.is_finite() && b.is_finite() && 0.0 <= a && a < b && b <= self.duration + 1e-9) {
                return bad(format!(
                    "window {a}:{b} s: must satisfy 0 ≤ start < end ≤ duration = {} s",
                    self.duration
                ));
            }
            if !(l.d0.is_finite() && l.d0 > 0.0 && l.d0 <= 1e-2) {
                return bad(format!("d0 = {}: must be in (0, 0.01]", l.d0));
            }
            if !(l.renorm.is_finite() && l.renorm >= dt && l.renorm * 4.0 <= b - a + 1e-9) {
                return bad(format!(
                    "renormalisation interval {} s: must be ≥ dt = {dt} s and fit at least 4 times in the window {a}:{b} s",
                    l.renorm
                ));
            }
            if l.blocks < 2 {
                return bad(format!("blocks = {}: must be at least 2", l.blocks));
            }
        }
        Ok(())
    }
}

/// Runs one analysed trajectory of the planar arm from `initial` at t = 0.
pub fn analyse<const N: usize>(
    model: ArmModel<N>,
    params: LawParams,
    dt: f64,
    initial: ArmState<N>,
    spec: &RunSpec,
) -> Result<RunAnalysis, AnalysisError> {
    analyse_flow(ArmFlow::new(model, params, dt, initial), spec)
}

/// Runs one analysed trajectory of any arm's closed loop, `flow` standing at t = 0: the planar
/// arm's [`analyse`] and a robot's are this one run, so a sweep cell, a basin cell and a λ_max
/// estimate mean the same on every arm.
pub fn analyse_flow<const N: usize, L: ClosedLoopLaw<N>>(
    flow: ArmFlow<N, L>,
    spec: &RunSpec,
) -> Result<RunAnalysis, AnalysisError> {
    let period = flow.sim().law.stats_setup().period;
    spec.validate(period, flow.sim().dt())?;
    let flow = flow.with_stats(spec.duration, spec.transient);
    let mut section = Section::new(flow.coords().len(), flow.angle_coords());
    let periods = (spec.duration / period + 1e-9).floor() as u64;
    let eps = 1e-9 * period;
    let mut record = |k: u64, f: &ArmFlow<N, L>| {
        let t = k as f64 * period;
        if t >= spec.transient - eps {
            section.push(t, &f.coords());
        }
    };
    let (flow, lyapunov, growth) = match &spec.lyapunov {
        Some(l) => {
            let mut pair = Benettin::new(flow, l.d0, l.renorm)?;
            record(0, pair.reference());
            for k in 1..=periods {
                pair.advance_to(k as f64 * period)?;
                record(k, pair.reference());
            }
            pair.advance_to(spec.duration)?;
            let est = pair.estimate(l.window[0], l.window[1], l.blocks)?;
            let growth = pair.growth().to_vec();
            (pair.into_reference(), Some(est), growth)
        }
        None => {
            let mut flow = flow;
            record(0, &flow);
            for k in 1..=periods {
                flow.advance_to(k as f64 * period);
                if !flow.is_finite() {
                    return Err(AnalysisError::Diverged { t: flow.time() });
                }
                record(k, &flow);
            }
            flow.advance_to(spec.duration);
            (flow, None, Vec::new())
        }
    };
    if !flow.is_finite() {
        return Err(AnalysisError::Diverged { t: flow.time() });
    }
    let classification = classify(&section, &spec.classify);
    let summary = flow
        .stats()
        .map(|s| s.summary())
        .ok_or_else(|| AnalysisError::Invalid("run statistics missing".into()))?;
    Ok(RunAnalysis {
        lyapunov,
        growth,
        classification,
        section,
        summary,
        final_coords: flow.coords(),
    })
}
