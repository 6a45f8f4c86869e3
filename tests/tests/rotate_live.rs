//! A live recording rotates at `[daemon] record_max_bytes` and keeps `record_keep` old files.

use std::os::unix::fs::PermissionsExt;
use std::time::{Duration, Instant};
use tests::live::ctl;
use tests::*;

#[test]
fn a_live_recording_rotates_and_keeps_only_the_newest_files() {
    let _g = serial();
    let ns = unique_namespace("rotate");
    let dir = TempDir::new(&ns);
    let cfg = write_config(
        dir.path(),
        &ns,
        "record_max_bytes = 8192\nrecord_keep = 2\n",
        "",
    );
    let (_plant, mut daemon) = live::spawn_pair(dir.path(), &cfg);
    let until = Instant::now() + Duration::from_secs(15);
    while status_mode(&ns).as_deref() != Some("Run") {
        assert!(Instant::now() < until, "never ran:\n{}", daemon.log());
        std::thread::sleep(Duration::from_millis(100));
    }
    let (code, _, err) = ctl(&ns, &["record", "start", "rot.csv"]);
    assert_eq!(code, 0, "{err}");
    // About 400 bytes a row at 1 kHz: 8 KiB is ~20 rows, so a second makes dozens of files.
    std::thread::sleep(Duration::from_secs(1));
    let (code, out, err) = ctl(&ns, &["record", "stop"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let rotations = v["rotations"].as_u64().unwrap();
    assert!(rotations >= 10, "{v}");
    let out_dir = dir.path().join("out");
    let mut files: Vec<String> = std::fs::read_dir(&out_dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("rot."))
        .collect();
    files.sort();
    let mut expected: Vec<String> = (rotations - 2..=rotations)
        .map(|k| format!("rot.{k}.csv"))
        .collect();
    expected.sort();
    assert_eq!(files, expected, "{v}");
    let header = std::fs::read_to_string(out_dir.join(&files[0]))
        .unwrap()
        .lines()
        .next()
        .unwrap()
        .to_string();
    assert!(header.starts_with("t,state_seq"), "{header}");
    for f in &files {
        let p = out_dir.join(f);
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(text.len() <= 8192, "{f}: {} bytes", text.len());
        assert_eq!(text.lines().next(), Some(header.as_str()), "{f}");
        assert!(text.ends_with('\n'), "{f} ends mid-row");
        let mode = std::fs::metadata(&p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600, "{f}");
    }
    assert!(daemon.terminate(Duration::from_secs(10)).success());
}

fn status_mode(ns: &str) -> Option<String> {
    let (code, out, _) = ctl(ns, &["status", "--json"]);
    if code != 0 {
        return None;
    }
    let v: serde_json::Value = serde_json::from_str(&out).ok()?;
    v["mode"].as_str().map(str::to_string)
}
