//! A recording rewritten as a ROS 2 bag (`chaosctl export REC --ros2 OUT`): an MCAP file with
//! the `ros2` profile, every channel a ROS 2 message in CDR with its `ros2msg` schema.
//!
//! A live recording mixes CDR channels (joint states, the description) with JSON ones (poses,
//! transforms, timing, the log) so that Foxglove shows everything by name; that mix is not a
//! ROS 2 bag, and ROS 2 tools (rosbag2, Python's `rosbags`) refuse it ("profile is not ros2").
//! The export keeps what has a standard message and says what it leaves out:
//!
//! | recording | bag | message |
//! |---|---|---|
//! | `/joint_states` | `/joint_states` | `sensor_msgs/msg/JointState` (the bytes as they are) |
//! | `/robot_description` | `/robot_description` | `std_msgs/msg/String` (as they are) |
//! | `/tf` | `/tf` | `tf2_msgs/msg/TFMessage` |
//! | `/chaosd/tip`, `/chaosd/target` | the same | `geometry_msgs/msg/PoseStamped` |
//! | `/chaosd/residual` | `/chaosd/period_residual`, `/chaosd/tracking_error`, `/chaosd/mu` | `std_msgs/msg/Float64` |
//! | `/chaosd/events` | `/rosout` | `rcl_interfaces/msg/Log` |
//!
//! Left out: the scene (it would need `visualization_msgs`), the per-tick timing and the command
//! (chaosd's own fields, no standard message) and the replay text; `chaosctl export --csv` and
//! the recording itself keep them.

use crate::mcap_read::{McapFile, Message};
use crate::view::cdr::Cdr;
use crate::view::Topic;
use serde_json::Value;
use std::collections::BTreeMap;
use std::io::{Seek, Write};

const SEP: &str =
    "================================================================================\n";
const TIME: &str = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
const HEADER: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
const QUATERNION: &str =
    "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n";

/// A channel of the bag.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Out {
    JointStates,
    Description,
    Tf,
    Tip,
    Target,
    PeriodResidual,
    TrackingError,
    Mu,
    Rosout,
}

impl Out {
    fn topic(self) -> &'static str {
        match self {
            Out::JointStates => "/joint_states",
            Out::Description => "/robot_description",
            Out::Tf => "/tf",
            Out::Tip => "/chaosd/tip",
            Out::Target => "/chaosd/target",
            Out::PeriodResidual => "/chaosd/period_residual",
            Out::TrackingError => "/chaosd/tracking_error",
            Out::Mu => "/chaosd/mu",
            Out::Rosout => "/rosout",
        }
    }

    /// The message type and its `ros2msg` definition with its dependencies, as rosbag2 stores it.
    fn schema(self) -> (&'static str, String) {
        match self {
            Out::JointStates => (
                "sensor_msgs/msg/JointState",
                crate::view::schemas::JOINT_STATE.into(),
            ),
            Out::Description => ("std_msgs/msg/String", crate::view::schemas::STRING.into()),
            Out::Tf => (
                "tf2_msgs/msg/TFMessage",
                [
                    "geometry_msgs/TransformStamped[] transforms\n",
                    SEP,
                    "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
                    SEP,
                    HEADER,
                    SEP,
                    TIME,
                    SEP,
                    "MSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
                    SEP,
                    "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n",
                    SEP,
                    QUATERNION,
                ]
                .concat(),
            ),
            Out::Tip | Out::Target => (
                "geometry_msgs/msg/PoseStamped",
                [
                    "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
                    SEP,
                    HEADER,
                    SEP,
                    TIME,
                    SEP,
                    "MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
                    SEP,
                    "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n",
                    SEP,
                    QUATERNION,
                ]
                .concat(),
            ),
            Out::PeriodResidual | Out::TrackingError | Out::Mu => {
                ("std_msgs/msg/Float64", "float64 data\n".into())
            }
            Out::Rosout => (
                "rcl_interfaces/msg/Log",
                [
                    "byte DEBUG=10\nbyte INFO=20\nbyte WARN=30\nbyte ERROR=40\nbyte FATAL=50\n\
                     builtin_interfaces/Time stamp\nuint8 level\nstring name\nstring msg\n\
                     string file\nstring function\nuint32 line\n",
                    SEP,
                    TIME,
                ]
                .concat(),
            ),
        }
    }
}

/// One message of the bag.
struct Converted {
    out: Out,
    log_time: u64,
    sequence: u32,
    data: Vec<u8>,
}

/// Messages written per bag topic.
pub type Counts = BTreeMap<&'static str, u64>;

/// Writes `file` as a ROS 2 bag into `w` (see the module doc); returns the messages per topic.
pub fn write<W: Write + Seek>(file: &McapFile, w: W) -> Result<Counts, String> {
    let mut all = convert(file)?;
    // Readers replay in log time; the recording writes channels interleaved, so sort once.
    all.sort_by_key(|m| (m.log_time, m.out));
    let mut writer = mcap::WriteOptions::new()
        .profile("ros2")
        .compression(Some(mcap::Compression::Lz4))
        .library(format!("chaosd {}", env!("CARGO_PKG_VERSION")))
        .create(w)
        .map_err(|e| e.to_string())?;
    let mut channels: BTreeMap<Out, u16> = BTreeMap::new();
    let mut counts = Counts::new();
    for m in &all {
        let id = match channels.get(&m.out) {
            Some(&id) => id,
            None => {
                let (name, text) = m.out.schema();
                let schema = writer
                    .add_schema(name, "ros2msg", text.as_bytes())
                    .map_err(|e| e.to_string())?;
                let id = writer
                    .add_channel(schema, m.out.topic(), "cdr", &BTreeMap::new())
                    .map_err(|e| e.to_string())?;
                channels.insert(m.out, id);
                id
            }
        };
        let header = mcap::records::MessageHeader {
            channel_id: id,
            sequence: m.sequence,
            log_time: m.log_time,
            publish_time: m.log_time,
        };
        writer
            .write_to_known_channel(&header, &m.data)
            .map_err(|e| e.to_string())?;
        *counts.entry(m.out.topic()).or_default() += 1;
    }
    writer.finish().map_err(|e| e.to_string())?;
    writer.into_inner().flush().map_err(|e| e.to_string())?;
    Ok(counts)
}

fn convert(file: &McapFile) -> Result<Vec<Converted>, String> {
    let mut all = Vec::new();
    let mut push = |out: Out, m: &Message, data: Vec<u8>| {
        all.push(Converted {
            out,
            log_time: m.log_time,
            sequence: m.row,
            data,
        })
    };
    for m in file.messages(Topic::JointStates) {
        push(Out::JointStates, m, m.data.clone());
    }
    for m in file.messages(Topic::RobotDescription) {
        push(Out::Description, m, m.data.clone());
    }
    for (topic, out, f) in [
        (Topic::Transforms, Out::Tf, tf as Encode),
        (Topic::Tip, Out::Tip, pose_stamped),
        (Topic::Target, Out::Target, pose_stamped),
        (Topic::Events, Out::Rosout, log),
    ] {
        for m in file.messages(topic) {
            let v = json(topic, m)?;
            let data = f(&v).map_err(|e| format!("{}, row {}: {e}", topic.name(), m.row))?;
            push(out, m, data);
        }
    }
    for m in file.messages(Topic::Residual) {
        let v = json(Topic::Residual, m)?;
        for (out, key) in [
            (Out::PeriodResidual, "period_residual"),
            (Out::TrackingError, "tracking_error"),
            (Out::Mu, "mu"),
        ] {
            // A field a run did not have (NaN is written as null) is left out, not invented.
            if let Some(x) = v[key].as_f64() {
                let mut buf = Vec::with_capacity(16);
                Cdr::new(&mut buf).f64(x);
                push(out, m, buf);
            }
        }
    }
    Ok(all)
}

type Encode = fn(&Value) -> Result<Vec<u8>, String>;

fn json(topic: Topic, m: &Message) -> Result<Value, String> {
    serde_json::from_slice(&m.data).map_err(|e| format!("{}, row {}: {e}", topic.name(), m.row))
}

fn num(v: &Value, key: &str) -> Result<f64, String> {
    v[key]
        .as_f64()
        .ok_or_else(|| format!("no number {key:?} in {v}"))
}

fn text<'a>(v: &'a Value, key: &str) -> Result<&'a str, String> {
    v[key]
        .as_str()
        .ok_or_else(|| format!("no string {key:?} in {v}"))
}

/// `std_msgs/Header` from a JSON `timestamp` ({sec, nsec}) and a frame.
fn header(w: &mut Cdr<'_>, stamp: &Value, frame: &str) -> Result<(), String> {
    let sec = stamp["sec"].as_u64().ok_or("no timestamp.sec")?;
    let nsec = stamp["nsec"].as_u64().ok_or("no timestamp.nsec")?;
    w.time(sec.saturating_mul(1_000_000_000).saturating_add(nsec));
    w.string(frame);
    Ok(())
}

fn xyz(w: &mut Cdr<'_>, v: &Value) -> Result<(), String> {
    for k in ["x", "y", "z"] {
        w.f64(num(v, k)?);
    }
    Ok(())
}

fn xyzw(w: &mut Cdr<'_>, v: &Value) -> Result<(), String> {
    for k in ["x", "y", "z", "w"] {
        w.f64(num(v, k)?);
    }
    Ok(())
}

/// `tf2_msgs/msg/TFMessage` from `foxglove.FrameTransforms`.
fn tf(v: &Value) -> Result<Vec<u8>, String> {
    let list = v["transforms"].as_array().ok_or("no \"transforms\" list")?;
    let mut buf = Vec::with_capacity(64 + 128 * list.len());
    let mut w = Cdr::new(&mut buf);
    w.u32(list.len() as u32);
    for t in list {
        header(&mut w, &t["timestamp"], text(t, "parent_frame_id")?)?;
        w.string(text(t, "child_frame_id")?);
        xyz(&mut w, &t["translation"])?;
        xyzw(&mut w, &t["rotation"])?;
    }
    Ok(buf)
}

/// `geometry_msgs/msg/PoseStamped` from `foxglove.PoseInFrame`.
fn pose_stamped(v: &Value) -> Result<Vec<u8>, String> {
    let mut buf = Vec::with_capacity(96);
    let mut w = Cdr::new(&mut buf);
    header(&mut w, &v["timestamp"], text(v, "frame_id")?)?;
    xyz(&mut w, &v["pose"]["position"])?;
    xyzw(&mut w, &v["pose"]["orientation"])?;
    Ok(buf)
}

/// `rcl_interfaces/msg/Log` from `foxglove.Log` (levels 1-5 → 10-50).
fn log(v: &Value) -> Result<Vec<u8>, String> {
    let level = v["level"].as_u64().ok_or("no level")?.clamp(1, 5) as u8 * 10;
    let mut buf = Vec::with_capacity(128);
    let mut w = Cdr::new(&mut buf);
    let stamp = &v["timestamp"];
    let sec = stamp["sec"].as_u64().ok_or("no timestamp.sec")?;
    let nsec = stamp["nsec"].as_u64().ok_or("no timestamp.nsec")?;
    w.time(sec.saturating_mul(1_000_000_000).saturating_add(nsec));
    w.u8(level);
    w.string(text(v, "name")?);
    w.string(text(v, "message")?);
    w.string(v["file"].as_str().unwrap_or(""));
    w.string("");
    w.u32(v["line"].as_u64().unwrap_or(0) as u32);
    Ok(buf)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn a_pose_is_a_header_then_seven_aligned_doubles() {
        let v = json!({"timestamp": {"sec": 2, "nsec": 5}, "frame_id": "world",
            "pose": {"position": {"x": 1.0, "y": 2.0, "z": 3.0},
                     "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}});
        let b = pose_stamped(&v).unwrap();
        // 4 header + 8 stamp + 4 + "world\0" (6) = 22, padded to 24 from the header's end, + 56.
        assert_eq!(b.len(), 4 + 24 + 56);
        assert_eq!(&b[4..8], &2i32.to_le_bytes());
        assert_eq!(&b[28..36], &1.0f64.to_le_bytes());
        assert_eq!(&b[76..84], &1.0f64.to_le_bytes());
        let e = pose_stamped(&json!({"timestamp": {"sec": 1, "nsec": 0}})).unwrap_err();
        assert!(e.contains("frame_id"), "{e}");
    }

    #[test]
    fn foxglove_levels_become_ros_levels() {
        let v = json!({"timestamp": {"sec": 1, "nsec": 0}, "level": 3, "message": "Blocked",
            "name": "chaosd", "file": "", "line": 0});
        let b = log(&v).unwrap();
        assert_eq!(b[12], 30);
    }
}
