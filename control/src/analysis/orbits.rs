//! Period-T orbits of the uncontrolled arm, their Floquet multipliers, and their stability under
//! Pyragas feedback as μ varies.
//!
//! Pyragas control is non-invasive: on an orbit of period τ = T the term −μ[q̇(t) − q̇(t − T)]
//! vanishes, so the orbits it can stabilise are exactly the period-T orbits of the μ = 0 system.
//! Those are fixed points of the stroboscopic map Φ_T (integrate one period from t = 0; the circle's
//! phase is pinned by starting at t = 0 ≡ kT), found here by Newton's method on
//! F(x) = Φ_T(x) − x with angles compared modulo 2π. The Jacobian DΦ_T comes from central finite
//! differences; its eigenvalues are the orbit's Floquet multipliers at μ = 0.
//!
//! With μ ≠ 0 the closed loop is a delay equation with infinitely many multipliers, so stability is
//! judged by λ_max instead: a Benettin pair starts *on* the orbit with the orbit's own history
//! (the trajectory runs one period with the feedback off, which fills the delay line with the
//! orbit's q̇ over the last τ, and the feedback switches on at t = T), and λ_max < 0 means Pyragas
//! control stabilises the orbit at that μ. The reference is also watched: if it drifts away from
//! the orbit, the orbit is unstable whatever the average says.
//!
//! "Away" needs a tolerance well above the Newton residual. The simulated Pyragas term is not
//! exactly non-invasive: RK4's mid-stages read q̇(s − τ) by linear interpolation between stored
//! samples (docs/science.md, "Time, integration and determinism"), an O(dt²·|d³q/dt³|) error that the feedback multiplies by μ. The
//! controlled loop's orbit therefore sits a little off the μ = 0 orbit (about 4e-5 in the section
//! norm at μ = 0.2 with dt = 1 ms), and the default tolerance (1e-2) is far above that and far below
//! the size of the chaotic excursions.

use super::closed_loop::ArmFlow;
pub use super::floquet::multipliers;
use super::floquet::{
    delay_multipliers, section_rate, DelayMultipliers, FloquetError, FloquetSpec,
};
use super::lyapunov::{Benettin, LyapunovError, LyapunovEstimate, Trajectory};
use super::poincare::Section;
use super::run::period_steps;
use crate::arm::{ArmModel, VecN};
use crate::basics::wrap_angle;
use crate::law::LawParams;
use crate::sim::{ArmState, ClosedLoopLaw, Simulation};
use crate::tick_law::TickLaw;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// Why an orbit search or stability check failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum OrbitError {
    #[error("{0}")]
    Invalid(String),
    #[error("Newton's method did not converge: |Φ_T(x) − x| = {residual:.3e} after {iterations} iterations")]
    NotConverged { residual: f64, iterations: usize },
    #[error("Newton's method stalled: DΦ_T − I is singular (a Floquet multiplier at 1)")]
    Singular,
    #[error("the trajectory diverged (non-finite state)")]
    Diverged,
    #[error(transparent)]
    Lyapunov(#[from] LyapunovError),
    #[error(transparent)]
    Floquet(#[from] FloquetError),
}

/// Newton's method settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct NewtonConfig {
    /// Converged when |Φ_T(x) − x| ≤ tol.
    pub tol: f64,
    pub max_iter: usize,
    /// Finite-difference step for DΦ_T.
    pub fd_step: f64,
    /// Largest Newton step (trust region, in state-space norm).
    pub max_step: f64,
}

impl Default for NewtonConfig {
    fn default() -> Self {
        Self {
            tol: 1e-10,
            max_iter: 40,
            fd_step: 1e-6,
            max_step: 0.5,
        }
    }
}

/// A period-T orbit of the μ = 0 closed loop, given by its point on the section t = kT.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PeriodicOrbit {
    /// Joint angles at t = kT, wrapped into (−π, π].
    pub q: Vec<f64>,
    pub qd: Vec<f64>,
    /// |Φ_T(x) − x| at the solution.
    pub residual: f64,
    pub iterations: usize,
    /// Floquet multipliers at μ = 0 as (re, im), largest modulus first.
    pub multipliers: Vec<[f64; 2]>,
}

impl PeriodicOrbit {
    /// The largest multiplier's modulus.
    pub fn max_multiplier(&self) -> f64 {
        self.multipliers
            .first()
            .map(|m| m[0].hypot(m[1]))
            .unwrap_or(f64::NAN)
    }
    /// ln|largest multiplier| / T: the orbit's largest Lyapunov exponent at μ = 0.
    pub fn floquet_exponent(&self, period: f64) -> f64 {
        self.max_multiplier().ln() / period
    }
    /// What the leading Floquet multiplier says about the orbit at μ = 0: stable, elliptic,
    /// an unstable focus, hyperbolic (with the odd-number limitation of Pyragas control named).
    pub fn kind(&self) -> String {
        let Some(&[re, im]) = self.multipliers.first() else {
            return "unknown".into();
        };
        let m = re.hypot(im);
        let odd = self
            .multipliers
            .iter()
            .filter(|z| z[1].abs() < 1e-9 && z[0] > 1.0)
            .count()
            % 2
            == 1;
        if im.abs() > 1e-9 && (m - 1.0).abs() < 1e-4 {
            format!(
                "elliptic (|ρ| = 1, rotation {:.3} rad per period)",
                im.atan2(re).abs()
            )
        } else if m < 1.0 - 1e-4 {
            "stable".into()
        } else if im.abs() > 1e-9 {
            format!("unstable focus (|ρ| = {m:.3})")
        } else if re > 0.0 {
            format!(
                "hyperbolic (ρ = {re:.3}){}",
                if odd {
                    ", odd number of real ρ > 1: Pyragas control cannot stabilise it"
                } else {
                    ""
                }
            )
        } else {
            format!("hyperbolic with reflection (ρ = {re:.3})")
        }
    }

    pub fn coords(&self) -> Vec<f64> {
        self.q.iter().chain(&self.qd).copied().collect()
    }
    pub fn state<const N: usize>(&self) -> ArmState<N> {
        ArmState {
            q: VecN::<N>::from_column_slice(&self.q),
            qd: VecN::<N>::from_column_slice(&self.qd),
            phi: 0.0,
        }
    }
}

fn check_fixed<const N: usize, L: ClosedLoopLaw<N>>(law: &L) -> Result<(), OrbitError> {
    if law.is_floating() {
        return Err(OrbitError::Invalid(
            "period-T orbits need the fixed-base model: the floating base's attitude drifts, so its \
             motion does not close after one period"
                .into(),
        ));
    }
    Ok(())
}

fn to_state<const N: usize>(x: &DVector<f64>) -> ArmState<N> {
    ArmState {
        q: VecN::<N>::from_fn(|i, _| x[i]),
        qd: VecN::<N>::from_fn(|i, _| x[N + i]),
        phi: 0.0,
    }
}

/// The stroboscopic map of any arm's loop without feedback: `steps` steps (one task period)
/// from t = 0 and state `x`. On a period-T orbit the Pyragas term vanishes, so the orbits the
/// feedback can stabilise are this map's fixed points ([`newton_orbit`]).
pub fn stroboscopic_map<const N: usize, L: ClosedLoopLaw<N>>(
    law: &L,
    dt: f64,
    steps: u64,
    x: &ArmState<N>,
) -> ArmState<N> {
    let mut law = law.clone();
    law.core_mut().feedback = false;
    let tau = law.core().tau;
    let mut sim = Simulation::of(law, dt, *x, tau);
    for _ in 0..steps {
        sim.step();
    }
    *sim.state()
}

/// A stroboscopic map Φ_T of some arm's loop ([`stroboscopic_map`] of its law).
pub type PeriodMap<'a, const N: usize> = &'a dyn Fn(&ArmState<N>) -> ArmState<N>;

/// F(x) = Φ_T(x) − x with angle differences wrapped.
fn residual_map<const N: usize>(map: PeriodMap<N>, x: &DVector<f64>) -> DVector<f64> {
    let y = map(&to_state::<N>(x));
    DVector::from_fn(2 * N, |i, _| {
        if i < N {
            wrap_angle(y.q[i] - x[i])
        } else {
            y.qd[i - N] - x[i]
        }
    })
}

/// DΦ_T at `x` by central differences (2·2N evaluations of the map).
pub fn monodromy<const N: usize>(
    model: &ArmModel<N>,
    params: &LawParams,
    dt: f64,
    steps: u64,
    x: &ArmState<N>,
    h: f64,
) -> DMatrix<f64> {
    let law = TickLaw::Planar {
        model: *model,
        params: *params,
    };
    monodromy_of(&|y| stroboscopic_map(&law, dt, steps, y), x, h)
}

/// DΦ_T of any period map at `x` by central differences.
pub fn monodromy_of<const N: usize>(map: PeriodMap<N>, x: &ArmState<N>, h: f64) -> DMatrix<f64> {
    let base: Vec<f64> = x.q.iter().chain(x.qd.iter()).copied().collect();
    let mut m = DMatrix::zeros(2 * N, 2 * N);
    for j in 0..2 * N {
        let mut plus = DVector::from_column_slice(&base);
        let mut minus = plus.clone();
        plus[j] += h;
        minus[j] -= h;
        let (a, b) = (map(&to_state::<N>(&plus)), map(&to_state::<N>(&minus)));
        for i in 0..N {
            m[(i, j)] = wrap_angle(a.q[i] - b.q[i]) / (2.0 * h);
            m[(N + i, j)] = (a.qd[i] - b.qd[i]) / (2.0 * h);
        }
    }
    m
}

/// Newton's method on Φ_T(x) − x from `seed` for the planar arm (μ = 0; the fixed-base model
/// only): [`find_orbit_of`] its law.
pub fn find_orbit<const N: usize>(
    model: &ArmModel<N>,
    params: &LawParams,
    dt: f64,
    seed: &ArmState<N>,
    cfg: &NewtonConfig,
) -> Result<PeriodicOrbit, OrbitError> {
    let law = TickLaw::Planar {
        model: *model,
        params: *params,
    };
    find_orbit_of(&law, params.task.period, dt, seed, cfg)
}

/// Newton's method on Φ_T(x) − x from `seed` for any arm's law (a fixed base), T = `period`.
pub fn find_orbit_of<const N: usize, L: ClosedLoopLaw<N>>(
    law: &L,
    period: f64,
    dt: f64,
    seed: &ArmState<N>,
    cfg: &NewtonConfig,
) -> Result<PeriodicOrbit, OrbitError> {
    check_fixed(law)?;
    let steps = period_steps(period, dt).map_err(|e| OrbitError::Invalid(e.to_string()))?;
    newton_orbit(&|y| stroboscopic_map(law, dt, steps, y), seed, cfg)
}

/// Newton's method on Φ_T(x) − x from `seed`, for any arm's period map. Joint differences are
/// wrapped to (−π, π], as for revolute joints.
pub fn newton_orbit<const N: usize>(
    map: PeriodMap<N>,
    seed: &ArmState<N>,
    cfg: &NewtonConfig,
) -> Result<PeriodicOrbit, OrbitError> {
    let mut x = DVector::from_fn(2 * N, |i, _| if i < N { seed.q[i] } else { seed.qd[i - N] });
    let norm = |v: &DVector<f64>| {
        let n = v.norm();
        if n.is_finite() {
            n
        } else {
            f64::INFINITY
        }
    };
    let mut f = residual_map(map, &x);
    let mut r = norm(&f);
    let mut iterations = 0;
    while r > cfg.tol {
        if iterations == cfg.max_iter || !r.is_finite() {
            return Err(OrbitError::NotConverged {
                residual: r,
                iterations,
            });
        }
        iterations += 1;
        let jac = monodromy_of(map, &to_state::<N>(&x), cfg.fd_step)
            - DMatrix::<f64>::identity(2 * N, 2 * N);
        let mut step = jac.lu().solve(&(-&f)).ok_or(OrbitError::Singular)?;
        let len = step.norm();
        if !len.is_finite() {
            return Err(OrbitError::Singular);
        }
        if len > cfg.max_step {
            step *= cfg.max_step / len;
        }
        let mut alpha = 1.0;
        let mut accepted = false;
        for _ in 0..12 {
            let trial = &x + &step * alpha;
            let ft = residual_map(map, &trial);
            let rt = norm(&ft);
            if rt < r {
                x = trial;
                f = ft;
                r = rt;
                accepted = true;
                break;
            }
            alpha *= 0.5;
        }
        if !accepted {
            return Err(OrbitError::NotConverged {
                residual: r,
                iterations,
            });
        }
    }
    for i in 0..N {
        x[i] = wrap_angle(x[i]);
    }
    let state = to_state::<N>(&x);
    let m = monodromy_of(map, &state, cfg.fd_step);
    Ok(PeriodicOrbit {
        q: state.q.iter().copied().collect(),
        qd: state.qd.iter().copied().collect(),
        residual: r,
        iterations,
        multipliers: multipliers(&m)?,
    })
}

/// Distinct orbits by their section point (angles modulo 2π), numbered in order of discovery.
#[derive(Clone, Debug)]
pub struct OrbitCatalog {
    section: Section,
    tol: f64,
}

impl OrbitCatalog {
    /// Points closer than `tol` are the same orbit; `angles` leading coordinates are angles.
    pub fn new(dim: usize, angles: usize, tol: f64) -> Self {
        Self {
            section: Section::new(dim, angles),
            tol,
        }
    }
    pub fn find(&self, x: &[f64]) -> Option<usize> {
        (0..self.section.len())
            .find(|&i| self.section.distance(self.section.point(i), x) <= self.tol)
    }
    /// The orbit's index, and whether it is new.
    pub fn find_or_insert(&mut self, x: &[f64]) -> (usize, bool) {
        match self.find(x) {
            Some(i) => (i, false),
            None => {
                self.section.push(self.section.len() as f64, x);
                (self.section.len() - 1, true)
            }
        }
    }
    pub fn len(&self) -> usize {
        self.section.len()
    }
    pub fn is_empty(&self) -> bool {
        self.section.is_empty()
    }
    pub fn point(&self, i: usize) -> &[f64] {
        self.section.point(i)
    }
}

/// Indices k of the `count` closest returns |x_{k+1} − x_k| (local minima, closest first): the
/// classic seeds for a period-1 orbit search in a chaotic section.
pub fn close_returns(section: &Section, count: usize) -> Vec<usize> {
    let d = section.return_distances(1);
    let mut minima: Vec<(usize, f64)> = (0..d.len())
        .filter(|&i| (i == 0 || d[i] <= d[i - 1]) && (i + 1 == d.len() || d[i] <= d[i + 1]))
        .map(|i| (i, d[i]))
        .collect();
    minima.sort_by(|a, b| a.1.total_cmp(&b.1));
    minima.into_iter().take(count).map(|(i, _)| i).collect()
}

/// How to judge an orbit's stability at one μ.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct StabilitySpec {
    /// Time after the feedback switches on before averaging starts (s).
    pub settle: f64,
    /// Averaging window length (s).
    pub duration: f64,
    pub d0: f64,
    pub blocks: usize,
    /// The reference counts as having left the orbit beyond this section distance.
    pub leave_tol: f64,
}

impl Default for StabilitySpec {
    fn default() -> Self {
        Self {
            settle: 10.0,
            duration: 100.0,
            d0: 1e-8,
            blocks: 6,
            leave_tol: 1e-2,
        }
    }
}

/// The verdict on one orbit at one μ.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct OrbitStability {
    pub mu: f64,
    pub lyapunov: LyapunovEstimate,
    /// The leading Floquet multipliers of the delayed loop on the orbit (None at μ = 0, where
    /// the loop is not a delay equation: see [`PeriodicOrbit::multipliers`]).
    pub floquet: Option<DelayMultipliers>,
    /// How fast a small offset from the orbit shrinks (< 0) or grows, measured on the section
    /// x(kT) of a perturbed run (1/s); None when it could not be measured (the offset left the
    /// linear range or reached round-off within a few periods).
    pub section_rate: Option<f64>,
    /// First section time at which the reference was farther than `leave_tol` from the orbit.
    pub left_orbit_at: Option<f64>,
    /// Largest section distance of the reference from the orbit over the run.
    pub max_distance: f64,
    pub verdict: Verdict,
}

/// An orbit's stability at one μ.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    /// λ_max + 2·stderr < 0 and the reference stayed within `leave_tol` of the orbit.
    Stable,
    /// The reference left the orbit, or λ_max − 2·stderr > 0.
    Unstable,
    /// Neither: λ_max is within two standard errors of 0 (e.g. μ = 0 at an elliptic orbit).
    Marginal,
}

impl Verdict {
    pub fn label(&self) -> &'static str {
        match self {
            Verdict::Stable => "stable",
            Verdict::Unstable => "unstable",
            Verdict::Marginal => "marginal",
        }
    }
}

/// λ_max of the planar arm's loop at `params.mu`, starting on `orbit` with its own history:
/// [`orbit_stability_of`] its law.
pub fn orbit_stability<const N: usize>(
    model: &ArmModel<N>,
    params: &LawParams,
    dt: f64,
    orbit: &PeriodicOrbit,
    spec: &StabilitySpec,
) -> Result<OrbitStability, OrbitError> {
    let law = TickLaw::Planar {
        model: *model,
        params: *params,
    };
    orbit_stability_of(&law, params.task.period, dt, orbit, spec)
}

/// λ_max of any arm's loop at its own μ, starting on `orbit` (a period-T orbit of the loop
/// without feedback, T = `period`) with its own history: one period along the orbit with the
/// feedback off, so the delay line holds the orbit's past, then [`stability_on_orbit`].
pub fn orbit_stability_of<const N: usize, L: ClosedLoopLaw<N>>(
    law: &L,
    period: f64,
    dt: f64,
    orbit: &PeriodicOrbit,
    spec: &StabilitySpec,
) -> Result<OrbitStability, OrbitError> {
    check_fixed(law)?;
    let (tau, mu) = (law.core().tau, law.core().mu);
    check_stability_run(period, tau, dt, spec)?;
    let mut law = law.clone();
    law.core_mut().t_on = period;
    law.core_mut().auto_mu = None;
    let mut flow = ArmFlow::of(Simulation::of(law, dt, orbit.state::<N>(), tau));
    flow.advance_to(period);
    stability_on_orbit(flow, orbit, period, mu, spec)
}

/// The rules of a stability run: τ = T (so the feedback vanishes on a period-T orbit) and a
/// window of at least four periods.
pub fn check_stability_run(
    period: f64,
    tau: f64,
    dt: f64,
    spec: &StabilitySpec,
) -> Result<(), OrbitError> {
    let steps = period_steps(period, dt).map_err(|e| OrbitError::Invalid(e.to_string()))?;
    if ((tau / dt) - steps as f64).abs() > 1e-6 {
        return Err(OrbitError::Invalid(format!(
            "τ = {tau} s differs from the task period T = {period} s: the feedback does not vanish on a \
             period-T orbit, so these orbits are not orbits of the controlled loop"
        )));
    }
    if !(spec.settle >= 0.0 && spec.duration >= 4.0 * period && spec.d0 > 0.0 && spec.blocks >= 2) {
        return Err(OrbitError::Invalid(format!(
            "stability window: settle {} s ≥ 0, duration {} s ≥ 4 T, d0 > 0 and blocks ≥ 2 needed",
            spec.settle, spec.duration
        )));
    }
    Ok(())
}

/// The stability of `orbit` at gain `mu`, judged from `flow`, which ran one period along it with
/// the feedback off (so its delay line holds the orbit's own history) and switches the feedback
/// on now. Three measures that must agree: the leading Floquet multipliers of the delayed loop
/// ([`super::floquet`]), λ_max by Benettin's method, and the contraction rate of the section.
/// Any arm's loop ([`orbit_stability_of`]).
pub fn stability_on_orbit<const N: usize, L: ClosedLoopLaw<N>>(
    flow: ArmFlow<N, L>,
    orbit: &PeriodicOrbit,
    period: f64,
    mu: f64,
    spec: &StabilitySpec,
) -> Result<OrbitStability, OrbitError> {
    let steps =
        period_steps(period, flow.sim().dt()).map_err(|e| OrbitError::Invalid(e.to_string()))?;
    let floquet = if flow.has_delay_state() {
        Some(delay_multipliers(
            flow.sim(),
            steps,
            &FloquetSpec::default(),
        )?)
    } else {
        None
    };
    let section_rate = section_rate(flow.sim(), steps, spec.settle + spec.duration);
    let target = orbit.coords();
    let probe = Section::new(2 * N, N);
    let mut pair = Benettin::new(flow, spec.d0, period)?;
    let start = period + spec.settle;
    let end = start + spec.duration;
    let periods = (end / period).round() as u64;
    let mut left_orbit_at = None;
    let mut max_distance: f64 = 0.0;
    for k in 2..=periods {
        let t = k as f64 * period;
        pair.advance_to(t)?;
        let d = probe.distance(&pair.reference().coords(), &target);
        max_distance = max_distance.max(d);
        if left_orbit_at.is_none() && (d > spec.leave_tol || d.is_nan()) {
            left_orbit_at = Some(t);
        }
    }
    let lyapunov = pair.estimate(start, end, spec.blocks)?;
    let (l, se) = (lyapunov.lambda_max, lyapunov.stderr);
    let verdict = if left_orbit_at.is_some() || l - 2.0 * se > 0.0 {
        Verdict::Unstable
    } else if l + 2.0 * se < 0.0 {
        Verdict::Stable
    } else {
        Verdict::Marginal
    };
    Ok(OrbitStability {
        mu,
        lyapunov,
        floquet,
        section_rate,
        left_orbit_at,
        max_distance,
        verdict,
    })
}

#[cfg(test)]
mod tests {
    use super::PeriodicOrbit;

    fn orbit(multipliers: &[[f64; 2]]) -> PeriodicOrbit {
        PeriodicOrbit {
            q: vec![0.0; 3],
            qd: vec![0.0; 3],
            residual: 0.0,
            iterations: 1,
            multipliers: multipliers.to_vec(),
        }
    }

    #[test]
    fn an_orbit_is_named_by_its_leading_multipliers() {
        assert_eq!(orbit(&[]).kind(), "unknown");
        assert_eq!(orbit(&[[0.5, 0.0]]).kind(), "stable");
        let (c, s) = (1.24f64.cos(), 1.24f64.sin());
        assert_eq!(
            orbit(&[[c, s], [c, -s]]).kind(),
            "elliptic (|ρ| = 1, rotation 1.240 rad per period)"
        );
        assert_eq!(
            orbit(&[[1.2, 0.9], [1.2, -0.9]]).kind(),
            "unstable focus (|ρ| = 1.500)"
        );
        // One real multiplier above 1: Pyragas control cannot stabilise it (odd-number rule);
        // two can be.
        assert!(orbit(&[[2.0, 0.0]]).kind().contains("cannot stabilise"));
        assert_eq!(
            orbit(&[[2.0, 0.0], [1.5, 0.0]]).kind(),
            "hyperbolic (ρ = 2.000)"
        );
        assert_eq!(
            orbit(&[[-2.0, 0.0]]).kind(),
            "hyperbolic with reflection (ρ = -2.000)"
        );
    }
}
