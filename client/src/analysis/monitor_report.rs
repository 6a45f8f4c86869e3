//! The report of `chaosctl monitor`: the confusion table, auto-μ against fixed μ, the edits, and
//! the figure; as text, JSON and CSV.

use super::fmt_list;
use super::monitor_cells::{AutoCell, BestFixed, EditKind, FixedCell, Offline};
use crate::plot::{Chart, Figure, Panel, Series, Style, DARK, PALETTE};
use anyhow::{Context, Result};
use control::adapt::AutoMu;
use control::monitor::{MonitorSettings, Verdict};
use serde::Serialize;
use std::io::Write;
use std::path::Path;

const OFFLINE: [Offline; 4] = [
    Offline::Chaotic,
    Offline::Stable,
    Offline::Marginal,
    Offline::Failed,
];
const VERDICTS: [Verdict; 5] = [
    Verdict::Chaotic,
    Verdict::Converging,
    Verdict::Periodic,
    Verdict::Regular,
    Verdict::Unknown,
];

/// Auto-μ on one start against the best fixed μ of the analysis and the smallest fixed μ of the
/// sweep that stabilises it.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    pub start: usize,
    pub q0: Vec<f64>,
    pub auto_verdict: Verdict,
    pub auto_periodic_at: Option<f64>,
    pub auto_mu_final: f64,
    pub auto_effort: f64,
    /// The auto run's first verdict and when it came (s).
    pub auto_first_verdict: Option<(Verdict, f64)>,
    /// The auto run's first steering onto the model's cycle (`control::target`): when it began,
    /// when the pull was taken away and why, or why there was none.
    pub auto_target: Option<control::monitor::run::TargetRun>,
    /// The best fixed gain the analysis finds for the start (`chaosctl tune`), and that gain
    /// run fixed.
    pub best_fixed: Option<BestFixed>,
    /// The smallest μ of the sweep the monitor saw end periodic (offline not chaotic).
    pub smallest_fixed_mu: Option<f64>,
    pub fixed_periodic_at: Option<f64>,
    pub fixed_effort: Option<f64>,
}

/// An auto run with an edit half-way.
#[derive(Clone, Debug, Serialize)]
pub struct EditRun {
    pub start: usize,
    pub edit: EditKind,
    pub periodic_before_edit: bool,
    pub mu_at_edit: Option<f64>,
    /// The gain the model chose for the edited set-up.
    pub model_mu_after_edit: Option<f64>,
    pub verdict: Verdict,
    /// Seconds from the edit until the verdict was periodic again.
    pub periodic_after_s: Option<f64>,
    pub mu_final: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub duration_s: f64,
    pub wall_s: f64,
    pub tau: f64,
    pub auto: AutoMu,
    pub monitor: MonitorSettings,
    /// counts[offline][verdict] in the order of `offline_labels` × `verdict_labels`.
    pub offline_labels: Vec<Offline>,
    pub verdict_labels: Vec<Verdict>,
    pub confusion: Vec<Vec<usize>>,
    /// Cells where both call it chaotic, or offline stable and the monitor periodic, converging
    /// or regular.
    pub agree: usize,
    pub judged: usize,
    /// Median and largest detection delay (periods to the first verdict) over the agreeing cells.
    pub delay_median_periods: Option<f64>,
    pub delay_max_periods: Option<f64>,
    /// Median and largest periods until the verdict settled (capture included).
    pub settled_median_periods: Option<f64>,
    pub settled_max_periods: Option<f64>,
    pub comparisons: Vec<Comparison>,
    pub edits: Vec<EditRun>,
    pub cells: Vec<FixedCell>,
    #[serde(skip)]
    auto_runs: Vec<AutoCell>,
    #[serde(skip)]
    starts: Vec<Vec<f64>>,
}

fn agrees(o: Offline, v: Verdict) -> bool {
    matches!(
        (o, v),
        (Offline::Chaotic, Verdict::Chaotic)
            | (
                Offline::Stable,
                Verdict::Periodic | Verdict::Converging | Verdict::Regular
            )
    )
}

impl Report {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        tau: f64,
        starts: Vec<Vec<f64>>,
        cells: Vec<FixedCell>,
        auto_runs: Vec<AutoCell>,
        best: Vec<BestFixed>,
        auto: AutoMu,
        monitor: MonitorSettings,
        duration_s: f64,
        wall_s: f64,
    ) -> Self {
        let oi = |o: Offline| OFFLINE.iter().position(|x| *x == o).unwrap_or(3);
        let vi = |v: Verdict| VERDICTS.iter().position(|x| *x == v).unwrap_or(4);
        let mut confusion = vec![vec![0; VERDICTS.len()]; OFFLINE.len()];
        for c in &cells {
            confusion[oi(c.offline)][vi(c.verdict)] += 1;
        }
        let judged = cells
            .iter()
            .filter(|c| matches!(c.offline, Offline::Chaotic | Offline::Stable))
            .count();
        let sorted = |f: &dyn Fn(&FixedCell) -> Option<f64>| {
            let mut v: Vec<f64> = cells
                .iter()
                .filter(|c| agrees(c.offline, c.verdict))
                .filter_map(f)
                .collect();
            v.sort_by(f64::total_cmp);
            v
        };
        let delays = sorted(&|c| c.first_verdict_periods);
        let settled = sorted(&|c| c.settled_periods);
        Self {
            duration_s,
            wall_s,
            tau,
            auto,
            monitor,
            offline_labels: OFFLINE.to_vec(),
            verdict_labels: VERDICTS.to_vec(),
            agree: cells
                .iter()
                .filter(|c| agrees(c.offline, c.verdict))
                .count(),
            judged,
            delay_median_periods: delays.get(delays.len() / 2).copied(),
            delay_max_periods: delays.last().copied(),
            settled_median_periods: settled.get(settled.len() / 2).copied(),
            settled_max_periods: settled.last().copied(),
            comparisons: comparisons(&cells, &auto_runs, &best, &starts, tau),
            edits: edit_runs(&auto_runs),
            confusion,
            cells,
            auto_runs,
            starts,
        }
    }

    /// Writes PREFIX.json, PREFIX-cells.csv and the figure, and prints the tables (or the JSON).
    pub fn write(&self, prefix: &Path, json: bool) -> Result<()> {
        let text = serde_json::to_string_pretty(self)?;
        let json_path = crate::plot::with_ext(prefix, "json");
        std::fs::write(&json_path, &text)
            .with_context(|| format!("cannot write {}", json_path.display()))?;
        let csv = prefix.with_file_name(format!(
            "{}-cells.csv",
            prefix
                .file_name()
                .and_then(|n| n.to_str())
                .unwrap_or("monitor")
        ));
        self.write_csv(&csv)?;
        let mut files = vec![json_path, csv];
        files.extend(self.plot(prefix)?);
        if json {
            println!("{text}");
            return Ok(());
        }
        self.print();
        super::print_written(&files);
        Ok(())
    }

    fn print(&self) {
        println!(
            "The monitor against the offline λ_max ({} cells, {} s each, τ = {} s):\n",
            self.cells.len(),
            self.duration_s,
            self.tau
        );
        print!("{:<18}", "offline \\ monitor");
        for v in VERDICTS {
            print!("{:>12}", v.name());
        }
        println!();
        for (o, row) in OFFLINE.iter().zip(&self.confusion) {
            print!("{:<18}", format!("{o:?}").to_lowercase());
            for n in row {
                print!("{n:>12}");
            }
            println!();
        }
        let show = |v: Option<f64>| v.map_or("n/a".into(), |x| format!("{x:.0}"));
        println!(
            "\nagree on {} of {} judged cells (offline chaotic or stable); over those, the first verdict \
             came after {} periods (median), {} (max), and the final one after {} (median), {} (max: \
             late captures)\n",
            self.agree,
            self.judged,
            show(self.delay_median_periods),
            show(self.delay_max_periods),
            show(self.settled_median_periods),
            show(self.settled_max_periods)
        );
        let gamma = match self.auto.gamma_given {
            true => format!("γ = {}", self.auto.gamma),
            false => "γ from the model".into(),
        };
        println!(
            "auto-μ ({gamma}, max_mu = {}, the gain from the model) against the best fixed μ of \
             the analysis and the smallest fixed μ of the sweep that stabilises each start:",
            self.auto.max_mu
        );
        let one = |v: Option<f64>| v.map_or("n/a".into(), |x| format!("{x:.1}"));
        for c in &self.comparisons {
            let first = c.auto_first_verdict.map_or("no verdict".into(), |(v, t)| {
                format!("{} at {t:.1} s", v.name())
            });
            let best = match &c.best_fixed {
                Some(b @ BestFixed { mu: Ok(m), .. }) => format!(
                    "best μ = {m:.3} ({} at {} s, effort {:.1})",
                    b.verdict.name(),
                    one(b.periodic_at),
                    b.effort
                ),
                Some(BestFixed { mu: Err(e), .. }) => format!("no best μ: {e}"),
                None => "no best μ".into(),
            };
            let steered = match &c.auto_target {
                Some(t) => match (t.released_at, t.released, &t.error) {
                    (Some(at), Some(why), _) => {
                        format!(", steered {:.1}–{at:.1} s ({why:?})", t.since)
                    }
                    (_, _, Some(e)) => format!(", not steered ({e})"),
                    _ => ", steered to the end".into(),
                },
                None => String::new(),
            };
            println!(
                "  start ({}): auto first {first}{steered}, {} at {} s, μ → {:.3}, effort {:.1} | \
                 {best} | smallest fixed μ = {} periodic at {} s, effort {}",
                fmt_list(&c.q0),
                c.auto_verdict.name(),
                one(c.auto_periodic_at),
                c.auto_mu_final,
                c.auto_effort,
                c.smallest_fixed_mu
                    .map_or("none".into(), |m| format!("{m}")),
                show(c.fixed_periodic_at),
                c.fixed_effort.map_or("n/a".into(), |e| format!("{e:.1}")),
            );
        }
        println!("\nauto-μ after an edit half-way:");
        for e in &self.edits {
            println!(
                "  start {} {:?}: periodic before: {}, μ at edit {}, model's μ after {}, then {} {} s \
                 after, μ → {:.3}",
                e.start + 1,
                e.edit,
                e.periodic_before_edit,
                e.mu_at_edit.map_or("n/a".into(), |m| format!("{m:.3}")),
                e.model_mu_after_edit.map_or("n/a".into(), |m| format!("{m:.3}")),
                e.verdict.name(),
                show(e.periodic_after_s),
                e.mu_final
            );
        }
        println!(
            "\n{} runs in {:.1} s wall",
            self.cells.len() + self.auto_runs.len(),
            self.wall_s
        );
    }

    fn write_csv(&self, path: &Path) -> Result<()> {
        let mut w = std::io::BufWriter::new(
            std::fs::File::create(path)
                .with_context(|| format!("cannot create {}", path.display()))?,
        );
        writeln!(
            w,
            "start,mu,lambda_max,stderr,offline,verdict,first_verdict,first_verdict_periods,settled_periods,effort"
        )?;
        let opt = |v: Option<f64>| v.map_or(String::new(), |x| format!("{x:.6e}"));
        for c in &self.cells {
            writeln!(
                w,
                "{},{},{},{},{:?},{},{},{},{},{:.6e}",
                c.start + 1,
                c.mu,
                opt(c.lambda_max),
                opt(c.stderr),
                c.offline,
                c.verdict.name(),
                c.first_verdict.name(),
                opt(c.first_verdict_periods),
                opt(c.settled_periods),
                c.effort
            )?;
        }
        w.flush()?;
        Ok(())
    }

    fn plot(&self, prefix: &Path) -> Result<Vec<std::path::PathBuf>> {
        let color = |v: Verdict| match v {
            Verdict::Chaotic => PALETTE[3 % PALETTE.len()],
            Verdict::Converging => PALETTE[1 % PALETTE.len()],
            Verdict::Periodic => PALETTE[2 % PALETTE.len()],
            Verdict::Regular => PALETTE[4 % PALETTE.len()],
            Verdict::Unknown => DARK,
        };
        let lambda = VERDICTS
            .iter()
            .map(|&v| {
                let pts = self
                    .cells
                    .iter()
                    .filter(|c| c.verdict == v)
                    .filter_map(|c| c.lambda_max.map(|l| (c.mu, l)))
                    .collect();
                let style = Style::Markers {
                    size: 4,
                    filled: true,
                };
                Series::new(Some(format!("monitor: {}", v.name())), color(v), style, pts)
            })
            .collect();
        let runs: Vec<&AutoCell> = self
            .auto_runs
            .iter()
            .filter(|a| a.edit == EditKind::None)
            .collect();
        let trace = |f: &dyn Fn(&control::monitor::run::PeriodPoint) -> f64| -> Vec<Series> {
            runs.iter()
                .map(|a| {
                    let pts = a.trace.iter().map(|p| (p.t, f(p))).collect();
                    let label = format!("start ({})", fmt_list(&self.starts[a.start]));
                    let c = PALETTE[a.start % PALETTE.len()];
                    Series::new(Some(label), c, Style::Line(2), pts)
                })
                .collect()
        };
        let chart = |title: &str, x: &str, y: &str, series| Chart {
            title: title.into(),
            x_label: x.into(),
            y_label: y.into(),
            series,
            legend: true,
            ..Default::default()
        };
        Figure {
            title: Some("The chaos monitor against the offline λ_max, and μ = \"auto\"".into()),
            panels: vec![
                Panel::Chart(chart(
                    "offline λ_max over the sweep, coloured by the monitor's final verdict",
                    "Pyragas gain μ (1/s)",
                    "λ_max (1/s)",
                    lambda,
                )),
                Panel::Chart(chart(
                    "μ = \"auto\": the gain over time, per start",
                    "t (s)",
                    "μ (1/s)",
                    trace(&|p| p.mu),
                )),
                Panel::Chart(chart(
                    "μ = \"auto\": the period residual over time",
                    "t (s)",
                    "log10 mean |q̇(t) − q̇(t−τ)| per period (rad/s)",
                    trace(&|p| p.residual.max(1e-16).log10()),
                )),
            ],
            cols: 1,
            panel_size: (1000, 420),
        }
        .save(prefix)
    }
}

fn comparisons(
    cells: &[FixedCell],
    autos: &[AutoCell],
    best_fixed: &[BestFixed],
    starts: &[Vec<f64>],
    tau: f64,
) -> Vec<Comparison> {
    autos
        .iter()
        .filter(|a| a.edit == EditKind::None)
        .map(|a| {
            let best = cells
                .iter()
                .filter(|c| c.start == a.start && c.verdict == Verdict::Periodic)
                .filter(|c| c.offline != Offline::Chaotic)
                .min_by(|x, y| x.mu.total_cmp(&y.mu));
            Comparison {
                start: a.start,
                q0: starts[a.start].clone(),
                auto_verdict: a.verdict,
                auto_periodic_at: a.periodic_at,
                auto_mu_final: a.mu_final,
                auto_effort: a.effort,
                auto_first_verdict: a.first_verdict,
                auto_target: a.model.iter().find_map(|m| m.target.clone()),
                best_fixed: best_fixed.iter().find(|b| b.start == a.start).cloned(),
                smallest_fixed_mu: best.map(|c| c.mu),
                fixed_periodic_at: best.and_then(|c| c.settled_periods).map(|p| p * tau),
                fixed_effort: best.map(|c| c.effort),
            }
        })
        .collect()
}

fn edit_runs(autos: &[AutoCell]) -> Vec<EditRun> {
    autos
        .iter()
        .filter(|a| a.edit != EditKind::None)
        .map(|a| {
            let at = a.edit_at.unwrap_or(0.0);
            let before = a.trace.iter().take_while(|p| p.t < at).last();
            EditRun {
                start: a.start,
                edit: a.edit,
                periodic_before_edit: before.is_some_and(|p| p.verdict == Verdict::Periodic),
                mu_at_edit: a.mu_at_edit,
                model_mu_after_edit: a.model.iter().find(|m| m.t >= at).and_then(|m| m.mu),
                verdict: a.verdict,
                periodic_after_s: a.periodic_at.filter(|t| *t >= at).map(|t| t - at),
                mu_final: a.mu_final,
            }
        })
        .collect()
}
