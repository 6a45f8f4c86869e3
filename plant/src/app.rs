//! The plant process's `main`, as a library function, so that a bridge's own `main` is a few
//! lines: parse the standard flags, load and validate the config, run the loop, print one
//! summary line, map errors to an exit code.
//!
//! ```no_run
//! use clap::Parser;
//! use plant::app::{self, PlantArgs};
//! # use plant::{Actuation, Plant, PlantError};
//! # struct MyBridge;
//! # impl Plant for MyBridge {
//! #     fn n(&self) -> usize { 3 }
//! #     fn flags(&self) -> u32 { 0 }
//! #     fn activate(&mut self) -> Result<(), PlantError> { Ok(()) }
//! #     fn write(&mut self, _: Actuation<'_>) -> Result<(), PlantError> { Ok(()) }
//! #     fn read(&mut self, _: f64, _: &mut protocol::StateSample) -> Result<(), PlantError> { Ok(()) }
//! #     fn deactivate(&mut self) {}
//! # }
//!
//! #[derive(Parser)]
//! struct Args {
//!     #[command(flatten)]
//!     plant: PlantArgs,
//! }
//!
//! fn main() -> std::process::ExitCode {
//!     let args = Args::parse();
//!     app::serve("my-bridge", &args.plant, |_launch| Ok(MyBridge))
//! }
//! ```

use crate::config::PlantConfig;
use crate::report::PlantSummary;
use crate::seam::Plant;
use anyhow::{anyhow, Context, Result};
use control::System;
use std::path::PathBuf;
use std::process::ExitCode;

/// The flags every plant process takes; `#[command(flatten)]` them into a bridge's own `Args`.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct PlantArgs {
    /// TOML config file (the same file the daemon reads; a plant uses the arm ([robot], or [arm] in the planar arm's older form), [sim], [command] and [plant]).
    #[arg(long, conflicts_with = "preset")]
    pub config: Option<PathBuf>,
    /// A built-in set-up instead of a file.
    #[arg(long)]
    pub preset: Option<String>,
    /// Overrides plant.namespace.
    #[arg(long)]
    pub namespace: Option<String>,
    /// Overrides plant.output_dir.
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// Stop after this many seconds (default: on SIGINT or SIGTERM). A daemon that shuts down
    /// leaves the arm braked, not the plant stopped: as a real arm outlives its controller, the
    /// plant waits braked for a daemon to start again (a restarted daemon takes the arm over).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Overrides plant.dynamics: kinematic, rigid-body, or mujoco (MuJoCo's physics of the
    /// robot's URDF or MJCF, by chaosd-plant-mujoco: docs/mujoco.md).
    #[arg(long, value_parser = parse_engine)]
    pub engine: Option<crate::config::Dynamics>,
}

fn parse_engine(name: &str) -> Result<crate::config::Dynamics, String> {
    use crate::config::Dynamics;
    [Dynamics::Kinematic, Dynamics::RigidBody, Dynamics::Mujoco]
        .into_iter()
        .find(|d| d.name() == name)
        .ok_or_else(|| format!("{name:?}: the engines are kinematic, rigid-body and mujoco"))
}

/// A validated start: the whole system config, the `[plant]` table, and the run length.
#[derive(Clone, Debug)]
pub struct Launch {
    pub system: System,
    pub plant: PlantConfig,
    pub duration: Option<f64>,
}

impl Launch {
    /// What the arm is, for the handshake with the daemon.
    pub fn arm(&self) -> protocol::ArmInfo {
        crate::handshake::describe(&self.system)
    }
}

/// Loads and validates everything before anything starts; errors name the field.
pub fn load(args: &PlantArgs) -> Result<Launch> {
    // A plant never evaluates the law, so a secondary task registered only in the controller's
    // program (examples/custom-task) must not stop it; the daemon checks the name.
    control::secondary::custom::outside_the_controller();
    let system = match (&args.config, &args.preset) {
        (Some(p), _) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read config file {}", p.display()))?;
            rt::robot::parse(&text).with_context(|| format!("in {}", p.display()))?
        }
        (None, Some(name)) => rt::robot::preset(name)?,
        (None, None) => rt::robot::preset("paper")?,
    };
    let mut plant = PlantConfig::from_table(system.tables().1.as_ref())?;
    if let Some(ns) = &args.namespace {
        plant.namespace = ns.clone();
    }
    if let Some(o) = &args.output {
        plant.output_dir = o.clone();
    }
    if let Some(e) = args.engine {
        plant.dynamics = e;
    }
    plant.validate()?;
    if let Some(d) = args.duration {
        if !(d.is_finite() && d > 0.0 && d <= 1e7) {
            return Err(anyhow!(
                "--duration {d}: must be a finite number of seconds > 0"
            ));
        }
    }
    Ok(Launch {
        system,
        plant,
        duration: args.duration,
    })
}

/// Loads, builds the plant with `make`, runs it and reports: a bridge's whole `main`.
pub fn serve<P: Plant>(
    name: &str,
    args: &PlantArgs,
    make: impl FnOnce(&Launch) -> Result<P>,
) -> ExitCode {
    main_with(name, args, |l| {
        let mut plant = make(l)?;
        crate::run::run(&mut plant, &l.plant, &l.arm(), l.duration)
    })
}

/// Like [`serve`], for a plant whose type depends on the config (the simulator's arm size).
pub fn main_with(
    name: &str,
    args: &PlantArgs,
    body: impl FnOnce(&Launch) -> Result<PlantSummary>,
) -> ExitCode {
    rt::log::init();
    match load(args).and_then(|l| body(&l)) {
        Ok(s) => {
            let c = &s.counters;
            let in_time = s.in_time_share.map_or(String::new(), |f| {
                format!(", {:.3} % answered in time", f * 100.0)
            });
            tracing::info!(
                "{name}: stopped after {:.1} s: {} states, {} commands ({} rejected), {} timeouts, {} late cycles{in_time}; round trip {}",
                s.duration_s,
                c.states_published,
                c.commands_received,
                c.commands_rejected,
                c.command_timeouts,
                c.late_cycles,
                s.round_trip.one_line()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            rt::log::fatal(name, &format!("{e:#}"));
            ExitCode::from(2)
        }
    }
}
