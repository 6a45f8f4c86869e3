//! The arm an offline command studies, whichever arm it is.
//!
//! A command is written once against [`Subject`]: it sets the gain and the start, checks the
//! set-up once, and runs [`Subject::analyse`] (`control::analysis::analyse_flow` on the planar
//! arm's law or a robot's) or its own [`LoopVisitor`] on the arm's simulation. Only this file
//! tells the arms apart, so a new command does not fork on the arm.

use crate::analysis::StartArgs;
use crate::setup::SetupArgs;
use anyhow::{Context, Result};
use control::analysis::{
    analyse_flow, find_orbit_of, orbit_stability_of, stroboscopic_map, ArmFlow, NewtonConfig,
    OrbitStability, PeriodicOrbit, RunAnalysis, RunSpec, StabilitySpec,
};
use control::config::{LawSection, ModelKind};
use control::monitor::run::{watch_sim, Edit, Watched};
use control::monitor::MonitorSettings;
use control::sim::ClosedLoopLaw;
use control::steer::Blocked;
use control::{with_dof, ArmState, Simulation, System, VecN};

/// The set-up an offline command studies: the daemon's own [`System`], with the offline
/// commands' runs and checks. A few hundred copies at most, built once per study.
#[derive(Clone, Debug)]
pub struct Subject {
    system: System,
}

impl Subject {
    /// The set-up the flags name (`--preset`, `--config` and the model flags), `mu` over the
    /// file's when given. A robot's chain is loaded here, once.
    pub fn load(setup: &SetupArgs, mu: Option<f64>) -> Result<Self> {
        Ok(Self {
            system: setup.load(mu)?,
        })
    }

    /// The whole set-up as the daemon holds it.
    pub fn system(&self) -> &System {
        &self.system
    }

    /// The whole set-up, to change (checked again by whatever runs it).
    pub fn system_mut(&mut self) -> &mut System {
        &mut self.system
    }

    /// The Pyragas gain μ (1/s).
    pub fn mu(&self) -> f64 {
        self.feedback().mu
    }

    pub fn set_mu(&mut self, mu: f64) {
        self.feedback_mut().mu = mu;
    }

    /// The `[feedback]` section (one type for every arm).
    pub fn feedback(&self) -> &control::config::FeedbackSection {
        self.system.feedback_section()
    }

    /// The `[feedback]` section, to change.
    pub fn feedback_mut(&mut self) -> &mut control::config::FeedbackSection {
        self.system.feedback_section_mut()
    }

    /// The path at full speed from t = 0 (`task.ramp = 0`), said on stderr when the file had
    /// a ramp: a period map from t = 0 through the ramp has fixed points that are not the
    /// periodic loop's.
    pub fn full_speed_path(&mut self) {
        let ramp = self.system.task_ramp_mut();
        if *ramp > 0.0 {
            eprintln!(
                "task.ramp = {} s is left out: the orbits are those of the full-speed path",
                *ramp
            );
            *ramp = 0.0;
        }
    }

    /// Turns the safety filter on or off.
    pub fn set_safety(&mut self, on: bool) {
        self.system.safety_section_mut().enabled = on;
    }

    /// The start posture q(0).
    pub fn q0(&self) -> Vec<f64> {
        self.start_coords(false)
    }

    /// The start's angles q(0), or with `rate` its rates q̇(0).
    pub fn start_coords(&self, rate: bool) -> Vec<f64> {
        self.system.start_coords(rate)
    }

    /// One checked set-up per start of `args` (the paper's three on a 3-link planar arm unless
    /// `q0_given`); a bad one is named by its number.
    pub fn starts(&self, args: &StartArgs, q0_given: bool) -> Result<Vec<Subject>> {
        let three = !q0_given && self.is_planar_3_link();
        args.postures(self.q0(), three)
            .into_iter()
            .enumerate()
            .map(|(i, q0)| {
                self.with_start(q0)
                    .with_context(|| format!("start {}", i + 1))
            })
            .collect()
    }

    /// This set-up from another start posture, checked.
    pub fn with_start(&self, q0: Vec<f64>) -> Result<Self> {
        self.with_start_coords(false, q0)
    }

    /// This set-up from other start angles (or, with `rate`, rates), checked.
    pub fn with_start_coords(&self, rate: bool, x: Vec<f64>) -> Result<Self> {
        let mut s = self.clone();
        let sim = s.system.sim_section_mut();
        match rate {
            false => sim.q0 = Some(x),
            true => sim.qd0 = Some(x),
        }
        s.check()?;
        Ok(s)
    }

    /// The `[law]` section (one type for every arm).
    pub fn law(&self) -> &LawSection {
        self.system.law_section()
    }

    /// `--duration` and `--transient` (s), checked as every command checks them; a transient
    /// left out is at most half the run. (A robot's whole set-up is checked when it is built.)
    pub fn set_duration(&mut self, duration: Option<f64>, transient: Option<f64>) -> Result<()> {
        crate::setup::set_sim_duration(self.system.sim_section_mut(), duration, transient)?;
        Ok(self.system.validate()?)
    }

    /// The `[sim]` run's duration and the transient its statistics skip (s).
    pub fn duration(&self) -> (f64, f64) {
        let sim = self.system.sim_section();
        (sim.duration, sim.transient)
    }

    /// The rate of the pull onto a planned cycle (`safety.plan_hz`).
    pub fn plan_hz(&self) -> f64 {
        self.system.safety_section().plan_hz
    }

    /// `"planar"`, or the robot's description.
    pub fn name(&self) -> String {
        self.system.robot_name()
    }

    /// The planar arm's base model; None for a robot.
    pub fn base_model(&self) -> Option<ModelKind> {
        self.system.planar().map(|c| c.planar_part().arm.model)
    }

    /// The task's rows and path: `position circle` (the planar arm's is always a position).
    pub fn task_name(&self) -> String {
        self.system.task_name()
    }

    /// The joint count.
    pub fn n(&self) -> usize {
        self.system.n()
    }

    /// Whether the base turns (the planar floating base): its attitude is then a coordinate.
    pub fn floating(&self) -> bool {
        self.base_model() == Some(ModelKind::Floating)
    }

    /// The task period T (s).
    pub fn period(&self) -> f64 {
        self.system.period()
    }

    /// The integration step (s).
    pub fn dt(&self) -> f64 {
        self.system.sim_section().dt
    }

    /// The delay τ (s) and the time the feedback comes on (s).
    pub fn tau_and_t_on(&self) -> (f64, f64) {
        let f = self.feedback();
        (f.tau_for(self.period()), f.t_on)
    }

    /// The space the arm moves in: 2 (a planar arm, seen from above) or 3.
    pub fn dims(&self) -> usize {
        self.system.obstacle_dims()
    }

    /// Replaces the file's obstacles by the `--obstacle` flags, when there are any (discs
    /// X,Y,R on a planar arm, spheres X,Y,Z,R on a robot), checked against the set-up.
    pub fn set_obstacles(&mut self, args: &crate::setup::ObstacleArgs) -> Result<()> {
        args.apply(&mut self.system)
    }

    /// Whether this is the paper's 3-link planar arm (whose sweep has the paper's three starts).
    pub fn is_planar_3_link(&self) -> bool {
        self.system.planar().is_some_and(|c| c.n() == 3)
    }

    /// One line for a figure's title.
    pub fn describe(&self) -> String {
        self.system.title()
    }

    /// Checks what a run needs beyond a valid file: the planar circle reachable from the start,
    /// a robot's start one angle per joint, and the period a whole number of steps.
    pub fn check(&self) -> Result<()> {
        Ok(self.system.check_run()?)
    }

    /// One analysed run (λ_max with `spec.lyapunov`, the section's class, the run's summary).
    pub fn analyse(&self, spec: &RunSpec) -> Result<RunAnalysis> {
        self.run_loop(Analyse(spec))
    }

    /// A run of `duration` s with the daemon's chaos monitor watching, each of `edits` (sorted
    /// by time) swapped in at its time as the daemon swaps a live change (`chaosctl monitor`).
    pub fn watch(
        &self,
        duration: f64,
        settings: MonitorSettings,
        edits: &[Edit],
    ) -> Result<Watched> {
        self.run_loop(Watch {
            duration,
            settings,
            edits,
            model: self.system(),
        })
    }

    /// Hands `visitor` this arm's closed loop at t = 0, its delay line holding exactly τ (as the
    /// Lyapunov pair needs). A robot runs as the daemon would: steered onto a planned cycle
    /// when `safety.plan` asks.
    pub fn run_loop<V: LoopVisitor>(&self, visitor: V) -> Result<V::Out> {
        self.run_with(visitor, Plan::Robot)
    }

    /// [`Self::run_loop`] with the law alone, never steered onto a planned cycle (the obstacle
    /// study compares the law's own avoidance with the filter's).
    pub fn run_law<V: LoopVisitor>(&self, visitor: V) -> Result<V::Out> {
        self.run_with(visitor, Plan::Never)
    }

    /// [`Self::run_loop`] as the daemon runs either arm: steered onto a planned cycle when
    /// `safety.plan` asks, the delay line sized for the longest τ the file allows.
    pub fn run_as_daemon<V: LoopVisitor>(&self, visitor: V) -> Result<V::Out> {
        self.run_with(visitor, Plan::Every)
    }

    fn run_with<V: LoopVisitor>(&self, visitor: V, plan: Plan) -> Result<V::Out> {
        let system = &self.system;
        let steered = match plan {
            Plan::Never => false,
            Plan::Robot => system.chain().is_some(),
            Plan::Every => true,
        };
        with_dof!(system.n(), N => {
            let (law, blocked) = match steered {
                true => control::plan::planned_law::<N>(system),
                false => (system.tick_law::<N>(), None),
            };
            // The daemon's delay line holds the longest τ a live change may ask; an analysis's
            // holds exactly τ (the Lyapunov pair renormalises the whole history).
            let capacity = match plan {
                Plan::Every => system.feedback().max_tau,
                _ => law.core().tau,
            };
            if let (Some(b), Plan::Robot) = (&blocked, plan) {
                eprintln!("safety.plan: no clean cycle, running without steering: {}", b.reason);
            }
            let sim = Simulation::of(law, system.sim_section().dt, system.initial_state::<N>(), capacity);
            visitor.visit(sim, Start { subject: self, blocked })
        })
    }

    /// The smallest margin of the obstacles' safety zones (m; +∞ without obstacles).
    pub fn obstacle_margin(&self) -> f64 {
        let rows = self.system.obstacle_rows();
        rows.iter().map(|o| o.margin).fold(f64::INFINITY, f64::min)
    }

    /// Newton's method at μ = 0 from a section point (q, q̇) of a run: one line on the period-T
    /// orbit there, or None (none found; orbits are refined on a fixed base with τ = T only,
    /// where the feedback vanishes on them).
    pub fn refine(&self, point: &[f64]) -> Option<String> {
        let (tau, _) = self.tau_and_t_on();
        if self.floating() || (tau - self.period()).abs() > 1e-9 || point.len() != 2 * self.n() {
            return None;
        }
        let o = self.find_orbit(point).ok()?;
        let on_circle = o
            .multipliers
            .iter()
            .filter(|m| (m[0].hypot(m[1]) - 1.0).abs() < 1e-3)
            .count();
        Some(format!(
            "the μ = 0 orbit through q = ({}) (Newton residual {:.1e}): {}, largest |ρ| = {:.4}, {on_circle} of {} multipliers on the unit circle",
            crate::analysis::fmt_list(&o.q),
            o.residual,
            o.kind(),
            o.max_multiplier(),
            o.multipliers.len()
        ))
    }

    /// Newton's method on the law's period map Φ_T (the feedback off: with τ = T it vanishes
    /// on a period-T orbit) from the state `point` = (q, q̇); the law alone, never steered.
    pub fn find_orbit(&self, point: &[f64]) -> Result<PeriodicOrbit> {
        self.run_law(FindOrbit { point })?
            .map_err(anyhow::Error::msg)
    }

    /// |Φ_T(x) − x| at the state `point` = (q, q̇): how far it is from a period-T orbit.
    pub fn period_map_residual(&self, point: &[f64]) -> Result<f64> {
        self.run_law(MapResidual { point })
    }

    /// λ_max of the loop at its own μ, starting on `orbit` (a period-T orbit of the loop
    /// without feedback) with the orbit's own history; the law alone, never steered.
    pub fn orbit_stability(
        &self,
        orbit: &PeriodicOrbit,
        spec: &StabilitySpec,
    ) -> Result<OrbitStability> {
        self.run_law(OnOrbit { orbit, spec })
    }
}

/// Which arms a run steers onto a planned cycle when `safety.plan` asks.
#[derive(Clone, Copy)]
enum Plan {
    /// Neither: the law alone.
    Never,
    /// A robot (the offline analyses; the planar arm's are the law's own).
    Robot,
    /// Either, as the daemon does.
    Every,
}

/// How a run starts, beside its loop.
pub struct Start<'a> {
    /// The set-up the loop was built from.
    pub subject: &'a Subject,
    /// `safety.plan` asked for a clean cycle and none was found: the law runs unsteered.
    pub blocked: Option<Blocked>,
}

/// What a command does with an arm's closed loop, written once for every arm
/// ([`Subject::run_loop`] calls it with the planar arm's law or a robot's).
pub trait LoopVisitor {
    type Out;
    fn visit<const N: usize, L: ClosedLoopLaw<N>>(
        self,
        sim: Simulation<N, L>,
        start: Start<'_>,
    ) -> Result<Self::Out>;
}

/// The arm's state (q, q̇) from `point`, refused when it has the wrong length.
fn state_of<const N: usize>(point: &[f64]) -> Result<ArmState<N>> {
    if point.len() != 2 * N {
        anyhow::bail!(
            "a state of this arm has {} numbers, not {}",
            2 * N,
            point.len()
        );
    }
    Ok(ArmState::<N> {
        q: VecN::<N>::from_fn(|i, _| point[i]),
        qd: VecN::<N>::from_fn(|i, _| point[N + i]),
        phi: 0.0,
    })
}

/// [`Subject::find_orbit`]: a found orbit, or Newton's failure as text (the caller decides
/// whether that is an error).
struct FindOrbit<'a> {
    point: &'a [f64],
}

impl LoopVisitor for FindOrbit<'_> {
    type Out = Result<PeriodicOrbit, String>;
    fn visit<const N: usize, L: ClosedLoopLaw<N>>(
        self,
        sim: Simulation<N, L>,
        start: Start<'_>,
    ) -> Result<Self::Out> {
        let seed = state_of::<N>(self.point)?;
        let newton = NewtonConfig::default();
        let found = find_orbit_of(&sim.law, start.subject.period(), sim.dt(), &seed, &newton);
        Ok(found.map_err(|e| e.to_string()))
    }
}

/// [`Subject::period_map_residual`].
struct MapResidual<'a> {
    point: &'a [f64],
}

impl LoopVisitor for MapResidual<'_> {
    type Out = f64;
    fn visit<const N: usize, L: ClosedLoopLaw<N>>(
        self,
        sim: Simulation<N, L>,
        start: Start<'_>,
    ) -> Result<f64> {
        let x = state_of::<N>(self.point)?;
        let steps = control::analysis::period_steps(start.subject.period(), sim.dt())?;
        let y = stroboscopic_map(&sim.law, sim.dt(), steps, &x);
        Ok(((y.q - x.q).norm_squared() + (y.qd - x.qd).norm_squared()).sqrt())
    }
}

/// [`Subject::orbit_stability`].
struct OnOrbit<'a> {
    orbit: &'a PeriodicOrbit,
    spec: &'a StabilitySpec,
}

impl LoopVisitor for OnOrbit<'_> {
    type Out = OrbitStability;
    fn visit<const N: usize, L: ClosedLoopLaw<N>>(
        self,
        sim: Simulation<N, L>,
        start: Start<'_>,
    ) -> Result<OrbitStability> {
        let (law, dt) = (&sim.law, sim.dt());
        Ok(orbit_stability_of(
            law,
            start.subject.period(),
            dt,
            self.orbit,
            self.spec,
        )?)
    }
}

/// [`Subject::watch`]: the chaos monitor on the loop.
struct Watch<'a> {
    duration: f64,
    settings: MonitorSettings,
    edits: &'a [Edit],
    /// The set-up the loop runs: with `mu = "auto"` the gain comes from it, as in the daemon.
    model: &'a control::System,
}

impl LoopVisitor for Watch<'_> {
    type Out = Watched;
    fn visit<const N: usize, L: ClosedLoopLaw<N>>(
        self,
        mut sim: Simulation<N, L>,
        _: Start<'_>,
    ) -> Result<Watched> {
        Ok(watch_sim(
            &mut sim,
            self.duration,
            self.settings,
            self.edits,
            Some(self.model),
        ))
    }
}

/// [`Subject::analyse`]: `control::analysis::analyse_flow` on the loop.
struct Analyse<'a>(&'a RunSpec);

impl LoopVisitor for Analyse<'_> {
    type Out = RunAnalysis;
    fn visit<const N: usize, L: ClosedLoopLaw<N>>(
        self,
        sim: Simulation<N, L>,
        _: Start<'_>,
    ) -> Result<RunAnalysis> {
        Ok(analyse_flow(ArmFlow::of(sim), self.0)?)
    }
}

impl std::fmt::Display for Subject {
    /// The fingerprint text of a shard's grid: the whole configuration (a chain's numbers too).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.system.fingerprint_text())
    }
}
