//! The chaos monitor: is the self-motion chaotic, converging or periodic, and on what evidence?
//!
//! The offline tools measure Lyapunov exponents with a model ([`crate::analysis`]); a running
//! daemon has only what its arm does. So the monitor works on the tick stream alone, once per
//! period τ (docs/monitor.md):
//! - the **period residual** |q̇(t) − q̇(t − τ)|, full and null-space, averaged over each period,
//!   and its trend (the per-period factor over the last few periods: below 1 it decays, and its
//!   rate is the leading Floquet multiplier);
//! - a **finite-time Lyapunov estimate** from the once-per-period returns of (q, q̇), a
//!   stroboscopic Poincaré map, by Rosenstein's method over a sliding window ([`rosenstein`]).
//!   Twelve returns are twelve periods; until they are there, the same map is read at
//!   [`PHASES`] phases of the path, each phase's samples paired only with their own phase and
//!   followed a whole period at a time, so that four periods of samples give an estimate and
//!   the first verdict comes within eight;
//! - the **0–1 test's K** on a scalar self-motion coordinate sampled at the returns
//!   ([`zero_one`]).
//!
//! The verdict, judged at every return ([`Verdict`]; the rule is in [`ChaosMonitor::judge`]),
//! changes only when the same new verdict comes twice in a row, so one lucky period does not
//! make an edge. The daemon runs it on its reporter thread (off the loop's core), the offline
//! study in the simulation: the same code, fed the same numbers. Memory is fixed at construction.

pub mod rosenstein;
pub mod run;
pub mod zero_one;

use crate::basics::MAX_JOINTS;
use serde::Serialize;
use std::collections::VecDeque;

/// The state a return records: q and q̇, zero-padded to the largest arm.
pub type Return = [f64; 2 * MAX_JOINTS];

/// What the self-motion is doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    /// Not enough periods yet, or evidence that does not agree.
    #[default]
    Unknown,
    Chaotic,
    Converging,
    /// Period τ: the delayed feedback vanishes on it.
    Periodic,
    /// Regular but not of period τ: another period, or quasi-periodic (K ≈ 0). The feedback
    /// keeps acting on it.
    Regular,
}

impl Verdict {
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Unknown => "unknown",
            Verdict::Chaotic => "chaotic",
            Verdict::Converging => "converging",
            Verdict::Periodic => "periodic",
            Verdict::Regular => "regular",
        }
    }

    /// A number for metrics: 0 unknown, 1 chaotic, 2 converging, 3 periodic, 4 regular.
    pub fn code(self) -> u32 {
        self as u32
    }

    /// The verdict of a code (unknown for codes a newer daemon may send).
    pub fn from_code(code: u32) -> Self {
        [
            Self::Chaotic,
            Self::Converging,
            Self::Periodic,
            Self::Regular,
        ]
        .into_iter()
        .find(|v| v.code() == code)
        .unwrap_or_default()
    }
}

/// The monitor's settings (`[monitor]` in the daemon's config).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct MonitorSettings {
    /// Returns kept for the 0–1 test (the Lyapunov estimate uses the newest [`LYAP_WINDOW`]).
    pub window: usize,
    /// Mean residual over a period (rad/s) below which the motion is periodic.
    pub periodic_residual: f64,
}

impl Default for MonitorSettings {
    fn default() -> Self {
        Self {
            window: 256,
            periodic_residual: PERIODIC_RESIDUAL,
        }
    }
}

/// The default periodic threshold (rad/s). A simulated orbit's residual falls to 1e-13; a live
/// one's stops at a few 1e-3, the noise of sampling a state up to a period late (q̈ · 1 ms);
/// chaos gives 1–10. So 2e-2 is far from both.
pub const PERIODIC_RESIDUAL: f64 = 2e-2;

/// Once periodic, the verdict stays so while the residual is below this many times the
/// threshold: a settled live arm's residual wanders about the threshold with timing noise (up
/// to 2.5e-2 seen on the planar arm), and the verdict must not flap with it; chaos is 40× above.
pub const LEAVE_PERIODIC: f64 = 5.0;

/// Once-a-period returns the Lyapunov estimate uses from the twelfth on (the newest ones: a
/// converging arm must not be judged by the chaos it left long ago); the 0–1 test's window holds
/// at least as many.
pub const LYAP_WINDOW: usize = 32;
/// Samples a period the Lyapunov estimate takes: the stroboscopic map at eight phases of the
/// path instead of one, so that a few periods hold enough pairs.
pub const PHASES: usize = 8;
/// Periods of samples the Lyapunov estimate uses (the newest ones: a converging arm must not be
/// judged by the chaos it left long ago).
pub const LYAP_PERIODS: usize = rosenstein::MIN_RETURNS;
/// How the Lyapunov estimate pairs its samples: a neighbour at the same phase at least a period
/// away, followed period by period for two periods; no estimate before four periods of samples
/// (the first verdict, confirmed, then comes at the fifth period).
pub const SAMPLING: rosenstein::Sampling = rosenstein::Sampling {
    phases: PHASES,
    apart: PHASES,
    horizon: 2,
    stride: PHASES,
    min_samples: 4 * PHASES,
};
/// Periods the residual trend is measured over.
pub const TREND: usize = 4;
/// A residual falling this many periods in a row converges whatever λ says (the Lyapunov
/// window still holds the chaos the arm is leaving).
pub const LONG_FALL: usize = 8;
/// Periods before any verdict.
pub const MIN_PERIODS: u64 = 3;
/// λ (1/s) beyond which the estimate counts as positive or negative.
pub const LAMBDA_TOL: f64 = 0.02;
/// K above which the 0–1 test says chaotic.
pub const K_CHAOTIC: f64 = 0.5;
/// K below which it says regular. Between the two the test is not sure on a window this short
/// (the planar arm's chaos gives 0.26–1.0 over 256 returns), and λ decides.
pub const K_REGULAR: f64 = 0.2;
/// The residual must fall by at least this factor per period to count as converging.
pub const CONVERGING_RATE: f64 = 0.9;

/// The evidence behind the newest verdict.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Default)]
pub struct Evidence {
    pub verdict: Verdict,
    /// Controller time (s) the verdict last changed.
    pub since: f64,
    /// Periods seen since the monitor (re)started.
    pub periods: u64,
    /// Returns in the window the 0–1 test used.
    pub window: usize,
    /// Mean |q̇(t) − q̇(t − τ)| over the last period (rad/s), and its null-space part.
    pub residual: f64,
    pub null_residual: f64,
    /// The residual's factor per period over the last [`TREND`] periods (< 1: decaying).
    pub residual_trend: Option<f64>,
    /// Finite-time largest Lyapunov estimate (1/s) from the newest returns.
    pub lambda: Option<f64>,
    /// The 0–1 test's K (≈ 1 chaotic, ≈ 0 regular).
    pub k: Option<f64>,
}

/// A verdict change, for the log and the event stream.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Edge {
    pub t: f64,
    pub from: Verdict,
    pub to: Verdict,
    pub evidence: Evidence,
}

/// The monitor (see the module docs).
#[derive(Clone, Debug)]
pub struct ChaosMonitor {
    settings: MonitorSettings,
    tau: f64,
    next_return: Option<f64>,
    next_sample: Option<f64>,
    /// The states at [`PHASES`] phases a period, newest [`LYAP_PERIODS`] periods.
    samples: VecDeque<Return>,
    /// The current period's sums: full residual, null-space residual, ticks.
    acc: (f64, f64, u64),
    returns: VecDeque<Return>,
    residuals: VecDeque<f64>,
    candidate: Verdict,
    evidence: Evidence,
    scratch_phi: Vec<f64>,
    scratch_k: Vec<f64>,
    scratch_returns: Vec<Return>,
}

impl ChaosMonitor {
    /// A monitor for period `tau` (s). Every buffer is sized here.
    pub fn new(settings: MonitorSettings, tau: f64) -> Self {
        let w = settings.window.max(LYAP_WINDOW);
        Self {
            settings,
            tau,
            next_return: None,
            next_sample: None,
            samples: VecDeque::with_capacity(PHASES * LYAP_PERIODS + 1),
            acc: (0.0, 0.0, 0),
            returns: VecDeque::with_capacity(w + 1),
            residuals: VecDeque::with_capacity(LONG_FALL + 2),
            candidate: Verdict::Unknown,
            evidence: Evidence::default(),
            scratch_phi: Vec::with_capacity(w),
            scratch_k: Vec::with_capacity(2 * w),
            scratch_returns: Vec::with_capacity(PHASES * LYAP_PERIODS),
        }
    }

    pub fn settings(&self) -> &MonitorSettings {
        &self.settings
    }

    /// Forgets everything from before `t` (an edit changed the system, or τ): the window starts
    /// again, the verdict is unknown until the evidence is back.
    pub fn restart(&mut self, t: f64, tau: f64) {
        let e = self.evidence;
        *self = Self {
            settings: self.settings,
            tau,
            next_return: None,
            next_sample: None,
            samples: std::mem::take(&mut self.samples),
            acc: (0.0, 0.0, 0),
            returns: std::mem::take(&mut self.returns),
            residuals: std::mem::take(&mut self.residuals),
            candidate: Verdict::Unknown,
            evidence: Evidence {
                verdict: Verdict::Unknown,
                since: if e.verdict == Verdict::Unknown {
                    e.since
                } else {
                    t
                },
                ..Evidence::default()
            },
            scratch_phi: std::mem::take(&mut self.scratch_phi),
            scratch_k: std::mem::take(&mut self.scratch_k),
            scratch_returns: std::mem::take(&mut self.scratch_returns),
        };
        self.returns.clear();
        self.samples.clear();
        self.residuals.clear();
    }

    pub fn evidence(&self) -> &Evidence {
        &self.evidence
    }

    pub fn tau(&self) -> f64 {
        self.tau
    }

    /// One tick the law ran on: time `t` (s), the state, and the law's residuals. At the end of
    /// each period it records a return and judges; returns the edge if the verdict changed.
    pub fn push(
        &mut self,
        t: f64,
        q: &[f64],
        qd: &[f64],
        residual: f64,
        null: f64,
    ) -> Option<Edge> {
        let next = *self.next_return.get_or_insert(t + self.tau);
        if residual.is_finite() && null.is_finite() {
            self.acc.0 += residual;
            self.acc.1 += null;
            self.acc.2 += 1;
        }
        self.sample(t, q, qd);
        if t < next {
            return None;
        }
        // A gap longer than a period (a pause, a stall) restarts the phase, not the history.
        self.next_return = Some(if t - next > self.tau {
            t + self.tau
        } else {
            next + self.tau
        });
        self.record(q, qd);
        self.judge(t)
    }

    /// Takes a sample at each of the [`PHASES`] phases of a period. A gap that skips a phase (a
    /// stall, a pause, ticks sparser than τ/8) starts the samples again from this tick: the
    /// estimate pairs samples by their index's phase, which a skipped phase would shift.
    fn sample(&mut self, t: f64, q: &[f64], qd: &[f64]) {
        let step = self.tau / PHASES as f64;
        let next = *self.next_sample.get_or_insert(t);
        if t < next {
            return;
        }
        if t - next >= step {
            self.samples.clear();
            self.next_sample = Some(t + step);
        } else {
            self.next_sample = Some(next + step);
        }
        push_bounded(&mut self.samples, state(q, qd), PHASES * LYAP_PERIODS);
    }

    fn record(&mut self, q: &[f64], qd: &[f64]) {
        let x = state(q, qd);
        push_bounded(&mut self.returns, x, self.settings.window.max(LYAP_WINDOW));
        let (full, null, ticks) = std::mem::take(&mut self.acc);
        let ticks = ticks.max(1) as f64;
        self.evidence.residual = full / ticks;
        self.evidence.null_residual = null / ticks;
        push_bounded(&mut self.residuals, self.evidence.residual, LONG_FALL + 1);
        self.evidence.periods += 1;
    }

    /// Measures the evidence and applies the rule:
    /// 1. fewer than [`MIN_PERIODS`] periods: unknown;
    /// 2. the last period's mean residual below `periodic_residual`, or below
    ///    [`LEAVE_PERIODIC`] times it while the verdict is periodic: periodic;
    /// 3. converging, when the residual fell in each of the last [`TREND`] periods, by
    ///    [`CONVERGING_RATE`] a period or faster, and λ is not positive; or fell in each of the
    ///    last [`LONG_FALL`] periods; or falls while λ is negative (chaos has runs of a few
    ///    falling periods too, but not with λ ≤ 0 or eight in a row);
    /// 4. K above [`K_CHAOTIC`]: chaotic; K below [`K_REGULAR`]: regular (another period, or
    ///    quasi-periodic: Rosenstein's λ over a few steps sees the linear drift on a torus as
    ///    growth, the 0–1 test does not);
    /// 5. no K yet or K between the two: λ above [`LAMBDA_TOL`] is chaotic (how chaos is told
    ///    within a few periods, before the 0–1 test has samples);
    /// 6. otherwise unknown (the evidence disagrees).
    ///
    /// A new verdict is taken when it comes twice in a row.
    fn judge(&mut self, t: f64) -> Option<Edge> {
        self.measure();
        let e = &self.evidence;
        let falls = falls(&self.residuals);
        let trend = e.residual_trend.unwrap_or(1.0);
        let lambda = e.lambda.unwrap_or(0.0);
        let converging = (falls >= TREND && trend <= CONVERGING_RATE && lambda <= LAMBDA_TOL)
            || falls >= LONG_FALL
            || (trend < 1.0 && lambda < -LAMBDA_TOL);
        let candidate = if e.periods < MIN_PERIODS {
            Verdict::Unknown
        } else if e.residual < self.settings.periodic_residual
            || (e.verdict == Verdict::Periodic
                && e.residual < LEAVE_PERIODIC * self.settings.periodic_residual)
        {
            Verdict::Periodic
        } else if converging {
            Verdict::Converging
        } else if e.k.is_some_and(|k| k > K_CHAOTIC) {
            Verdict::Chaotic
        } else if e.k.is_some_and(|k| k < K_REGULAR) {
            Verdict::Regular
        } else if lambda > LAMBDA_TOL {
            Verdict::Chaotic
        } else {
            Verdict::Unknown
        };
        let confirmed = candidate == self.candidate;
        self.candidate = candidate;
        let from = self.evidence.verdict;
        if !confirmed || candidate == from {
            return None;
        }
        self.evidence.verdict = candidate;
        self.evidence.since = t;
        Some(Edge {
            t,
            from,
            to: candidate,
            evidence: self.evidence,
        })
    }

    /// Residual trend, λ over the newest returns, K over the window.
    fn measure(&mut self) {
        let r = &self.residuals;
        self.evidence.residual_trend = (r.len() > TREND)
            .then(|| {
                let (old, new) = (r[r.len() - 1 - TREND], r[r.len() - 1]);
                (old > 0.0).then(|| (new / old).powf(1.0 / TREND as f64))
            })
            .flatten();
        // Until the window holds enough once-a-period returns, the samples at every phase.
        self.scratch_returns.clear();
        let lambda = if self.returns.len() < rosenstein::MIN_RETURNS {
            self.scratch_returns.extend(self.samples.iter());
            rosenstein::lyapunov_per_sample(&self.scratch_returns, &SAMPLING)
        } else {
            let newest = self.returns.len().saturating_sub(LYAP_WINDOW);
            self.scratch_returns
                .extend(self.returns.iter().skip(newest));
            rosenstein::lyapunov_per_step(&self.scratch_returns)
        };
        self.evidence.lambda = lambda.map(|l| l / self.tau);
        self.scratch_phi.clear();
        self.scratch_phi
            .extend(self.returns.iter().map(self_motion_coordinate));
        self.evidence.window = self.scratch_phi.len();
        self.evidence.k = zero_one::k_statistic(&self.scratch_phi, &mut self.scratch_k);
    }
}

/// q and q̇, zero-padded to the largest arm.
fn state(q: &[f64], qd: &[f64]) -> Return {
    let mut x: Return = [0.0; 2 * MAX_JOINTS];
    let n = q.len().min(MAX_JOINTS);
    x[..n].copy_from_slice(&q[..n]);
    x[MAX_JOINTS..MAX_JOINTS + n].copy_from_slice(&qd[..n]);
    x
}

/// A generic scalar of the posture at a return. At a return the hand is at the same point of
/// its path, so the posture differs from one return to the next only by self-motion; any
/// generic combination of the joints sees it.
fn self_motion_coordinate(x: &Return) -> f64 {
    x[..MAX_JOINTS]
        .iter()
        .enumerate()
        .map(|(i, v)| v / (i + 1) as f64)
        .sum()
}

/// How many periods in a row, up to the newest, the residual fell.
fn falls(r: &VecDeque<f64>) -> usize {
    let v: Vec<f64> = r.iter().rev().copied().collect();
    v.windows(2).take_while(|w| w[0] < w[1]).count()
}

fn push_bounded<T>(d: &mut VecDeque<T>, v: T, cap: usize) {
    if d.len() == cap {
        d.pop_front();
    }
    d.push_back(v);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds a monitor `periods` periods of a scalar map's orbit as the posture, one tick per
    /// period plus one between, with the residual `|x_{k} − x_{k−1}|`.
    fn run(map: impl Fn(f64) -> f64, x0: f64, periods: usize) -> (ChaosMonitor, Vec<Edge>) {
        let settings = MonitorSettings {
            periodic_residual: 1e-3,
            ..MonitorSettings::default()
        };
        let mut m = ChaosMonitor::new(settings, 1.0);
        let (mut x, mut prev) = (x0, x0);
        let mut edges = Vec::new();
        for k in 0..periods {
            let r = (x - prev).abs();
            for half in [0.0, 0.5] {
                let t = k as f64 + half;
                edges.extend(m.push(t, &[x, 0.3 * x], &[0.0, 0.0], r, r));
            }
            prev = x;
            x = map(x);
        }
        (m, edges)
    }

    #[test]
    fn logistic_chaos_is_chaotic_within_a_few_dozen_periods() {
        let (m, edges) = run(|x| 3.99 * x * (1.0 - x), 0.2, 200);
        let e = m.evidence();
        assert_eq!(e.verdict, Verdict::Chaotic, "{e:?}");
        assert!(e.k.unwrap() > 0.8 && e.lambda.unwrap() > 0.3, "{e:?}");
        assert!(
            edges[0].to == Verdict::Chaotic && edges[0].t < 20.0,
            "{edges:?}"
        );
    }

    #[test]
    fn a_contracting_map_converges_then_is_periodic() {
        let (m, edges) = run(|x| 0.5 + 0.6 * (x - 0.5), 0.9, 40);
        let seen: Vec<Verdict> = edges.iter().map(|e| e.to).collect();
        assert_eq!(seen, [Verdict::Converging, Verdict::Periodic], "{edges:?}");
        assert_eq!(m.evidence().verdict, Verdict::Periodic);
        let trend = edges[0].evidence.residual_trend.unwrap();
        assert!((trend - 0.6).abs() < 1e-6, "{trend}");
    }

    #[test]
    fn a_periodic_verdict_does_not_flap_with_a_residual_about_the_threshold() {
        let mut m = ChaosMonitor::new(MonitorSettings::default(), 1.0);
        let mut edges = Vec::new();
        // One return a period (t = k), the residual 1e-3, then wandering about 2e-2, then chaos.
        let residual = |k: usize| match k {
            0..20 => 1e-3,
            20..60 => [0.015, 0.025, 0.03, 0.018][k % 4],
            _ => 2.0,
        };
        for k in 0..70 {
            let x = [0.1 * (k as f64 * 0.7).sin()];
            edges.extend(m.push(k as f64, &x, &x, residual(k), residual(k)));
        }
        let seen: Vec<(Verdict, f64)> = edges.iter().map(|e| (e.to, e.t)).collect();
        assert_eq!(seen[0].0, Verdict::Periodic, "{seen:?}");
        assert_eq!(seen.len(), 2, "{seen:?}");
        assert!(
            seen[1].0 != Verdict::Periodic && seen[1].1 > 60.0,
            "{seen:?}"
        );
    }

    /// The logistic map's orbit as the posture, `ticks` ticks a period (the posture a smooth
    /// picture of the iterate at each phase), from the tick `skip` on every second tick lost.
    fn ticked(ticks: usize, periods: usize, skip: usize) -> ChaosMonitor {
        let mut m = ChaosMonitor::new(MonitorSettings::default(), 1.0);
        let mut x = 0.2;
        for k in 0..periods {
            for j in (0..ticks).filter(|j| k * ticks + j < skip || j % 2 == 0) {
                let phase = j as f64 / ticks as f64;
                let q = [x * (1.0 + phase), x * x];
                m.push(k as f64 + phase, &q, &[0.0, 0.0], 1.0, 1.0);
            }
            x = 3.99 * x * (1.0 - x);
        }
        m
    }

    #[test]
    fn chaos_is_told_within_eight_periods_from_samples_at_every_phase() {
        let m = ticked(16, 8, usize::MAX);
        let e = m.evidence();
        assert_eq!(e.verdict, Verdict::Chaotic, "{e:?}");
        assert!(e.lambda.unwrap() > 0.3, "{e:?}");
        // Ticks too sparse for eight phases (a skipped phase restarts the samples): no λ until
        // twelve once-a-period returns are there.
        let e = *ticked(8, 8, 8).evidence();
        assert_eq!((e.verdict, e.lambda), (Verdict::Unknown, None), "{e:?}");
        let e = *ticked(8, 14, 8).evidence();
        assert_eq!(e.verdict, Verdict::Chaotic, "{e:?}");
    }

    #[test]
    fn restart_forgets_the_window() {
        let (mut m, _) = run(|x| 3.99 * x * (1.0 - x), 0.2, 100);
        m.restart(100.0, 2.0);
        let e = m.evidence();
        assert_eq!(
            (e.verdict, e.periods, e.window, e.since),
            (Verdict::Unknown, 0, 0, 100.0)
        );
        assert_eq!(m.tau(), 2.0);
    }

    #[test]
    fn nan_residuals_are_skipped_not_averaged() {
        let mut m = ChaosMonitor::new(MonitorSettings::default(), 1.0);
        m.push(0.0, &[0.0], &[0.0], f64::NAN, 0.0);
        m.push(0.5, &[0.0], &[0.0], 0.2, 0.1);
        m.push(1.0, &[0.0], &[0.0], 0.2, 0.1);
        assert_eq!(m.evidence().residual, 0.2);
    }
}
