//! The offline chaos-analysis commands: `lyapunov`, `sweep`, `poincare`, `orbits`, `basins`,
//! `starts`, `figures`, `obstacles` and `arm-figure`.
//!
//! The math lives in `control::analysis`; this module turns flags into validated run specs,
//! spreads independent runs over the cores, prints, writes CSV/JSON and plots. Every input is
//! checked before the first simulation starts (ranges, windows, initial-state lengths, whether the
//! task circle is reachable), and every problem is an error with exit code 2, never a panic.

pub mod arm_figure;
pub mod basins;
pub mod basins_map;
pub mod figures;
pub mod lyapunov;
pub mod monitor;
pub mod monitor_cells;
pub mod monitor_report;
pub mod mujoco_judge;
pub mod obstacle_cells;
pub mod obstacles;
pub mod obstacles_judged;
pub mod orbits;
pub mod parallel;
pub mod poincare;
pub mod shard;
pub mod starts;
pub mod sweep;
pub mod tune;

use crate::setup::{parse_list, FloatList, SetupArgs};
use anyhow::{bail, Result};
use clap::Args;
use control::analysis::{ClassifyConfig, LyapunovSpec, RunSpec};
use std::f64::consts::FRAC_PI_2;

/// Values parsed from one `START:END:STEP` argument.
#[derive(Clone, Debug, PartialEq)]
pub struct Range(pub Vec<f64>);

fn parse_range_arg(s: &str) -> Result<Range, String> {
    parse_range(s).map(Range)
}

/// The model flags of `simulate`, with `--mu` taking a range: for the commands that scan μ.
#[derive(Args, Debug, Clone)]
pub struct ScanModelArgs {
    #[command(flatten)]
    pub setup: SetupArgs,
    /// Pyragas gains μ: START:END:STEP (e.g. 0:3:0.1) or one value.
    #[arg(long = "mu", value_parser = parse_range_arg, allow_hyphen_values = true)]
    pub mu: Option<Range>,
}

impl ScanModelArgs {
    /// The μ values to scan: `--mu`, else `default_mu`.
    pub fn mus(&self, default_mu: &str) -> Result<Vec<f64>> {
        match &self.mu {
            Some(r) => Ok(r.0.clone()),
            None => parse_range(default_mu).map_err(anyhow::Error::msg),
        }
    }
}

/// Parses `START:END:STEP` into start, start + step, … up to END (inclusive, to rounding), or a
/// single number into one value.
pub fn parse_range(s: &str) -> Result<Vec<f64>, String> {
    let parts: Vec<&str> = s.split(':').map(str::trim).collect();
    let num = |x: &str| {
        x.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                format!("{x:?} is not a finite number (expected START:END:STEP, e.g. 0:3:0.1)")
            })
    };
    match parts.as_slice() {
        [one] => Ok(vec![num(one)?]),
        [a, b, c] => {
            let (start, end, step) = (num(a)?, num(b)?, num(c)?);
            if step <= 0.0 {
                return Err(format!("step {step} in {s:?}: must be > 0"));
            }
            if end < start {
                return Err(format!("{s:?}: END ({end}) is below START ({start}); write START:END:STEP with START ≤ END"));
            }
            let n = ((end - start) / step + 1e-9).floor() as u64 + 1;
            if n > 100_000 {
                return Err(format!("{s:?} has {n} points; at most 100000 are allowed"));
            }
            // Multiply rather than accumulate, and clean up the rounding (0.1·3 = 0.30000000000000004).
            Ok((0..n)
                .map(|i| {
                    let v = start + i as f64 * step;
                    (v * 1e9).round() / 1e9
                })
                .collect())
        }
        _ => Err(format!(
            "{s:?}: expected START:END:STEP (e.g. 0:3:0.1) or a single number"
        )),
    }
}

/// Parses `START:END` (seconds).
pub fn parse_window(s: &str) -> Result<[f64; 2], String> {
    let parts: Vec<&str> = s.split(':').map(str::trim).collect();
    let num = |x: &str| {
        x.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                format!(
                    "{x:?} is not a finite number (expected START:END in seconds, e.g. 100:300)"
                )
            })
    };
    match parts.as_slice() {
        [a, b] => {
            let (a, b) = (num(a)?, num(b)?);
            if b <= a {
                return Err(format!("window {s:?}: END must be greater than START"));
            }
            Ok([a, b])
        }
        _ => Err(format!(
            "window {s:?}: expected START:END in seconds, e.g. 100:300"
        )),
    }
}

/// Flags that choose how λ_max is measured (shared by `lyapunov` and `sweep`).
#[derive(Args, Debug, Clone)]
pub struct LyapunovArgs {
    /// Simulated time per run (s).
    #[arg(long, default_value_t = 300.0)]
    pub duration: f64,
    /// Seconds averaged, START:END (default: from a third of the duration to the end).
    #[arg(long, value_parser = parse_window, allow_hyphen_values = true)]
    pub window: Option<[f64; 2]>,
    /// Initial and renormalised separation of the Lyapunov pair.
    #[arg(long, default_value_t = 1e-8)]
    pub d0: f64,
    /// Renormalisation interval (s; default: the task period T).
    #[arg(long)]
    pub renorm: Option<f64>,
    /// Blocks for the standard error of λ_max.
    #[arg(long, default_value_t = 10)]
    pub blocks: usize,
}

/// Flags of the Poincaré classifier.
#[derive(Args, Debug, Clone)]
pub struct ClassifyArgs {
    /// Return-distance tolerance for "period-p".
    #[arg(long, default_value_t = 1e-6)]
    pub tol: f64,
    /// Largest period p tested.
    #[arg(long = "max-period", default_value_t = 8)]
    pub max_period: usize,
}

impl ClassifyArgs {
    pub fn config(&self) -> Result<ClassifyConfig> {
        if !(self.tol.is_finite() && self.tol > 0.0) {
            bail!("--tol {}: must be a finite number > 0", self.tol);
        }
        if !(1..=64).contains(&self.max_period) {
            bail!("--max-period {}: must be between 1 and 64", self.max_period);
        }
        Ok(ClassifyConfig {
            tol: self.tol,
            max_period: self.max_period,
            ..ClassifyConfig::default()
        })
    }
}

impl LyapunovArgs {
    /// The run spec for a task of `period` integrated at `dt`, validated (window inside the
    /// duration, renorm, d0, blocks).
    pub fn spec(&self, period: f64, dt: f64, classify: ClassifyConfig) -> Result<RunSpec> {
        let d = self.duration;
        if !(d.is_finite() && d > 0.0) {
            bail!("--duration {d}: must be a finite number of seconds > 0");
        }
        let window = self.window.unwrap_or([(d / 3.0).round(), d]);
        if window[0] < 0.0 || window[1] > d + 1e-9 {
            bail!(
                "--window {}:{}: must lie inside the run, 0:{d} (use --duration to run longer)",
                window[0],
                window[1]
            );
        }
        let spec = RunSpec {
            duration: d,
            transient: window[0],
            lyapunov: Some(LyapunovSpec {
                d0: self.d0,
                renorm: self.renorm.unwrap_or(period),
                window,
                blocks: self.blocks,
            }),
            classify,
        };
        spec.validate(period, dt)?;
        Ok(spec)
    }
}

/// The paper's start and two others: the default initial states of `sweep` (3-link arms).
pub const DEFAULT_STARTS: [[f64; 3]; 3] = [
    [0.0, FRAC_PI_2, FRAC_PI_2],
    [0.3, 1.2, 1.9],
    [-0.5, 2.0, 1.0],
];

/// Initial joint angles to run from, as given by repeated `--start a,b,c`.
#[derive(Args, Debug, Clone)]
pub struct StartArgs {
    /// Initial joint angles q0 (rad) of one run; repeat for several. Without it: --q0, or for
    /// 3-link arms the paper's (0, π/2, π/2) plus (0.3, 1.2, 1.9) and (−0.5, 2.0, 1.0).
    #[arg(long = "start", value_parser = parse_list, allow_hyphen_values = true)]
    pub starts: Vec<FloatList>,
}

impl StartArgs {
    /// The start postures: `--start` as given, else the set-up's own (`--q0` or the file's), else
    /// for a 3-link planar arm the paper's three.
    pub fn postures(&self, base_q0: Vec<f64>, default_three: bool) -> Vec<Vec<f64>> {
        if !self.starts.is_empty() {
            self.starts.iter().map(|s| s.0.clone()).collect()
        } else if default_three {
            DEFAULT_STARTS.iter().map(|s| s.to_vec()).collect()
        } else {
            vec![base_q0]
        }
    }
}

/// "a, b, c" with 3 decimals.
pub fn fmt_list(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:.3}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A short name for a number in a file name: 0.2 → "0.2", 1 → "1".
pub fn fmt_num(v: f64) -> String {
    let s = format!("{v}");
    s.replace('-', "m")
}

/// Checks `--duration` and `--transient`: the section needs points after the transient.
pub fn check_run_window(duration: f64, transient: f64) -> Result<()> {
    if !(duration.is_finite() && duration > 0.0) {
        anyhow::bail!("--duration {duration}: must be a finite number of seconds > 0");
    }
    if !(transient >= 0.0 && transient < duration) {
        anyhow::bail!("--transient {transient}: must be in [0, --duration = {duration}) so that the section has points");
    }
    Ok(())
}

/// "chaotic" / "stable" / "marginal" from λ and its standard error (two standard errors).
pub fn verdict(e: &control::analysis::LyapunovEstimate) -> &'static str {
    if e.lambda_max - 2.0 * e.stderr > 0.0 {
        "chaotic (λ_max > 0 by more than two standard errors)"
    } else if e.lambda_max + 2.0 * e.stderr < 0.0 {
        "stable (λ_max < 0 by more than two standard errors)"
    } else {
        "marginal (λ_max within two standard errors of 0)"
    }
}

/// The decorations of every λ_max-against-μ plot: the paper's claimed window (when the scan
/// reaches it) and the λ = 0 line between stable and chaotic.
pub fn lambda_plot_marks(mu_max: f64) -> (Vec<crate::plot::Band>, Vec<crate::plot::Rule>) {
    use crate::plot::{Band, Rule, GREY, PALETTE};
    let bands = if mu_max >= 1.3 {
        vec![Band {
            from: 1.3,
            to: 2.3,
            color: PALETTE[2],
            label: Some("paper's claimed window 1.3 < μ < 2.3".into()),
        }]
    } else {
        vec![]
    };
    (
        bands,
        vec![Rule {
            value: 0.0,
            vertical: false,
            color: GREY,
            label: None,
        }],
    )
}

/// Tells the user which files a command wrote.
pub fn print_written(files: &[std::path::PathBuf]) {
    if files.is_empty() {
        return;
    }
    let list: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    println!("wrote {}", list.join(", "));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::setup::transient_or;

    #[test]
    fn a_default_transient_halves_for_a_short_run_and_a_given_one_never_changes() {
        assert_eq!(transient_or(None, 100.0, 300.0), 100.0);
        assert_eq!(transient_or(None, 20.0, 20.0), 10.0);
        assert_eq!(transient_or(None, 100.0, 60.0), 30.0);
        // Given: checked by check_run_window, never changed here.
        assert_eq!(transient_or(Some(30.0), 100.0, 20.0), 30.0);
        assert!(check_run_window(20.0, transient_or(Some(30.0), 100.0, 20.0)).is_err());
        assert!(check_run_window(20.0, transient_or(None, 100.0, 20.0)).is_ok());
    }

    #[test]
    fn ranges_parse_and_reject() {
        assert_eq!(parse_range("0:3:0.1").unwrap().len(), 31);
        assert_eq!(parse_range("0:3:0.1").unwrap()[3], 0.3);
        assert_eq!(parse_range("1.5").unwrap(), vec![1.5]);
        assert_eq!(parse_range("0:1:0.3").unwrap(), vec![0.0, 0.3, 0.6, 0.9]);
        for bad in [
            "0:3:0",
            "0:3:-0.1",
            "3:0:0.1",
            "a:1:0.1",
            "0:1",
            "0:nan:0.1",
            "0:1e9:1e-6",
        ] {
            assert!(parse_range(bad).is_err(), "{bad}");
        }
        assert_eq!(parse_window("100:300").unwrap(), [100.0, 300.0]);
        for bad in ["300:100", "5", "a:b", "1:2:3"] {
            assert!(parse_window(bad).is_err(), "{bad}");
        }
    }
}
