//! MCAP recordings through the real daemon and plant: `chaosctl record start` writes MCAP by
//! default, every channel holds what the daemon says it wrote, the events name the operator's
//! edits, `chaosctl export --csv` gives the rows back, and, when `CHAOSD_PYTHON` names a Python
//! with `mcap` and `mcap-ros2-support` (CI sets one up), Python's reader agrees bit for bit; so
//! do Foxglove's own readers when `CHAOSD_FOXGLOVE_CHECK` names scripts/foxglove-check.

use daemon::mcap_read;
use daemon::view::cdr::{decode_joint_state, JointState};
use daemon::view::Topic;
use std::path::Path;
use std::time::Duration;
use tests::foxglove_check::{self, bits, ns};
use tests::live::*;
use tests::*;

/// Records about `secs` seconds of a running system, with one edit in the middle; returns the
/// file and `record stop`'s answer.
fn record(
    sys: &System,
    name: &str,
    edit: &[&str],
    secs: f64,
) -> (std::path::PathBuf, serde_json::Value) {
    let (code, out, err) = ctl(&sys.ns, &["record", "start", name]);
    assert_eq!(code, 0, "{err}");
    let started: serde_json::Value = serde_json::from_str(&out).unwrap();
    std::thread::sleep(Duration::from_secs_f64(secs / 2.0));
    let (code, _, err) = ctl(&sys.ns, edit);
    assert_eq!(code, 0, "{err}");
    std::thread::sleep(Duration::from_secs_f64(secs / 2.0));
    let (code, out, err) = ctl(&sys.ns, &["record", "stop"]);
    assert_eq!(code, 0, "{err}");
    let stop: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(stop["path"], started["path"]);
    (stop["path"].as_str().unwrap().into(), stop)
}

/// Everything the Rust reader can check against the daemon's answer.
fn check_file(path: &Path, stop: &serde_json::Value, joints: &[&str], link: &str) {
    assert_eq!(stop["format"], "mcap", "{stop}");
    let file = mcap_read::read(path).unwrap();
    // Every channel holds what the daemon says it wrote, in time order, inside the span.
    let (first, last) = (
        stop["first_log_time_ns"].as_u64().unwrap(),
        stop["last_log_time_ns"].as_u64().unwrap(),
    );
    for t in Topic::ALL {
        let msgs = file.messages(t);
        assert_eq!(
            msgs.len() as u64,
            stop["messages"][t.name()].as_u64().unwrap(),
            "{}",
            t.name()
        );
        let back = msgs.windows(2).find(|w| w[0].log_time > w[1].log_time);
        let back = back.map(|w| (w[0].row, w[0].log_time, w[1].row, w[1].log_time));
        assert!(back.is_none(), "{}: {back:?}", t.name());
        let out = msgs.iter().find(|m| !(first..=last).contains(&m.log_time));
        assert!(
            out.is_none(),
            "{}: {:?} outside {first}..={last}",
            t.name(),
            out.map(|m| (m.row, m.log_time))
        );
    }
    let rows = stop["rows"].as_u64().unwrap();
    assert!(rows > 1000, "{rows} rows in 2 s at 1 kHz");
    assert_eq!(file.messages(Topic::JointStates).len() as u64, rows);
    assert_eq!(file.messages(Topic::Timing).len() as u64, rows);
    assert_eq!(file.messages(Topic::Residual).len() as u64, rows);
    // The 3-D channels at 50 Hz: about 100 in 2 s.
    let tf = file.messages(Topic::Transforms).len() as u64;
    assert!(
        (rows / 20 - 2..=rows / 20 + 2).contains(&tf),
        "{tf} transforms for {rows} rows"
    );
    // The last joint state, decoded from CDR, is the daemon's, bit for bit.
    let js = decode_joint_state(&file.messages(Topic::JointStates).last().unwrap().data).unwrap();
    let want = &stop["last_joint_state"];
    let nums = |v: &serde_json::Value| -> Vec<f64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    assert_eq!(js.position, nums(&want["position"]));
    assert_eq!(js.velocity, nums(&want["velocity"]));
    assert_eq!(js.name, joints);
    // The transforms name the URDF's links; the robot description is there.
    let tf: serde_json::Value =
        serde_json::from_slice(&file.messages(Topic::Transforms)[0].data).unwrap();
    let children: Vec<&str> = tf["transforms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["child_frame_id"].as_str().unwrap())
        .collect();
    assert!(children.contains(&link), "{children:?}");
    let urdf = &file.messages(Topic::RobotDescription)[0].data;
    assert!(String::from_utf8_lossy(urdf).contains(link));
    assert!(
        file.metadata["config"].contains("[task]"),
        "{:?}",
        file.metadata
    );
    python_reads(path, stop);
    foxglove_reads(path, stop, &js);
    ros2_bag_reads(path, stop);
}

/// `chaosctl export REC --ros2 BAG`: an MCAP file with the `ros2` profile, every channel CDR
/// with a `ros2msg` schema, as many messages as the recording's channels they come from and the
/// same joint states byte for byte; `rosbags` reads it when `CHAOSD_PYTHON` names a Python with
/// it (scripts/ros2_readback.py).
fn ros2_bag_reads(path: &Path, stop: &serde_json::Value) {
    let bag = path.with_extension("ros2.mcap");
    let export = || {
        let (rec, out) = (path.to_str().unwrap(), bag.to_str().unwrap());
        std::process::Command::new(bin("chaosctl"))
            .args(["export", rec, "--ros2", out])
            .output()
            .unwrap()
    };
    let o = export();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let bytes = std::fs::read(&bag).unwrap();
    let header = mcap::read::LinearReader::new(&bytes)
        .unwrap()
        .find_map(|r| match r.unwrap() {
            mcap::records::Record::Header(h) => Some(h),
            _ => None,
        })
        .unwrap();
    assert_eq!(header.profile, "ros2");
    let mut counts = std::collections::BTreeMap::<String, u64>::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        assert_eq!(m.channel.message_encoding, "cdr", "{}", m.channel.topic);
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(schema.encoding, "ros2msg", "{}", m.channel.topic);
        *counts.entry(m.channel.topic.clone()).or_default() += 1;
    }
    let recorded = |t: Topic| stop["messages"][t.name()].as_u64().unwrap();
    assert_eq!(counts["/joint_states"], recorded(Topic::JointStates));
    assert_eq!(counts["/tf"], recorded(Topic::Transforms));
    assert_eq!(counts["/chaosd/tip"], recorded(Topic::Tip));
    assert_eq!(counts["/chaosd/period_residual"], recorded(Topic::Residual));
    let rosout = counts.get("/rosout").copied().unwrap_or(0);
    assert_eq!(rosout, recorded(Topic::Events));
    let rec = mcap_read::read(path).unwrap();
    let back = mcap_read::parse(&bytes).unwrap();
    let states = |f: &mcap_read::McapFile| -> Vec<Vec<u8>> {
        f.messages(Topic::JointStates)
            .iter()
            .map(|m| m.data.clone())
            .collect()
    };
    assert!(states(&rec) == states(&back), "the joint states differ");
    // Never over a file.
    let o = export();
    assert!(String::from_utf8_lossy(&o.stderr).contains("must not exist"));
    let Ok(python) = std::env::var("CHAOSD_PYTHON") else {
        eprintln!("CHAOSD_PYTHON not set: rosbags not run on the ROS 2 bag (CI runs it)");
        return;
    };
    readback(&python, "ros2_readback.py", &bag, stop);
}

/// Runs `scripts/SCRIPT FILE STOP.json` with `python`: it must pass and find the daemon's last
/// joint state bit for bit.
fn readback(python: &str, script: &str, file: &Path, stop: &serde_json::Value) {
    let stop_file = file.with_extension("stop.json");
    std::fs::write(&stop_file, stop.to_string()).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scripts")
        .join(script);
    let o = std::process::Command::new(python)
        .arg(script)
        .args([file, &stop_file])
        .output()
        .unwrap();
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(o.status.success(), "{out}\n{err}");
    assert!(out.contains("bit for bit"), "{out}");
    eprintln!("{out}");
}

/// Foxglove's own readers (scripts/foxglove-check): every message decoded with the decoder the
/// app picks and valid against its schemas, the official foxglove.* ones included; the counts
/// and the time span are the daemon's, and the last joint state is the daemon's and chaosd's
/// own decoder's, bit for bit. Skipped, saying so, without `CHAOSD_FOXGLOVE_CHECK`.
fn foxglove_reads(path: &Path, stop: &serde_json::Value, js: &JointState) {
    let file = path.to_str().unwrap();
    let limit = Duration::from_secs(120);
    let Some(seen) = foxglove_check::run(&["file", file], path.parent().unwrap(), limit) else {
        return;
    };
    assert_eq!(seen["compression"], serde_json::json!(["lz4"]), "{seen}");
    let counted = stop["messages"].as_object().unwrap();
    for (topic, n) in counted {
        let got = seen["topics"][topic]["count"].as_u64().unwrap_or(0);
        assert_eq!(Some(got), n.as_u64(), "{topic}: {seen}");
    }
    let topics = seen["topics"].as_object().unwrap();
    assert!(topics.keys().all(|t| counted.contains_key(t)), "{seen}");
    for t in ["first_log_time_ns", "last_log_time_ns"] {
        assert_eq!(Some(ns(&seen[t])), stop[t].as_u64(), "{t}: {seen}");
    }
    let last = &seen["last_joint_state"];
    assert_eq!(last["name"], serde_json::json!(js.name), "{last}");
    assert_eq!(last["frame_id"], js.frame_id.as_str());
    assert_eq!(ns(&last["stamp_ns"]), js.stamp_ns);
    let own = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&last["position"]), own(&js.position));
    assert_eq!(bits(&last["velocity"]), own(&js.velocity));
    assert_eq!(bits(&last["effort"]), own(&js.effort));
    let daemon = &stop["last_joint_state"];
    assert_eq!(bits(&last["position"]), bits(&daemon["position"]));
    assert_eq!(bits(&last["velocity"]), bits(&daemon["velocity"]));
    let total: u64 = topics.values().map(|t| t["count"].as_u64().unwrap()).sum();
    eprintln!(
        "Foxglove's readers: {total} messages on {} channels decoded and valid, as the daemon wrote; last joint state bit for bit",
        topics.len()
    );
}

/// Python's `mcap` reader with `mcap-ros2-support` checks the file (scripts/mcap_readback.py).
/// Skipped, saying so, without `CHAOSD_PYTHON`; CI sets it and `CHAOSD_REQUIRE_PYTHON=1`.
fn python_reads(path: &Path, stop: &serde_json::Value) {
    let Ok(python) = std::env::var("CHAOSD_PYTHON") else {
        assert!(
            std::env::var("CHAOSD_REQUIRE_PYTHON").is_err(),
            "CHAOSD_REQUIRE_PYTHON is set but CHAOSD_PYTHON is not"
        );
        eprintln!("CHAOSD_PYTHON not set: Python's mcap reader not run (CI runs it)");
        return;
    };
    readback(&python, "mcap_readback.py", path, stop);
    // The example a user starts from: examples/python/plot_residual.py draws the residual.
    let png = path.with_extension("png");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/python/plot_residual.py");
    let o = std::process::Command::new(std::env::var("CHAOSD_PYTHON").unwrap())
        .arg(script)
        .args([path, &png])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        std::fs::metadata(&png).unwrap().len() > 10_000,
        "{}",
        png.display()
    );
}

#[test]
fn a_planar_run_records_as_mcap_that_reads_back_exports_to_csv_and_logs_the_edits() {
    let _g = serial();
    let sys = start("mcap-planar", "");
    let (path, stop) = record(&sys, "rec/run.mcap", &["set", "mu", "0.2"], 2.0);
    assert!(path.starts_with(sys.dir.path().join("out")));
    check_file(&path, &stop, &["joint1", "joint2", "joint3"], "link3");
    // The operator's edit is an event, in their words.
    let file = mcap_read::read(&path).unwrap();
    let events: Vec<String> = file
        .messages(Topic::Events)
        .iter()
        .map(|m| {
            serde_json::from_slice::<serde_json::Value>(&m.data).unwrap()["message"].to_string()
        })
        .collect();
    assert!(
        events.iter().any(|e| e.contains("chaosctl set mu 0.2")),
        "{events:?}"
    );
    // The CSV export: one row per joint state, the last one the daemon's last state.
    let csv = path.with_extension("csv");
    let o = std::process::Command::new(bin("chaosctl"))
        .args(["export", path.to_str().unwrap(), "--csv"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header.len(), 4 + 3 + 3 + 2 + 3 + 5);
    let data: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(data.len() as u64, stop["rows"].as_u64().unwrap());
    let last = data.last().unwrap();
    let q1: f64 = last[4].parse().unwrap();
    let want = stop["last_joint_state"]["position"][0].as_f64().unwrap();
    assert!(
        (q1 - want).abs() <= 1e-11 * (1.0 + want.abs()),
        "{q1} vs {want}"
    );
    assert_eq!(last[1], stop["last_joint_state"]["seq"].to_string());
    // Exporting again refuses to overwrite; a CSV is not an MCAP file.
    let o = std::process::Command::new(bin("chaosctl"))
        .args(["export", path.to_str().unwrap(), "--csv"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("must not exist"));
    let o = std::process::Command::new(bin("chaosctl"))
        .args(["export", csv.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&o.stderr).contains("not an MCAP file"));
}

#[test]
fn a_panda_run_records_its_urdf_links_and_the_obstacle_it_is_given() {
    let _g = serial();
    let sys = start("mcap-panda", control::config::spatial::PANDA_PAPER);
    let edit = ["obstacle", "add", "0.3", "0.4", "0.9", "0.05"];
    let (path, stop) = record(&sys, "panda.mcap", &edit, 2.0);
    let joints: Vec<String> = (1..=7).map(|i| format!("panda_joint{i}")).collect();
    let joints: Vec<&str> = joints.iter().map(String::as_str).collect();
    check_file(&path, &stop, &joints, "panda_link7");
    // The scene after the edit shows the new sphere.
    let file = mcap_read::read(&path).unwrap();
    let last_scene = file
        .messages(Topic::Scene)
        .iter()
        .rev()
        .map(|m| serde_json::from_slice::<serde_json::Value>(&m.data).unwrap())
        .find(|v| v["entities"][1]["id"] == "obstacles")
        .unwrap();
    let spheres = last_scene["entities"][1]["spheres"].as_array().unwrap();
    assert!(
        spheres
            .iter()
            .any(|s| s["pose"]["position"]["z"] == 0.9 && s["size"]["x"] == 0.1),
        "{spheres:?}"
    );
}
