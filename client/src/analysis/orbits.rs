//! `chaosctl orbits`: period-T orbits of the uncontrolled arm by Newton's method on the
//! stroboscopic map, their Floquet multipliers, and the μ-window in which Pyragas feedback
//! stabilises each of them (λ_max starting on the orbit with its own history).
//!
//! Newton needs seeds near an orbit. Two kinds are used, on every arm: the closest returns
//! |x_(k+1) − x_k| of a μ = 0 run from each start (the classic close-return method), and the end
//! states of runs from each start at the seeding gains (`--seed-mu` and the set-up's own μ). The
//! feedback is non-invasive, so a run it settled ends near an orbit of the μ = 0 loop, and Newton
//! polishes it; a run that had not settled is tried all the same (Newton fails or finds another
//! orbit), and the report says what each seeding run became and which orbit it led to.

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
use plotters::style::RGBColor;
use serde::Serialize;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct OrbitsCmd {
    #[command(flatten)]
    pub model: ScanModelArgs,
    #[command(flatten)]
    pub starts: StartArgs,
    /// Close returns of each start's μ = 0 run tried as Newton seeds (0: none).
    #[arg(long, default_value_t = 8)]
    pub seeds: usize,
    /// Feedback gains whose runs' end states are also tried as seeds, with the set-up's own μ
    /// when it is > 0 (comma-separated).
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
    /// Output prefix: writes PREFIX.png and PREFIX.svg (λ_max on each orbit against μ; with a
    /// scan: always on the planar arm, on a robot with --mu).
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
    /// Each settled run's seed and the orbit it led to.
    settled: Vec<SeededOrbit>,
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

/// A seeding run from one start: the closest returns of its μ = 0 run, or where its run at a
/// seeding gain ended.
enum Seeding {
    CloseReturns(Subject),
    Settled(usize, Subject),
}

/// A Newton seed: a state (q, q̇) at t = kT, and for a settled run's end state, which run.
struct Seed {
    point: Vec<f64>,
    settled: Option<(usize, f64, String)>,
}

/// The checked study: the set-up (its path at full speed), the starts, the seeding gains, the
/// μ scanned on each orbit (none: no scan) and the runs' specs.
struct Plan {
    base: Subject,
    starts: Vec<Subject>,
    gains: Vec<f64>,
    mus: Vec<f64>,
    spec: StabilitySpec,
    seeding: RunSpec,
}

fn plan(args: &OrbitsCmd) -> Result<Plan> {
    let mut base = Subject::load(&args.model.setup, None)?;
    base.full_speed_path();
    if base.floating() {
        bail!("orbits needs the fixed-base model (--model fixed): the floating base's attitude drifts, so its motion never closes after one period");
    }
    let (period, (tau, _)) = (base.period(), base.tau_and_t_on());
    if (tau - period).abs() > 1e-9 {
        bail!("orbits needs τ = T (feedback.tau = {tau} s, task.period = {period} s): only then does the feedback vanish on period-T orbits");
    }
    if args.seeds > 1000 {
        bail!("--seeds {}: at most 1000", args.seeds);
    }
    // The set-up's own gain seeds too, first (a robot's preset runs at the gain it was tuned for).
    let mut gains = args.seed_mu.0.clone();
    if base.mu() > 0.0 && !gains.contains(&base.mu()) {
        gains.insert(0, base.mu());
    }
    for &m in &gains {
        if !(m.is_finite() && (0.0..=100.0).contains(&m)) {
            bail!("--seed-mu {m}: each gain must be in [0, 100]");
        }
    }
    let d = args.seed_duration;
    if !(d.is_finite() && d >= 2.0 * period && d <= 1e6) {
        bail!(
            "--seed-duration {d}: must be at least two task periods ({} s) and at most 1e6 s",
            2.0 * period
        );
    }
    let periods = (d / period).round();
    let mus = scanned_mus(args, &base)?;
    for &mu in &mus {
        let mut c = base.clone();
        c.set_mu(mu);
        c.check()?;
    }
    Ok(Plan {
        starts: base.starts(&args.starts, args.model.setup.q0.is_some())?,
        gains,
        mus,
        spec: stability_spec(args, period)?,
        // A whole number of periods, so that the end state lies on the section t = kT.
        seeding: RunSpec {
            duration: periods * period,
            // What the section became is read after the first 20 s (half a short run).
            transient: (periods * period / 2.0).min(20.0),
            lyapunov: None,
            classify: ClassifyConfig::default(),
        },
        base,
    })
}

/// `--mu`, else on the planar arm the paper's range 0:3:0.1; a robot's orbits are only scanned
/// when `--mu` asks (each cell is a 110 s Benettin run and an Arnoldi spectrum of a
/// 14 000-number history: minutes for a whole range).
fn scanned_mus(args: &OrbitsCmd, base: &Subject) -> Result<Vec<f64>> {
    match &args.model.mu {
        Some(r) => Ok(r.0.clone()),
        None if base.dims() == 2 => args.model.mus("0:3:0.1"),
        None => Ok(Vec::new()),
    }
}

/// What one seeding run gives: the closest returns of a μ = 0 run, or a run's end state.
fn seeds(run: &Seeding, spec: &RunSpec, count: usize) -> Vec<Seed> {
    match run {
        Seeding::CloseReturns(arm) => arm
            .analyse(spec)
            .map(|a| {
                close_returns(&a.section, count)
                    .into_iter()
                    .map(|i| Seed {
                        point: a.section.point(i).to_vec(),
                        settled: None,
                    })
                    .collect()
            })
            .unwrap_or_default(),
        Seeding::Settled(start, arm) => match arm.analyse(spec) {
            Ok(a) => vec![Seed {
                point: a.final_coords,
                settled: Some((*start, arm.mu(), a.classification.motion.label())),
            }],
            Err(e) => {
                eprintln!("orbits: start {}, seed μ = {}: {e:#}", start + 1, arm.mu());
                Vec::new()
            }
        },
    }
}

pub fn run(args: OrbitsCmd) -> Result<()> {
    let plan = plan(&args)?;
    let threads = jobs(args.jobs);

    // 1. Seeds: each start's μ = 0 close returns, then its end state at each seeding gain.
    let mut seeding = Vec::new();
    for (i, s) in plan.starts.iter().enumerate() {
        if args.seeds > 0 {
            let mut c = s.clone();
            c.set_mu(0.0);
            seeding.push(Seeding::CloseReturns(c));
        }
        for &m in &plan.gains {
            let mut c = s.clone();
            c.set_mu(m);
            seeding.push(Seeding::Settled(i, c));
        }
    }
    let seeds: Vec<Seed> = run_all(&seeding, threads, "seeding runs", |r| {
        seeds(r, &plan.seeding, args.seeds)
    })?
    .into_iter()
    .flatten()
    .collect();

    // 2. Newton from every seed; 3. distinct orbits in seed order.
    let arm = &plan.base;
    let found: Vec<Result<PeriodicOrbit, String>> = run_all(&seeds, threads, "Newton", |s| {
        arm.find_orbit(&s.point).map_err(|e| format!("{e:#}"))
    })?;
    let converged = found.iter().filter(|o| o.is_ok()).count();
    let n = arm.n();
    let mut catalog = OrbitCatalog::new(2 * n, n, 1e-6);
    let mut orbits: Vec<PeriodicOrbit> = Vec::new();
    let mut settled = Vec::new();
    for (seed, o) in seeds.iter().zip(found) {
        let id = o.as_ref().ok().map(|o| {
            let (i, new) = catalog.find_or_insert(&o.coords());
            if new {
                orbits.push(o.clone());
            }
            orbit_name(i)
        });
        if let Some((start, seed_mu, class)) = &seed.settled {
            settled.push(SeededOrbit {
                start: start + 1,
                seed_mu: *seed_mu,
                class: class.clone(),
                seed_residual: arm.period_map_residual(&seed.point)?,
                floquet_exponent: o.as_ref().ok().map(|o| o.floquet_exponent(arm.period())),
                id,
                orbit: o,
            });
        }
    }

    // 4. Stability of each orbit at each scanned μ.
    let mus = &plan.mus;
    let cells: Vec<(usize, f64)> = (0..orbits.len())
        .flat_map(|i| mus.iter().map(move |m| (i, *m)))
        .collect();
    let stab = stability(arm, &orbits, &cells, threads, &plan.spec)?;
    let reports = reports(orbits, mus, stab, arm.period());
    let files = match mus.is_empty() {
        true => Vec::new(),
        false => plot(&args.output, &reports, mus, &plan.spec, arm.dims() == 2)?,
    };
    let report = Report {
        seeds_tried: seeds.len(),
        seeds_converged: converged,
        settled,
        orbits: reports,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    print_report(&report, &plan);
    print_reports(&report.orbits, mus, &plan.spec);
    super::print_written(&files);
    Ok(())
}

/// The seeds and what each settled run found, as text.
fn print_report(r: &Report, plan: &Plan) {
    let arm = &plan.base;
    println!(
        "period-T orbits of {} at μ = 0 (T = {} s): {} seeds (from {} start{}: the closest returns of μ = 0 runs, and the end states of {} s runs with feedback from t = {} s), {} converged, {} distinct orbits",
        arm.describe(),
        arm.period(),
        r.seeds_tried,
        plan.starts.len(),
        if plan.starts.len() == 1 { "" } else { "s" },
        plan.seeding.duration,
        arm.tau_and_t_on().1,
        r.seeds_converged,
        r.orbits.len()
    );
    for o in &r.settled {
        let what = match &o.orbit {
            Ok(orb) => format!(
                "{}; orbit {}",
                newton_line(orb),
                o.id.as_deref().unwrap_or("?")
            ),
            Err(e) => format!("no orbit: {e}"),
        };
        let start = match plan.starts.len() {
            1 => String::new(),
            _ => format!("start {}, ", o.start),
        };
        println!(
            "  {start}seed μ = {} (section from {} s: {}): |Φ_T(x) − x| = {:.2e} at the seed; {what}",
            o.seed_mu, plan.seeding.transient, o.class, o.seed_residual
        );
    }
    if plan.mus.is_empty() {
        println!("(give --mu to measure each orbit's stability over μ)");
    }
}

/// Newton's result and what the multipliers at μ = 0 say.
fn newton_line(orb: &PeriodicOrbit) -> String {
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

/// The stability runs' window (`--settle`, `--average`), checked against the task period.
/// The stability runs' window (`--settle`, `--average`), checked against the task period.
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
        if mus.is_empty() {
            continue;
        }
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
    if mus.is_empty() || reports.is_empty() {
        return;
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

/// One settled seed: where the loop from start `start` with feedback gain `seed_mu` ended (at a
/// multiple of T), and the μ = 0 period-T orbit Newton's method found from there.
#[derive(Serialize)]
pub struct SeededOrbit {
    /// The start (from 1).
    pub start: usize,
    pub seed_mu: f64,
    /// What the seeding run's section (from 20 s on, or half a shorter run) became
    /// (`period-1` when it settled).
    pub class: String,
    /// |Φ_T(x) − x| at the seed, with the feedback off: how far the seed already was from a
    /// period-T orbit.
    pub seed_residual: f64,
    pub orbit: Result<PeriodicOrbit, String>,
    /// The orbit's name in the catalog (`A`, `B`, …).
    pub id: Option<String>,
    /// ln|largest multiplier| / T at μ = 0 (1/s): > 0, unstable without the feedback.
    pub floquet_exponent: Option<f64>,
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
