//! MCAP recordings (`chaosctl record start`, the default): the channels of [`crate::view`] in
//! LZ4-compressed chunks, written by the reporter thread.
//!
//! MCAP because it is what robotics tools open: Foxglove plays it with the arm in 3-D, Python's
//! `mcap` + `mcap-ros2-support` decode it, rosbag2 reads its ROS 2 channels. The file starts
//! with a `chaosd` metadata record (the running configuration, the loop's rate, the clock
//! offset) so that [`crate::mcap_read`] can export it back to chaosd's CSV.
//!
//! The size limit (`[daemon] record_max_bytes`, `record_keep`) works as for CSV
//! ([`crate::rotate`]): a new segment before the message bytes of this one would pass the limit
//! (compression only makes the file smaller than that count), each segment a whole MCAP file
//! that starts with the robot's description.

use crate::rotate::{remove_old, segment_path, Limit};
use crate::telemetry::TickRecord;
use crate::view::{Encoder, Level, Scene, Sink, TickContext, Topic};
use control::System;
use protocol::StateSample;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// The metadata record's name.
pub const METADATA: &str = "chaosd";

/// An open MCAP recording.
pub struct McapRecording {
    pub path: PathBuf,
    encoder: Encoder,
    out: Output,
    /// Unix time minus CLOCK_MONOTONIC (ns): a tick's `now_ns` plus this is its log time.
    offset_ns: i128,
    last_state: Option<StateSample>,
    /// The newest tick's log time: an operator's change is stamped with it (it takes effect at
    /// the next tick), so every channel's times run forwards.
    tick_ns: Option<u64>,
}

/// The file side: the writer, its channels, and the rotation.
struct Output {
    path: PathBuf,
    writer: Option<mcap::Writer<BufWriter<File>>>,
    channels: [Option<u16>; Topic::ALL.len()],
    counts: [u64; Topic::ALL.len()],
    limit: Limit,
    segment: u64,
    /// Message bytes in the current segment.
    written: u64,
    /// Ticks (joint states) in the current segment.
    segment_ticks: u64,
    metadata: BTreeMap<String, String>,
    /// The robot description, repeated at the start of every segment.
    description: Option<Vec<u8>>,
    first_ns: Option<u64>,
    last_ns: u64,
}

fn err(path: &Path) -> impl Fn(mcap::McapError) -> String + '_ {
    move |e| format!("{}: {e}", path.display())
}

impl Output {
    fn open(
        path: &Path,
        metadata: &BTreeMap<String, String>,
    ) -> Result<mcap::Writer<BufWriter<File>>, String> {
        let file = crate::recording_files::open(path)
            .map_err(|e| format!("cannot create {}: {e}", path.display()))?;
        let mut w = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Lz4))
            .library(format!("chaosd {}", env!("CARGO_PKG_VERSION")))
            .create(file)
            .map_err(err(path))?;
        let m = mcap::records::Metadata {
            name: METADATA.into(),
            metadata: metadata.clone(),
        };
        w.write_metadata(&m).map_err(err(path))?;
        Ok(w)
    }

    fn channel(&mut self, topic: Topic) -> Result<u16, String> {
        let k = topic as usize;
        if let Some(id) = self.channels[k] {
            return Ok(id);
        }
        let path = segment_path(&self.path, self.segment);
        let w = self.writer.as_mut().ok_or("the recording is closed")?;
        let (name, encoding, text) = topic.schema();
        let schema = w
            .add_schema(name, encoding, text.as_bytes())
            .map_err(err(&path))?;
        let id = w
            .add_channel(schema, topic.name(), topic.encoding(), &BTreeMap::new())
            .map_err(err(&path))?;
        self.channels[k] = Some(id);
        Ok(id)
    }

    fn rotate(&mut self) -> Result<(), String> {
        self.close()?;
        self.segment += 1;
        let next = segment_path(&self.path, self.segment);
        self.writer = Some(Self::open(&next, &self.metadata)?);
        self.channels = [None; Topic::ALL.len()];
        self.written = 0;
        self.segment_ticks = 0;
        remove_old(&self.path, self.segment, self.limit.keep).map_err(|e| e.to_string())?;
        if let Some(d) = self.description.clone() {
            self.write(Topic::RobotDescription, 0, self.last_ns, &d)?;
        }
        Ok(())
    }

    fn write(&mut self, topic: Topic, row: u64, unix_ns: u64, data: &[u8]) -> Result<(), String> {
        let channel_id = self.channel(topic)?;
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: row as u32,
            log_time: unix_ns,
            publish_time: unix_ns,
        };
        let path = segment_path(&self.path, self.segment);
        let w = self.writer.as_mut().ok_or("the recording is closed")?;
        w.write_to_known_channel(&header, data)
            .map_err(err(&path))?;
        if topic != Topic::RobotDescription {
            self.written += data.len() as u64;
        }
        if topic == Topic::JointStates {
            self.segment_ticks += 1;
        }
        self.counts[topic as usize] += 1;
        self.first_ns = Some(self.first_ns.map_or(unix_ns, |f| f.min(unix_ns)));
        self.last_ns = self.last_ns.max(unix_ns);
        Ok(())
    }

    fn close(&mut self) -> Result<(), String> {
        let path = segment_path(&self.path, self.segment);
        if let Some(mut w) = self.writer.take() {
            w.finish().map_err(err(&path))?;
        }
        Ok(())
    }
}

impl Sink for Output {
    fn put(&mut self, topic: Topic, row: u64, unix_ns: u64, data: &[u8]) -> Result<(), String> {
        if topic == Topic::RobotDescription {
            self.description = Some(data.to_vec());
        }
        let full = self
            .limit
            .max_bytes
            .is_some_and(|m| self.written + data.len() as u64 > m);
        // The robot description heads every segment and does not count against the limit (the
        // Panda's URDF is 10 KB, the floor 4 KB), and a segment holds at least one tick, so a
        // small limit never leaves one message a file.
        if full && self.segment_ticks > 0 {
            self.rotate()?;
        }
        self.write(topic, row, unix_ns, data)
    }
}

impl Drop for Output {
    fn drop(&mut self) {
        let _ = self.close();
    }
}

/// Unix time minus CLOCK_MONOTONIC, now (ns).
pub fn clock_offset() -> i128 {
    let unix = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as i128);
    unix - protocol::monotonic_ns() as i128
}

impl McapRecording {
    /// Starts a recording of `system` (a loop at `rate_hz`) at `name` inside `out_dir`.
    pub fn start(
        out_dir: &Path,
        name: &str,
        system: &System,
        rate_hz: f64,
        limit: Limit,
    ) -> Result<Self, String> {
        let path = crate::recording_files::resolve(out_dir, name, "mcap")?;
        let offset_ns = clock_offset();
        let metadata = BTreeMap::from([
            ("config".to_string(), system.to_toml()),
            ("rate_hz".to_string(), rate_hz.to_string()),
            ("n".to_string(), system.n().to_string()),
            ("arm".to_string(), system.describe_arm()),
            ("clock_offset_ns".to_string(), offset_ns.to_string()),
        ]);
        let out = Output {
            writer: Some(Output::open(&path, &metadata)?),
            path: path.clone(),
            channels: [None; Topic::ALL.len()],
            counts: [0; Topic::ALL.len()],
            limit,
            segment: 0,
            written: 0,
            segment_ticks: 0,
            metadata,
            description: None,
            first_ns: None,
            last_ns: 0,
        };
        let encoder = Encoder::new(Scene::of(system), rate_hz);
        Ok(Self {
            path,
            encoder,
            out,
            offset_ns,
            last_state: None,
            tick_ns: None,
        })
    }

    fn unix_ns(&self, monotonic_ns: u64) -> u64 {
        (monotonic_ns as i128 + self.offset_ns).max(0) as u64
    }

    /// Message bytes written so far (the file is smaller: its chunks are compressed).
    pub fn bytes(&self) -> u64 {
        self.out.written
    }

    /// Answered states recorded so far.
    pub fn rows(&self) -> u64 {
        self.encoder.rows
    }

    /// One tick whose law ran on `st`.
    pub fn tick(
        &mut self,
        r: &TickRecord,
        st: &StateSample,
        ctx: TickContext,
    ) -> Result<(), String> {
        let ns = self.unix_ns(r.now_ns);
        if self.tick_ns.is_none() {
            // The description and the scene at the first tick's time: ticks still queued when
            // the recording started are older than "now", and every channel runs forwards.
            self.encoder.start(ns, &mut self.out)?;
        }
        self.encoder.tick(r, st, ctx, ns, &mut self.out)?;
        self.last_state = Some(*st);
        self.tick_ns = Some(ns);
        Ok(())
    }

    /// Now on the recording's clock: the newest tick's time (see `tick_ns`).
    fn now(&self) -> u64 {
        self.tick_ns
            .unwrap_or_else(|| self.unix_ns(protocol::monotonic_ns()))
    }

    /// A tick's replay text (see [`crate::replay`]) on `/chaosd/replay`, at the tick's time.
    pub fn replay_text(&mut self, monotonic_ns: u64, text: &str) -> Result<(), String> {
        let ns = self.unix_ns(monotonic_ns);
        let line =
            serde_json::to_vec(&serde_json::json!({ "text": text })).map_err(|e| e.to_string())?;
        self.out.put(Topic::Replay, self.encoder.rows, ns, &line)
    }

    /// A line on `/chaosd/events`, stamped with the newest tick's time.
    pub fn event(&mut self, level: Level, text: &str) -> Result<(), String> {
        let ns = self.now();
        self.encoder.event(ns, level, text, &mut self.out)
    }

    /// An operator's change: an event in `text`, and the new configuration's scene when it
    /// changed.
    pub fn note(&mut self, text: &str, system: Option<&System>) -> Result<(), String> {
        self.event(Level::Info, text)?;
        match system {
            Some(s) => self.set_system(s),
            None => Ok(()),
        }
    }

    /// The configuration changed: the new path and obstacles.
    pub fn set_system(&mut self, system: &System) -> Result<(), String> {
        let Some(ns) = self.tick_ns else {
            // Before the first tick: the first tick writes it.
            self.encoder.replace_scene(Scene::of(system));
            return Ok(());
        };
        self.encoder.set_scene(Scene::of(system), ns, &mut self.out)
    }

    /// Closes the file; the JSON answer to `record stop`: the path, the rows, the messages per
    /// channel, and the last joint state as the daemon had it (for a reader to check against).
    pub fn finish(mut self) -> Result<String, String> {
        if self.tick_ns.is_none() {
            let now = self.now();
            self.encoder.start(now, &mut self.out)?;
        }
        self.out.close()?;
        let messages: serde_json::Map<String, serde_json::Value> = Topic::ALL
            .iter()
            .map(|t| (t.name().to_string(), self.out.counts[*t as usize].into()))
            .collect();
        let n = self.encoder.scene().joints.len();
        let last = self.last_state.map(|s| {
            let n = (s.n as usize).min(n);
            serde_json::json!({
                "seq": s.seq, "stamp_ns": s.stamp_ns,
                "position": &s.q[..n], "velocity": &s.qd[..n],
            })
        });
        Ok(serde_json::json!({
            "path": self.path,
            "format": "mcap",
            "rows": self.encoder.rows,
            "messages": messages,
            "first_log_time_ns": self.out.first_ns,
            "last_log_time_ns": self.out.last_ns,
            "rotations": self.out.segment,
            "last_file": segment_path(&self.path, self.out.segment),
            "last_joint_state": last,
        })
        .to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view::TickContext;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("chaosd-mcap-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// `rows` ticks of the paper arm, one a millisecond.
    fn ticks(rec: &mut McapRecording, rows: u64) {
        ticks_n(rec, rows, 3)
    }

    /// `rows` ticks of an `n`-joint arm, one a millisecond.
    fn ticks_n(rec: &mut McapRecording, rows: u64, n: u32) {
        let ctx = TickContext {
            chaos: control::monitor::Verdict::Unknown,
            blocked: None,
        };
        for k in 0..rows {
            let mut r = TickRecord::blank();
            r.now_ns = 1_000_000_000 + k * 1_000_000;
            r.t = k as f64 * 1e-3;
            let st = StateSample {
                seq: k,
                n,
                ..StateSample::default()
            };
            rec.tick(&r, &st, ctx).unwrap();
        }
    }

    #[test]
    fn at_the_size_limit_it_starts_a_new_whole_mcap_file_that_names_its_robot_again() {
        let dir = scratch("rotate");
        let sys = control::System::Planar(control::Config::preset("paper").unwrap());
        let limit = Limit {
            max_bytes: Some(200_000),
            keep: 1,
        };
        let mut rec = McapRecording::start(&dir, "r.mcap", &sys, 1000.0, limit).unwrap();
        ticks(&mut rec, 3000);
        let answer: serde_json::Value = serde_json::from_str(&rec.finish().unwrap()).unwrap();
        let rotations = answer["rotations"].as_u64().unwrap();
        assert!(rotations >= 2, "{answer}");
        // The newest segment and `keep` = 1 older one remain; each is a whole recording.
        let mut rows = 0;
        for k in 0..=rotations {
            let p = segment_path(&dir.join("r.mcap"), k);
            if k + 1 < rotations {
                assert!(!p.exists(), "{} kept", p.display());
                continue;
            }
            assert!(std::fs::metadata(&p).unwrap().len() <= 200_000);
            let f = crate::mcap_read::read(&p).unwrap();
            assert_eq!(f.messages(Topic::RobotDescription).len(), 1);
            assert!(f.metadata["config"].contains("[task]"));
            rows += f.messages(Topic::JointStates).len();
        }
        assert!(rows > 0 && rows < 3000, "{rows}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_urdf_larger_than_the_limit_heads_every_segment_without_leaving_one_message_a_file() {
        let dir = scratch("rotate-urdf");
        let sys = rt::robot::preset("panda").unwrap();
        let limit = Limit {
            max_bytes: Some(4096),
            keep: 1000,
        };
        let mut rec = McapRecording::start(&dir, "p.mcap", &sys, 1000.0, limit).unwrap();
        ticks_n(&mut rec, 400, 7);
        let answer: serde_json::Value = serde_json::from_str(&rec.finish().unwrap()).unwrap();
        let rotations = answer["rotations"].as_u64().unwrap();
        assert!(rotations >= 2, "{answer}");
        let mut rows = 0;
        for k in 0..=rotations {
            let f = crate::mcap_read::read(&segment_path(&dir.join("p.mcap"), k)).unwrap();
            assert_eq!(f.messages(Topic::RobotDescription).len(), 1, "segment {k}");
            let states = f.messages(Topic::JointStates).len();
            let topics: Vec<(&str, usize)> = Topic::ALL
                .iter()
                .map(|t| (t.name(), f.messages(*t).len()))
                .collect();
            assert!(states >= 1 || k == rotations, "segment {k}: {topics:?}");
            rows += states;
        }
        assert_eq!(rows, 400);
        // Each segment holds several ticks (about 4 KB of them), not one message.
        assert!(rotations < 400 / 3, "{rotations} segments for 400 ticks");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_export_gives_one_csv_row_per_tick_with_the_recorded_numbers() {
        let dir = scratch("export");
        let sys = control::System::Planar(control::Config::preset("paper").unwrap());
        let limit = Limit {
            max_bytes: None,
            keep: 0,
        };
        let mut rec = McapRecording::start(&dir, "e.mcap", &sys, 1000.0, limit).unwrap();
        ticks(&mut rec, 10);
        rec.event(Level::Info, "hello").unwrap();
        rec.finish().unwrap();
        let f = crate::mcap_read::read(&dir.join("e.mcap")).unwrap();
        let mut csv = Vec::new();
        assert_eq!(f.to_csv(&mut csv).unwrap(), 10);
        let text = String::from_utf8(csv).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], crate::recording::csv_header(3));
        assert!(lines[10].starts_with("0.009000,9,"), "{}", lines[10]);
        assert_eq!(f.messages(Topic::Events).len(), 1);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
