//! The Pyragas gain chosen from the model (docs/monitor.md, "The gain from the model").
//!
//! The speed-gradient law ([`crate::adapt`]) finds a gain by trying: it raises μ while the motion
//! is not periodic, so it learns only from the plant, slowly, and on an arm it was not calibrated
//! for it can sweep past every gain that works. The daemon has a model of its arm, so it can ask
//! the question directly. The feedback vanishes on a period-T orbit, so the cycles it can make
//! stable are the period-T orbits of the loop without it; on such an orbit the loop with the
//! feedback is a delay equation whose leading Floquet multiplier ρ₁(μ) says whether the arm
//! converges onto the cycle at gain μ (|ρ₁| < 1) and how fast ([`crate::analysis::floquet`]).
//! So: find the cycle the set-up settles on (Newton's method on the period map, seeded from where
//! the arm is or from a run of the set-up), compute |ρ₁(μ)| over the gains it allows, and take
//! the smallest gain that converges nearly as fast as the fastest ([`KNEE`]).
//!
//! Why not the fastest itself: |ρ₁| says how fast an arm *near* the cycle converges, not from how
//! far it is caught. Its minimum is a broad plateau (on the planar arm, −0.29 to −0.32 /s from
//! μ = 0.15 to 0.27), and at its far end the cycle's basin collapses: at fixed μ = 0.23, the
//! fastest, 6 of 8 chaotic starts were still chaotic after 600 s, while μ = 0.1 caught 8 of 8
//! (`chaosctl monitor`, docs/monitor.md). The smallest gain on the plateau keeps nearly all of
//! the rate and the most of the basin.
//!
//! |ρ₁(μ)| is not convex (two multipliers trade places as μ grows), so a coarse grid over
//! (0, max_mu], geometric so that a generous bound does not step over the small gains, finds the
//! best neighbourhood and a golden-section search refines within it: the
//! chosen gain is the analysis's minimum, not a grid step.
//!
//! This allocates and takes from a fraction of a second (the planar arm) to seconds (a 7-joint
//! arm): the daemon runs it on a thread of its own, never on the loop, and the offline
//! `chaosctl tune` calls the same function.

use crate::analysis::{
    delay_multipliers, find_orbit_of, period_steps, FloquetSpec, NewtonConfig, OrbitError,
    PeriodicOrbit,
};
use crate::basics::number::short;
use crate::sim::{ArmState, ClosedLoopLaw, Simulation};
use crate::system::System;
use serde::Serialize;

/// The smallest gain on the search's grid (1/s): below it the feedback's time constant is
/// longer than a minute of running, too slow to be the fastest convergence.
pub const SMALLEST_GRID_GAIN: f64 = 0.02;

/// The chosen gain is the smallest whose rate ln|ρ₁|/T is at least this share of the fastest
/// rate found (see the module docs).
pub const KNEE: f64 = 0.8;

/// Bisection steps that place the knee between two gains of the scan.
const KNEE_STEPS: usize = 5;

/// How the gain is searched for.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TuneSpec {
    /// The largest gain considered (`feedback.max_mu`).
    pub max_mu: f64,
    /// Gains of the coarse grid over (0, max_mu]; μ = 0 is always tried too.
    pub grid: usize,
    /// Golden-section steps around the best grid gain.
    pub refine: usize,
    /// The most periods a seeding run lasts (it stops once settled); Newton's method starts
    /// from its closest return.
    pub settle_periods: u64,
    /// The gain of the first seeding run (the second runs at `max_mu`).
    pub seed_mu: f64,
}

impl TuneSpec {
    /// The search a set-up asks for: up to its `max_mu` (or the default bound), seeded at its own
    /// gain when that is positive, else at half the bound.
    pub fn of(system: &System) -> Self {
        let fb = system.feedback();
        let max_mu = fb
            .auto
            .map_or(crate::adapt::DEFAULT_MAX_MU.max(fb.mu), |a| a.max_mu);
        let seed_mu = if fb.mu > 0.0 && fb.mu <= max_mu {
            fb.mu
        } else {
            0.5 * max_mu
        };
        Self {
            max_mu,
            grid: 8,
            refine: 6,
            settle_periods: 300,
            seed_mu,
        }
    }

    /// The coarse grid's gains, rising to `max_mu`: geometric from the smaller of
    /// [`SMALLEST_GRID_GAIN`] and `max_mu / grid`, so that a generous bound still looks closely
    /// at the small gains where the best one usually is (a linear grid up to 100 stepped over
    /// the paper's valley at 0.23 and settled on 1.8).
    ///
    /// ```
    /// # use control::tune::TuneSpec;
    /// # let spec = TuneSpec { max_mu: 100.0, grid: 8, refine: 6, settle_periods: 300, seed_mu: 1.0 };
    /// let g = spec.grid_gains();
    /// assert_eq!(g.len(), 8);
    /// assert!((g[0] - 0.02).abs() < 1e-12 && g[7] == 100.0);
    /// assert!(g.iter().any(|&mu| (0.1..0.5).contains(&mu)));
    /// ```
    pub fn grid_gains(&self) -> Vec<f64> {
        let top = self.max_mu;
        if self.grid == 1 {
            return vec![top];
        }
        let low = SMALLEST_GRID_GAIN.min(top / self.grid as f64);
        let last = (self.grid - 1) as f64;
        (0..self.grid)
            .map(|k| match k {
                k if k + 1 == self.grid => top,
                k => low * (top / low).powf(k as f64 / last),
            })
            .collect()
    }

    fn check(&self) -> Result<(), TuneError> {
        let bad = if !(self.max_mu.is_finite() && self.max_mu > 0.0 && self.max_mu <= 100.0) {
            format!("max_mu = {} must be in (0, 100]", short(self.max_mu))
        } else if !(self.seed_mu.is_finite() && self.seed_mu >= 0.0) {
            format!("the seeding gain {} must be ≥ 0", self.seed_mu)
        } else if !(1..=64).contains(&self.grid) {
            format!("grid = {} must be 1 to 64 gains", self.grid)
        } else if self.refine > 64 {
            format!("refine = {} must be at most 64 steps", self.refine)
        } else if self.settle_periods > 10_000 {
            format!(
                "settle_periods = {} must be at most 10000",
                self.settle_periods
            )
        } else {
            return Ok(());
        };
        Err(TuneError::Invalid(format!("gain search: {bad}")))
    }
}

/// The leading multiplier at one gain.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct GainPoint {
    pub mu: f64,
    /// |ρ₁|: how much of an offset from the cycle is left after one period.
    pub multiplier: f64,
    /// ln|ρ₁| / T (1/s): < 0 converges.
    pub rate: f64,
    /// Whether Arnoldi's method converged (always at μ = 0, where the map is finite).
    pub converged: bool,
}

/// Where Newton's method started.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum Seed {
    /// The state the caller gave (the daemon: the arm's newest return, at a whole period).
    Given,
    /// The closest return of a run of the set-up from its start at this gain.
    Settled { mu: f64 },
}

/// The gain the model recommends, and why.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GainChoice {
    /// The smallest gain with [`KNEE`] of the fastest rate.
    pub mu: f64,
    /// |ρ₁| at `mu`.
    pub multiplier: f64,
    /// ln|ρ₁| / T at `mu` (1/s).
    pub rate: f64,
    /// The task period T (s).
    pub period: f64,
    pub seed: Seed,
    /// The cycle the gain makes stable (its point at t = kT; its μ = 0 multipliers).
    pub orbit: PeriodicOrbit,
    /// Every gain tried, by μ.
    pub scanned: Vec<GainPoint>,
    /// The gain that converges fastest (its |ρ₁| the smallest found).
    pub fastest: GainPoint,
    /// The RMS joint speed |q̇| over the cycle (rad/s): the scale of a residual.
    pub speed: f64,
    /// The speed-gradient correction's γ for this gain and speed
    /// ([`crate::adapt::model_gamma`]; [`crate::adapt::DEFAULT_GAMMA`] on a cycle at rest).
    pub gamma: f64,
}

impl GainChoice {
    /// One line: the gain, how fast it converges and against what.
    ///
    /// ```
    /// use control::tune::{GainChoice, GainPoint, Seed};
    /// use control::analysis::PeriodicOrbit;
    /// let p = |mu: f64, m: f64| GainPoint { mu, multiplier: m, rate: m.ln(), converged: true };
    /// let c = GainChoice {
    ///     mu: 0.2, multiplier: 0.5, rate: 0.5f64.ln(), period: 1.0, seed: Seed::Given,
    ///     orbit: PeriodicOrbit { q: vec![0.0; 3], qd: vec![0.0; 3], residual: 1e-12,
    ///                            iterations: 3, multipliers: vec![[1.0, 0.0]] },
    ///     scanned: vec![p(0.0, 1.0), p(0.2, 0.5), p(0.3, 0.45), p(0.4, 0.9)],
    ///     fastest: p(0.3, 0.45), speed: 2.0, gamma: 2.5e-3,
    /// };
    /// assert_eq!(c.why(), "μ = 0.2: the cycle converges ×0.5 a period (-0.69/s), \
    ///     the smallest of 4 gains in [0, 0.4] with 80 % of the fastest rate \
    ///     (μ = 0.3: ×0.45, -0.80/s; ×1 at μ = 0); γ = 0.0025 for the cycle's 2 rad/s");
    /// ```
    pub fn why(&self) -> String {
        let top = self.scanned.iter().map(|p| p.mu).fold(0.0, f64::max);
        let at_zero = self
            .scanned
            .iter()
            .find(|p| p.mu == 0.0)
            .map_or(String::new(), |p| {
                format!("; ×{} at μ = 0", short(p.multiplier))
            });
        let f = &self.fastest;
        format!(
            "μ = {}: the cycle converges ×{} a period ({:.2}/s), the smallest of {} gains in \
             [0, {}] with {:.0} % of the fastest rate (μ = {}: ×{}, {:.2}/s{at_zero}); γ = {} \
             for the cycle's {} rad/s",
            short(self.mu),
            short(self.multiplier),
            self.rate,
            self.scanned.len(),
            short(top),
            100.0 * KNEE,
            short(f.mu),
            short(f.multiplier),
            f.rate,
            short(self.gamma),
            short(self.speed)
        )
    }
}

/// Why no gain could be chosen.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TuneError {
    /// The set-up is not one whose gain this can choose (the message says why).
    #[error("{0}")]
    Invalid(String),
    #[error("no period-T cycle found: {0}")]
    NoCycle(String),
    #[error(
        "no gain in [0, {}] makes the cycle stable: the best, μ = {}, leaves ×{} of an offset a period",
        short(*max_mu),
        short(best.mu),
        short(best.multiplier)
    )]
    NoStableGain { best: GainPoint, max_mu: f64 },
    #[error("the loop diverged while its multipliers were computed")]
    Diverged,
}

/// Periods after which a search that found no cycle to stabilise is tried again, seeded with
/// the arm's state then: a chaotic arm wanders past other cycles, and Newton's method finds
/// the one nearest the seed.
pub const RETRY_PERIODS: i64 = 2;

/// The most such retries after a start or an edit.
pub const MAX_RETRIES: u32 = 30;

impl TuneError {
    /// Whether a search from another state of the arm may find what this one did not (a
    /// cycle, or one a gain makes stable); not for a set-up that has no gain to choose.
    ///
    /// ```
    /// use control::tune::TuneError;
    /// assert!(TuneError::NoCycle("far".into()).worth_retrying());
    /// assert!(!TuneError::Invalid("the feedback is off".into()).worth_retrying());
    /// ```
    pub fn worth_retrying(&self) -> bool {
        !matches!(self, TuneError::Invalid(_))
    }

    /// When to search again after this error at period index `period`, the `tries`-th retry
    /// so far: (the period index, the retries then), or None when it is not worth it or the
    /// retries ran out ([`RETRY_PERIODS`], [`MAX_RETRIES`]). The daemon and the offline
    /// monitor both ask this.
    ///
    /// ```
    /// use control::tune::{TuneError, MAX_RETRIES, RETRY_PERIODS};
    /// let far = TuneError::NoCycle("far".into());
    /// assert_eq!(far.retry(10, 0), Some((10 + RETRY_PERIODS, 1)));
    /// assert_eq!(far.retry(10, MAX_RETRIES), None);
    /// assert_eq!(TuneError::Invalid("off".into()).retry(10, 0), None);
    /// ```
    pub fn retry(&self, period: i64, tries: u32) -> Option<(i64, u32)> {
        (self.worth_retrying() && tries < MAX_RETRIES)
            .then_some((period + RETRY_PERIODS, tries + 1))
    }
}

/// Arnoldi's settings for the search: the leading pair only, to 1e-5.
const FLOQUET: FloquetSpec = FloquetSpec {
    count: 2,
    max_krylov: 80,
    tol: 1e-5,
    fd_step: 1e-6,
};

/// The gain for the cycle the set-up settles on, by the model: the smallest that converges onto
/// it with [`KNEE`] of the fastest rate (see the module docs). `seed` is (q, q̇) at a whole number of periods (the daemon's newest return), tried first.
///
/// ```
/// use control::tune::{choose_gain, TuneSpec};
/// let system = control::System::preset("paper", &control::system::builtin_robot).unwrap();
/// let spec = TuneSpec { grid: 4, refine: 2, ..TuneSpec::of(&system) };
/// let c = choose_gain(&system, None, &spec).unwrap();
/// assert!(c.multiplier < 1.0 && c.mu > 0.0 && c.mu <= spec.max_mu, "{}", c.why());
/// ```
pub fn choose_gain(
    system: &System,
    seed: Option<&[f64]>,
    spec: &TuneSpec,
) -> Result<GainChoice, TuneError> {
    spec.check()?;
    let (fb, period, dt) = (system.feedback(), system.period(), system.sim_section().dt);
    if !system.feedback_section().enabled {
        return Err(TuneError::Invalid(
            "the delayed feedback is off (feedback.enabled = false): there is no gain to choose"
                .into(),
        ));
    }
    if (fb.tau - period).abs() > 1e-9 * period {
        return Err(TuneError::Invalid(format!(
            "τ = {} s differs from the task period T = {period} s: the feedback does not vanish on \
             a period-T cycle, so no cycle of the arm is the feedback's to stabilise",
            fb.tau
        )));
    }
    let steps = period_steps(period, dt).map_err(|e| TuneError::Invalid(e.to_string()))?;
    // Newton's period map runs from t = 0: without the start's ramp, as the arm runs later.
    let mut steady = system.clone();
    *steady.task_ramp_mut() = 0.0;
    crate::with_dof!(system.n(), N => {
        let search = Search {
            start: system.tick_law::<N>(),
            law: steady.tick_law::<N>(),
            x0: system.initial_state::<N>(),
            period,
            dt,
            steps,
            spec: *spec,
        };
        search.run(seed)
    })
}

/// The seeding runs tried after those at the seeding gain and at the bound have found no cycle
/// a gain makes stable, as shares of the seeding gain. Above the best gain the cycle's basin
/// shrinks (module docs): from the planar start (0.3, 1.2, 1.9) the runs at μ = 0.2 and 0.4
/// both end near a cycle no gain makes stable, and the run at 0.1 on the one the other starts
/// find. Tried only when the first ones fail, so they cost nothing where those work.
const LOWER_SEEDS: [f64; 2] = [0.5, 0.25];

/// Where Newton's method starts, in the order tried: the caller's state (the arm's own), then
/// runs of the set-up at the seeding gain, at the bound and at the [`LOWER_SEEDS`].
#[derive(Clone, Copy)]
enum Source {
    Given,
    Settle(f64),
}

/// Why one source gave no cycle (the search goes on to the next; all of them make
/// [`TuneError::NoCycle`]).
struct NotFound(String);

/// One gain search on one arm's law.
struct Search<const N: usize, L: ClosedLoopLaw<N>> {
    /// The law as the set-up starts (the seeding runs).
    start: L,
    /// The law at full speed (the period map).
    law: L,
    x0: ArmState<N>,
    period: f64,
    dt: f64,
    steps: u64,
    spec: TuneSpec,
}

impl<const N: usize, L: ClosedLoopLaw<N>> Search<N, L> {
    fn run(&self, given: Option<&[f64]>) -> Result<GainChoice, TuneError> {
        if self.law.is_floating() {
            return Err(TuneError::Invalid(
                "the floating base's attitude drifts, so its motion has no period-T cycle to \
                 stabilise: choose μ with `chaosctl sweep`"
                    .into(),
            ));
        }
        let mut tried = Vec::new();
        let mut unstable = None::<GainPoint>;
        let mut gains = vec![self.spec.seed_mu, self.spec.max_mu];
        gains.extend(LOWER_SEEDS.iter().map(|share| share * self.spec.seed_mu));
        gains.dedup();
        let settles = gains.into_iter().filter(|&mu| mu > 0.0).map(Source::Settle);
        for source in std::iter::once(Source::Given).chain(settles) {
            let (orbit, seed) = match self.cycle(source, given) {
                Some(Ok(found)) => found,
                Some(Err(NotFound(why))) => {
                    tried.push(why);
                    continue;
                }
                None => continue,
            };
            let mut scanned = self.scan(&orbit)?;
            let fastest = fastest(&scanned);
            if fastest.multiplier.is_nan() || fastest.multiplier >= 1.0 {
                // A cycle no gain makes stable (the arm near another one): the next source.
                if unstable.is_none_or(|u| fastest.multiplier < u.multiplier) {
                    unstable = Some(fastest);
                }
                continue;
            }
            let knee = self.knee(&orbit, &mut scanned, fastest)?;
            let speed = self.speed(&orbit);
            let gamma =
                crate::adapt::model_gamma(knee.mu, speed).unwrap_or(crate::adapt::DEFAULT_GAMMA);
            return Ok(GainChoice {
                mu: knee.mu,
                multiplier: knee.multiplier,
                rate: knee.rate,
                period: self.period,
                seed,
                orbit,
                scanned,
                fastest,
                speed,
                gamma,
            });
        }
        match unstable {
            Some(best) => Err(TuneError::NoStableGain {
                best,
                max_mu: self.spec.max_mu,
            }),
            None => Err(TuneError::NoCycle(tried.join("; "))),
        }
    }

    /// A period-T cycle by Newton's method from `source`: the given state, or the closest return
    /// of a run of the set-up at a gain. None when there is no given state to start from.
    fn cycle(
        &self,
        source: Source,
        given: Option<&[f64]>,
    ) -> Option<Result<(PeriodicOrbit, Seed), NotFound>> {
        match source {
            Source::Given => {
                let x = given.and_then(state_of::<N>)?;
                Some(
                    self.newton(&x)
                        .map(|o| (o, Seed::Given))
                        .map_err(|e| NotFound(format!("from the given state: {e}"))),
                )
            }
            Source::Settle(mu) => {
                let found = match self.settle(mu).map(|x| self.newton(&x)) {
                    Some(Ok(o)) => return Some(Ok((o, Seed::Settled { mu }))),
                    Some(Err(e)) => e.to_string(),
                    None => "the run diverged".to_string(),
                };
                Some(Err(NotFound(format!(
                    "from the closest return of a run of up to {} s at μ = {}: {found}",
                    self.spec.settle_periods as f64 * self.period,
                    short(mu)
                ))))
            }
        }
    }

    fn newton(&self, x: &ArmState<N>) -> Result<PeriodicOrbit, OrbitError> {
        let cfg = NewtonConfig {
            tol: 1e-9,
            ..NewtonConfig::default()
        };
        find_orbit_of(&self.law, self.period, self.dt, x, &cfg)
    }

    /// The closest return of a run of the set-up from its start at gain `mu`: x(kT) with the
    /// smallest |x(kT) − x((k − 1)T)| over at most `settle_periods` periods, the run stopping
    /// once a return is within 1e-6 of the one before (settled). None when it diverged first.
    fn settle(&self, mu: f64) -> Option<ArmState<N>> {
        let mut law = self.start.clone();
        let core = law.core_mut();
        (core.mu, core.t_on, core.feedback, core.auto_mu) = (mu, 0.0, true, None);
        let tau = law.core().tau;
        let mut sim = Simulation::of(law, self.dt, self.x0, tau);
        let (mut last, mut best) = (*sim.state(), None::<(f64, ArmState<N>)>);
        for _ in 0..self.spec.settle_periods {
            for _ in 0..self.steps {
                sim.step();
            }
            let x = *sim.state();
            if !x.is_finite() {
                break;
            }
            let d = ((x.q - last.q).map(crate::basics::wrap_angle).norm_squared()
                + (x.qd - last.qd).norm_squared())
            .sqrt();
            if best.is_none_or(|(b, _)| d < b) {
                best = Some((d, x));
            }
            if d < 1e-6 {
                break;
            }
            last = x;
        }
        best.map(|(_, x)| x)
    }

    /// |ρ₁| at μ = 0 and on the grid ([`TuneSpec::grid_gains`]), then a golden-section search
    /// between the best grid gain's neighbours; every gain tried, by μ.
    fn scan(&self, orbit: &PeriodicOrbit) -> Result<Vec<GainPoint>, TuneError> {
        let mut points = vec![self.at(orbit, 0.0)?];
        for mu in self.spec.grid_gains() {
            points.push(self.at(orbit, mu)?);
        }
        let best = (0..points.len())
            .min_by(|&a, &b| points[a].multiplier.total_cmp(&points[b].multiplier))
            .unwrap_or(0);
        let (mut a, mut b) = (
            points[best.saturating_sub(1)].mu,
            points[(best + 1).min(points.len() - 1)].mu,
        );
        // Golden section: keep the inner point with the smaller |ρ₁|.
        let g = 0.5 * (5f64.sqrt() - 1.0);
        let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
        let (mut fc, mut fd) = (None, None);
        for _ in 0..self.spec.refine {
            let pc = match fc {
                Some(p) => p,
                None => self.at(orbit, c)?,
            };
            let pd = match fd {
                Some(p) => p,
                None => self.at(orbit, d)?,
            };
            for p in [pc, pd] {
                if !points.contains(&p) {
                    points.push(p);
                }
            }
            if pc.multiplier <= pd.multiplier {
                (b, d, fd) = (d, c, Some(pc));
                c = b - g * (b - a);
                fc = None;
            } else {
                (a, c, fc) = (c, d, Some(pd));
                d = a + g * (b - a);
                fd = None;
            }
        }
        points.sort_by(|x, y| x.mu.total_cmp(&y.mu));
        points.dedup_by(|x, y| x.mu == y.mu);
        Ok(points)
    }

    /// The smallest positive gain whose rate is at least [`KNEE`] of `fastest`'s: the first such
    /// gain of the scan, moved down by bisection towards the scanned gain below it. The gains
    /// tried join `scanned`.
    fn knee(
        &self,
        orbit: &PeriodicOrbit,
        scanned: &mut Vec<GainPoint>,
        fastest: GainPoint,
    ) -> Result<GainPoint, TuneError> {
        let target = KNEE * fastest.rate;
        let good = |p: &GainPoint| p.mu > 0.0 && p.rate <= target;
        let Some(i) = scanned.iter().position(good) else {
            return Ok(fastest);
        };
        let (mut low, mut high) = (scanned[i.saturating_sub(1)].mu, scanned[i]);
        for _ in 0..KNEE_STEPS {
            let p = self.at(orbit, 0.5 * (low + high.mu))?;
            scanned.push(p);
            if good(&p) {
                high = p;
            } else {
                low = p.mu;
            }
        }
        scanned.sort_by(|x, y| x.mu.total_cmp(&y.mu));
        Ok(high)
    }

    /// The RMS of |q̇| over one period along `orbit` (rad/s; the feedback vanishes there).
    fn speed(&self, orbit: &PeriodicOrbit) -> f64 {
        let mut law = self.law.clone();
        law.core_mut().feedback = false;
        let tau = law.core().tau;
        let mut sim = Simulation::of(law, self.dt, orbit.state::<N>(), tau);
        let mut sum = 0.0;
        for _ in 0..self.steps {
            sim.step();
            sum += sim.state().qd.norm_squared();
        }
        (sum / self.steps as f64).sqrt()
    }

    /// The leading multiplier of the loop at gain `mu` on `orbit`: one period along it with the
    /// feedback off fills the delay line with the orbit's own history, then the feedback is on.
    fn at(&self, orbit: &PeriodicOrbit, mu: f64) -> Result<GainPoint, TuneError> {
        if mu == 0.0 {
            let m = orbit.max_multiplier();
            return Ok(GainPoint {
                mu,
                multiplier: m,
                rate: m.ln() / self.period,
                converged: true,
            });
        }
        let mut law = self.law.clone();
        let core = law.core_mut();
        (core.mu, core.t_on, core.feedback, core.auto_mu) = (mu, self.period, true, None);
        let tau = law.core().tau;
        let mut sim = Simulation::of(law, self.dt, orbit.state::<N>(), tau);
        for _ in 0..self.steps {
            sim.step();
        }
        let f = delay_multipliers(&sim, self.steps, &FLOQUET).map_err(|e| match e {
            crate::analysis::FloquetError::Diverged => TuneError::Diverged,
            other => TuneError::Invalid(other.to_string()),
        })?;
        let m = f.multipliers.first().map_or(f64::NAN, |z| z[0].hypot(z[1]));
        Ok(GainPoint {
            mu,
            multiplier: m,
            rate: f.exponent,
            converged: f.converged,
        })
    }
}

/// The scanned gain with the smallest |ρ₁|.
fn fastest(scanned: &[GainPoint]) -> GainPoint {
    *scanned
        .iter()
        .min_by(|a, b| a.multiplier.total_cmp(&b.multiplier))
        .expect("the scan has μ = 0 at least")
}

/// (q, q̇) from 2N numbers; None for any other length or a non-finite number.
fn state_of<const N: usize>(x: &[f64]) -> Option<ArmState<N>> {
    if x.len() != 2 * N || !x.iter().all(|v| v.is_finite()) {
        return None;
    }
    Some(ArmState {
        q: crate::arm::VecN::<N>::from_column_slice(&x[..N]),
        qd: crate::arm::VecN::<N>::from_column_slice(&x[N..]),
        phi: 0.0,
    })
}
