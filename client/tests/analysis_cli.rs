//! The analysis commands end to end through the built `chaosctl`: bad input is a clear error with
//! exit code 2 (never a panic), and small real runs produce their files.

mod common;

use common::chaosctl;
use std::path::PathBuf;

fn scratch(name: &str) -> PathBuf {
    common::scratch("analysis", name)
}

/// Fails with exit code 2 and a message containing every `needle`, and does not panic.
fn refused(args: &[&str], needles: &[&str]) {
    common::refused(args, needles);
}

#[test]
fn bad_mu_ranges_are_refused() {
    refused(&["sweep", "--mu", "0:3:0"], &["step", "> 0"]);
    refused(&["sweep", "--mu", "0:3:-0.1"], &["step"]);
    refused(&["sweep", "--mu", "3:0:0.1"], &["END", "START"]);
    refused(&["sweep", "--mu", "0:x:0.1"], &["not a finite number"]);
    refused(&["basins", "--mu", "0:3"], &["START:END:STEP"]);
    refused(&["orbits", "--mu", "-1:1:0.5"], &["feedback.mu"]);
}

#[test]
fn windows_outside_the_run_are_refused() {
    refused(
        &["lyapunov", "--duration", "300", "--window", "100:400"],
        &["window", "inside the run"],
    );
    refused(
        &["lyapunov", "--window", "300:100"],
        &["END must be greater than START"],
    );
    refused(
        &[
            "lyapunov",
            "--duration",
            "50",
            "--window",
            "40:50",
            "--renorm",
            "5",
        ],
        &["renormalisation"],
    );
    refused(&["lyapunov", "--d0", "0"], &["d0"]);
    refused(
        &["poincare", "--duration", "100", "--transient", "150"],
        &["--transient"],
    );
    refused(&["figures", "--duration=-5"], &["--duration"]);
    refused(&["figures", "--duration=1e12"], &["--duration"]);
    refused(
        &["figures", "--preset", "panda", "--duration=1e12"],
        &["--duration"],
    );
    refused(
        &["basins", "--duration", "50", "--transient", "30"],
        &["section would have 21 points"],
    );
    refused(
        &["lyapunov", "--window", "-10:100"],
        &["window", "inside the run"],
    );
}

/// A run shorter than a default transient (figures 20 s, poincare 100 s) is not refused over a
/// flag the user did not pass: the section starts half-way, as `simulate`'s does.
#[test]
fn a_short_duration_alone_runs_with_the_transient_halved() {
    let dir = scratch("short");
    let ran = |args: &[&str]| {
        let out = chaosctl(args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{args:?}: {err}");
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let (figures, prefix) = (dir.join("figures"), dir.join("section"));
    let f = figures.to_str().unwrap();
    let text = ran(&[
        "figures",
        "--preset",
        "panda",
        "--duration",
        "10",
        "--output-dir",
        f,
    ]);
    assert!(figures.join("mu0.25_residual.png").is_file(), "{text}");
    let p = prefix.to_str().unwrap();
    let text = ran(&["poincare", "--duration", "60", "--output", p]);
    assert!(text.contains("t = kT from 30 to 60 s"), "{text}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn wrong_initial_states_and_unreachable_tasks_are_refused() {
    refused(&["lyapunov", "--q0", "1,2"], &["sim.q0", "3 entries"]);
    refused(&["sweep", "--start", "0,1"], &["sim.q0", "3 entries"]);
    refused(&["sweep", "--start", "0,a,1"], &["not a number"]);
    refused(&["basins", "--vary", "q9=0:1:0.5"], &["3 joints"]);
    let dir = scratch("unreachable");
    let cfg = dir.join("far.toml");
    std::fs::write(&cfg, "[task]\ncenter = [4.0, 3.0]\n").unwrap();
    refused(
        &["lyapunov", "--config", cfg.to_str().unwrap()],
        &["task.center", "reaches only"],
    );
    refused(
        &["sweep", "--config", cfg.to_str().unwrap()],
        &["task.center", "reaches only"],
    );
    refused(&["orbits", "--model", "floating"], &["fixed-base"]);
    refused(&["orbits", "--tau", "0.5"], &["τ = T"]);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn lyapunov_json_has_the_estimate() {
    let out = chaosctl(&[
        "lyapunov",
        "--duration",
        "40",
        "--window",
        "10:40",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let l = v["lambda_max"].as_f64().unwrap();
    let se = v["stderr"].as_f64().unwrap();
    assert!(l.is_finite() && se.is_finite() && se >= 0.0, "{v}");
    assert_eq!(v["intervals"].as_u64(), Some(30));
    assert_eq!(v["history_in_norm"].as_bool(), Some(false));
}

#[test]
fn small_sweep_writes_csv_and_plots_quietly() {
    let dir = scratch("sweep");
    let prefix = dir.join("s");
    let out = chaosctl(&[
        "sweep",
        "--mu",
        "0:0.2:0.1",
        "--duration",
        "30",
        "--window",
        "10:30",
        "--jobs",
        "2",
        "--output",
        prefix.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    // Not a terminal: no progress bar.
    assert!(err.trim().is_empty(), "stderr should be empty: {err}");
    let csv = std::fs::read_to_string(dir.join("s.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 3 * 3, "{csv}");
    assert!(csv.lines().nth(1).unwrap().starts_with("0,0,"));
    // A robot's sweep writes the same columns (spatial_cli.rs): how each run ended, too.
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let residual = header.iter().position(|h| *h == "residual_final").unwrap();
    for line in csv.lines().skip(1) {
        let v: f64 = line.split(',').nth(residual).unwrap().parse().unwrap();
        assert!(v.is_finite() && v >= 0.0, "{line}");
    }
    let png = std::fs::read(dir.join("s.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    assert!(std::fs::read_to_string(dir.join("s.svg"))
        .unwrap()
        .contains("<svg"));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("simulated s per wall s"), "{stdout}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn safety_and_projection_flags_are_validated_and_applied() {
    refused(&["simulate", "--safety", "maybe"], &["on or off"]);
    refused(
        &["lyapunov", "--projection", "sideways"],
        &["full or null-space"],
    );
    refused(&["obstacles", "--preset", "paper"], &["no obstacles"]);
    refused(&["obstacles", "--starts", "0"], &["--starts"]);
    refused(&["obstacles", "--mu", "0,x"], &["not a number"]);
    refused(&["obstacles", "--mu=-1"], &["feedback.mu"]);
    refused(
        &["obstacles", "--duration", "30", "--rms-from", "40"],
        &["--rms-from"],
    );
    refused(&["arm-figure", "--frames", "20"], &["--frames"]);
    refused(&["obstacles", "--obstacle", "1,2"], &["X,Y,R"]);
    refused(&["arm-figure", "--obstacle", "1,2,-0.3"], &["radius"]);
    // The paper's obstacle, 30 s from the paper's start: off, a link goes through it; on, never.
    let run = |safety: &str| {
        let out = chaosctl(&[
            "simulate",
            "--preset",
            "paper-obstacle",
            "--safety",
            safety,
            "--projection",
            "null-space",
            "--duration",
            "30",
            "--json",
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()
    };
    let (off, on) = (run("off"), run("on"));
    assert_eq!(off["safety_enabled"].as_bool(), Some(false), "{off}");
    assert_eq!(on["safety_enabled"].as_bool(), Some(true), "{on}");
    assert_eq!(on["projection"].as_str(), Some("null-space"), "{on}");
    assert!(off["time_in_contact"].as_f64().unwrap() > 1.0, "{off}");
    assert_eq!(on["time_in_contact"].as_f64(), Some(0.0), "{on}");
    assert!(on["min_clearance"].as_f64().unwrap() >= 0.05 - 1e-3, "{on}");
    assert!(on["safety_active_time"].as_f64().unwrap() > 0.0, "{on}");
    assert!(on["safety_infeasible_steps"].as_u64().is_some(), "{on}");
    assert!(off["min_joint_margin"].is_null(), "{off}");
}

/// Reads a CSV into rows of (header → value).
fn csv_rows(text: &str) -> Vec<std::collections::HashMap<String, String>> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    lines
        .map(|l| {
            header
                .iter()
                .zip(l.split(','))
                .map(|(h, v)| (h.to_string(), v.to_string()))
                .collect()
        })
        .collect()
}

#[test]
fn obstacle_study_keeps_filtered_runs_clear() {
    let dir = scratch("obstacles");
    let prefix = dir.join("o");
    // Five starts of the basin grid (q1 = 0.75 begins inside the obstacle), two μ, both filters.
    let out = chaosctl(&[
        "obstacles",
        "--starts",
        "5",
        "--mu",
        "0,1.8",
        "--duration",
        "40",
        "--jobs",
        "2",
        "--output",
        prefix.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.trim().is_empty(), "stderr should be empty: {err}");
    let rows = csv_rows(&std::fs::read_to_string(dir.join("o.csv")).unwrap());
    assert_eq!(rows.len(), 5 * 2 * 2);
    let num = |r: &std::collections::HashMap<String, String>, k: &str| -> f64 {
        r[k].parse()
            .unwrap_or_else(|_| panic!("{k} = {:?} in {r:?}", r[k]))
    };
    let mut started_inside = 0;
    for r in &rows {
        assert!(r["error"].is_empty(), "{r:?}");
        started_inside += usize::from(r["start_in_contact"] == "true");
        if r["safety"] == "on" {
            assert_eq!(num(r, "time_in_contact_after_clear"), 0.0, "{r:?}");
            assert!(num(r, "min_clearance_after_clear") >= 0.05 - 1e-3, "{r:?}");
            assert!(num(r, "first_clear") < 1.0, "{r:?}");
        } else if r["mu"] == "0" {
            // The paper's potential alone: every start goes through the obstacle.
            assert!(num(r, "time_in_contact_after_clear") > 1.0, "{r:?}");
        }
        if r["safety"] == "on" && r["mu"] == "0" {
            assert!(num(r, "rms_tracking_error") <= 1e-4, "{r:?}");
        }
    }
    assert_eq!(
        started_inside, 4,
        "q1 = 0.75 starts inside, filter off and on, 2 μ"
    );
    let png = std::fs::read(dir.join("o.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("| 1.8 | on | 5 (1) |"), "{stdout}");

    let arm = dir.join("arm");
    let out = chaosctl(&[
        "arm-figure",
        "--from",
        "10",
        "--frames",
        "4",
        "--output",
        arm.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("filter on : t = 10…11 s"), "{stdout}");
    assert!(std::fs::read_to_string(dir.join("arm.svg"))
        .unwrap()
        .contains("<svg"));
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn the_trajectory_csv_ends_with_the_final_state() {
    let csv = scratch("final-row").join("run.csv");
    for stride in ["1000", "700"] {
        let out = chaosctl(&[
            "simulate",
            "--duration",
            "5",
            "--stride",
            stride,
            "--csv",
            csv.to_str().unwrap(),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = std::fs::read_to_string(&csv).unwrap();
        let times: Vec<f64> = text
            .lines()
            .skip(1)
            .map(|l| l.split(',').next().unwrap().parse().unwrap())
            .collect();
        assert_eq!(times.first(), Some(&0.0), "stride {stride}");
        assert_eq!(
            times.last(),
            Some(&5.0),
            "stride {stride}: the row at t = 5 is missing"
        );
        let mut sorted = times.clone();
        sorted.dedup();
        assert_eq!(sorted.len(), times.len(), "stride {stride}: a row repeated");
    }
}

#[test]
fn monitor_validates_the_chaos_monitor_end_to_end_and_refuses_bad_settings() {
    refused(
        &["monitor", "--preset", "paper", "--gamma", "1"],
        &["feedback.gamma", "at most"],
    );
    refused(
        &["monitor", "--preset", "paper", "--periodic-residual", "0"],
        &["--periodic-residual"],
    );
    let dir = scratch("monitor");
    let prefix = dir.join("m");
    let out = chaosctl(&[
        "monitor",
        "--preset",
        "paper",
        "--mu",
        "0:0.1:0.1",
        "--start",
        "0.3,1.2,1.9",
        "--duration",
        "150",
        "--output",
        prefix.to_str().unwrap(),
        "--json",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // μ = 0: chaotic by both; μ = 0.1 from this start: captured by the period-1 orbit.
    let cells = r["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 2, "{r}");
    assert_eq!(cells[0]["verdict"], "chaotic");
    assert_eq!(cells[0]["offline"], "chaotic");
    assert_eq!(cells[1]["verdict"], "periodic");
    assert_eq!(r["comparisons"][0]["smallest_fixed_mu"], 0.1);
    assert!(r["delay_median_periods"].as_f64().unwrap() <= 20.0, "{r}");
    for f in ["m.json", "m-cells.csv", "m.png", "m.svg"] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `orbits` on the paper's arm: the close returns of each start's μ = 0 run and each start's
/// run at a seeding gain seed Newton; every such seed is named by the orbit it led to, which is
/// in the catalog, and where the run settled (period-1) μ = 0.1 holds that orbit.
#[test]
fn orbits_names_the_orbit_each_settled_run_led_to() {
    let dir = scratch("orbits");
    let out = chaosctl(&[
        "orbits",
        "--seeds",
        "2",
        "--seed-mu",
        "0.1",
        "--mu",
        "0.1",
        "--average",
        "20",
        "--json",
        "--output",
        dir.join("o").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["seeds_tried"].as_u64(), Some(9), "{v}");
    let ids: Vec<&str> = v["orbits"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o["id"].as_str().unwrap())
        .collect();
    let settled = v["settled"].as_array().unwrap();
    assert_eq!(settled.len(), 3, "one per start: {v}");
    let mut settled_on_one = 0;
    for s in settled {
        assert_eq!(s["seed_mu"].as_f64(), Some(0.1), "{s}");
        let id = s["id"]
            .as_str()
            .expect("each settled run leads to an orbit");
        assert!(ids.contains(&id), "{id} not in {ids:?}");
        if s["class"] == "period-1" {
            // A run the feedback settled ends near an orbit that feedback holds.
            let all = v["orbits"].as_array().unwrap();
            let orbit = all.iter().find(|o| o["id"] == id).unwrap();
            assert_eq!(orbit["stability"][0]["Ok"]["verdict"], "stable", "{orbit}");
            settled_on_one += 1;
        }
    }
    assert!(settled_on_one >= 2, "{v}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn tune_shows_the_gain_the_daemon_would_choose_and_refuses_what_has_no_cycle() {
    let out = chaosctl(&[
        "tune", "--preset", "demo", "--grid", "4", "--refine", "3", "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let (mu, m) = (v["mu"].as_f64().unwrap(), v["multiplier"].as_f64().unwrap());
    assert!(mu > 0.0 && mu <= 0.4 && m < 1.0, "{v}");
    let scanned = v["scanned"].as_array().unwrap();
    assert!(scanned.len() >= 6, "{v}");
    // The fastest is the best of the scan; the choice keeps 80 % of its rate.
    let fastest = v["fastest"]["multiplier"].as_f64().unwrap();
    for p in scanned {
        assert!(
            fastest <= p["multiplier"].as_f64().unwrap(),
            "{p} beats the fastest {v}"
        );
    }
    let rate = |x: &serde_json::Value| x.as_f64().unwrap();
    assert!(rate(&v["rate"]) <= 0.8 * rate(&v["fastest"]["rate"]), "{v}");
    assert!(
        v["why"].as_str().unwrap().contains("of the fastest rate"),
        "{v}"
    );
    assert_eq!(v["orbit"]["q"].as_array().unwrap().len(), 3);
    // The table marks the choice.
    let out = chaosctl(&["tune", "--preset", "demo", "--grid", "2", "--refine", "0"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && text.contains("\nchosen    μ = "),
        "{text}"
    );
    assert_eq!(
        text.lines().filter(|l| l.starts_with('*')).count(),
        1,
        "{text}"
    );
    refused(&["tune", "--preset", "paper-floating"], &["floating base"]);
    refused(
        &["tune", "--preset", "paper", "--seed", "1,2"],
        &["6 numbers"],
    );
    refused(
        &["tune", "--preset", "paper", "--max-mu", "-1"],
        &["max_mu"],
    );
    refused(
        &["tune", "--preset", "paper", "--tau", "0.7"],
        &["differs from the task period"],
    );
}
