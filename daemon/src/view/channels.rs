//! chaosd's channels and the one encoder that fills them from the reporter's tick records.
//!
//! A recording and a live viewer carry the same channels, so the encoding lives here once and
//! writes into a [`Sink`]. Per answered state: the joint state, the tick's timing, the
//! residual and the command (the full loop rate, what a person plots). At [`VIEW_HZ`]: the link
//! transforms, the tool point and its target (what a 3-D view needs; more would only grow the
//! file). On change and once a second: the scene (path, obstacles). On their events: the log.

use super::cdr;
use super::scene::{quaternion, Posed, Scene, WORLD};
use crate::telemetry::TickRecord;
use control::monitor::Verdict;
use protocol::{Mode, StateSample};
use serde_json::json;

/// How often the 3-D channels are written (Hz), at most the loop's rate.
pub const VIEW_HZ: f64 = 50.0;

/// A channel of chaosd's recordings and live view.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Topic {
    JointStates,
    RobotDescription,
    Transforms,
    Tip,
    Target,
    Scene,
    Timing,
    Residual,
    Command,
    Events,
    /// A replay recording's text, one message a tick (`crate::replay`), as `{"text": …}`: JSON
    /// with a schema, so that every channel of a replay recording decodes in Foxglove.
    Replay,
}

impl Topic {
    pub const ALL: [Topic; 11] = [
        Topic::JointStates,
        Topic::RobotDescription,
        Topic::Transforms,
        Topic::Tip,
        Topic::Target,
        Topic::Scene,
        Topic::Timing,
        Topic::Residual,
        Topic::Command,
        Topic::Events,
        Topic::Replay,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Topic::JointStates => "/joint_states",
            Topic::RobotDescription => "/robot_description",
            Topic::Transforms => "/tf",
            Topic::Tip => "/chaosd/tip",
            Topic::Target => "/chaosd/target",
            Topic::Scene => "/chaosd/scene",
            Topic::Timing => "/chaosd/timing",
            Topic::Residual => "/chaosd/residual",
            Topic::Command => "/chaosd/command",
            Topic::Events => "/chaosd/events",
            Topic::Replay => "/chaosd/replay",
        }
    }

    /// The message encoding (MCAP's well-known names).
    pub fn encoding(self) -> &'static str {
        match self {
            Topic::JointStates | Topic::RobotDescription => "cdr",
            _ => "json",
        }
    }

    /// The schema's name, encoding and text.
    pub fn schema(self) -> (&'static str, &'static str, String) {
        use super::schemas as s;
        match self {
            Topic::JointStates => (
                "sensor_msgs/msg/JointState",
                "ros2msg",
                s::JOINT_STATE.into(),
            ),
            Topic::RobotDescription => ("std_msgs/msg/String", "ros2msg", s::STRING.into()),
            Topic::Transforms => (
                "foxglove.FrameTransforms",
                "jsonschema",
                s::frame_transforms(),
            ),
            Topic::Tip | Topic::Target => {
                ("foxglove.PoseInFrame", "jsonschema", s::pose_in_frame())
            }
            Topic::Scene => ("foxglove.SceneUpdate", "jsonschema", s::scene_update()),
            Topic::Timing => ("chaosd.Timing", "jsonschema", s::timing()),
            Topic::Residual => ("chaosd.Residual", "jsonschema", s::residual()),
            Topic::Command => ("chaosd.Command", "jsonschema", s::command()),
            Topic::Events => ("foxglove.Log", "jsonschema", s::log()),
            Topic::Replay => ("chaosd.ReplayLine", "jsonschema", s::replay_line()),
        }
    }
}

/// Where encoded messages go: a file, a socket.
pub trait Sink {
    /// One message: its channel, the recording's row it belongs to, its time (ns since the
    /// Unix epoch) and its bytes.
    fn put(&mut self, topic: Topic, row: u64, unix_ns: u64, data: &[u8]) -> Result<(), String>;
}

/// Log levels of `foxglove.Log`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    Info = 2,
    Warning = 3,
    Error = 4,
}

/// What the reporter knows of a tick besides its record.
#[derive(Clone, Copy, Debug)]
pub struct TickContext<'a> {
    pub chaos: Verdict,
    /// Why the daemon is `Blocked`, while it is.
    pub blocked: Option<&'a str>,
}

/// Encodes ticks into messages. Remembers what it last said, to log changes once.
pub struct Encoder {
    scene: Scene,
    buf: Vec<u8>,
    json: Vec<u8>,
    view_every: u64,
    /// Rows (answered states) encoded so far.
    pub rows: u64,
    last_mode: Option<Mode>,
    last_blocked: Option<String>,
    last_chaos: Option<Verdict>,
    scene_at: Option<u64>,
}

fn stamp(unix_ns: u64) -> serde_json::Value {
    json!({"sec": unix_ns / 1_000_000_000, "nsec": unix_ns % 1_000_000_000})
}

fn vec3(p: &[f64; 3]) -> serde_json::Value {
    json!({"x": p[0], "y": p[1], "z": p[2]})
}

fn pose(pos: &[f64; 3], q: &[f64; 4]) -> serde_json::Value {
    json!({"position": vec3(pos), "orientation": {"x": q[0], "y": q[1], "z": q[2], "w": q[3]}})
}

const IDENTITY: [f64; 4] = [0.0, 0.0, 0.0, 1.0];

impl Encoder {
    /// An encoder for a loop running at `rate_hz`.
    pub fn new(scene: Scene, rate_hz: f64) -> Self {
        Self {
            scene,
            buf: Vec::with_capacity(1024),
            json: Vec::with_capacity(4096),
            view_every: (rate_hz / VIEW_HZ).round().max(1.0) as u64,
            rows: 0,
            last_mode: None,
            last_blocked: None,
            last_chaos: None,
            scene_at: None,
        }
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// A new configuration's scene, written with the next tick's.
    pub fn replace_scene(&mut self, scene: Scene) {
        self.scene = scene;
        self.scene_at = None;
    }

    /// A new configuration's scene, written at once.
    pub fn set_scene(
        &mut self,
        scene: Scene,
        unix_ns: u64,
        sink: &mut dyn Sink,
    ) -> Result<(), String> {
        self.scene = scene;
        self.write_scene(unix_ns, sink)
    }

    fn put_json(
        &mut self,
        topic: Topic,
        unix_ns: u64,
        v: &serde_json::Value,
        sink: &mut dyn Sink,
    ) -> Result<(), String> {
        self.json.clear();
        serde_json::to_writer(&mut self.json, v).map_err(|e| e.to_string())?;
        sink.put(topic, self.rows, unix_ns, &self.json)
    }

    /// What a reader needs before the first tick: the robot's description and the scene.
    pub fn start(&mut self, unix_ns: u64, sink: &mut dyn Sink) -> Result<(), String> {
        if let Some(urdf) = &self.scene.urdf {
            cdr::encode_string(&mut self.buf, urdf);
            sink.put(Topic::RobotDescription, self.rows, unix_ns, &self.buf)?;
        }
        self.write_scene(unix_ns, sink)
    }

    /// One log line on `/chaosd/events`.
    pub fn event(
        &mut self,
        unix_ns: u64,
        level: Level,
        text: &str,
        sink: &mut dyn Sink,
    ) -> Result<(), String> {
        let v = json!({"timestamp": stamp(unix_ns), "level": level as u8, "message": text, "name": "chaosd", "file": "", "line": 0});
        self.put_json(Topic::Events, unix_ns, &v, sink)
    }

    /// A tick whose law ran on state `st`: every per-tick channel, the 3-D ones at [`VIEW_HZ`],
    /// and an event for every change of mode, fault, `Blocked` or the monitor's verdict.
    pub fn tick(
        &mut self,
        r: &TickRecord,
        st: &StateSample,
        ctx: TickContext,
        unix_ns: u64,
        sink: &mut dyn Sink,
    ) -> Result<(), String> {
        self.events(r, ctx, unix_ns, sink)?;
        let n = (st.n as usize).min(self.scene.joints.len());
        let effort = match &r.command {
            Some(c) if c.interface == control::command::CommandMode::Torque.code() => &c.tau[..n],
            _ => &[][..],
        };
        cdr::encode_joint_state(
            &mut self.buf,
            unix_ns,
            &self.scene.base,
            &self.scene.joints[..n],
            &st.q[..n],
            &st.qd[..n],
            effort,
        );
        sink.put(Topic::JointStates, self.rows, unix_ns, &self.buf)?;
        let timing = json!({
            "t": r.t, "state_seq": st.seq, "state_stamp_ns": st.stamp_ns, "phi": st.phi,
            "lateness_ns": r.lateness_ns, "compute_ns": r.compute_ns, "state_age_ns": r.state_age_ns,
        });
        self.put_json(Topic::Timing, unix_ns, &timing, sink)?;
        let mut residual = json!({
            "t": r.t, "tracking_error": r.tracking_error, "period_residual": r.period_residual,
            "null_residual": r.null_residual, "mu": r.mu, "chaos": ctx.chaos.name(),
        });
        // With no obstacle the clearance is infinite, which JSON cannot say (serde writes null,
        // which the schema's "number" refuses): the field is left out then.
        if r.clearance.is_finite() {
            residual["clearance"] = json!(r.clearance);
        }
        self.put_json(Topic::Residual, unix_ns, &residual, sink)?;
        if let Some(c) = &r.command {
            use control::command::CommandMode as M;
            let mode = M::from_code(c.interface);
            let mut command = json!({
                "seq": c.seq, "mode": c.mode, "interface": mode.map_or("unknown", |m| m.name()),
                "qdd": &c.qdd[..n],
            });
            // The reference the interface sends, beside q̈ (the others are unused zeros).
            match mode {
                Some(M::Position) => command["q"] = json!(&c.q[..n]),
                Some(M::Velocity) => command["qd"] = json!(&c.qd[..n]),
                Some(M::Torque) => command["tau"] = json!(&c.tau[..n]),
                _ => {}
            }
            self.put_json(Topic::Command, unix_ns, &command, sink)?;
        }
        if self.rows.is_multiple_of(self.view_every) {
            let posed = self.scene.posed(st.phi, &st.q[..n]);
            self.view(&posed, r.t, unix_ns, sink)?;
        }
        let second = unix_ns / 1_000_000_000;
        if self.scene_at != Some(second) {
            self.write_scene(unix_ns, sink)?;
        }
        self.rows += 1;
        Ok(())
    }

    fn events(
        &mut self,
        r: &TickRecord,
        ctx: TickContext,
        unix_ns: u64,
        sink: &mut dyn Sink,
    ) -> Result<(), String> {
        if let Some(f) = &r.fault {
            let text = format!("FAULT at t = {:.3} s: {f}", r.t);
            self.event(unix_ns, Level::Error, &text, sink)?;
        }
        if self.last_mode != Some(r.mode) {
            if let Some(was) = self.last_mode {
                let text = format!("mode {was:?} → {:?} at t = {:.3} s", r.mode, r.t);
                self.event(unix_ns, Level::Info, &text, sink)?;
            }
            self.last_mode = Some(r.mode);
        }
        if self.last_blocked.as_deref() != ctx.blocked {
            let text = match ctx.blocked {
                Some(why) => format!("Blocked at t = {:.3} s: {why}", r.t),
                None => format!("no longer Blocked at t = {:.3} s", r.t),
            };
            self.event(unix_ns, Level::Warning, &text, sink)?;
            self.last_blocked = ctx.blocked.map(str::to_string);
        }
        if self.last_chaos != Some(ctx.chaos) {
            if self.last_chaos.is_some() {
                let text = format!("chaos monitor: {} at t = {:.3} s", ctx.chaos.name(), r.t);
                self.event(unix_ns, Level::Info, &text, sink)?;
            }
            self.last_chaos = Some(ctx.chaos);
        }
        Ok(())
    }

    fn view(
        &mut self,
        posed: &Posed,
        t: f64,
        unix_ns: u64,
        sink: &mut dyn Sink,
    ) -> Result<(), String> {
        let transforms: Vec<_> = self
            .scene
            .transforms(posed)
            .map(|(parent, child, p)| {
                json!({
                    "timestamp": stamp(unix_ns), "parent_frame_id": parent, "child_frame_id": child,
                    "translation": vec3(&[p.pos.x, p.pos.y, p.pos.z]), "rotation": {
                        "x": quaternion(&p.rot)[0], "y": quaternion(&p.rot)[1],
                        "z": quaternion(&p.rot)[2], "w": quaternion(&p.rot)[3]},
                })
            })
            .collect();
        self.put_json(
            Topic::Transforms,
            unix_ns,
            &json!({ "transforms": transforms }),
            sink,
        )?;
        let tip = json!({"timestamp": stamp(unix_ns), "frame_id": WORLD, "pose": pose(&posed.tip, &IDENTITY)});
        self.put_json(Topic::Tip, unix_ns, &tip, sink)?;
        let target = self.scene.target(t);
        let target = json!({"timestamp": stamp(unix_ns), "frame_id": WORLD, "pose": pose(&target, &IDENTITY)});
        self.put_json(Topic::Target, unix_ns, &target, sink)?;
        let joints = posed.points.iter();
        let joints = joints.map(|p| sphere(p, 0.06, [0.1, 0.1, 0.1, 1.0]));
        let arm_line = line(&posed.points, 0.03, [0.2, 0.5, 0.9, 1.0]);
        let arm = entity(unix_ns, "arm", vec![arm_line], joints.collect());
        let update = json!({"deletions": [], "entities": [arm]});
        self.put_json(Topic::Scene, unix_ns, &update, sink)
    }

    fn write_scene(&mut self, unix_ns: u64, sink: &mut dyn Sink) -> Result<(), String> {
        let s = &self.scene;
        let path = entity(
            unix_ns,
            "path",
            vec![line(&s.path, 0.01, [0.1, 0.7, 0.2, 1.0])],
            Vec::new(),
        );
        let obstacles = s.obstacles.iter();
        let obstacles = obstacles.map(|(c, r)| sphere(c, 2.0 * r, [0.9, 0.2, 0.1, 0.5]));
        let obstacles = entity(unix_ns, "obstacles", Vec::new(), obstacles.collect());
        let update = json!({"deletions": [], "entities": [path, obstacles]});
        self.scene_at = Some(unix_ns / 1_000_000_000);
        self.put_json(Topic::Scene, unix_ns, &update, sink)
    }
}

/// A `foxglove.SceneEntity` in `world` that stays until replaced, drawn with `lines` and
/// `spheres`. Every primitive list is there, empty or not: the official schema requires them all.
fn entity(
    unix_ns: u64,
    id: &str,
    lines: Vec<serde_json::Value>,
    spheres: Vec<serde_json::Value>,
) -> serde_json::Value {
    json!({
        "timestamp": stamp(unix_ns), "frame_id": WORLD, "id": id, "lifetime": stamp(0),
        "frame_locked": false, "metadata": [], "arrows": [], "cubes": [], "spheres": spheres,
        "cylinders": [], "lines": lines, "triangles": [], "texts": [], "models": [],
    })
}

fn line(points: &[[f64; 3]], thickness: f64, color: [f64; 4]) -> serde_json::Value {
    json!({
        "type": 0, "pose": pose(&[0.0; 3], &IDENTITY), "thickness": thickness,
        "scale_invariant": false, "points": points.iter().map(vec3).collect::<Vec<_>>(),
        "color": {"r": color[0], "g": color[1], "b": color[2], "a": color[3]},
        "colors": [], "indices": [],
    })
}

fn sphere(center: &[f64; 3], diameter: f64, color: [f64; 4]) -> serde_json::Value {
    json!({
        "pose": pose(center, &IDENTITY), "size": vec3(&[diameter; 3]),
        "color": {"r": color[0], "g": color[1], "b": color[2], "a": color[3]},
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Collects what an encoder writes.
    struct Collect(Vec<(Topic, Vec<u8>)>);

    impl Sink for Collect {
        fn put(&mut self, topic: Topic, _row: u64, _ns: u64, data: &[u8]) -> Result<(), String> {
            self.0.push((topic, data.to_vec()));
            Ok(())
        }
    }

    fn has_null(v: &serde_json::Value) -> bool {
        match v {
            serde_json::Value::Null => true,
            serde_json::Value::Array(a) => a.iter().any(has_null),
            serde_json::Value::Object(o) => o.values().any(has_null),
            _ => false,
        }
    }

    #[test]
    fn no_json_message_carries_a_null_not_even_without_obstacles() {
        let sys = rt::robot::preset("paper").unwrap();
        let mut enc = Encoder::new(Scene::of(&sys), 1000.0);
        let mut out = Collect(Vec::new());
        enc.start(1_000_000_000, &mut out).unwrap();
        // An answered state (its age known), and no obstacle: the clearance is infinite.
        let r = TickRecord {
            state_age_ns: Some(1000),
            ran_law: true,
            ..TickRecord::blank()
        };
        assert_eq!(r.clearance, f64::INFINITY);
        let st = StateSample {
            n: 3,
            ..StateSample::default()
        };
        let ctx = TickContext {
            chaos: Verdict::Unknown,
            blocked: None,
        };
        enc.tick(&r, &st, ctx, 1_000_000_000, &mut out).unwrap();
        let json = out.0.iter().filter(|(t, _)| t.encoding() == "json");
        let mut topics = Vec::new();
        for (t, data) in json {
            let v: serde_json::Value = serde_json::from_slice(data).unwrap();
            assert!(!has_null(&v), "{}: {v}", t.name());
            topics.push(*t);
        }
        assert!(topics.contains(&Topic::Residual) && topics.contains(&Topic::Scene));
    }
}
