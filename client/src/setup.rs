//! Turning command-line flags into one validated [`Config`].
//!
//! Every offline command takes the same model and initial-state flags. They are applied on top of
//! a config file or a preset and then validated once, so a bad flag gets the same field-naming
//! message as a bad file entry.

use anyhow::{bail, Context, Result};
use clap::Args;
use control::config::{ModelKind, ProjectionKind};
use control::System;
use std::path::PathBuf;

/// The model and initial-state flags every offline command shares (all but `--mu`, which is one
/// value for a single run and a range for a scan).
#[derive(Args, Debug, Clone)]
pub struct SetupArgs {
    /// TOML config file (see `chaosctl config --preset paper` for every key).
    #[arg(long, conflicts_with = "preset")]
    pub config: Option<PathBuf>,
    /// Built-in set-up: paper, paper-eq11, paper-obstacle, paper-floating, demo; panda, panda-paper (spatial, 7 joints).
    #[arg(long)]
    pub preset: Option<String>,
    /// Pyragas delay τ (s).
    #[arg(long)]
    pub tau: Option<f64>,
    /// Time the delayed feedback switches on (s).
    #[arg(long = "t-on")]
    pub t_on: Option<f64>,
    /// Integration step (s).
    #[arg(long)]
    pub dt: Option<f64>,
    /// Initial joint angles, comma-separated (rad).
    #[arg(long, value_parser = parse_list, allow_hyphen_values = true)]
    pub q0: Option<FloatList>,
    /// Initial joint rates, comma-separated (rad/s).
    #[arg(long, value_parser = parse_list, allow_hyphen_values = true)]
    pub qd0: Option<FloatList>,
    /// Plant model: fixed or floating.
    #[arg(long, value_parser = parse_model)]
    pub model: Option<ModelKind>,
    /// The safety filter on the commanded q̈ (obstacle clearance, joint limits; null space
    /// first): on or off. Default: the file's `safety.enabled`; the paper* presets: off,
    /// `demo`: on.
    #[arg(long, value_parser = parse_on_off, value_name = "on|off")]
    pub safety: Option<bool>,
    /// Where the Pyragas term acts: full (every joint, the paper's form) or null-space
    /// (projected by I − J⁺J onto the self-motion). Default: the file's
    /// `feedback.projection`; every preset: full.
    #[arg(long, value_parser = parse_projection, value_name = "full|null-space")]
    pub projection: Option<ProjectionKind>,
}

/// The flags of a single run: [`SetupArgs`] and one μ.
#[derive(Args, Debug, Clone)]
pub struct ModelArgs {
    #[command(flatten)]
    pub setup: SetupArgs,
    /// Pyragas gain μ (≥ 0).
    #[arg(long)]
    pub mu: Option<f64>,
}

/// A comma-separated list of numbers given as one argument.
#[derive(Debug, Clone, PartialEq)]
pub struct FloatList(pub Vec<f64>);

/// Parses `a,b,c` into numbers, naming the bad item.
pub fn parse_list(s: &str) -> Result<FloatList, String> {
    s.split(',')
        .map(|x| {
            let x = x.trim();
            x.parse::<f64>().map_err(|_| {
                format!("{x:?} is not a number (expected a comma-separated list like 0,1.57,1.57)")
            })
        })
        .collect::<Result<Vec<_>, _>>()
        .map(FloatList)
}

fn parse_model(s: &str) -> Result<ModelKind, String> {
    match s {
        "fixed" => Ok(ModelKind::Fixed),
        "floating" => Ok(ModelKind::Floating),
        _ => Err(format!("{s:?} is not a model (expected fixed or floating)")),
    }
}

fn parse_on_off(s: &str) -> Result<bool, String> {
    match s {
        "on" => Ok(true),
        "off" => Ok(false),
        _ => Err(format!("{s:?}: expected on or off")),
    }
}

fn parse_projection(s: &str) -> Result<ProjectionKind, String> {
    match s {
        "full" => Ok(ProjectionKind::Full),
        "null-space" => Ok(ProjectionKind::NullSpace),
        _ => Err(format!(
            "{s:?} is not a projection (expected full or null-space)"
        )),
    }
}

impl SetupArgs {
    /// The set-up the file or preset names (default `paper`), before the flags; a robot's chain
    /// is loaded here, once.
    fn base(&self) -> Result<System> {
        let resolve = &rt::robot::resolve;
        match (&self.config, &self.preset) {
            (Some(path), _) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("cannot read config file {}", path.display()))?;
                System::read(&text, resolve).with_context(|| format!("in {}", path.display()))
            }
            (None, Some(p)) => Ok(System::named(p, resolve)?),
            (None, None) => Ok(System::named("paper", resolve)?),
        }
    }

    /// The set-up with the flags applied (and `mu`, when given), validated: the same flags mean
    /// the same on every arm (`--model` is the planar arm's base alone).
    pub fn load(&self, mu: Option<f64>) -> Result<System> {
        let mut s = self.base()?;
        match (&mut s, self.model) {
            (System::Planar(c), Some(m)) => {
                c.planar_mut().expect("a planar system").arm.model = m
            }
            (System::Spatial(_), Some(_)) => bail!(
                "--model applies to the planar arm; a spatial robot is given by [robot] in its config"
            ),
            _ => {}
        }
        let f = s.feedback_section_mut();
        if let Some(v) = mu {
            f.mu = v;
        }
        if let Some(v) = self.tau {
            f.tau = Some(v);
            if v > f.capacity() && v.is_finite() {
                f.max_tau = Some(v);
            }
        }
        if let Some(v) = self.t_on {
            f.t_on = v;
        }
        if let Some(p) = self.projection {
            f.projection = p;
        }
        let sim = s.sim_section_mut();
        if let Some(v) = self.dt {
            sim.dt = v;
        }
        if let Some(v) = &self.q0 {
            sim.q0 = Some(v.0.clone());
        }
        if let Some(v) = &self.qd0 {
            sim.qd0 = Some(v.0.clone());
        }
        if let Some(on) = self.safety {
            s.safety_section_mut().enabled = on;
        }
        s.validate()?;
        Ok(s)
    }
}

/// `--transient` as given, else its default, which a run no longer than it halves to half the
/// run: a short `--duration` alone is never refused over a flag the user did not pass (every
/// command with a transient, `simulate`'s `[sim]` included).
pub fn transient_or(given: Option<f64>, default: f64, duration: f64) -> f64 {
    given.unwrap_or(if default < duration {
        default
    } else {
        duration / 2.0
    })
}

/// `--duration` and `--transient` on any arm's `[sim]` (the caller checks the whole set-up).
pub fn set_sim_duration(
    sim: &mut control::config::SimSection,
    duration: Option<f64>,
    transient: Option<f64>,
) -> Result<()> {
    if let Some(d) = duration {
        if !(d.is_finite() && d > 0.0) {
            bail!("--duration {d}: must be a finite number of seconds > 0");
        }
        sim.duration = d;
        sim.transient = transient_or(transient, sim.transient, d);
    }
    if let Some(t) = transient {
        sim.transient = t;
    }
    Ok(())
}

/// `--obstacle X,Y,R[,MARGIN]` (a sphere X,Y,Z,R[,MARGIN] for a robot), repeated: replaces the
/// configuration's obstacles.
#[derive(Args, Debug, Clone)]
pub struct ObstacleArgs {
    /// An obstacle at (X, Y) with radius R (m) and the paper's potential margin (default 0.1 m);
    /// for a URDF robot a sphere X,Y,Z,R[,MARGIN]. Repeat for several. Replaces the obstacles of
    /// the config file or preset.
    #[arg(long = "obstacle", value_parser = parse_list, allow_hyphen_values = true, value_name = "X,Y,R[,MARGIN]")]
    pub obstacles: Vec<FloatList>,
}

impl ObstacleArgs {
    /// Puts the given obstacles into `system` in place of its own (none given: unchanged), each
    /// checked as a file's entry is, then the whole set-up checked.
    pub fn apply(&self, system: &mut System) -> Result<()> {
        if self.obstacles.is_empty() {
            return Ok(());
        }
        let dims = system.obstacle_dims();
        let form = match dims {
            2 => "X,Y,R or X,Y,R,MARGIN",
            _ => "a sphere X,Y,Z,R or X,Y,Z,R,MARGIN on a robot",
        };
        system.clear_obstacles();
        for o in &self.obstacles {
            let v = o.0.as_slice();
            if !(dims + 1..=dims + 2).contains(&v.len()) {
                bail!("--obstacle {v:?}: expected {form}");
            }
            let margin = v.get(dims + 1).copied();
            let margin = margin.unwrap_or(control::config::obstacles::OBSTACLE_MARGIN);
            system
                .add_obstacle(&v[..dims], v[dims], margin)
                .with_context(|| format!("--obstacle {v:?}"))?;
        }
        Ok(system.validate()?)
    }
}
