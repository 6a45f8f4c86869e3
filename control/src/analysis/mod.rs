//! Chaos analysis of the closed loop (docs/science.md, "Measuring chaos"): Lyapunov exponents, stroboscopic Poincaré
//! sections and their classification, period-T orbits with their Floquet multipliers and their
//! stability under Pyragas feedback.
//!
//! Like the rest of `control`, this is pure math: no I/O, threads or clocks. The command-line
//! tools (`chaosctl lyapunov | sweep | poincare | orbits | basins | figures`) parallelise, print
//! and plot around it. The pieces:
//!
//! - [`lyapunov`]: Benettin's method, generic over a [`Trajectory`], with the delay-history
//!   renormalisation that a delay equation (μ ≠ 0) needs. Known systems are plugged into the same
//!   code in the tests.
//! - [`closed_loop`]: the arm simulation as a [`Trajectory`] ([`ArmFlow`]).
//! - [`poincare`]: the section at t = kT and the period-p / converging / quasi-periodic /
//!   irregular classifier (its rule is documented there).
//! - [`run`]: one analysed run, the unit every tool is built from.
//! - [`orbits`]: Newton's method on the stroboscopic map, Floquet multipliers, stability vs μ.
//! - [`floquet`]: the leading Floquet multipliers of the loop with its delayed feedback (the
//!   monodromy operator of the delay equation, by Arnoldi on the simulation's period map).

pub mod closed_loop;
pub mod floquet;
pub mod lyapunov;
pub mod orbits;
pub mod poincare;
pub mod run;

pub use closed_loop::ArmFlow;
pub use floquet::{delay_multipliers, DelayMultipliers, FloquetError, FloquetSpec};
pub use lyapunov::{Benettin, Growth, LyapunovError, LyapunovEstimate, Trajectory};
pub use orbits::{
    close_returns, find_orbit, find_orbit_of, newton_orbit, orbit_stability, orbit_stability_of,
    stroboscopic_map, NewtonConfig, OrbitCatalog, OrbitError, OrbitStability, PeriodicOrbit,
    StabilitySpec, Verdict,
};
pub use poincare::{classify, zero_one_k, Classification, ClassifyConfig, Motion, Section};
pub use run::{
    analyse, analyse_flow, check_reachable, period_steps, AnalysisError, LyapunovSpec, RunAnalysis,
    RunSpec,
};
