//! chaosd-plant: serves the simulated arm over iceoryx2 until SIGINT/SIGTERM.

use anyhow::{anyhow, Context, Result};
use clap::Parser;
use control::{with_dof, Config};
use plant::{PlantConfig, SimPlant};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "chaosd-plant",
    version,
    about = "The chaosd plant process: a simulated arm served over iceoryx2"
)]
struct Args {
    /// TOML config file (the same file the daemon reads; this process uses [arm], [sim] and [plant]).
    #[arg(long, conflicts_with = "preset")]
    config: Option<PathBuf>,
    /// A built-in set-up instead of a file.
    #[arg(long)]
    preset: Option<String>,
    /// Overrides plant.namespace.
    #[arg(long)]
    namespace: Option<String>,
    /// Overrides plant.output_dir.
    #[arg(long)]
    output: Option<PathBuf>,
    /// Stop after this many seconds.
    #[arg(long)]
    duration: Option<f64>,
}

fn load(args: &Args) -> Result<(Config, PlantConfig)> {
    let system = match (&args.config, &args.preset) {
        (Some(p), _) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read config file {}", p.display()))?;
            Config::from_toml_str(&text).with_context(|| format!("in {}", p.display()))?
        }
        (None, Some(name)) => Config::preset(name)?,
        (None, None) => Config::preset("paper")?,
    };
    system.validate()?;
    let mut plant = PlantConfig::from_table(system.plant.as_ref())?;
    if let Some(ns) = &args.namespace {
        plant.namespace = ns.clone();
    }
    if let Some(o) = &args.output {
        plant.output_dir = o.clone();
    }
    plant.validate()?;
    if let Some(d) = args.duration {
        if !(d.is_finite() && d > 0.0 && d <= 1e7) {
            return Err(anyhow!(
                "--duration {d}: must be a finite number of seconds > 0"
            ));
        }
    }
    Ok((system, plant))
}

fn main() -> ExitCode {
    let args = Args::parse();
    let result = load(&args).and_then(|(system, cfg)| {
        with_dof!(system.n(), N => {
            let mut sim = SimPlant::<N>::new(system.model::<N>(), system.initial_state(), cfg.substeps, cfg.brake_gain);
            plant::run::run(&mut sim, &cfg, args.duration)
        })
    });
    match result {
        Ok(s) => {
            eprintln!(
                "chaosd-plant: stopped after {:.1} s: {} states, {} commands ({} rejected), {} timeouts; round trip {}",
                s.duration_s,
                s.counters.states_published,
                s.counters.commands_received,
                s.counters.commands_rejected,
                s.counters.command_timeouts,
                s.round_trip.one_line()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("chaosd-plant: error: {e:#}");
            ExitCode::from(2)
        }
    }
}
