//! Sharded scans end to end through the built `chaosctl`: for `sweep`, `basins` and `obstacles`,
//! the shards merged with `chaosctl merge` give the unsharded CSV byte for byte, whatever order
//! the files come in; a missing shard is named, and a shard given twice or from another grid is
//! refused.

mod common;

use common::{ok, refused, s};
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    common::scratch("shards", name)
}

/// Runs `scan` unsharded and as `n` shards, merges the shards (in reverse order), and checks
/// the CSVs are identical. Returns the shard files.
fn merged_equals_unsharded(dir: &Path, scan: &[&str], n: usize, rows: usize) -> Vec<PathBuf> {
    let whole = dir.join("whole");
    let mut args = scan.to_vec();
    args.extend(["--jobs", "2", "--output", s(&whole)]);
    ok(&args);
    let mut files = Vec::new();
    for i in 0..n {
        let part = dir.join("part");
        let spec = format!("{i}/{n}");
        let mut args = scan.to_vec();
        args.extend(["--jobs", "1", "--output", s(&part), "--shard", &spec]);
        let stdout = ok(&args);
        let file = dir.join(format!("part.shard-{i}-of-{n}.json"));
        assert!(stdout.contains(s(&file)), "{stdout}");
        // A shard writes its own file only, no CSV or plot.
        assert!(!dir.join("part.csv").exists());
        files.push(file);
    }
    let merged = dir.join("merged.csv");
    let mut args = vec!["merge", "--out", s(&merged)];
    args.extend(files.iter().rev().map(|f| s(f)));
    ok(&args);
    let a = std::fs::read(dir.join("whole.csv")).unwrap();
    let b = std::fs::read(&merged).unwrap();
    assert_eq!(
        String::from_utf8_lossy(&a).lines().count(),
        1 + rows,
        "{}",
        String::from_utf8_lossy(&a)
    );
    assert!(
        a == b,
        "{scan:?}: merged CSV differs from the unsharded one:\n{}\n---\n{}",
        String::from_utf8_lossy(&a),
        String::from_utf8_lossy(&b)
    );
    assert!(dir.join("merged.png").exists() && dir.join("merged.svg").exists());
    files
}

#[test]
fn sweep_shards_merge_to_the_unsharded_csv_and_a_missing_shard_is_named() {
    let dir = scratch("sweep");
    // 3 μ × 3 starts = 9 points in 4 shards (uneven: 3, 2, 2, 2).
    let scan = [
        "sweep",
        "--mu",
        "0:0.2:0.1",
        "--duration",
        "30",
        "--window",
        "10:30",
    ];
    let files = merged_equals_unsharded(&dir, &scan, 4, 9);
    let m2 = dir.join("m2");
    let out = s(&m2);
    // Shard 2/4 missing: its points (2 and 6) are named, and so is the shard.
    let err = refused(
        &[
            "merge",
            "--out",
            out,
            s(&files[0]),
            s(&files[1]),
            s(&files[3]),
        ],
        &[
            "incomplete: 2 of 9 points missing",
            "no file for shard 2/4",
            "point 2 (μ = 0, start 3)",
            "point 6 (μ = 0.2, start 1)",
        ],
    );
    assert!(!err.contains("point 3 "), "{err}");
    // The same shard twice.
    refused(
        &["merge", "--out", out, s(&files[0]), s(&files[0])],
        &["shard 0/4 given twice"],
    );
    // A shard of another grid.
    let other = dir.join("other");
    ok(&[
        "sweep",
        "--mu",
        "0:0.3:0.1",
        "--duration",
        "30",
        "--window",
        "10:30",
        "--output",
        s(&other),
        "--shard",
        "1/4",
    ]);
    refused(
        &[
            "merge",
            "--out",
            out,
            s(&files[0]),
            s(&dir.join("other.shard-1-of-4.json")),
        ],
        &["shards of different scans", "grid"],
    );
    // Not a shard file at all, and no file.
    refused(
        &["merge", "--out", out, s(&dir.join("whole.csv"))],
        &["not a chaosctl shard file"],
    );
    refused(
        &["merge", "--out", out, s(&dir.join("nope.json"))],
        &["cannot read"],
    );
    assert!(!dir.join("m2.csv").exists());
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn basins_shards_merge_to_the_unsharded_csv() {
    let dir = scratch("basins");
    // Orbit names (A, B, …) are given in grid order over all points, so they must come out the
    // same when the points were computed on different shards.
    // Near the paper's period-1 orbits: this grid settles on two of them, A first seen at point 0
    // (shard 0) and B at point 9 (shard 1 of 4).
    let scan = [
        "basins",
        "--q0",
        "1.550079628,-0.488376467,-0.934331288",
        "--qd0=-4.311482957,9.229261970,-4.051303515",
        "--vary",
        "q1=-1:1.5:0.5",
        "--mu",
        "0.1:1.1:0.5",
        "--duration",
        "60",
        "--transient",
        "20",
    ];
    merged_equals_unsharded(&dir, &scan, 4, 18);
    let csv = std::fs::read_to_string(dir.join("merged.csv")).unwrap();
    assert!(
        csv.contains(",orbit,A,") && csv.contains(",orbit,B,"),
        "the grid should reach two orbits: {csv}"
    );
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn panda_sweep_shards_merge_to_the_unsharded_csv() {
    let dir = scratch("sweep-panda");
    // 3 μ × 2 starts of the Panda in 4 shards.
    let scan = [
        "sweep",
        "--preset",
        "panda",
        "--mu",
        "0:1:0.5",
        "--start=0,-0.785,0,-2.356,0,1.571,0.785",
        "--start=0.3,-0.785,0,-2.356,0,1.571,0.785",
        "--t-on",
        "5",
        "--duration",
        "30",
    ];
    merged_equals_unsharded(&dir, &scan, 4, 6);
    let csv = std::fs::read_to_string(dir.join("merged.csv")).unwrap();
    assert!(csv.starts_with("mu,start,q0,lambda_max,"), "{csv}");
    // The two starts are two runs: their λ_max differ at μ = 0.
    let lambda: Vec<&str> = csv
        .lines()
        .skip(1)
        .take(2)
        .map(|l| l.split(',').nth(3).unwrap())
        .collect();
    assert_ne!(lambda[0], lambda[1], "{csv}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn panda_basins_shards_merge_to_the_unsharded_csv() {
    let dir = scratch("basins-panda");
    // 3 starts × 2 μ of the Panda in 4 shards (2, 2, 1, 1 points).
    let scan = [
        "basins",
        "--preset",
        "panda",
        "--vary",
        "q1=-0.2:0.2:0.2",
        "--mu",
        "0:1:1",
        "--duration",
        "90",
        "--transient",
        "10",
    ];
    // The planar arm's rule holds for a robot's map too: a section too short to classify
    // (the Panda's T = 2 s: 11 points from 10 to 30 s) is refused, not mapped as chaos.
    let mut short = scan;
    short[8] = "30";
    refused(&short, &["11 points", "at least 40"]);
    let files = merged_equals_unsharded(&dir, &scan, 4, 6);
    // The orbits the runs settled on are refined by Newton at μ = 0 as the planar arm's are.
    let m2 = dir.join("m2");
    let mut args = vec!["merge", "--out", s(&m2)];
    args.extend(files.iter().map(|f| s(f)));
    let map = ok(&args);
    assert!(
        map.contains("orbit A:")
            && map.contains("the μ = 0 orbit through q = (")
            && map.contains("of 14 multipliers on the unit circle"),
        "{map}"
    );
    // A shard whose recorded run window was edited is of another grid.
    let text = std::fs::read_to_string(&files[0]).unwrap();
    let edited = text.replacen("\"90\"", "\"91\"", 1);
    assert_ne!(edited, text);
    let forged = dir.join("forged.shard-0-of-4.json");
    std::fs::write(&forged, edited).unwrap();
    let out = dir.join("m3");
    let mut args = vec!["merge", "--out", s(&out), s(&forged)];
    args.extend(files[1..].iter().map(|f| s(f)));
    refused(&args, &["grid"]);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn obstacles_shards_merge_to_the_unsharded_csv() {
    let dir = scratch("obstacles");
    let scan = [
        "obstacles",
        "--mu",
        "0,1.1",
        "--starts",
        "3",
        "--duration",
        "30",
        "--rms-from",
        "5",
    ];
    merged_equals_unsharded(&dir, &scan, 5, 12);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn bad_shard_specs_are_refused() {
    refused(&["sweep", "--shard", "4/4"], &["0 to 3"]);
    refused(&["basins", "--shard", "1"], &["I/N"]);
    refused(&["obstacles", "--shard", "0/0"], &["N must be"]);
    refused(&["merge", "--out", "x"], &["required"]);
}
