//! Adaptive delayed feedback: `feedback.mu = "auto"` (docs/monitor.md).
//!
//! A fixed μ that stabilises one start, task or payload fails for another (the basins show it),
//! so the user should not have to pick it from a sweep. The speed-gradient law of Lehnert et al.
//! (Chaos 21, 043111, 2011) descends Q = ½|q̇(t) − q̇(t − τ)|²:
//!
//! μ̇ = γ |q̇(t) − q̇(t − τ)|²
//!
//! so the gain grows while the motion is not τ-periodic and stops once it is. The residual is the
//! null-space part when the feedback is projected there (the part the feedback can act on). The
//! gain does not grow while the law already asks for more than the joints may do (`demand > 1`):
//! that is the runaway guard's criterion, and a larger gain would only feed it.
//!
//! **Sweeps.** The pure law only ever raises μ. On the planar arm the gains that stabilise are a
//! narrow window (about 0.05–0.2, depending on the start), a chaotic attractor coexists with the
//! orbit above it, and capture by the orbit takes a chaotic transient of 30–130 s even at a good
//! fixed gain. A gain that crosses the window faster than that overshoots into the chaos above it
//! and, only ever growing, never comes back (measured: half the starts). So chaosd bounds the law
//! by `max_mu` and, when μ reaches the bound while the residual still grows it, starts a new
//! sweep from μ = 0 with γ halved: each sweep lingers twice as long in the window, and the chaos
//! in between scrambles the state for another try. μ never passes `max_mu`.
//!
//! The update is one multiply-add on the tick, shared by the daemon's controller and the offline
//! simulation, so what the book measures is what the daemon runs.

use crate::basics::{ConfigError, LiveError};
use serde::{Deserialize, Serialize};

/// The speed-gradient law's settings (a `Copy` block inside the law's parameters).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AutoMu {
    /// Adaptation gain γ (s/rad²: μ grows by γ·r² per second at residual r rad/s).
    pub gamma: f64,
    /// Whether γ is the user's (`feedback.gamma`, a live `set gamma`); if not, the model's
    /// gain brings its own ([`model_gamma`]) and [`DEFAULT_GAMMA`] serves until it comes.
    #[serde(default)]
    pub gamma_given: bool,
    /// The bound μ never passes.
    pub max_mu: f64,
    /// The gain the model recommends ([`crate::tune`]), once the daemon has chosen it: μ leaks
    /// back towards it (time constant [`LEAK_TIME_S`]) once the residual no longer drives it up,
    /// stays within [`BAND`] of it, and a sweep starts again from it rather than from 0. Never in
    /// a config file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub anchor: Option<f64>,
}

/// The default γ: at the planar arm's chaotic residual of about 5 rad/s, μ grows by 0.0075 per
/// second, so the first sweep spends about 20 s in the window of gains that stabilise (measured
/// over starts: `chaosctl monitor`, the book's "Knowing when it is chaotic").
pub const DEFAULT_GAMMA: f64 = 3e-4;
/// The default bound: above the planar arm's period-1 window (0.05–0.35 over the starts tried).
pub const DEFAULT_MAX_MU: f64 = 0.4;
/// The residual (rad/s) at which γ is judged: the planar arm's chaotic self-motion gives 4–12.
pub const REFERENCE_RESIDUAL: f64 = 5.0;
/// At the reference residual, one period may move μ by at most this share of `max_mu`.
pub const MAX_SHARE_PER_PERIOD: f64 = 0.1;

/// How fast μ returns to the model's gain once the residual stops driving it up (s): ten
/// periods of the planar arm, five of the Panda's, so a correction the plant needed outlives a
/// short calm but not a settled cycle.
pub const LEAK_TIME_S: f64 = 10.0;

/// With the model's gain μ_m, the plant moves μ within μ_m · (1 ± BAND). The residual drives μ
/// up while the motion is chaotic (to μ_m + γ r² · [`LEAK_TIME_S`], +0.15 at the planar arm's
/// 5 rad/s), and above the model's gain the planar cycle's basin collapses (μ ≥ 0.25 caught 1
/// of 8 starts in 300 s against 8 of 8 at 0.1 and 0.2): the correction is for a plant that
/// differs from the model by a payload or friction, not for undoing the model's choice.
pub const BAND: f64 = 0.5;

/// The model's γ for its gain `mu` on a cycle whose joint speed is `speed` (rad/s, the RMS of
/// |q̇| over a period): a residual that large, a motion that no longer repeats at all, drives μ
/// to the edge of the [`BAND`] in about [`LEAK_TIME_S`] (μ settles where the growth γ r² meets
/// the leak (μ − μ_m)/[`LEAK_TIME_S`]). So the correction is scaled to the arm it corrects: the
/// planar cycle (10.9 rad/s, μ = 0.114) gets 4.8e-5, where the hand-calibrated
/// [`DEFAULT_GAMMA`] put the band's edge at 4.4 rad/s, and the Panda's slower one (1.06 rad/s,
/// μ = 0.244) 0.011, where the planar γ moved μ by 5e-3 at its chaotic residual of 1.3 rad/s
/// and so did not correct at all. None for a speed or gain that is not a positive number.
///
/// ```
/// use control::adapt::{model_gamma, BAND, LEAK_TIME_S};
/// let g = model_gamma(0.2, 4.0).unwrap();
/// assert!((g * 16.0 * LEAK_TIME_S - BAND * 0.2).abs() < 1e-15);
/// assert_eq!(model_gamma(0.2, 0.0), None);
/// ```
pub fn model_gamma(mu: f64, speed: f64) -> Option<f64> {
    let g = BAND * mu / (LEAK_TIME_S * speed * speed);
    (g.is_finite() && g > 0.0).then_some(g)
}

impl Default for AutoMu {
    fn default() -> Self {
        Self {
            gamma: DEFAULT_GAMMA,
            gamma_given: false,
            max_mu: DEFAULT_MAX_MU,
            anchor: None,
        }
    }
}

impl AutoMu {
    /// μ after one step of `dt` at residual `r` (rad/s) with the law's `demand` (see the module
    /// docs). Never NaN for a finite `mu`: a non-finite residual leaves μ as it is.
    ///
    /// ```
    /// use control::adapt::AutoMu;
    /// let a = AutoMu { gamma: 0.5, gamma_given: true, max_mu: 1.0, anchor: None };
    /// assert_eq!(a.step(0.0, 2.0, 0.01, 0.3), 0.02); // 0.5 · 2² · 0.01
    /// assert_eq!(a.step(0.99, 2.0, 0.01, 0.3), 1.0); // bounded
    /// assert_eq!(a.step(0.5, 2.0, 0.01, 1.5), 0.5); // the joints are saturated: no growth
    /// // With the model's gain 0.2, a settled cycle (r = 0) brings μ back down to it, and the
    /// // plant moves it by at most half of it either way.
    /// let m = AutoMu { anchor: Some(0.2), ..a };
    /// assert!(m.step(0.25, 0.0, 0.01, 0.3) < 0.25 && m.step(0.25, 0.0, 0.01, 0.3) > 0.2);
    /// assert_eq!(m.step(0.2, 0.0, 0.01, 0.3), 0.2);
    /// assert!((m.step(0.2, 100.0, 0.01, 0.3) - 0.3).abs() < 1e-15); // 1.5 × 0.2, rounded
    /// ```
    #[inline]
    pub fn step(&self, mu: f64, r: f64, dt: f64, demand: f64) -> f64 {
        let grow = self.gamma * r * r * dt;
        let Some(anchor) = self.anchor else {
            if !(grow.is_finite() && demand <= 1.0) {
                return mu;
            }
            return (mu + grow).min(self.max_mu);
        };
        let grow = if grow.is_finite() && demand <= 1.0 {
            grow
        } else {
            0.0
        };
        let leak = (mu - anchor) * (dt / LEAK_TIME_S).min(1.0);
        let (low, high) = (anchor * (1.0 - BAND), anchor * (1.0 + BAND));
        // `max`/`min` rather than `clamp`: this runs on the tick, and `clamp` panics on a NaN
        // or inverted bound (the same result for every valid one).
        (mu + grow - leak)
            .max(low)
            .min(high)
            .max(0.0)
            .min(self.max_mu)
    }

    /// [`Self::step`], and when μ reaches `max_mu` still growing, a new sweep: μ starts again
    /// from the model's gain (0 without one) and γ halves (see the module docs). Returns the
    /// new μ.
    ///
    /// ```
    /// use control::adapt::AutoMu;
    /// let mut a = AutoMu { gamma: 0.5, gamma_given: true, max_mu: 1.0, anchor: None };
    /// assert_eq!(a.advance(0.99, 2.0, 0.01, 0.3), 0.0);
    /// assert_eq!(a.gamma, 0.25);
    /// let mut a = AutoMu { gamma: 0.5, gamma_given: true, max_mu: 1.0, anchor: Some(0.8) };
    /// assert_eq!(a.advance(0.99, 2.0, 0.01, 0.3), 0.8);
    /// ```
    #[inline]
    pub fn advance(&mut self, mu: f64, r: f64, dt: f64, demand: f64) -> f64 {
        let next = self.step(mu, r, dt, demand);
        if next >= self.max_mu && next > mu {
            self.gamma *= 0.5;
            return self.anchor.unwrap_or(0.0);
        }
        next
    }

    /// Refuses settings that cannot work: γ must be > 0, `max_mu` in (0, 100], and one period
    /// at the reference residual of 5 rad/s may not move μ by more than a tenth of `max_mu` (a
    /// γ that jumps past the stable range before the orbit can answer). The error names the
    /// largest γ the period `tau` allows. The bound is for a γ the user gives: the model's
    /// ([`model_gamma`]) is scaled to its own arm's speed, and keeps a period's move at that
    /// speed to a twentieth of the model's gain.
    ///
    /// ```
    /// use control::adapt::AutoMu;
    /// assert!(AutoMu::default().check(1.0).is_ok());
    /// let e = AutoMu { gamma: 0.1, gamma_given: true, max_mu: 1.0, anchor: None }.check(1.0).unwrap_err().to_string();
    /// assert!(e.contains("at most 4.0e-3"), "{e}");
    /// ```
    pub fn check(&self, tau: f64) -> Result<(), crate::basics::ConfigError> {
        use crate::basics::invalid;
        if !(self.max_mu.is_finite() && self.max_mu > 0.0 && self.max_mu <= 100.0) {
            let e = "must be a finite number in (0, 100]";
            return Err(invalid("feedback.max_mu", self.max_mu, e));
        }
        let largest = MAX_SHARE_PER_PERIOD * self.max_mu / (tau * REFERENCE_RESIDUAL.powi(2));
        let too_big = self.gamma_given && self.gamma > largest;
        if !(self.gamma.is_finite() && self.gamma > 0.0) || too_big {
            let e = format!(
                "must be > 0 and at most {largest:.1e} (with max_mu = {} and τ = {tau} s, a residual \
                 of 5 rad/s would move μ by more than a tenth of its range in one period)",
                self.max_mu
            );
            return Err(invalid("feedback.gamma", self.gamma, &e));
        }
        Ok(())
    }

    /// The residual the law adapts on: the null-space part when the feedback is projected there.
    #[inline]
    pub fn residual(projection: crate::resolve::Projection, full: f64, null: f64) -> f64 {
        match projection {
            crate::resolve::Projection::Full => full,
            crate::resolve::Projection::NullSpace => null,
        }
    }
}

/// μ after one step of `dt` whose law output was `out`: unchanged unless the gain adapts and
/// the delayed term was applied on that step. The one call the controller and the simulations
/// make.
#[inline]
pub fn next_mu<const N: usize>(
    auto: &mut Option<AutoMu>,
    mu: f64,
    projection: crate::resolve::Projection,
    out: &crate::resolve::ControlOutput<N>,
    dt: f64,
) -> f64 {
    match auto {
        Some(a) if out.flags & crate::basics::flags::FEEDBACK_ACTIVE != 0 => {
            let r = AutoMu::residual(projection, out.period_residual, out.null_residual);
            a.advance(mu, r, dt, out.demand)
        }
        _ => mu,
    }
}

/// A live `chaosctl set` of `mu` (a number, or `auto`), `gamma` or `max_mu` on a feedback
/// section's gain and adaptation. Validation follows with the whole config.
///
/// ```
/// use control::adapt::{set_live, AutoMu};
/// let (mut mu, mut auto) = (0.2, None);
/// set_live("mu", Some("auto"), &mut mu, &mut auto).unwrap();
/// assert_eq!(auto, Some(AutoMu::default()));
/// set_live("gamma", Some("1e-4"), &mut mu, &mut auto).unwrap();
/// set_live("mu", Some("0.1"), &mut mu, &mut auto).unwrap();
/// assert_eq!((mu, auto), (0.1, None));
/// assert!(set_live("max_mu", Some("1"), &mut mu, &mut auto).is_err());
/// // Auto from a gain above its cap starts at the cap.
/// let (mut mu, mut auto) = (0.5, None);
/// set_live("mu", Some("auto"), &mut mu, &mut auto).unwrap();
/// assert_eq!(mu, AutoMu::default().max_mu);
/// ```
pub fn set_live(
    key: &str,
    value: Option<&str>,
    mu: &mut f64,
    auto: &mut Option<AutoMu>,
) -> Result<(), LiveError> {
    let v = value.ok_or_else(|| LiveError::Missing { key: key.into() })?;
    let number = || crate::basics::live_number(key, Some(v));
    match (key.trim_start_matches("feedback."), auto.as_mut()) {
        ("mu", _) if v == "auto" => {
            auto.get_or_insert_with(AutoMu::default);
        }
        ("mu", _) => {
            *mu = number().map_err(|e| LiveError::NotAGain(Box::new(e)))?;
            *auto = None;
        }
        ("gamma", Some(a)) => (a.gamma, a.gamma_given) = (number()?, true),
        ("max_mu", Some(a)) => a.max_mu = number()?,
        (k, _) => return Err(LiveError::NeedsAuto { key: k.into() }),
    }
    // The adaptation never goes past max_mu: the gain it starts from may not either, or the
    // answer and the file would say a gain the loop never runs.
    if let Some(a) = auto {
        *mu = mu.min(a.max_mu);
    }
    Ok(())
}

/// How `feedback.mu` is written in a config file: a number, or `"auto"`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MuSetting {
    Fixed(f64),
    Auto,
}

impl Default for MuSetting {
    fn default() -> Self {
        MuSetting::Fixed(0.0)
    }
}

impl Serialize for MuSetting {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            MuSetting::Fixed(v) => s.serialize_f64(*v),
            MuSetting::Auto => s.serialize_str("auto"),
        }
    }
}

impl<'de> Deserialize<'de> for MuSetting {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Number(f64),
            Word(String),
        }
        match Raw::deserialize(d)? {
            Raw::Number(v) => Ok(MuSetting::Fixed(v)),
            Raw::Word(w) if w == "auto" => Ok(MuSetting::Auto),
            Raw::Word(w) => Err(serde::de::Error::custom(format!(
                "feedback.mu = \"{w}\": must be a number ≥ 0 or \"auto\""
            ))),
        }
    }
}

/// The adaptation a `[feedback]` table asks for: `Some` for `mu = "auto"` (γ and the bound
/// defaulted), an error for `gamma`/`max_mu` without it (they would silently do nothing).
pub fn auto_from_toml(
    mu: MuSetting,
    gamma: Option<f64>,
    max_mu: Option<f64>,
) -> Result<Option<AutoMu>, ConfigError> {
    if !mu.is_auto() {
        return match (gamma, max_mu) {
            (None, None) => Ok(None),
            _ => Err(ConfigError::AutoTuningWithoutAuto),
        };
    }
    Ok(Some(AutoMu {
        gamma: gamma.unwrap_or(DEFAULT_GAMMA),
        gamma_given: gamma.is_some(),
        max_mu: max_mu.unwrap_or(DEFAULT_MAX_MU),
        anchor: None,
    }))
}

impl std::str::FromStr for MuSetting {
    type Err = LiveError;
    /// `auto` or a finite number ≥ 0 (a command line's `--mu`).
    fn from_str(s: &str) -> Result<Self, LiveError> {
        if s == "auto" {
            return Ok(MuSetting::Auto);
        }
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() && v >= 0.0 => Ok(MuSetting::Fixed(v)),
            _ => Err(LiveError::NotAGainWord { value: s.into() }),
        }
    }
}

impl MuSetting {
    /// The gain the law starts from (0 for "auto": the speed gradient raises it).
    pub fn start(self) -> f64 {
        match self {
            MuSetting::Fixed(v) => v,
            MuSetting::Auto => 0.0,
        }
    }

    pub fn is_auto(self) -> bool {
        self == MuSetting::Auto
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grows_with_the_squared_residual_and_stops_at_zero() {
        let a = AutoMu {
            gamma: 0.2,
            gamma_given: true,
            max_mu: 3.0,
            anchor: None,
        };
        assert_eq!(a.step(0.1, 0.0, 0.001, 0.0), 0.1);
        let one = a.step(0.0, 1.0, 0.001, 0.0);
        let two = a.step(0.0, 2.0, 0.001, 0.0);
        assert!((two / one - 4.0).abs() < 1e-12);
        assert_eq!(a.step(0.3, f64::NAN, 0.001, 0.0), 0.3);
        assert_eq!(a.step(0.3, 1.0, 0.001, f64::NAN), 0.3);
    }

    /// The step runs on the tick: an anchor or bound that validation would refuse (a NaN, a
    /// negative gain, an inverted band) gives a gain in [0, max_mu], never a panic.
    #[test]
    fn an_anchored_step_never_panics_and_stays_in_range() {
        for anchor in [f64::NAN, -0.2, 0.0, f64::INFINITY, 0.2] {
            for mu in [f64::NAN, -1.0, 0.0, 0.25, 5.0] {
                let a = AutoMu {
                    gamma: 3e-4,
                    gamma_given: true,
                    max_mu: 0.4,
                    anchor: Some(anchor),
                };
                let next = a.step(mu, 2.0, 0.001, 0.3);
                assert!(
                    (0.0..=0.4).contains(&next),
                    "anchor {anchor}, μ {mu}: {next}"
                );
            }
        }
    }

    #[test]
    fn refuses_bad_gains() {
        for (g, m) in [
            (0.0, 2.0),
            (-1.0, 2.0),
            (f64::NAN, 2.0),
            (0.1, 0.0),
            (0.1, 1e3),
        ] {
            assert!(
                AutoMu {
                    gamma: g,
                    gamma_given: true,
                    max_mu: m,
                    anchor: None,
                }
                .check(1.0)
                .is_err(),
                "γ {g} max {m}"
            );
        }
        // A shorter period allows a faster gain.
        let a = AutoMu {
            gamma: 0.006,
            gamma_given: true,
            max_mu: 1.0,
            anchor: None,
        };
        assert!(a.check(1.0).is_err() && a.check(0.5).is_ok());
    }

    #[test]
    fn mu_setting_reads_numbers_and_auto() {
        #[derive(Deserialize, Serialize)]
        struct T {
            mu: MuSetting,
        }
        let t: T = toml::from_str("mu = \"auto\"").unwrap();
        assert!(t.mu.is_auto());
        let t: T = toml::from_str("mu = 0.2").unwrap();
        assert_eq!(t.mu, MuSetting::Fixed(0.2));
        let e = toml::from_str::<T>("mu = \"fast\"")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("number ≥ 0 or \"auto\""), "{e}");
        assert_eq!(
            toml::to_string(&T {
                mu: MuSetting::Auto
            })
            .unwrap()
            .trim(),
            "mu = \"auto\""
        );
    }
}
