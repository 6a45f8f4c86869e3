//! `chaosctl orbits`: period-T orbits of the uncontrolled arm by Newton's method on the
//! stroboscopic map, their Floquet multipliers, and the μ-window in which Pyragas feedback
//! stabilises each of them (λ_max starting on the orbit with its own history).
//!
//! Newton needs seeds near an orbit. Two kinds are used: the closest returns |x_(k+1) − x_k| of a
//! μ = 0 run from each start (the classic close-return method), and the end states of feedback runs
//! at the `--seed-mu` gains that settled on a period-1 orbit (the feedback is non-invasive, so those
//! are orbits of the μ = 0 loop up to the discretisation error, and Newton polishes them).

use super::parallel::{jobs, run_all};
use super::{fmt_list, ScanModelArgs, StartArgs};
use crate::plot::{Chart, Figure, Panel, Series, Style, PALETTE};
use crate::setup::{parse_list, FloatList};
use crate::subject::Subject;
use anyhow::{bail, Result};
use clap::Args;
use control::analysis::{
    close_returns, ClassifyConfig, OrbitCatalog, OrbitStability, PeriodicOrbit, RunSpec,
    StabilitySpec, Verdict,
};
use control::config::ModelKind;
use plotters::style::RGBColor;
use serde::Serialize;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct OrbitsCmd {
    #[command(flatten)]
    pub model: ScanModelArgs,
    #[command(flatten)]
    pub starts: StartArgs,
    /// Close returns of each start's μ = 0 run tried as Newton seeds.
    #[arg(long, default_value_t = 8)]
    pub seeds: usize,
    /// Feedback gains whose period-1 end states are also tried as seeds (comma-separated).
    #[arg(long = "seed-mu", value_parser = parse_list, default_value = "0.1,0.2")]
    pub seed_mu: FloatList,
    /// Simulated time of each seeding run (s).
    #[arg(long = "seed-duration", default_value_t = 300.0)]
    pub seed_duration: f64,
    /// Time after the feedback switches on before λ_max is averaged (s).
    #[arg(long, default_value_t = 10.0)]
    pub settle: f64,
    /// Length of the averaging window for λ_max on the orbit (s).
    #[arg(long, default_value_t = 100.0)]
    pub average: f64,
    /// Worker threads (default: every core).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Output prefix: writes PREFIX.png and PREFIX.svg (λ_max on each orbit against μ).
    #[arg(long, default_value = "orbits")]
    pub output: PathBuf,
    /// Print the orbits and their stability as JSON.
    #[arg(long)]
    pub json: bool,
}

/// One orbit and its stability over μ.
#[derive(Serialize)]
pub struct OrbitReport {
    pub id: String,
    pub kind: String,
    #[serde(flatten)]
    pub orbit: PeriodicOrbit,
    /// ln|largest multiplier| / T at μ = 0 (1/s).
    pub floquet_exponent: f64,
    /// μ intervals (over the scanned values) in which the orbit is stable.
    pub stable_windows: Vec<[f64; 2]>,
    /// μ intervals in which the delayed loop's leading multiplier is inside the unit circle,
    /// their edges interpolated between the scanned μ where ln|ρ₁|/T changes sign.
    pub floquet_windows: Vec<[f64; 2]>,
    /// The scanned μ with the fastest decay, and that rate ln|ρ₁|/T (1/s).
    pub fastest: Option<[f64; 2]>,
    pub stability: Vec<Result<OrbitStability, String>>,
}

#[derive(Serialize)]
struct Report {
    seeds_tried: usize,
    seeds_converged: usize,
    orbits: Vec<OrbitReport>,
}

/// Letter names: A, B, …, Z, AA, AB, …
pub fn orbit_name(i: usize) -> String {
    let mut s = String::new();
    let mut k = i;
    loop {
        s.insert(0, (b'A' + (k % 26) as u8) as char);
        if k < 26 {
            break;
        }
        k = k / 26 - 1;
    }
    s
}

fn windows(mus: &[f64], stab: &[Result<OrbitStability, String>]) -> Vec<[f64; 2]> {
    let mut out: Vec<[f64; 2]> = Vec::new();
    let mut open: Option<[f64; 2]> = None;
    for (mu, s) in mus.iter().zip(stab) {
        let stable = matches!(s, Ok(s) if s.verdict == Verdict::Stable);
        match (stable, open.as_mut()) {
            (true, Some(w)) => w[1] = *mu,
            (true, None) => open = Some([*mu, *mu]),
            (false, Some(_)) => out.extend(open.take()),
            (false, None) => {}
        }
    }
    out.extend(open);
    out
}

/// The (μ, ln|ρ₁|/T) of every scanned μ where the delayed spectrum was computed.
fn floquet_rates(mus: &[f64], stab: &[Result<OrbitStability, String>]) -> Vec<[f64; 2]> {
    mus.iter()
        .zip(stab)
        .filter_map(|(m, s)| Some([*m, s.as_ref().ok()?.floquet.as_ref()?.exponent]))
        .collect()
}

/// Where the rate is negative, as μ intervals; an edge between two scanned gains of opposite
/// sign is where the straight line between them crosses 0.
fn floquet_windows(rates: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let crossing = |[m0, l0]: [f64; 2], [m1, l1]: [f64; 2]| m0 + (m1 - m0) * l0 / (l0 - l1);
    let mut out = Vec::new();
    let mut open: Option<f64> = None;
    for (i, &[mu, l]) in rates.iter().enumerate() {
        let prev = i.checked_sub(1).map(|j| rates[j]);
        match (l < 0.0, open) {
            (true, None) => {
                open = Some(match prev {
                    Some(p) if p[1] >= 0.0 => crossing(p, [mu, l]),
                    _ => mu,
                })
            }
            (false, Some(start)) => {
                let p = prev.expect("an open window has a predecessor");
                out.push([start, crossing(p, [mu, l])]);
                open = None;
            }
            _ => {}
        }
    }
    if let (Some(start), Some(last)) = (open, rates.last()) {
        out.push([start, last[0]]);
    }
    out
}

/// Interpolated windows as text, to three decimals.
fn fmt_floquet_windows(w: &[[f64; 2]]) -> String {
    if w.is_empty() {
        return "none of the scanned μ".into();
    }
    w.iter()
        .map(|[a, b]| format!("{a:.3}–{b:.3}"))
        .collect::<Vec<_>>()
        .join(", ")
}

fn fmt_windows(w: &[[f64; 2]]) -> String {
    if w.is_empty() {
        return "none of the scanned μ".into();
    }
    w.iter()
        .map(|[a, b]| {
            if a == b {
                format!("{a}")
            } else {
                format!("{a}–{b}")
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// A seeding run: the closest returns of a μ = 0 run, or where a feedback run settled.
enum Seeding {
    CloseReturns(Subject),
    Settled(Subject),
}

pub fn run(args: OrbitsCmd) -> Result<()> {
    if let Some(mut cfg) = crate::spatial::load(&args.model.setup, None)? {
        cfg.task.ramp = periodic_path(cfg.task.ramp);
        return spatial(&args, &Subject::robot(cfg)?);
    }
    let (mut base, mus) = args.model.load("0:3:0.1")?;
    base.task.ramp = periodic_path(base.task.ramp);
    if base.arm.model != ModelKind::Fixed {
        bail!("orbits needs the fixed-base model (--model fixed): the floating base's attitude drifts, so its motion never closes after one period");
    }
    if (base.tau() - base.task.period).abs() > 1e-9 {
        bail!(
            "orbits needs τ = T (feedback.tau = {} s, task.period = {} s): only then does the feedback vanish on period-T orbits",
            base.tau(),
            base.task.period
        );
    }
    if args.seeds > 1000 {
        bail!("--seeds {}: at most 1000", args.seeds);
    }
    for &m in &args.seed_mu.0 {
        if !(m.is_finite() && m > 0.0 && m <= 100.0) {
            bail!("--seed-mu {m}: each gain must be in (0, 100]");
        }
    }
    if !(args.seed_duration.is_finite() && args.seed_duration > 40.0) {
        bail!(
            "--seed-duration {}: must be more than 40 s",
            args.seed_duration
        );
    }
    let spec = stability_spec(&args, base.task.period)?;
    let starts = args.starts.configs(&base, args.model.setup.q0.is_some())?;
    let threads = jobs(args.jobs);

    // 1. Seeds.
    let mut seeding = Vec::new();
    for s in &starts {
        let mut c = s.clone();
        c.feedback.mu = 0.0;
        seeding.push(Seeding::CloseReturns(Subject::planar(c)));
        for &m in &args.seed_mu.0 {
            let mut c = s.clone();
            c.feedback.mu = m;
            c.validate()?;
            seeding.push(Seeding::Settled(Subject::planar(c)));
        }
    }
    let run_spec = RunSpec {
        duration: args.seed_duration,
        transient: 20.0,
        lyapunov: None,
        classify: ClassifyConfig::default(),
    };
    let nseeds = args.seeds;
    let seeds: Vec<Vec<Vec<f64>>> = run_all(&seeding, threads, "seeding runs", |s| match s {
        Seeding::CloseReturns(arm) => arm
            .analyse(&run_spec)
            .map(|a| {
                close_returns(&a.section, nseeds)
                    .into_iter()
                    .map(|i| a.section.point(i).to_vec())
                    .collect()
            })
            .unwrap_or_default(),
        Seeding::Settled(arm) => arm
            .analyse(&run_spec)
            .ok()
            .filter(|a| a.classification.motion.period() == Some(1))
            .map(|a| vec![a.final_coords])
            .unwrap_or_default(),
    })?;
    let seeds: Vec<Vec<f64>> = seeds.into_iter().flatten().collect();

    // 2. Newton from every seed; 3. distinct orbits in seed order.
    let n = base.n();
    let arm = Subject::planar(base.clone());
    let found: Vec<Option<PeriodicOrbit>> =
        run_all(&seeds, threads, "Newton", |x| arm.find_orbit(x).ok())?;
    let converged = found.iter().filter(|o| o.is_some()).count();
    let mut catalog = OrbitCatalog::new(2 * n, n, 1e-6);
    let mut orbits: Vec<PeriodicOrbit> = Vec::new();
    for o in found.into_iter().flatten() {
        if catalog.find_or_insert(&o.coords()).1 {
            orbits.push(o);
        }
    }

    // 4. Stability of each orbit at each μ.
    let cells: Vec<(usize, f64)> = (0..orbits.len())
        .flat_map(|i| mus.iter().map(move |m| (i, *m)))
        .collect();
    let stab = stability(&arm, &orbits, &cells, threads, &spec)?;
    let reports = reports(orbits, &mus, stab, base.task.period);
    let files = plot(&args.output, &reports, &mus, &spec, true)?;
    if args.json {
        let r = Report {
            seeds_tried: seeds.len(),
            seeds_converged: converged,
            orbits: reports,
        };
        println!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(());
    }
    println!(
        "chaosd period-T orbits (μ = 0, fixed base): {} seeds, {} converged, {} distinct orbits",
        seeds.len(),
        converged,
        reports.len()
    );
    print_reports(&reports, &mus, &spec);
    super::print_written(&files);
    Ok(())
}

/// The stability runs' window (`--settle`, `--average`), checked against the task period.
/// The orbits of the periodic loop: a path that starts from rest (`task.ramp`) is a start-up
/// transient, and a period map from t = 0 through the ramp has fixed points that are not the
/// cycle's. The path runs at full speed from t = 0 here (said on stderr).
fn periodic_path(ramp: f64) -> f64 {
    if ramp > 0.0 {
        eprintln!("task.ramp = {ramp} s is left out: the orbits are those of the full-speed path");
    }
    0.0
}

fn stability_spec(args: &OrbitsCmd, period: f64) -> Result<StabilitySpec> {
    let spec = StabilitySpec {
        settle: args.settle,
        duration: args.average,
        ..StabilitySpec::default()
    };
    if !(spec.settle.is_finite() && spec.settle >= 0.0) {
        bail!("--settle {}: must be ≥ 0", spec.settle);
    }
    if !(spec.duration.is_finite() && spec.duration >= 4.0 * period) {
        bail!(
            "--average {}: must be at least 4 task periods ({} s)",
            spec.duration,
            4.0 * period
        );
    }
    Ok(spec)
}

/// Each orbit, its Floquet multipliers at μ = 0 and its λ_max over μ, as text.
fn print_reports(reports: &[OrbitReport], mus: &[f64], spec: &StabilitySpec) {
    for r in reports {
        println!("\norbit {}: {}", r.id, r.kind);
        println!("  q(kT)      ({}) rad", fmt_list(&r.orbit.q));
        println!("  q̇(kT)      ({}) rad/s", fmt_list(&r.orbit.qd));
        println!(
            "  Newton     |Φ_T(x) − x| = {:.1e} after {} iterations",
            r.orbit.residual, r.orbit.iterations
        );
        println!(
            "  Floquet    {}",
            r.orbit
                .multipliers
                .iter()
                .map(|[a, b]| if b.abs() > 1e-9 {
                    format!("{a:.4}{b:+.4}i")
                } else {
                    format!("{a:.4}")
                })
                .collect::<Vec<_>>()
                .join("  ")
        );
        println!("  stable for μ in {}", fmt_windows(&r.stable_windows));
        if let Some([mu, rate]) = r.fastest {
            let pace = if rate < 0.0 {
                format!("an e-fold in {:.1} s", -1.0 / rate)
            } else {
                "growing: not stabilised".into()
            };
            println!(
                "  Floquet    |ρ₁| < 1 for μ in {}; fastest at μ = {mu}: {rate:+.4} /s ({pace})",
                fmt_floquet_windows(&r.floquet_windows),
            );
        }
        println!(
            "  {:>6}  {:>10}  {:>17}  {:>9}  {:<8}  leading multipliers with the feedback",
            "μ", "λ Floquet", "λ_max Benettin", "section", "verdict"
        );
        for (m, s) in mus.iter().zip(&r.stability) {
            println!("  {}", stability_row(*m, s));
        }
    }
    println!(
        "\n(rates in 1/s. λ Floquet = ln|ρ₁|/T from the leading multipliers of the delayed loop's \
         one-period map; λ_max by Benettin on the orbit with its own history, averaged over {}–{} s \
         after the feedback switches on, ± one standard error; section = the measured decay of a \
         small offset at t = kT. Stable: λ_max + 2 s.e. < 0 and the arm stayed on the orbit.)",
        spec.settle,
        spec.settle + spec.duration
    );
}

/// One μ's line of the stability table.
fn stability_row(mu: f64, s: &Result<OrbitStability, String>) -> String {
    let s = match s {
        Ok(s) => s,
        Err(e) => return format!("{mu:>6}  error: {e}"),
    };
    let opt = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{v:+.4}"));
    let (floquet, multipliers) = match &s.floquet {
        Some(f) => (
            format!("{:+.4}{}", f.exponent, if f.converged { "" } else { "?" }),
            fmt_multipliers(&f.multipliers),
        ),
        None => ("—".into(), "(μ = 0: the multipliers above)".into()),
    };
    format!(
        "{mu:>6}  {floquet:>10}  {:>17}  {:>9}  {:<8}  {multipliers}",
        format!("{:+.4} ± {:.4}", s.lyapunov.lambda_max, s.lyapunov.stderr),
        opt(s.section_rate),
        s.verdict.label(),
    )
}

/// Multipliers as `a±bi` (one of each conjugate pair) and reals, with their moduli.
fn fmt_multipliers(m: &[[f64; 2]]) -> String {
    m.iter()
        .filter(|[_, b]| *b >= -1e-9)
        .map(|[a, b]| {
            if b.abs() > 1e-9 {
                format!("{a:.4}±{b:.4}i (|ρ| {:.4})", a.hypot(*b))
            } else {
                format!("{a:.4}")
            }
        })
        .collect::<Vec<_>>()
        .join("  ")
}

/// The λ_max-over-μ figure; `paper` marks the window the paper claims (for its planar arm).
fn plot(
    prefix: &std::path::Path,
    reports: &[OrbitReport],
    mus: &[f64],
    spec: &StabilitySpec,
    paper: bool,
) -> Result<Vec<PathBuf>> {
    // Orbits stabilised somewhere get their own colour; the rest share one grey entry (after they
    // leave the orbit, their λ_max is the exponent of wherever the trajectory went).
    let points = |r: &OrbitReport| -> (Vec<(f64, f64)>, Vec<f64>) {
        mus.iter()
            .zip(&r.stability)
            .filter_map(|(m, s)| {
                s.as_ref()
                    .ok()
                    .map(|s| ((*m, s.lyapunov.lambda_max), s.lyapunov.stderr))
            })
            .unzip()
    };
    let never: Vec<&OrbitReport> = reports
        .iter()
        .filter(|r| r.stable_windows.is_empty())
        .collect();
    let mut series: Vec<Series> = never
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let (pts, _) = points(r);
            let label = (i == 0).then(|| {
                format!(
                    "never stabilised: {}",
                    never
                        .iter()
                        .map(|r| r.id.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            });
            Series::new(label, RGBColor(185, 185, 185), Style::Line(1), pts)
        })
        .collect();
    for (i, r) in reports
        .iter()
        .filter(|r| !r.stable_windows.is_empty())
        .enumerate()
    {
        let (pts, err) = points(r);
        let short = r.kind.split(" (").next().unwrap_or("").to_string();
        series.push(
            Series::new(
                Some(format!(
                    "orbit {} ({short}), stable for μ in {}",
                    r.id,
                    fmt_windows(&r.stable_windows)
                )),
                PALETTE[i % PALETTE.len()],
                Style::LineMarkers { width: 2, size: 3 },
                pts,
            )
            .yerr(err),
        );
        let floquet: Vec<(f64, f64)> = mus
            .iter()
            .zip(&r.stability)
            .filter_map(|(m, s)| Some((*m, s.as_ref().ok()?.floquet.as_ref()?.exponent)))
            .collect();
        if !floquet.is_empty() {
            series.push(Series::new(
                Some(format!(
                    "orbit {}: ln|ρ₁|/T, the delayed loop's leading Floquet multiplier",
                    r.id
                )),
                PALETTE[i % PALETTE.len()],
                Style::Markers {
                    size: 6,
                    filled: false,
                },
                floquet,
            ));
        }
    }
    let mu_max = mus.iter().cloned().fold(0.0, f64::max);
    let mut marks = super::lambda_plot_marks(mu_max);
    if !paper {
        marks.0.clear();
    }
    Figure {
        title: Some("Which period-T orbit does Pyragas feedback stabilise, and for which μ?".into()),
        panels: vec![Panel::Chart(Chart {
            title: format!(
                "λ_max starting on each orbit with its own history, averaged {}–{} s after switch-on, and ln|ρ₁|/T (λ < 0: stabilised)",
                spec.settle,
                spec.settle + spec.duration
            ),
            x_label: "Pyragas gain μ (1/s)".into(),
            y_label: "λ_max on the orbit (1/s)".into(),
            series,
            bands: marks.0,
            rules: marks.1,
            legend: true,
            ..Default::default()
        })],
        cols: 1,
        panel_size: (1000, 560),
    }
    .save(prefix)
}

/// How close to 1 a multiplier's modulus counts as on the unit circle (the finite-difference
/// monodromy is good to about 1e-6).
const UNIT_CIRCLE: f64 = 1e-3;

/// λ_max of each (orbit, μ) cell on `arm`, in parallel.
fn stability(
    arm: &Subject,
    orbits: &[PeriodicOrbit],
    cells: &[(usize, f64)],
    threads: usize,
    spec: &StabilitySpec,
) -> Result<Vec<Result<OrbitStability, String>>> {
    run_all(cells, threads, "stability", |(i, mu)| {
        let mut a = arm.clone();
        a.set_mu(*mu);
        a.orbit_stability(&orbits[*i], spec)
            .map_err(|e| format!("{e:#}"))
    })
}

/// One seed of `orbits` on a robot: where the loop with feedback gain `seed_mu` ended (at a
/// multiple of T), and the μ = 0 period-T orbit Newton's method found from there.
#[derive(Serialize)]
pub struct SeededOrbit {
    pub seed_mu: f64,
    /// |Φ_T(x) − x| at the seed, with the feedback off: how far the seed already was from a
    /// period-T orbit.
    pub seed_residual: f64,
    pub orbit: Result<PeriodicOrbit, String>,
    /// ln|largest multiplier| / T at μ = 0 (1/s): > 0, unstable without the feedback.
    pub floquet_exponent: Option<f64>,
}

/// For each gain, the loop run `duration` s (rounded to whole periods), then the μ = 0
/// loop's period-T orbit from the end state.
fn settled_orbits(arm: &Subject, gains: &[f64], duration: f64) -> Result<Vec<SeededOrbit>> {
    let period = arm.period();
    let (tau, _) = arm.tau_and_t_on();
    if (tau - period).abs() > 1e-9 {
        bail!("orbits needs τ = T (feedback.tau = {tau} s, task.period = {period} s): only then does the feedback vanish on period-T orbits");
    }
    let mut out = Vec::new();
    for &mu in gains {
        let mut a = arm.clone();
        a.set_mu(mu);
        let seed = a.end_state((duration / period).round() as u64)?;
        let orbit = arm.find_orbit(&seed).map_err(|e| format!("{e:#}"));
        out.push(SeededOrbit {
            seed_mu: mu,
            seed_residual: arm.period_map_residual(&seed)?,
            floquet_exponent: orbit.as_ref().ok().map(|o| o.floquet_exponent(period)),
            orbit,
        });
    }
    Ok(out)
}

/// A spatial robot: the orbit each seeding gain's run settles on, found again at μ = 0, and its
/// Floquet multipliers there; with `--mu`, each distinct orbit's λ_max over μ as for the planar
/// arm (the same stability run, table and figure).
fn spatial(args: &OrbitsCmd, arm: &Subject) -> Result<()> {
    let period = arm.period();
    let scan = match &args.model.mu {
        Some(m) => Some((m.0.clone(), stability_spec(args, period)?)),
        None => None,
    };
    if !(args.seed_duration.is_finite() && args.seed_duration >= period) {
        bail!(
            "--seed-duration {}: must be at least one period ({period} s)",
            args.seed_duration,
        );
    }
    let mut gains = args.seed_mu.0.clone();
    if arm.mu() > 0.0 && !gains.contains(&arm.mu()) {
        gains.insert(0, arm.mu());
    }
    for &m in &gains {
        if !(m.is_finite() && (0.0..=100.0).contains(&m)) {
            bail!("--seed-mu {m}: each gain must be in [0, 100]");
        }
    }
    let found = settled_orbits(arm, &gains, args.seed_duration)?;
    let reports = match &scan {
        Some((mus, spec)) => Some(spatial_scan(args, arm, &found, mus, spec)?),
        None => None,
    };
    let files = match (&reports, &scan) {
        (Some(r), Some((mus, spec))) => plot(&args.output, r, mus, spec, false)?,
        _ => Vec::new(),
    };
    if args.json {
        match reports {
            Some(r) => println!("{}", serde_json::to_string_pretty(&r)?),
            None => println!("{}", serde_json::to_string_pretty(&found)?),
        }
        return Ok(());
    }
    println!(
        "period-T orbits of {} at μ = 0 (T = {period} s), seeded by {} s runs with feedback from t = {} s:",
        arm.describe(),
        args.seed_duration,
        arm.tau_and_t_on().1
    );
    for o in &found {
        let what = match &o.orbit {
            Ok(orb) => {
                let on_circle = orb
                    .multipliers
                    .iter()
                    .filter(|m| (m[0].hypot(m[1]) - 1.0).abs() < UNIT_CIRCLE)
                    .count();
                let rho = orb.max_multiplier();
                let verdict = if rho > 1.0 + UNIT_CIRCLE {
                    "unstable without the feedback"
                } else if rho >= 1.0 - UNIT_CIRCLE {
                    "neutral without the feedback: nothing pulls the self-motion onto it"
                } else {
                    "stable without the feedback"
                };
                format!(
                    "Newton converged in {} iterations (residual {:.1e}); largest Floquet multiplier |ρ| = {rho:.4}, {on_circle} of {} on the unit circle (±{UNIT_CIRCLE}): {verdict}",
                    orb.iterations,
                    orb.residual,
                    orb.multipliers.len(),
                )
            }
            Err(e) => format!("no orbit: {e}"),
        };
        println!(
            "  seed μ = {}: |Φ_T(x) − x| = {:.2e} at the seed; {what}",
            o.seed_mu, o.seed_residual
        );
    }
    if let (Some(reports), Some((mus, spec))) = (reports, scan) {
        println!("\n{} distinct orbits, λ_max over μ on each:", reports.len());
        print_reports(&reports, &mus, &spec);
        super::print_written(&files);
    }
    Ok(())
}

/// The distinct orbits the seeds found, each with its λ_max at every μ of `mus` (in parallel).
fn spatial_scan(
    args: &OrbitsCmd,
    arm: &Subject,
    found: &[SeededOrbit],
    mus: &[f64],
    spec: &StabilitySpec,
) -> Result<Vec<OrbitReport>> {
    let n = arm.n();
    let mut catalog = OrbitCatalog::new(2 * n, n, 1e-6);
    let mut orbits: Vec<PeriodicOrbit> = Vec::new();
    for o in found.iter().filter_map(|o| o.orbit.as_ref().ok()) {
        if catalog.find_or_insert(&o.coords()).1 {
            orbits.push(o.clone());
        }
    }
    let cells: Vec<(usize, f64)> = (0..orbits.len())
        .flat_map(|i| mus.iter().map(move |m| (i, *m)))
        .collect();
    let stab = stability(arm, &orbits, &cells, jobs(args.jobs), spec)?;
    Ok(reports(orbits, mus, stab, arm.period()))
}

/// Each orbit with its stability at every μ (`stab`: orbit-major, μ inner) and its name.
fn reports(
    orbits: Vec<PeriodicOrbit>,
    mus: &[f64],
    stab: Vec<Result<OrbitStability, String>>,
    period: f64,
) -> Vec<OrbitReport> {
    let mut stab = stab.into_iter();
    orbits
        .into_iter()
        .enumerate()
        .map(|(i, o)| {
            let s: Vec<_> = stab.by_ref().take(mus.len()).collect();
            let rates = floquet_rates(mus, &s);
            OrbitReport {
                floquet_windows: floquet_windows(&rates),
                fastest: rates.into_iter().min_by(|a, b| a[1].total_cmp(&b[1])),
                id: orbit_name(i),
                kind: o.kind(),
                floquet_exponent: o.floquet_exponent(period),
                stable_windows: windows(mus, &s),
                stability: s,
                orbit: o,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_windows() {
        assert_eq!(orbit_name(0), "A");
        assert_eq!(orbit_name(25), "Z");
        assert_eq!(orbit_name(26), "AA");
        assert_eq!(fmt_windows(&[]), "none of the scanned μ");
        assert_eq!(fmt_windows(&[[0.1, 0.3], [1.5, 1.5]]), "0.1–0.3, 1.5");
        // Orbit J of the paper preset: stable from about 1.15 to 2.0.
        let rates = [[1.1, 0.2676], [1.2, -0.1461], [1.9, -0.0137], [2.0, 0.0004]];
        let w = floquet_windows(&rates);
        assert_eq!(w.len(), 1);
        assert!((w[0][0] - (1.1 + 0.1 * 0.2676 / (0.2676 + 0.1461))).abs() < 1e-12);
        assert!((w[0][1] - (1.9 + 0.1 * 0.0137 / 0.0141)).abs() < 1e-12);
        // Open at either end: the scanned μ itself.
        assert_eq!(
            floquet_windows(&[[0.1, -0.2], [0.2, -0.3]]),
            vec![[0.1, 0.2]]
        );
        assert!(floquet_windows(&[[0.1, 0.2]]).is_empty());
    }
}
