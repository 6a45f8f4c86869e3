//! `chaosd-bench plants`: what each plant costs its core, side by side. The Panda at 1 kHz
//! against the kinematic plant (acceleration mode), chaosd's rigid-body arm and MuJoCo (torque
//! mode: the physics a torque needs), each one `chaosd demo` on the state trigger, in rounds so
//! that every row sees the same drift of a shared VM.
//!
//! The step is the plant's `read` of one cycle, which is its physics over the period; lateness
//! is the plant loop's wake-up against its deadline, so a plant whose step ate the period shows
//! there too. MuJoCo's rows run when `chaosd-plant-mujoco` is built beside the bench
//! (`scripts/mujoco-setup`), once on the set-up's own URDF (no collision geometry) and once on
//! a model with meshes, whose contact judging is part of the cost.

use crate::e2e::{read_json, sibling};
use crate::report::{self, Report};
use anyhow::{Context, Result};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The mesh model `scripts/mujoco-setup` links: example-robot-data's Panda.
pub const DEFAULT_MESH_MODEL: &str = "out/mujoco/panda.urdf";

/// One row: the mode and the plant's physics.
struct Row {
    label: String,
    mode: &'static str,
    /// `--plant mujoco`, and the model it loads (None: the set-up's own).
    mujoco: Option<Option<PathBuf>>,
}

/// The rows this machine can run; a note for each one it cannot.
fn rows(mesh_model: &Path) -> (Vec<Row>, Vec<String>) {
    let mut rows = vec![
        Row {
            label: "kinematic (acceleration mode)".into(),
            mode: "acceleration",
            mujoco: None,
        },
        Row {
            label: "chaosd rigid body, RK4 × 4".into(),
            mode: "torque",
            mujoco: None,
        },
    ];
    let mut notes = Vec::new();
    if sibling("chaosd-plant-mujoco").is_err() {
        notes.push(
            "MuJoCo: chaosd-plant-mujoco is not built here (scripts/mujoco-setup builds it)".into(),
        );
        return (rows, notes);
    }
    rows.push(Row {
        label: "MuJoCo, the built-in URDF (no meshes) × 4".into(),
        mode: "torque",
        mujoco: Some(None),
    });
    if mesh_model.is_file() {
        rows.push(Row {
            label: format!("MuJoCo, {} (meshes) × 4", mesh_model.display()),
            mode: "torque",
            mujoco: Some(Some(mesh_model.to_path_buf())),
        });
    } else {
        notes.push(format!(
            "MuJoCo with meshes: {} not found (scripts/mujoco-setup links it)",
            mesh_model.display()
        ));
    }
    (rows, notes)
}

pub fn run(quick: bool, mesh_model: &Path, out: &Path, command: &str) -> Result<report::Output> {
    let mut report = Report::new(out, "plants")?;
    let (seconds, rounds) = if quick { (6.0, 1) } else { (20.0, 2) };
    let (rows, notes) = rows(mesh_model);
    let mut table = String::from(
        "| plant | mode | round | step p50 / p99 / max | plant lateness p50 / p99 / p99.9 / max | daemon lateness p99 | answered in time | tracking RMS | contacts |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    for round in 1..=rounds {
        for (i, row) in rows.iter().enumerate() {
            let dir = report
                .dir
                .join(format!("{}-{round}", report::slug(&row.label)));
            let (d, p) = one(row, seconds, &dir, i)
                .with_context(|| format!("plants row {:?}", row.label))?;
            table.push_str(&line(row, round, &d, &p));
        }
    }
    let notes: String = notes.iter().map(|n| format!("\n- {n}")).collect();
    report.push_tables(
        &format!(
            "## What a plant costs\n\n{}, {}. `{command}`\n\n\
             The Panda at 1 kHz, state trigger, {seconds:.0} s per run, the rows one after \
             another in {rounds} round(s). Step: the plant's read of one cycle (its physics over \
             the period, 4 substeps); lateness: the plant loop's wake-up against its deadline. \
             Contacts: MuJoCo's count of periods a link touched an obstacle or the arm itself \
             (– where the plant does not judge).{notes}\n\n{table}",
            report::now_utc(),
            report::machine()
        ),
        &[crate::book::names::PLANTS],
    )?;
    report.finish()
}

/// One demo into `dir`; the daemon's and the plant's summaries.
fn one(row: &Row, seconds: f64, dir: &Path, i: usize) -> Result<(Value, Value)> {
    let ns = format!("bench-plants-{}-{i}", std::process::id());
    let mut cmd = Command::new(sibling("chaosd")?);
    cmd.args(["demo", "--robot", "panda", "--mode", row.mode])
        .args(["--namespace", &ns, "--duration", &seconds.to_string()])
        .arg("--output")
        .arg(dir);
    if let Some(model) = &row.mujoco {
        cmd.args(["--plant", "mujoco"]);
        if let Some(m) = model {
            cmd.arg("--mujoco-model").arg(m);
        }
    }
    crate::device::run_demo(cmd)?;
    Ok((
        read_json(&dir.join("daemon-summary.json"))?,
        read_json(&dir.join("plant-summary.json"))?,
    ))
}

fn line(row: &Row, round: usize, d: &Value, p: &Value) -> String {
    let us = |v: &Value, k: &str| v[k].as_f64().map_or("n/a".into(), |x| format!("{x:.1}"));
    let pct = |v: &Value, ks: &[&str]| {
        let all: Vec<String> = ks.iter().map(|k| us(v, k)).collect();
        format!("{} µs", all.join(" / "))
    };
    let contacts = &p["contacts"];
    let contacts = if contacts["judged"].as_bool() == Some(true) {
        let n = |k: &str| contacts[k].as_u64().unwrap_or(0);
        format!(
            "{} obstacle, {} self",
            n("obstacle_contact_periods"),
            n("self_contact_periods")
        )
    } else {
        "–".into()
    };
    format!(
        "| {} | {} | {round} | {} | {} | {} | {} | {} | {contacts} |\n",
        row.label,
        row.mode,
        pct(&p["step"], &["p50_us", "p99_us", "max_us"]),
        pct(&p["lateness"], &["p50_us", "p99_us", "p999_us", "max_us"]),
        pct(&d["lateness"], &["p99_us"]),
        p["in_time_share"]
            .as_f64()
            .map_or("n/a".into(), |s| format!("{:.2} %", s * 100.0)),
        d["tracking_rms_m"]
            .as_f64()
            .filter(|t| t.is_finite())
            .map_or("n/a".into(), |t| format!("{t:.1e} m")),
    )
}
