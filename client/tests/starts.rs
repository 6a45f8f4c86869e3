//! `chaosctl starts` end to end through the built binary: each row is the run `chaosctl
//! simulate` makes from that start (the same numbers at every check), the verdicts follow the
//! rows, the shards merge to the unsharded CSV byte for byte, and bad flags are refused.

mod common;

use common::{ok, refused, s};
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    common::scratch("starts", name)
}

/// The CSV as (header, rows), each row its cells.
fn csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text
        .lines()
        .map(|l| l.split(',').map(String::from).collect());
    (lines.next().unwrap(), lines.collect())
}

fn cell(head: &[String], row: &[String], name: &str) -> String {
    let i = head.iter().position(|h| h == name).expect(name);
    row[i].clone()
}

#[test]
fn every_row_is_the_simulate_run_of_its_start_and_shards_merge_to_it() {
    let dir = scratch("panda");
    let out = dir.join("whole");
    let study = [
        "starts", "--preset", "panda", "--safety", "off", "--count", "5", "--seed", "3", "--check",
        "24:1e-1", "--check", "40:1e-3",
    ];
    let mut args = study.to_vec();
    args.extend(["--output", s(&out), "--json"]);
    let json: serde_json::Value = serde_json::from_str(&ok(&args)).unwrap();
    let (head, rows) = csv(&dir.join("whole.csv"));
    assert_eq!(rows.len(), 5);
    assert_eq!(json["run"].as_u64(), Some(5));
    // Start 2 as `simulate` runs it, to each check and to the start window.
    let row = &rows[2];
    let list = |prefix: &str| {
        (1..=7)
            .map(|j| cell(&head, row, &format!("{prefix}{j}")))
            .collect::<Vec<_>>()
            .join(",")
    };
    let (q0, qd0) = (
        format!("--q0={}", list("q")),
        format!("--qd0={}", list("qd")),
    );
    // The statistics skip the tracking check's 10 s (the default), as the study's do; only the
    // tracking numbers depend on it.
    let simulate = |duration: &str| -> serde_json::Value {
        let transient = if duration == "0.1" { "0" } else { "10" };
        let args = [
            "simulate",
            "--preset",
            "panda",
            "--safety",
            "off",
            &q0,
            &qd0,
            "--duration",
            duration,
            "--transient",
            transient,
            "--json",
        ];
        serde_json::from_str(&ok(&args)).unwrap()
    };
    let num = |v: &serde_json::Value| v.as_f64().unwrap();
    let at = |name: &str| cell(&head, row, name).parse::<f64>().unwrap();
    let (first, second, start) = (simulate("24"), simulate("40"), simulate("0.1"));
    assert_eq!(at("residual_24s"), num(&first["period_residual_final"]));
    assert_eq!(at("residual_40s"), num(&second["period_residual_final"]));
    assert_eq!(at("speed_ratio"), num(&second["max_speed_ratio"]));
    assert_eq!(at("accel_ratio"), num(&second["max_accel_ratio"]));
    assert_eq!(at("jerk_ratio"), num(&second["max_jerk_ratio"]));
    assert_eq!(at("min_joint_margin"), num(&second["min_joint_margin"]));
    assert_eq!(at("tracking_max"), num(&second["max_tracking_error"]));
    assert_eq!(at("accel_ratio_start"), num(&start["max_accel_ratio"]));
    // The verdict follows from the numbers: inside every limit, so the residuals decide.
    let inside = ["speed_ratio", "accel_ratio", "jerk_ratio"]
        .iter()
        .all(|k| at(k) <= 1.0)
        && at("min_joint_margin") > 0.0
        && at("tracking_max") <= 5e-3;
    let want = match (at("residual_24s") <= 1e-1, at("residual_40s") <= 1e-3) {
        _ if !inside => None,
        (false, _) => Some("slow at 24 s"),
        (true, false) => Some("slow at 40 s"),
        (true, true) => Some("periodic"),
    };
    if let Some(want) = want {
        assert_eq!(cell(&head, row, "verdict"), want);
    }
    let periodic = rows.iter().filter(|r| r[1] == "periodic").count();
    assert_eq!(json["periodic"].as_u64(), Some(periodic as u64));
    assert!(periodic >= 1, "the Panda near its start: {rows:?}");

    // Three shards, merged in reverse order: the same CSV.
    let mut files = Vec::new();
    for i in 0..3 {
        let spec = format!("{i}/3");
        let part = dir.join("part");
        let mut args = study.to_vec();
        args.extend(["--output", s(&part), "--shard", &spec, "--jobs", "1"]);
        ok(&args);
        files.push(dir.join(format!("part.shard-{i}-of-3.json")));
    }
    let merged = dir.join("merged.csv");
    let mut args = vec!["merge", "--out", s(&merged)];
    args.extend(files.iter().rev().map(|f| s(f)));
    ok(&args);
    assert_eq!(
        std::fs::read(dir.join("whole.csv")).unwrap(),
        std::fs::read(&merged).unwrap()
    );
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn a_larger_count_keeps_the_earlier_starts() {
    let dir = scratch("count");
    let run = |count: &str, name: &str| {
        let out = dir.join(name);
        ok(&[
            "starts",
            "--preset",
            "panda",
            "--draw",
            "box",
            "--count",
            count,
            "--check",
            "0.2:1",
            "--output",
            s(&out),
        ]);
        csv(&dir.join(format!("{name}.csv"))).1
    };
    let (two, three) = (run("2", "two"), run("3", "three"));
    let start = |r: &Vec<String>| r[2..16].to_vec();
    assert_eq!(start(&two[0]), start(&three[0]));
    assert_eq!(start(&two[1]), start(&three[1]));
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn bad_flags_are_refused_with_the_reason() {
    for (args, needle) in [
        (&["--count", "0"][..], "--count 0"),
        (&["--check", "0:1e-3"], "expected T:TOL"),
        (&["--check", "60"], "expected T:TOL"),
        (&["--tracking", "200:1e-3"], "before the run ends"),
        (&["--margin", "0.7"], "--margin"),
        (&["--rates", "-1"], "--rates"),
        (&["--start-window", "0"], "--start-window"),
        (&["--draw", "sideways"], "sideways"),
    ] {
        let mut all = vec!["starts", "--preset", "panda"];
        all.extend(args);
        refused(&all, &[needle]);
    }
    // The planar arm has no position limits to draw a box between.
    refused(
        &["starts", "--preset", "demo", "--draw", "box"],
        &["no position limits"],
    );
}

#[test]
fn a_robot_runs_through_its_command_interface_and_a_dynamic_arm() {
    let dir = scratch("plant");
    let out = dir.join("torque");
    let json = ok(&[
        "starts",
        "--preset",
        "panda",
        "--plant",
        "rigid-body",
        "--mode",
        "torque",
        "--count",
        "2",
        "--check",
        "6:1",
        "--output",
        s(&out),
        "--json",
    ]);
    let json: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(json["run"].as_u64(), Some(2), "{json}");
    for row in json["starts"].as_array().unwrap() {
        let r = row["residuals"][0].as_f64().unwrap();
        assert!(r.is_finite() && r > 0.0, "{row}");
        assert!(row["margin"].as_f64().unwrap() > 0.0, "{row}");
    }
    for (args, needle) in [
        (
            &["--preset", "demo", "--plant", "rigid-body"][..],
            "no mass model",
        ),
        (
            &["--preset", "panda", "--mode", "torque"],
            "--mode is the command interface",
        ),
        (
            &[
                "--preset",
                "panda",
                "--plant",
                "rigid-body",
                "--mode",
                "sideways",
            ],
            "sideways",
        ),
    ] {
        let mut all = vec!["starts"];
        all.extend(args);
        refused(&all, &[needle]);
    }
    // The plant's own table is read as the live plant reads it, and a bad value named.
    let cfg = dir.join("bad.toml");
    let panda = ok(&["config", "--preset", "panda"]);
    std::fs::write(&cfg, format!("{panda}\n[plant]\nsubsteps = 0\n")).unwrap();
    refused(
        &["starts", "--config", s(&cfg), "--plant", "rigid-body"],
        &["plant.substeps"],
    );
    std::fs::remove_dir_all(dir).ok();
}
