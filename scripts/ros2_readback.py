#!/usr/bin/env python3
"""Reads a ROS 2 bag written by `chaosctl export REC --ros2 BAG` with `rosbags` (the pure-Python
ROS bag library), as a ROS 2 user would, and checks it against the daemon's own numbers.

    ros2_readback.py BAG.mcap STOP.json

STOP.json is `chaosctl record stop`'s answer for the recording the bag was made from. rosbags
opens the bag only if its profile is `ros2`, and decodes every message with the message
definitions the bag carries (no typestore of its own), so a wrong definition or a misaligned
CDR field fails here. Checks: every message of every topic decodes; `/joint_states` holds one
message per recorded tick and its last one is the daemon's last joint state bit for bit; `/tf`
and the residual topics hold as many messages as the recording's channels they come from; the
poses are finite unit-quaternion poses; `/robot_description` holds the URDF. Exit 0 and one line
per check when all hold; 1 with the first failure otherwise. Run by tests/tests/mcap_live.rs
when CHAOSD_PYTHON names a Python with `rosbags` (.ci/run makes one).
"""

import json
import math
import sys
from pathlib import Path

from rosbags.highlevel import AnyReader


def fail(msg):
    print(f"ros2_readback: {msg}", file=sys.stderr)
    sys.exit(1)


def main():
    if len(sys.argv) != 3:
        fail("usage: ros2_readback.py BAG.mcap STOP.json")
    bag, stop_path = Path(sys.argv[1]), sys.argv[2]
    with open(stop_path) as f:
        stop = json.load(f)
    counts, last, urdf = {}, {}, None
    with AnyReader([bag]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for conn, _, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
            last[conn.topic] = msg
            if conn.topic in ("/chaosd/tip", "/chaosd/target"):
                p, o = msg.pose.position, msg.pose.orientation
                if not all(math.isfinite(v) for v in (p.x, p.y, p.z)):
                    fail(f"{conn.topic}: a pose that is not finite: {p}")
                norm = math.sqrt(o.x**2 + o.y**2 + o.z**2 + o.w**2)
                if abs(norm - 1.0) > 1e-9:
                    fail(f"{conn.topic}: a quaternion of norm {norm}")
            if conn.topic == "/robot_description":
                urdf = msg.data
    want_types = {
        "/joint_states": "sensor_msgs/msg/JointState",
        "/tf": "tf2_msgs/msg/TFMessage",
        "/chaosd/tip": "geometry_msgs/msg/PoseStamped",
        "/chaosd/target": "geometry_msgs/msg/PoseStamped",
        "/chaosd/period_residual": "std_msgs/msg/Float64",
        "/chaosd/tracking_error": "std_msgs/msg/Float64",
        "/robot_description": "std_msgs/msg/String",
    }
    for topic, t in want_types.items():
        if types.get(topic) != t:
            fail(f"{topic}: type {types.get(topic)}, not {t}")
    print(f"rosbags opened the bag (profile ros2): {len(types)} topics, every message decoded")
    recorded = stop["messages"]
    for topic, source in [
        ("/joint_states", "/joint_states"),
        ("/tf", "/tf"),
        ("/chaosd/tip", "/chaosd/tip"),
        ("/chaosd/period_residual", "/chaosd/residual"),
        ("/chaosd/tracking_error", "/chaosd/residual"),
    ]:
        if counts.get(topic) != recorded[source]:
            fail(f"{topic}: {counts.get(topic)} messages, the recording's {source} has {recorded[source]}")
    print(f"counts: {counts['/joint_states']} joint states, {counts['/tf']} transforms, as recorded")
    js, want = last["/joint_states"], stop["last_joint_state"]
    if list(js.position) != want["position"] or list(js.velocity) != want["velocity"]:
        fail(f"the last joint state {list(js.position)} is not the daemon's {want['position']}")
    print("the last joint state is the daemon's, bit for bit")
    if not urdf or "<robot" not in urdf:
        fail("no URDF on /robot_description")
    print(f"/robot_description: {len(urdf)} bytes of URDF")


if __name__ == "__main__":
    main()
