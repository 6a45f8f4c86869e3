//! The basins command's flags and the map it makes of the runs' ends (orbit names, CSV, printed
//! map, figure); `basins` makes the runs, on any arm.

use super::orbits::orbit_name;
use super::shard::{self, Shard};
use super::{fmt_list, ClassifyArgs, ScanModelArgs};
use crate::plot::{with_ext, Figure, Grid, Panel, DARK, PALETTE};
use anyhow::{Context, Result};
use clap::Args;
use control::analysis::{Motion, OrbitCatalog};
use plotters::style::RGBColor;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::PathBuf;

/// `NAME=START:END:STEP` with NAME one of q1…qn, qd1…qdn.
#[derive(Clone, Debug, PartialEq)]
pub struct Vary {
    pub rate: bool,
    pub joint: usize,
    pub values: Vec<f64>,
}

fn parse_vary(s: &str) -> Result<Vary, String> {
    let (name, range) = s
        .split_once('=')
        .ok_or_else(|| format!("{s:?}: expected NAME=START:END:STEP, e.g. q1=-1:1:0.1"))?;
    let name = name.trim();
    let (rate, idx) = if let Some(i) = name.strip_prefix("qd") {
        (true, i)
    } else if let Some(i) = name.strip_prefix('q') {
        (false, i)
    } else {
        return Err(format!(
            "{name:?}: the varied coordinate must be q1, q2, … or qd1, qd2, …"
        ));
    };
    let joint: usize = idx.parse().ok().filter(|j| *j >= 1).ok_or_else(|| {
        format!("{name:?}: the varied coordinate must be q1, q2, … or qd1, qd2, …")
    })?;
    let values = super::parse_range(range)?;
    Ok(Vary {
        rate,
        joint: joint - 1,
        values,
    })
}

#[derive(Args, Debug)]
pub struct BasinsCmd {
    #[command(flatten)]
    pub model: ScanModelArgs,
    /// The varied coordinate of the start and its values, e.g. q1=-1.5:1.5:0.125 (rad) or
    /// qd3=-2:2:0.25 (rad/s). The other coordinates come from --q0/--qd0 (default: the paper's).
    #[arg(long, value_parser = parse_vary, default_value = "q1=-1.5:1.5:0.125", allow_hyphen_values = true)]
    pub vary: Vary,
    /// Simulated time per run (s).
    #[arg(long, default_value_t = 300.0)]
    pub duration: f64,
    /// The section is classified from this time on (s) [default: 100, or half a shorter run].
    #[arg(long)]
    pub transient: Option<f64>,
    #[command(flatten)]
    pub classify: ClassifyArgs,
    /// Worker threads (default: every core).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Output prefix: writes PREFIX.csv, PREFIX.png and PREFIX.svg.
    #[arg(long, default_value = "basins")]
    pub output: PathBuf,
    /// Print the cells as JSON instead of the map.
    #[arg(long)]
    pub json: bool,
    /// Run only shard I of N (0 ≤ I < N; grid point k goes to shard k mod N) and write
    /// PREFIX.shard-I-of-N.json; `chaosctl merge` makes the map from all N.
    #[arg(long, value_parser = shard::parse_shard, value_name = "I/N")]
    pub shard: Option<Shard>,
}

impl BasinsCmd {
    /// `--transient`, or its default ([`crate::setup::transient_or`]).
    pub fn transient(&self) -> f64 {
        crate::setup::transient_or(self.transient, 100.0, self.duration)
    }
}

/// What the map needs from one run; a shard file carries exactly this per grid point.
#[derive(Serialize, Deserialize, Clone, Debug)]
pub struct RunEnd {
    pub motion: Motion,
    pub k01: Option<f64>,
    pub rms_tracking_error: f64,
    /// The final state's coordinates, to tell the period-1 orbits apart.
    pub final_coords: Vec<f64>,
}

/// The end of one run.
#[derive(Serialize, Clone, Debug, PartialEq)]
#[serde(tag = "outcome", rename_all = "kebab-case")]
pub enum Outcome {
    /// Settled on (or converging to) period-1 orbit `orbit` (A, B, …).
    Orbit {
        orbit: String,
        converging: bool,
    },
    /// Period p > 1.
    Periodic {
        period: usize,
    },
    QuasiPeriodic,
    Irregular,
    Failed {
        error: String,
    },
}

#[derive(Serialize, Clone, Debug)]
pub struct Cell {
    pub mu: f64,
    pub start: f64,
    #[serde(flatten)]
    pub outcome: Outcome,
    pub k01: Option<f64>,
    pub rms_tracking_error: Option<f64>,
}

/// Notes on the settled orbits, one per section point.
pub(crate) type Refine<'a> = Box<dyn Fn(&[Vec<f64>]) -> Vec<Option<String>> + 'a>;

/// What the map needs to know of the set-up, whichever arm it is.
pub(crate) struct MapBase<'a> {
    pub n: usize,
    /// The section has one more coordinate (the floating base's attitude).
    pub floating: bool,
    /// The start coordinates of the varied kind (q or q̇) the rows do not vary, for titles.
    pub fixed: Vec<f64>,
    pub mus: Vec<f64>,
    /// (varied start value, μ) of each grid point, rows (starts) outer, μ inner.
    pub cells: Vec<(f64, f64)>,
    /// A note on each settled orbit (Newton at μ = 0), by its section point.
    pub refine: Refine<'a>,
}

/// Names the orbits, writes the CSV and plot, prints the map.
pub(crate) fn finish(
    args: &BasinsCmd,
    base: &MapBase,
    runs: &[Result<RunEnd, String>],
) -> Result<()> {
    let (mus, n) = (&base.mus, base.n);
    // Name the period-1 orbits in a fixed order (by start, then μ) so labels are reproducible.
    // Controlled orbits at different μ differ by up to ~1e-3 (discretisation), distinct orbits by O(1).
    let mut catalog = OrbitCatalog::new(2 * n + usize::from(base.floating), n, 0.05);
    let mut out = Vec::with_capacity(runs.len());
    for (&(start, mu), r) in base.cells.iter().zip(runs) {
        let (outcome, k01, rms) = match r {
            Err(e) => (Outcome::Failed { error: e.clone() }, None, None),
            Ok(a) => {
                let o = match a.motion {
                    Motion::Periodic { period: 1, .. } | Motion::Converging { period: 1, .. } => {
                        let (i, _) = catalog.find_or_insert(&a.final_coords);
                        Outcome::Orbit {
                            orbit: orbit_name(i),
                            converging: matches!(a.motion, Motion::Converging { .. }),
                        }
                    }
                    Motion::Periodic { period, .. } | Motion::Converging { period, .. } => {
                        Outcome::Periodic { period }
                    }
                    Motion::QuasiPeriodic { .. } => Outcome::QuasiPeriodic,
                    Motion::Irregular { .. } | Motion::TooShort { .. } => Outcome::Irregular,
                };
                (o, a.k01, Some(a.rms_tracking_error))
            }
        };
        out.push(Cell {
            mu,
            start,
            outcome,
            k01,
            rms_tracking_error: rms,
        });
    }
    let orbit_points: Vec<Vec<f64>> = (0..catalog.len())
        .map(|i| catalog.point(i).to_vec())
        .collect();
    let refined = (base.refine)(&orbit_points);

    let csv = with_ext(&args.output, "csv");
    write_csv(&csv, &out)?;
    let files = plot(args, &base.fixed, mus, &out, catalog.len())?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    print_map(args, &base.fixed, mus, &out);
    for (i, p) in orbit_points.iter().enumerate() {
        println!(
            "  orbit {}: x(kT) ≈ ({}){}",
            orbit_name(i),
            fmt_list(p),
            refined[i]
                .as_deref()
                .map(|s| format!("; {s}"))
                .unwrap_or_default()
        );
    }
    let total = out.len();
    let count = |f: &dyn Fn(&Outcome) -> bool| out.iter().filter(|c| f(&c.outcome)).count();
    println!(
        "  {} of {total} runs settled on a period-1 orbit, {} stayed irregular, {} quasi-periodic, {} other periods, {} failed",
        count(&|o| matches!(o, Outcome::Orbit { .. })),
        count(&|o| matches!(o, Outcome::Irregular)),
        count(&|o| matches!(o, Outcome::QuasiPeriodic)),
        count(&|o| matches!(o, Outcome::Periodic { .. })),
        count(&|o| matches!(o, Outcome::Failed { .. })),
    );
    super::print_written(&[std::slice::from_ref(&csv), &files[..]].concat());
    Ok(())
}

pub(super) fn coord_name(v: &Vary) -> String {
    format!("{}{}", if v.rate { "qd" } else { "q" }, v.joint + 1)
}

fn symbol(o: &Outcome) -> String {
    match o {
        Outcome::Orbit { orbit, converging } => {
            if *converging {
                orbit.to_lowercase()
            } else {
                orbit.clone()
            }
        }
        Outcome::Periodic { period } => (period % 10).to_string(),
        Outcome::QuasiPeriodic => "~".into(),
        Outcome::Irregular => "#".into(),
        Outcome::Failed { .. } => "!".into(),
    }
}

fn print_map(args: &BasinsCmd, fixed: &[f64], mus: &[f64], cells: &[Cell]) {
    let name = coord_name(&args.vary);
    println!(
        "chaosd basins: {name} varied (rows), μ (columns); the other coordinates from ({}); {} s runs, section from {} s",
        fmt_list(fixed),
        args.duration,
        args.transient()
    );
    println!("  A, B, …: settled on period-1 orbit A, B, … (lower case: still converging)   2-9: period p");
    println!("  ~: quasi-periodic   #: irregular (chaotic)   !: failed");
    print!("{:>8} ", "μ →");
    for m in mus {
        print!("{:<5}", format!("{m}"));
    }
    println!();
    let ncol = mus.len();
    for row in cells.chunks(ncol).rev() {
        print!("{:>8} ", format!("{:.3}", row[0].start));
        for c in row {
            print!("{:<5}", symbol(&c.outcome));
        }
        println!();
    }
}

fn write_csv(path: &PathBuf, cells: &[Cell]) -> Result<()> {
    let file =
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = std::io::BufWriter::new(file);
    writeln!(
        w,
        "mu,start,outcome,orbit,period,converging,k01,rms_tracking_error,error"
    )?;
    for c in cells {
        let (kind, orbit, period, conv, err) = match &c.outcome {
            Outcome::Orbit { orbit, converging } => (
                "orbit",
                orbit.clone(),
                "1".to_string(),
                converging.to_string(),
                String::new(),
            ),
            Outcome::Periodic { period } => (
                "periodic",
                String::new(),
                period.to_string(),
                String::new(),
                String::new(),
            ),
            Outcome::QuasiPeriodic => (
                "quasi-periodic",
                String::new(),
                String::new(),
                String::new(),
                String::new(),
            ),
            Outcome::Irregular => (
                "irregular",
                String::new(),
                String::new(),
                String::new(),
                String::new(),
            ),
            Outcome::Failed { error } => (
                "failed",
                String::new(),
                String::new(),
                String::new(),
                error.replace(',', ";"),
            ),
        };
        writeln!(
            w,
            "{},{},{kind},{orbit},{period},{conv},{},{},{err}",
            c.mu,
            c.start,
            c.k01.map(|k| format!("{k:.4}")).unwrap_or_default(),
            c.rms_tracking_error
                .map(|v| format!("{v:.6e}"))
                .unwrap_or_default()
        )?;
    }
    w.flush()?;
    Ok(())
}

fn lighten(c: RGBColor) -> RGBColor {
    let f = |v: u8| (v as f64 + (255.0 - v as f64) * 0.55) as u8;
    RGBColor(f(c.0), f(c.1), f(c.2))
}

fn plot(
    args: &BasinsCmd,
    fixed: &[f64],
    mus: &[f64],
    cells: &[Cell],
    orbits: usize,
) -> Result<Vec<PathBuf>> {
    // Categories: per orbit settled / converging, then period-p, quasi-periodic, irregular, failed.
    let mut categories: Vec<(String, RGBColor)> = Vec::new();
    for i in 0..orbits {
        let c = PALETTE[i % PALETTE.len()];
        categories.push((format!("period-1 orbit {}", orbit_name(i)), c));
        categories.push((
            format!("→ orbit {} (converging)", orbit_name(i)),
            lighten(c),
        ));
    }
    let other = categories.len();
    categories.push(("other period p".into(), RGBColor(255, 200, 0)));
    categories.push(("quasi-periodic".into(), RGBColor(190, 190, 190)));
    categories.push(("irregular (chaotic)".into(), DARK));
    categories.push(("failed".into(), RGBColor(255, 0, 255)));
    let index = |o: &Outcome| match o {
        Outcome::Orbit { orbit, converging } => {
            let i = (0..orbits).find(|i| orbit_name(*i) == *orbit).unwrap_or(0);
            2 * i + usize::from(*converging)
        }
        Outcome::Periodic { .. } => other,
        Outcome::QuasiPeriodic => other + 1,
        Outcome::Irregular => other + 2,
        Outcome::Failed { .. } => other + 3,
    };
    let name = coord_name(&args.vary);
    let unit = if args.vary.rate { "rad/s" } else { "rad" };
    let grid = Grid {
        title: format!(
            "end state after {} s (section from {} s); other start coordinates ({})",
            args.duration,
            args.transient(),
            fmt_list(fixed)
        ),
        x_label: "Pyragas gain μ (1/s)".into(),
        y_label: format!("initial {name} ({unit})"),
        xs: mus.to_vec(),
        ys: args.vary.values.clone(),
        cells: cells.iter().map(|c| index(&c.outcome)).collect(),
        categories,
    };
    Figure {
        title: Some(
            "Basins: which starts does delayed feedback make periodic, for which μ?".into(),
        ),
        panels: vec![Panel::Grid(grid)],
        cols: 1,
        panel_size: (1100, 620),
    }
    .save(&args.output)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vary_parses_and_rejects() {
        assert_eq!(
            parse_vary("q2=0:1:0.5").unwrap(),
            Vary {
                rate: false,
                joint: 1,
                values: vec![0.0, 0.5, 1.0]
            }
        );
        assert!(parse_vary("qd3=-1:1:1").unwrap().rate);
        for bad in ["q0=0:1:0.5", "x1=0:1:0.1", "q1", "q1=1:0:0.1", "q1=0:1:0"] {
            assert!(parse_vary(bad).is_err(), "{bad}");
        }
    }
}
