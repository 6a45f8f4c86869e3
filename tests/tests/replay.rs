//! Record a live run (daemon + plant, a `chaosctl set` part-way) and replay it through the
//! daemon's controller with `chaosctl replay`: every command bit for bit, on the planar arm and
//! on the Panda. A recording with one bit changed is caught, and a cut one is refused with the
//! line.

use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};
use tests::live::{ctl, NEAR_ORBIT};
use tests::{bin, serial, unique_namespace, Proc, TempDir};

/// `chaosctl replay FILE`: (exit code, stdout, stderr).
fn replay(path: &Path) -> (i32, String, String) {
    let out = Command::new(bin("chaosctl"))
        .arg("replay")
        .arg(path)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

fn wait_for_run(ns: &str, daemon: &Proc, plant: &Proc) {
    let until = Instant::now() + Duration::from_secs(15);
    loop {
        let (code, out, _) = ctl(ns, &["status", "--json"]);
        if code == 0 && serde_json::from_str::<serde_json::Value>(&out).unwrap()["mode"] == "Run" {
            return;
        }
        assert!(
            Instant::now() < until,
            "daemon never ran; daemon log:\n{}\nplant log:\n{}",
            daemon.log(),
            plant.log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Runs daemon and plant with `--record NAME` for about 2 s, with `set mu 0.3 feedback on t_on 0`
/// part-way, and shuts them down; returns the directory (kept alive) and the recording's path.
fn record_live_run(test: &str, name: &str) -> (TempDir, std::path::PathBuf) {
    record_live(test, name, (NEAR_ORBIT, ""), &[])
}

/// [`record_live_run`] of the set-up `top` with `[plant]` lines `plant`, and the live commands
/// `more` after the `set`.
fn record_live(
    test: &str,
    name: &str,
    (top, plant): (&str, &str),
    more: &[&[&str]],
) -> (TempDir, std::path::PathBuf) {
    let ns = unique_namespace(test);
    let dir = TempDir::new(&ns);
    let cfg = tests::write_config_with(dir.path(), &ns, "", plant, top);
    let c = cfg.to_str().unwrap();
    let mut daemon = Proc::spawn(
        "daemon",
        &bin("chaosd"),
        &["run", "--config", c, "--record", name],
        dir.path(),
    );
    let mut plant = Proc::spawn("plant", &bin("chaosd-plant"), &["--config", c], dir.path());
    wait_for_run(&ns, &daemon, &plant);
    std::thread::sleep(Duration::from_millis(700));
    // A live change part-way: the feedback on with a new gain, from now.
    let (code, _, err) = ctl(&ns, &["set", "mu", "0.3", "feedback", "on", "t_on", "0"]);
    assert_eq!(code, 0, "{err}");
    for args in more {
        std::thread::sleep(Duration::from_millis(200));
        let (code, _, err) = ctl(&ns, args);
        assert_eq!(code, 0, "{args:?}: {err}");
    }
    std::thread::sleep(Duration::from_millis(1200));
    let (code, _, err) = ctl(&ns, &["shutdown"]);
    assert_eq!(code, 0, "{err}");
    assert!(daemon.wait_exit(Duration::from_secs(15)).success());
    plant.terminate(Duration::from_secs(10));
    let rec = dir.path().join("out").join(name);
    let mode = std::fs::metadata(&rec).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o600, "the recording is owner-only");
    (dir, rec)
}

/// Replays `rec`: all ticks bit-identical, more than 1500 of them, the one change among them.
fn replays_whole(rec: &Path) -> u64 {
    replays_with(rec, 1)
}

/// [`replays_whole`] with `changes` parameter changes among the ticks.
fn replays_with(rec: &Path, changes: u64) -> u64 {
    let (code, out, err) = replay(rec);
    assert_eq!(code, 0, "replay failed: {out}{err}");
    // "K of K ticks replayed bit-identically (C commands, 1 parameter changes, 0 resumes)"
    let words: Vec<&str> = out.split_whitespace().collect();
    let (matched, ticks): (u64, u64) = (words[0].parse().unwrap(), words[2].parse().unwrap());
    assert_eq!(matched, ticks, "{out}");
    assert!(ticks > 1500, "too short a run to mean much: {out}");
    assert!(
        out.contains(&format!(" {changes} parameter changes")),
        "{out}"
    );
    ticks
}

#[test]
fn a_live_run_replays_bit_for_bit_and_a_tampered_recording_is_caught() {
    let _g = serial();
    let (dir, rec) = record_live_run("replay", "rec/run.replay");
    replays_whole(&rec);

    // One bit of one command's q̈ changed, late in the run (after the change): caught.
    let text = std::fs::read_to_string(&rec).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let i = lines
        .iter()
        .rposition(|l| l.starts_with("T ") && !l.ends_with(" -"))
        .expect("a tick with a command");
    let mut fields: Vec<String> = lines[i].split(',').map(String::from).collect();
    let qdd0 = fields.len() - 5 * protocol::MAX_JOINTS; // the command's qdd[0]
    let v = u64::from_str_radix(&fields[qdd0], 16).unwrap() ^ 1;
    fields[qdd0] = format!("{v:016x}");
    lines[i] = fields.join(",");
    let tick = lines[i].split(' ').nth(1).unwrap().to_string();
    let tampered = dir.path().join("tampered.replay");
    std::fs::write(&tampered, lines.join("\n") + "\n").unwrap();
    let (code, out, _) = replay(&tampered);
    assert_eq!(code, 1, "{out}");
    assert!(
        out.contains(&format!(
            "first mismatch at tick {tick}: command.qdd[0] recorded"
        )) && out.contains(&format!("0x{v:016x}")),
        "{out}"
    );

    // A recording cut mid-line: a one-line error naming the line, exit 2.
    let cut = dir.path().join("cut.replay");
    std::fs::write(&cut, &text[..text.len() - 30]).unwrap();
    let (code, _, err) = replay(&cut);
    assert_eq!(code, 2);
    assert!(
        err.contains("truncated") && err.lines().count() == 1,
        "{err}"
    );
}

#[test]
fn a_live_panda_run_replays_bit_for_bit_with_its_edits_and_a_changed_torque_is_caught() {
    let _g = serial();
    // Torque mode: the command carries τ, the reference and q̈, and every field is compared.
    let top = format!(
        "{}\n[command]\nmode = \"torque\"\n",
        control::config::spatial::PANDA_PAPER
    );
    let sphere: &[&str] = &["obstacle", "add", "1.0", "-1.0", "1.5", "0.05"];
    let plant = "dynamics = \"rigid-body\"";
    let (dir, rec) = record_live("replay-panda", "panda.replay", (&top, plant), &[sphere]);
    replays_with(&rec, 2);
    let text = std::fs::read_to_string(&rec).unwrap();
    assert!(
        text.lines().nth(1).unwrap().contains(" arm="),
        "the robot's fingerprint"
    );
    // One bit of one torque, late in the run: caught by name.
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let i = lines
        .iter()
        .rposition(|l| l.starts_with("T ") && !l.ends_with(" -"))
        .expect("a tick with a command");
    let mut fields: Vec<String> = lines[i].split(',').map(String::from).collect();
    let tau0 = fields.len() - protocol::MAX_JOINTS; // the command's tau[0]
    let v = u64::from_str_radix(&fields[tau0], 16).unwrap() ^ 1;
    fields[tau0] = format!("{v:016x}");
    lines[i] = fields.join(",");
    let tick = lines[i].split(' ').nth(1).unwrap().to_string();
    let tampered = dir.path().join("tampered.replay");
    std::fs::write(&tampered, lines.join("\n") + "\n").unwrap();
    let (code, out, _) = replay(&tampered);
    assert_eq!(code, 1, "{out}");
    assert!(
        out.contains(&format!(
            "first mismatch at tick {tick}: command.tau[0] recorded"
        )),
        "{out}"
    );
}

#[test]
fn a_live_mcap_recording_replays_bit_for_bit_and_shows_the_run() {
    let _g = serial();
    let (_dir, rec) = record_live_run("replay-mcap", "rec/run.mcap");
    let ticks = replays_whole(&rec);
    // The same file is a recording a viewer opens: joint states, and the edit as an event.
    let file = daemon::mcap_read::read(&rec).unwrap();
    let states = file.messages(daemon::view::Topic::JointStates).len() as u64;
    assert!(
        states > ticks / 2,
        "{states} joint states for {ticks} ticks"
    );
    let events = file.messages(daemon::view::Topic::Events);
    assert!(
        events
            .iter()
            .any(|m| String::from_utf8_lossy(&m.data).contains("chaosctl set mu 0.3")),
        "{} events",
        events.len()
    );
    // Foxglove's own readers decode every channel of it, the replay channel included.
    let scratch = rec.parent().unwrap();
    let limit = std::time::Duration::from_secs(120);
    let file_arg = rec.to_str().unwrap();
    if let Some(v) = tests::foxglove_check::run(&["file", file_arg], scratch, limit) {
        let replay = &v["topics"]["/chaosd/replay"];
        assert_eq!(replay["count"].as_u64(), Some(ticks), "{v}");
        assert_eq!(replay["schema"], "chaosd.ReplayLine", "{v}");
    }
}
