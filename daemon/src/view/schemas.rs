//! The schemas a reader needs to decode chaosd's channels, written into every recording.
//!
//! Joint states and the robot description are ROS 2 messages (`ros2msg`, CDR), the format
//! rosbag2, Foxglove and Python's `mcap-ros2-support` decode with no help. Everything else is
//! JSON: Foxglove's own schemas where one fits (transforms, poses, scene, log), so its 3-D, plot
//! and log panels know them by name, and chaosd's where none does (timing, residual, command).
//! A JSON Schema here is what a tool reads to list fields; it is kept short but true.

/// `sensor_msgs/msg/JointState` with its dependencies, as rosbag2 stores it.
pub const JOINT_STATE: &str = "std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
";

/// `std_msgs/msg/String`.
pub const STRING: &str = "string data\n";

const TIME: &str =
    r#"{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}}"#;
const VEC3: &str = r#"{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}}"#;
const QUAT: &str = r#"{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}"#;

/// A JSON Schema object with the given `(name, schema)` properties.
fn object(title: &str, props: &[(&str, String)]) -> String {
    let body: Vec<String> = props.iter().map(|(k, v)| format!("\"{k}\":{v}")).collect();
    format!(
        r#"{{"title":"{title}","type":"object","properties":{{{}}}}}"#,
        body.join(",")
    )
}

fn number() -> String {
    r#"{"type":"number"}"#.into()
}

fn integer() -> String {
    r#"{"type":"integer"}"#.into()
}

fn string() -> String {
    r#"{"type":"string"}"#.into()
}

fn array(of: String) -> String {
    format!(r#"{{"type":"array","items":{of}}}"#)
}

fn pose() -> String {
    object(
        "foxglove.Pose",
        &[("position", VEC3.into()), ("orientation", QUAT.into())],
    )
}

/// `foxglove.FrameTransforms`.
pub fn frame_transforms() -> String {
    let one = object(
        "foxglove.FrameTransform",
        &[
            ("timestamp", TIME.into()),
            ("parent_frame_id", string()),
            ("child_frame_id", string()),
            ("translation", VEC3.into()),
            ("rotation", QUAT.into()),
        ],
    );
    object("foxglove.FrameTransforms", &[("transforms", array(one))])
}

/// `foxglove.PoseInFrame`.
pub fn pose_in_frame() -> String {
    object(
        "foxglove.PoseInFrame",
        &[
            ("timestamp", TIME.into()),
            ("frame_id", string()),
            ("pose", pose()),
        ],
    )
}

/// `foxglove.SceneUpdate` (the parts chaosd fills: spheres and line strips).
pub fn scene_update() -> String {
    let color = object(
        "foxglove.Color",
        &[
            ("r", number()),
            ("g", number()),
            ("b", number()),
            ("a", number()),
        ],
    );
    let sphere = object(
        "foxglove.SpherePrimitive",
        &[
            ("pose", pose()),
            ("size", VEC3.into()),
            ("color", color.clone()),
        ],
    );
    let line = object(
        "foxglove.LinePrimitive",
        &[
            ("type", integer()),
            ("pose", pose()),
            ("thickness", number()),
            ("scale_invariant", r#"{"type":"boolean"}"#.into()),
            ("points", array(VEC3.into())),
            ("color", color),
        ],
    );
    let entity = object(
        "foxglove.SceneEntity",
        &[
            ("timestamp", TIME.into()),
            ("frame_id", string()),
            ("id", string()),
            ("lifetime", TIME.into()),
            ("frame_locked", r#"{"type":"boolean"}"#.into()),
            ("spheres", array(sphere)),
            ("lines", array(line)),
        ],
    );
    // Every object lists its properties: Foxglove's JSON Schema reader fails on one that does
    // not, and drops the channel.
    let deletion = object(
        "foxglove.SceneEntityDeletion",
        &[
            ("timestamp", TIME.into()),
            ("type", integer()),
            ("id", string()),
        ],
    );
    object(
        "foxglove.SceneUpdate",
        &[("deletions", array(deletion)), ("entities", array(entity))],
    )
}

/// `foxglove.Log`.
/// `/chaosd/replay`: one tick of the replay format's text (docs/live-control.md).
pub fn replay_line() -> String {
    object("chaosd.ReplayLine", &[("text", string())])
}

pub fn log() -> String {
    object(
        "foxglove.Log",
        &[
            ("timestamp", TIME.into()),
            ("level", integer()),
            ("message", string()),
            ("name", string()),
            ("file", string()),
            ("line", integer()),
        ],
    )
}

/// `chaosd.Timing`: one tick's clock.
pub fn timing() -> String {
    object(
        "chaosd.Timing",
        &[
            ("t", number()),
            ("state_seq", integer()),
            ("state_stamp_ns", integer()),
            ("phi", number()),
            ("lateness_ns", integer()),
            ("compute_ns", integer()),
            ("state_age_ns", integer()),
        ],
    )
}

/// `chaosd.Residual`: how the law is doing.
pub fn residual() -> String {
    object(
        "chaosd.Residual",
        &[
            ("t", number()),
            ("tracking_error", number()),
            ("period_residual", number()),
            ("null_residual", number()),
            ("clearance", number()),
            ("mu", number()),
            ("chaos", string()),
        ],
    )
}

/// `chaosd.Command`: what the daemon sent: q̈, and the reference its interface sends (`q` for
/// position, `qd` for velocity, `tau` for torque).
pub fn command() -> String {
    object(
        "chaosd.Command",
        &[
            ("seq", integer()),
            ("mode", integer()),
            ("interface", string()),
            ("qdd", array(number())),
            ("q", array(number())),
            ("qd", array(number())),
            ("tau", array(number())),
        ],
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn every_json_schema_parses() {
        for s in [
            super::frame_transforms(),
            super::pose_in_frame(),
            super::scene_update(),
            super::log(),
            super::timing(),
            super::residual(),
            super::command(),
        ] {
            let v: serde_json::Value = serde_json::from_str(&s).unwrap();
            assert_eq!(v["type"], "object", "{s}");
            every_object_lists_its_properties(&v, &s);
        }
    }

    /// Foxglove's JSON Schema reader fails on an object schema without `properties` (and drops
    /// the channel); scripts/foxglove-check restates its other rules.
    fn every_object_lists_its_properties(v: &serde_json::Value, whole: &str) {
        if v["type"] == "object" {
            assert!(v["properties"].is_object(), "{v} in {whole}");
        }
        for (_, p) in v["properties"].as_object().into_iter().flatten() {
            every_object_lists_its_properties(p, whole);
        }
        if v["type"] == "array" {
            every_object_lists_its_properties(&v["items"], whole);
        }
    }
}
