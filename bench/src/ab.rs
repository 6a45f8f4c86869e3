//! `chaosd-bench ab --against OLD`: this build's `compute` (or `e2e`) against another build's,
//! interleaved, so that a regression shows as a ratio measured side by side.
//!
//! Absolute times on a shared VM move by ±30 % from one boot (or one minute) to the next; two
//! builds run one after the other, round after round, see the same machine. Each round runs
//! OLD's benchmark then this binary's (the order alternates, so neither always runs warm), each
//! writing its report; every p50 that both reports carry is compared, in a `p50` column or as
//! the first of a `p50 / p99 / max` one. OLD is a `chaosd-bench` binary with its own `chaosd` and
//! `chaosd-plant` beside it (`e2e` runs those): `scripts/ab-build REV` builds them at a revision.

use crate::report::Output;
use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A row that is this much slower (or faster) in the median, and in every round, is named.
const NOTABLE: f64 = 0.10;

/// p50s per (table, row) of one report, in nanoseconds; the row names its column when the
/// table has several p50s.
pub type P50s = BTreeMap<(String, String), f64>;

/// What is compared.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum What {
    Compute,
    E2e,
}

impl What {
    fn name(self) -> &'static str {
        match self {
            What::Compute => "compute",
            What::E2e => "e2e",
        }
    }
}

/// A time as `compute.md` prints it ("622 ns", "4.99 µs", "1.18 ms", "3.99 s"), in ns.
pub fn parse_time(s: &str) -> Option<f64> {
    let (num, unit) = s.trim().split_once(' ')?;
    let x: f64 = num.parse().ok()?;
    let scale = match unit {
        "ns" => 1.0,
        "µs" | "us" => 1e3,
        "ms" => 1e6,
        "s" => 1e9,
        _ => return None,
    };
    Some(x * scale)
}

fn cells(line: &str) -> Option<Vec<&str>> {
    let inner = line.trim().strip_prefix('|')?.strip_suffix('|')?;
    Some(inner.split('|').map(str::trim).collect())
}

/// A p50 column of a header: the column, the part of its " / " list that is the p50, its name.
type P50Column = (usize, usize, String);

fn p50_columns(header: &[&str]) -> Vec<P50Column> {
    header
        .iter()
        .enumerate()
        .filter_map(|(i, h)| {
            let parts: Vec<&str> = h.split(" / ").collect();
            let k = parts
                .iter()
                .position(|p| *p == "p50" || p.ends_with(" p50"))?;
            let name = parts[k].trim_end_matches("p50").trim();
            Some((i, k, name.to_string()))
        })
        .collect()
}

/// Every p50 of every table of `md` (see [`P50s`]).
pub fn p50s(md: &str) -> P50s {
    let mut out = P50s::new();
    let mut table: Option<(String, Vec<P50Column>)> = None;
    for line in md.lines() {
        let Some(c) = cells(line) else {
            table = None;
            continue;
        };
        if c.iter().all(|x| x.chars().all(|ch| ch == '-' || ch == ':')) {
            continue;
        }
        match &table {
            None => {
                let cols = p50_columns(&c);
                table = (!cols.is_empty()).then(|| (c[0].to_string(), cols));
            }
            Some((name, cols)) => {
                // A row is named by the words before its first p50 (the model table has an
                // operation and an implementation), not by counts, which vary from run to run.
                let words: Vec<&str> = c[..cols[0].0.min(c.len())]
                    .iter()
                    .copied()
                    .filter(|x| x.parse::<f64>().is_err())
                    .collect();
                for (i, k, col) in cols {
                    let part = c.get(*i).and_then(|x| x.split(" / ").nth(*k));
                    if let Some(ns) = part.and_then(parse_time) {
                        let mut row = words.join(" / ");
                        if !col.is_empty() {
                            row = format!("{row}: {col}");
                        }
                        out.insert((name.clone(), row), ns);
                    }
                }
            }
        }
    }
    out
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// One build's benchmark into `dir`, with `args` after the subcommand; its report.
fn bench(bin: &Path, what: What, args: &[String], quick: bool, dir: &Path) -> Result<String> {
    let mut cmd = Command::new(bin);
    cmd.arg(what.name()).args(args).arg("--out").arg(dir);
    if quick {
        cmd.arg("--quick");
    }
    let o = cmd
        .output()
        .with_context(|| format!("cannot run {}", bin.display()))?;
    if !o.status.success() {
        bail!(
            "{} {} failed: {}",
            bin.display(),
            what.name(),
            String::from_utf8_lossy(&o.stderr).trim()
        );
    }
    let md = dir.join(what.name()).join(format!("{}.md", what.name()));
    std::fs::read_to_string(&md).with_context(|| format!("cannot read {}", md.display()))
}

/// The comparison's text from each round's p50s of the two builds.
pub fn compare(old: &[P50s], new: &[P50s], against: &str, what: &str) -> String {
    let mut text = format!(
        "## A/B: this build against {against}\n\n{} interleaved rounds of `{what}`; p50 per row, \
         the median over rounds, and new/old per round. A row is named when its median ratio is \
         beyond ±{:.0} % and every round agrees.\n\n\
         | table | row | old p50 | new p50 | new/old | per round |\n|---|---|---|---|---|---|\n",
        old.len(),
        NOTABLE * 100.0
    );
    let mut notable = Vec::new();
    for (key, _) in old.first().into_iter().flatten() {
        let pairs: Vec<(f64, f64)> = old
            .iter()
            .zip(new)
            .filter_map(|(o, n)| Some((*o.get(key)?, *n.get(key)?)))
            .collect();
        if pairs.len() != old.len() || pairs.iter().any(|(o, _)| *o <= 0.0) {
            continue;
        }
        let ratios: Vec<f64> = pairs.iter().map(|(o, n)| n / o).collect();
        let (mo, mn) = (
            median(pairs.iter().map(|p| p.0).collect()),
            median(pairs.iter().map(|p| p.1).collect()),
        );
        let r = mn / mo;
        let each: Vec<String> = ratios.iter().map(|x| format!("{x:.2}")).collect();
        text += &format!(
            "| {} | {} | {} | {} | {r:.2} | {} |\n",
            key.0,
            key.1,
            crate::stats::fmt_ns(mo),
            crate::stats::fmt_ns(mn),
            each.join(" ")
        );
        if r > 1.0 + NOTABLE && ratios.iter().all(|x| *x > 1.0) {
            notable.push(format!("- slower: {} ({r:.2}×)", key.1));
        } else if r < 1.0 - NOTABLE && ratios.iter().all(|x| *x < 1.0) {
            notable.push(format!("- faster: {} ({r:.2}×)", key.1));
        }
    }
    text.push('\n');
    if notable.is_empty() {
        text += "No row moved beyond the threshold in every round.\n";
    } else {
        text += &notable.join("\n");
        text.push('\n');
    }
    text
}

/// The comparison asked for.
pub struct Ab<'a> {
    pub against: &'a Path,
    pub what: What,
    /// Passed to both builds' benchmark (e2e's `--rates 1000 --modes state`, say).
    pub args: &'a [String],
    pub rounds: usize,
}

/// Runs the rounds of `ab` under `out/ab`.
pub fn run(ab: &Ab<'_>, quick: bool, out: &Path) -> Result<Output> {
    let Ab {
        against,
        what,
        args,
        rounds,
    } = *ab;
    if rounds == 0 {
        bail!("--rounds must be at least 1");
    }
    if !against.is_file() {
        bail!(
            "--against {}: no such binary (scripts/ab-build REV builds one)",
            against.display()
        );
    }
    if what == What::E2e {
        for sibling in ["chaosd", "chaosd-plant"] {
            let p = against.with_file_name(sibling);
            if !p.is_file() {
                bail!(
                    "e2e runs the daemon and plant beside --against, and {} is missing \
                     (scripts/ab-build REV builds them)",
                    p.display()
                );
            }
        }
    }
    let me: PathBuf = std::env::current_exe().context("cannot find this binary")?;
    let dir = out.join("ab");
    let (mut old, mut new) = (Vec::new(), Vec::new());
    for k in 0..rounds {
        let runs = [(against, "old"), (me.as_path(), "new")];
        let order: Vec<_> = if k % 2 == 0 {
            runs.iter().collect()
        } else {
            runs.iter().rev().collect()
        };
        for (bin, which) in order {
            eprintln!("chaosd-bench ab: round {}/{rounds}: {which}", k + 1);
            let md = bench(bin, what, args, quick, &dir.join(format!("{which}-{k}")))?;
            let p = p50s(&md);
            if p.is_empty() {
                bail!("{}: its {} report has no p50", bin.display(), what.name());
            }
            if *which == "old" {
                old.push(p);
            } else {
                new.push(p);
            }
        }
    }
    let text = compare(&old, &new, &against.display().to_string(), what.name());
    std::fs::write(dir.join("ab.md"), &text)?;
    Ok(Output {
        text,
        tables: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const MD: &str = "## Compute\n\n| operation | p50 | p99 |\n|---|---|---|\n\
        | control law | 132 ns | 199 ns |\n| tick | 4.99 µs | 15 µs |\n\ntext\n\n\
        | monitor | n | p50 |\n|---|---|---|\n| a tick | 59941 | 40 ns |\n| bad | 1 | n/a |\n\n\
        | operation | implementation | p50 |\n|---|---|---|\n| RNEA | chaosd | 495 ns |\n\
        | RNEA | naive | 9.25 µs |\n";

    #[test]
    fn every_p50_of_every_table_is_read_in_nanoseconds() {
        let p = p50s(MD);
        let get = |t: &str, r: &str| p[&(t.to_string(), r.to_string())];
        assert_eq!(get("operation", "control law"), 132.0);
        assert!((get("operation", "tick") - 4990.0).abs() < 1e-9);
        assert_eq!(get("monitor", "a tick"), 40.0);
        assert_eq!(get("operation", "RNEA / chaosd"), 495.0);
        assert!((get("operation", "RNEA / naive") - 9250.0).abs() < 1e-9);
        assert_eq!(p.len(), 5);
        assert_eq!(parse_time("1.18 ms"), Some(1.18e6));
        assert_eq!(parse_time("3.99 s"), Some(3.99e9));
        assert_eq!(parse_time("fast"), None);
    }

    #[test]
    fn a_p50_first_in_a_list_of_percentiles_is_read_per_column() {
        let md = "| rate | ticks | wake-up p50 / p99 / max | round trip p50 / p99 |\n|---|---|---|---|\n\
                  | 1 kHz | 19999 | 70 ns / 16.12 µs / 506.11 µs | 3.5 µs / 20 µs |\n";
        let p = p50s(md);
        assert_eq!(p[&("rate".to_string(), "1 kHz: wake-up".to_string())], 70.0);
        assert_eq!(
            p[&("rate".to_string(), "1 kHz: round trip".to_string())],
            3500.0
        );
        assert_eq!(p.len(), 2);
    }

    #[test]
    fn a_row_slower_in_every_round_is_named_and_noise_is_not() {
        let row = |t: f64, u: f64| {
            let mut p = P50s::new();
            p.insert(("op".into(), "tick".into()), t);
            p.insert(("op".into(), "law".into()), u);
            p
        };
        let old = [row(100.0, 100.0), row(100.0, 100.0), row(100.0, 100.0)];
        let new = [row(130.0, 95.0), row(125.0, 120.0), row(128.0, 90.0)];
        let text = compare(&old, &new, "old", "compute");
        assert!(text.contains("- slower: tick (1.28×)"), "{text}");
        assert!(!text.contains("law ("), "{text}");
    }
}
