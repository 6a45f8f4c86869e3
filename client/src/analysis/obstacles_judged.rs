//! The study's MuJoCo section (`chaosctl obstacles --mujoco-judge`): per μ × filter how many runs
//! MuJoCo saw touching, and every run where chaosd's capsules and MuJoCo's geometry disagree.
//!
//! A disagreement is a run whose capsules never touched an obstacle after first getting clear
//! while MuJoCo, posing the same joints in the model's own geometry, saw a link touch one: the
//! filter's clearance held on the capsules and not on the arm. The other way round (capsules
//! touching, meshes clear) is the capsules' conservatism, counted but not listed.

use super::mujoco_judge::{Verdict, SAMPLE_S};
use super::obstacle_cells::Row;
use anyhow::{Context, Result};
use std::io::Write;
use std::path::Path;

/// Whether the capsules stayed out of every obstacle once clear.
fn capsules_clear(r: &Row) -> bool {
    r.summary.as_ref().is_some_and(|s| {
        s.first_clear.is_some() && s.time_in_contact_after_clear.is_none_or(|t| t == 0.0)
    })
}

fn verdict(r: &Row) -> Option<&Verdict> {
    r.verdict.as_ref().and_then(|v| v.as_ref().ok())
}

fn touched(v: &Verdict) -> bool {
    v.judged && v.contact_samples > 0
}

/// Prints the section after the study's table.
pub fn print(model: &Path, clearance: f64, rows: &[Row], mus: &[f64], filters: &[bool]) {
    println!(
        "\nMuJoCo's judge ({}): each run's joints posed every {} ms from the capsules' first clear moment; contact over the model's own geometry",
        model.display(),
        SAMPLE_S * 1e3
    );
    println!(
        "| μ | filter | runs judged | runs MuJoCo saw touching | MuJoCo contact (s) worst | smallest distance in MuJoCo (m) worst / median | capsules' min clearance after clear (m) worst / median (asked {clearance}) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for &mu in mus {
        for &on in filters {
            let group: Vec<&Row> = rows
                .iter()
                .filter(|r| r.mu == mu && r.safety == on)
                .collect();
            let judged: Vec<&Verdict> = group
                .iter()
                .filter_map(|r| verdict(r))
                .filter(|v| v.judged)
                .collect();
            let touching = judged.iter().filter(|v| touched(v)).count();
            let worst = judged.iter().map(|v| v.contact_samples).max();
            let dist = sorted(judged.iter().filter_map(|v| v.smallest_distance));
            let caps = sorted(
                group
                    .iter()
                    .filter_map(|r| r.summary.as_ref()?.min_clearance_after_clear),
            );
            println!(
                "| {mu} | {} | {} of {} | {touching} | {} | {} | {} |",
                if on { "on" } else { "off" },
                judged.len(),
                group.len(),
                worst.map_or("–".into(), |n| format!("{:.3}", n as f64 * SAMPLE_S)),
                pair(&dist),
                pair(&caps),
            );
        }
    }
    disagreements(rows);
}

fn disagreements(rows: &[Row]) {
    let judged = rows
        .iter()
        .filter(|r| verdict(r).is_some_and(|v| v.judged))
        .count();
    let odd: Vec<&Row> = rows
        .iter()
        .filter(|r| capsules_clear(r) && verdict(r).is_some_and(touched))
        .collect();
    let cautious = rows
        .iter()
        .filter(|r| !capsules_clear(r) && verdict(r).is_some_and(|v| v.judged && !touched(v)))
        .count();
    if odd.is_empty() {
        println!(
            "  disagreements: none: in all {judged} judged run(s), wherever the capsules stayed clear MuJoCo saw no link touch"
        );
    } else {
        println!(
            "  disagreements: {} of {judged} judged run(s) kept the capsules clear while MuJoCo saw a link touch:",
            odd.len()
        );
        for r in &odd {
            let v = verdict(r).expect("filtered");
            println!(
                "    μ = {}, filter {}, q1 = {}: first contact at t = {} s ({}), smallest distance {} m; capsules' min clearance {} m",
                r.mu,
                if r.safety { "on" } else { "off" },
                r.q0[0],
                v.first_contact_s.map_or("?".into(), |t| format!("{t:.3}")),
                v.first_pair.as_deref().unwrap_or("?"),
                v.smallest_distance.map_or("?".into(), |d| format!("{d:.4}")),
                r.summary
                    .as_ref()
                    .and_then(|s| s.min_clearance_after_clear)
                    .map_or("?".into(), |d| format!("{d:.4}")),
            );
        }
    }
    if cautious > 0 {
        println!("  {cautious} run(s) had capsules touching where MuJoCo's geometry stayed clear (the capsules' margin)");
    }
    let unjudged: Vec<String> = rows
        .iter()
        .filter_map(|r| match &r.verdict {
            Some(Err(e)) => Some(e.clone()),
            Some(Ok(v)) if !v.judged => {
                Some("the model has no collision geometry on the arm".into())
            }
            _ => None,
        })
        .collect();
    if let Some(first) = unjudged.first() {
        println!("  {} run(s) not judged: {first}", unjudged.len());
    }
}

fn sorted(v: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut v: Vec<f64> = v.filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v
}

/// "worst (smallest) / median" of sorted values.
fn pair(v: &[f64]) -> String {
    match v.len() {
        0 => "–".into(),
        n => format!("{:.4} / {:.4}", v[0], v[n / 2]),
    }
}

/// PREFIX-mujoco.csv: one line per run.
pub fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    let file =
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = std::io::BufWriter::new(file);
    writeln!(
        w,
        "mu,safety,q1,capsules_clear,capsule_min_clearance_after_clear,judged,contact_s,first_contact_s,first_pair,self_contact_s,smallest_distance,error"
    )?;
    let o = |v: Option<f64>| v.map(|x| format!("{x:.6e}")).unwrap_or_default();
    for r in rows {
        let (v, err) = match &r.verdict {
            Some(Ok(v)) => (Some(v), String::new()),
            Some(Err(e)) => (None, e.clone()),
            None => (None, r.error.clone().unwrap_or_default()),
        };
        writeln!(
            w,
            "{},{},{},{},{},{},{},{},{},{},{},{}",
            r.mu,
            r.safety,
            r.q0[0],
            capsules_clear(r),
            o(r.summary.as_ref().and_then(|s| s.min_clearance_after_clear)),
            v.is_some_and(|v| v.judged),
            o(v.map(|v| v.contact_samples as f64 * SAMPLE_S)),
            o(v.and_then(|v| v.first_contact_s)),
            v.and_then(|v| v.first_pair.clone())
                .unwrap_or_default()
                .replace(',', ";"),
            o(v.map(|v| v.self_samples as f64 * SAMPLE_S)),
            o(v.and_then(|v| v.smallest_distance)),
            err.replace([',', '\n'], ";"),
        )?;
    }
    w.flush()?;
    Ok(())
}
