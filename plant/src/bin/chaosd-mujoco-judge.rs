//! chaosd-mujoco-judge: MuJoCo's contact verdict on a trajectory of chaosd's joints, read from
//! standard input (one sample a line: `t q1 … qN`), as one JSON object on standard output (the
//! plant summary's `contacts`). `chaosctl obstacles --mujoco-judge MODEL` runs it per run.
//!
//! With `--point` (chaosd's capsule end points, one per joint and the tool point), it fits the
//! capsules to the model's geometry instead ([`plant::mujoco::fit`]), at the first sample's
//! pose: `chaosctl robot fit-radii` runs it.
//!
//! Built only with the `mujoco` feature, against the MuJoCo library (docs/mujoco.md).

use anyhow::{bail, Context, Result};
use clap::Parser;
use plant::mujoco::replay::Replay;
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "chaosd-mujoco-judge",
    version,
    about = "MuJoCo's contact verdict on a trajectory of chaosd's joints (stdin: `t q1 … qN` a line; stdout: JSON)"
)]
struct Args {
    /// The robot's URDF or MJCF, with the collision geometry to judge by.
    #[arg(long)]
    model: PathBuf,
    /// chaosd's joint names, in order, comma-separated.
    #[arg(long, value_delimiter = ',', required = true)]
    joints: Vec<String>,
    /// An obstacle sphere X,Y,Z,R (m); repeat for several.
    #[arg(long = "sphere", value_name = "X,Y,Z,R")]
    spheres: Vec<String>,
    /// Where a URDF's `package://NAME/` paths point: NAME=DIR; repeat for several.
    #[arg(long = "package", value_name = "NAME=DIR")]
    packages: Vec<String>,
    /// Fit the capsules instead: chaosd's capsule end points X,Y,Z (m, base frame) at the first
    /// sample's pose, each joint's origin in order and then the tool point.
    #[arg(long = "point", value_name = "X,Y,Z", conflicts_with = "spheres")]
    points: Vec<String>,
}

fn point(text: &str) -> Result<[f64; 3]> {
    let v: Vec<f64> = text
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--point {text:?}: expected three numbers X,Y,Z"))?;
    match v.as_slice() {
        &[x, y, z] if v.iter().all(|x| x.is_finite()) => Ok([x, y, z]),
        _ => bail!("--point {text:?}: expected three finite numbers X,Y,Z"),
    }
}

fn sphere(text: &str) -> Result<([f64; 3], f64)> {
    let v: Vec<f64> = text
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--sphere {text:?}: expected four numbers X,Y,Z,R"))?;
    match v.as_slice() {
        &[x, y, z, r] if v.iter().all(|x| x.is_finite()) && r > 0.0 => Ok(([x, y, z], r)),
        _ => bail!("--sphere {text:?}: expected X,Y,Z,R with R > 0"),
    }
}

fn package(text: &str) -> Result<(String, PathBuf)> {
    match text.split_once('=') {
        Some((n, d)) if !n.is_empty() && !d.is_empty() => Ok((n.into(), d.into())),
        _ => bail!("--package {text:?}: expected NAME=DIR"),
    }
}

/// One line of the trajectory: its time and the joints.
fn sample(line: &str, n: usize, at: usize) -> Result<(f64, Vec<f64>)> {
    let v: Vec<f64> = line
        .split_whitespace()
        .map(str::parse::<f64>)
        .collect::<Result<_, _>>()
        .with_context(|| format!("line {at}: not numbers"))?;
    if v.len() != n + 1 || !v.iter().all(|x| x.is_finite()) {
        bail!(
            "line {at}: expected t and {n} finite joint angles, got {} numbers",
            v.len()
        );
    }
    Ok((v[0], v[1..].to_vec()))
}

fn run(args: &Args) -> Result<String> {
    let spheres = args
        .spheres
        .iter()
        .map(|s| sphere(s))
        .collect::<Result<Vec<_>>>()?;
    let packages: BTreeMap<_, _> = args
        .packages
        .iter()
        .map(|p| package(p))
        .collect::<Result<_>>()?;
    let n = args.joints.len();
    if !args.points.is_empty() {
        let points = args
            .points
            .iter()
            .map(|p| point(p))
            .collect::<Result<Vec<_>>>()?;
        let Some(line) = std::io::stdin().lock().lines().next() else {
            bail!("no pose on standard input (a line `t q1 … qN`)");
        };
        let (_, q) = sample(&line.context("cannot read the pose")?, n, 1)?;
        let links = plant::mujoco::fit::fit(&args.model, &packages, &args.joints, &q, &points)?;
        return Ok(serde_json::to_string(&links)?);
    }
    let mut replay = None;
    for (i, line) in std::io::stdin().lock().lines().enumerate() {
        let line = line.context("cannot read the trajectory")?;
        if line.trim().is_empty() {
            continue;
        }
        let (t, q) = sample(&line, n, i + 1)?;
        let r = match &mut replay {
            Some(r) => r,
            None => replay.insert(Replay::new(
                &args.model,
                &packages,
                &args.joints,
                &spheres,
                &q,
            )?),
        };
        r.pose(t, &q);
    }
    let Some(r) = replay else {
        bail!("no trajectory on standard input");
    };
    Ok(serde_json::to_string(&r.report())?)
}

fn main() -> ExitCode {
    let args = Args::parse();
    match run(&args) {
        Ok(json) => {
            println!("{json}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("chaosd-mujoco-judge: {e:#}");
            ExitCode::from(2)
        }
    }
}
