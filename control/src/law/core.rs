//! The part of the law's parameters that every arm has alike: the tracking gains, the
//! pseudo-inverse's damping, the secondary task's weight α, the Pyragas term and its adaptation,
//! the safety limits and the pause.
//!
//! An arm's own block ([`super::LawParams`] for the planar arm, [`super::spatial::SpatialParams`]
//! for a URDF chain) holds one [`LawCore`] beside what only it has (its task's shape, its
//! obstacles' geometry, its steering). Whatever reads or changes the feedback (the closed loop,
//! the μ adaptation, the daemon's live gain and pause) reads or changes the core, so it is
//! written once for every arm and a new kind of arm gets it by holding a core.

use super::pipeline::Gains;
use crate::adapt::{next_mu, AutoMu};
use crate::resolve::{ControlOutput, Projection};
use crate::safety::SafetyParams;

/// Which secondary task drives the null space: one set for every arm, each arm computing it
/// on its own geometry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Secondary {
    None,
    /// η = +∇w, w = √det(JJᵀ) of the task rows (eq. 1).
    #[default]
    Manipulability,
    /// η = −∇c, c the joint-limit centring cost (joints without limits are left alone).
    Centring,
    /// η = −∇h, the obstacle potential (eqs. 7-10): discs on the planar arm, spheres against
    /// capsules on a chain.
    Obstacles,
    /// A task the program registered ([`crate::secondary::custom`]), by its index there.
    Custom(u8),
}

impl Secondary {
    /// The task a config names: a built-in's name or a registered task's.
    ///
    /// ```
    /// use control::Secondary;
    /// assert_eq!(Secondary::parse("centring"), Some(Secondary::Centring));
    /// assert_eq!(Secondary::parse("manipulabilty"), None);
    /// ```
    pub fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "none" => Secondary::None,
            "manipulability" => Secondary::Manipulability,
            "centring" => Secondary::Centring,
            "obstacles" => Secondary::Obstacles,
            s => Secondary::Custom(crate::secondary::custom::lookup(s)?),
        })
    }

    /// What [`Self::parse`] takes, for a refusal's message.
    pub fn names() -> String {
        let custom = crate::secondary::custom::names();
        let built_in = "\"none\", \"manipulability\", \"centring\" or \"obstacles\"";
        if custom.is_empty() {
            format!("{built_in} (a task of your own runs in a program that registers it: examples/custom-task)")
        } else {
            format!(
                "{built_in}, or a task this program registered: {}",
                custom.join(", ")
            )
        }
    }
}

/// Every arm's gains, feedback and limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LawCore {
    /// Position-error gain K_p.
    pub kp: f64,
    /// Velocity-error gain K_v.
    pub kv: f64,
    /// Null-space gain α.
    pub alpha: f64,
    pub secondary: Secondary,
    /// Damped least squares starts when σ_min(J) falls below this.
    pub damping_threshold: f64,
    /// λ at σ_min = 0.
    pub damping_max: f64,
    /// Pyragas gain μ ≥ 0.
    pub mu: f64,
    /// Pyragas delay τ (s).
    pub tau: f64,
    /// Feedback is active for t ≥ t_on.
    pub t_on: f64,
    /// Master switch for the delayed feedback (the daemon's `dfc on|off`).
    pub feedback: bool,
    /// Where the delayed term acts.
    pub projection: Projection,
    /// `feedback.mu = "auto"`: the caller adapts `mu` after each step ([`crate::adapt`]).
    pub auto_mu: Option<AutoMu>,
    /// The safety filter applied to the result ([`crate::safety`]).
    pub safety: SafetyParams,
    /// Tracking error (m) above which tracking counts as lost.
    pub track_loss: f64,
    /// Tracking paused (the daemon's blocked hold): the arm brakes to rest, the filter keeping
    /// clearance as ever ([`crate::safety::pause_brake`]).
    pub pause: bool,
}

/// The feedback numbers a closed loop reads from its law.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopFeedback {
    pub mu: f64,
    pub tau: f64,
    pub projection: Projection,
    /// Feedback switched on with μ ≠ 0: the q̇ history is part of the state.
    pub delay_is_state: bool,
}

impl LawCore {
    /// Whether the delayed term applies at time t.
    #[inline]
    pub fn feedback_active(&self, t: f64) -> bool {
        self.feedback && (self.mu != 0.0 || self.auto_mu.is_some()) && t >= self.t_on
    }

    /// The gains the law's pipeline reads at time `t`.
    #[inline]
    pub fn gains(&self, t: f64) -> Gains<'_> {
        Gains {
            alpha: self.alpha,
            damping_threshold: self.damping_threshold,
            damping_max: self.damping_max,
            mu: self.mu,
            feedback_on: self.feedback_active(t),
            projection: self.projection,
            pause: self.pause,
            track_loss: self.track_loss,
            safety: &self.safety,
        }
    }

    /// μ, τ, where the feedback acts, and whether the delayed history is part of the state.
    pub fn loop_feedback(&self) -> LoopFeedback {
        LoopFeedback {
            mu: self.mu,
            tau: self.tau,
            projection: self.projection,
            delay_is_state: self.feedback && self.mu != 0.0,
        }
    }

    /// One adaptation step of μ after a law run whose output was `out`, `dt` after the last
    /// (`feedback.mu = "auto"`; a fixed gain is left as it is). Not while tracking is paused:
    /// the braking arm's residual says nothing about the gain.
    #[inline]
    pub fn adapt<const N: usize>(&mut self, out: &ControlOutput<N>, dt: f64) {
        if !self.pause {
            self.mu = next_mu(&mut self.auto_mu, self.mu, self.projection, out, dt);
        }
    }

    /// After a new parameter block: an adapting gain goes on from `mu` (the gain before the
    /// change) rather than from the block's start, so an edit does not throw the adaptation away;
    /// never past the block's `max_mu`, which the adaptation itself never passes. A block that
    /// brings a new gain from the model (an anchor other than `anchor`, the one before) starts
    /// from that gain: it is the point of the block ([`crate::adapt::AutoMu::anchor`]).
    pub fn carry_adapted_mu(&mut self, mu: f64, anchor: Option<f64>) {
        if let Some(a) = self.auto_mu {
            let from = match a.anchor {
                Some(m) if Some(m) != anchor => m,
                _ => mu,
            };
            self.mu = from.min(a.max_mu);
        }
    }
}
