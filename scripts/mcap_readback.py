#!/usr/bin/env python3
"""Reads a chaosd MCAP recording with the Python `mcap` reader and `mcap-ros2-support`, as any
robotics user would, and checks it against the daemon's own numbers.

    mcap_readback.py RECORDING.mcap STOP.json

STOP.json is `chaosctl record stop`'s answer: the messages the daemon wrote per channel, the
first and last log times, and the last joint state as the daemon had it. Checks: every channel's
message count; log times inside [first, last] and never going back within a channel; the last
`/joint_states` message, decoded by mcap-ros2-support, equal to the daemon's last joint state bit
for bit; every JSON channel parses; the URDF is there. Exit 0 and one line per check when all
hold; 1 with the first failure otherwise. Run by tests/tests/mcap_live.rs when CHAOSD_PYTHON
names a Python with the two packages (.ci/run makes one).
"""

import json
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def fail(msg):
    print(f"mcap_readback: {msg}", file=sys.stderr)
    sys.exit(1)


def main():
    if len(sys.argv) != 3:
        fail("usage: mcap_readback.py RECORDING.mcap STOP.json")
    path, stop_path = sys.argv[1], sys.argv[2]
    with open(stop_path) as f:
        stop = json.load(f)
    counts, last_log, last_state, urdf = {}, {}, None, None
    first, last = stop["first_log_time_ns"], stop["last_log_time_ns"]
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        if "chaosd" not in meta or "config" not in meta["chaosd"]:
            fail("no chaosd metadata record with the config")
        for schema, channel, message in reader.iter_messages():
            topic = channel.topic
            counts[topic] = counts.get(topic, 0) + 1
            t = message.log_time
            if not first <= t <= last:
                fail(f"{topic}: log time {t} outside [{first}, {last}]")
            if t < last_log.get(topic, 0):
                fail(f"{topic}: log time goes back ({last_log[topic]} then {t})")
            last_log[topic] = t
            if channel.message_encoding == "json":
                json.loads(message.data)
        # Decode with mcap-ros2-support, the way Foxglove's users' scripts do.
        f.seek(0)
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, ros in reader.iter_decoded_messages(
            topics=["/joint_states", "/robot_description"]
        ):
            if channel.topic == "/joint_states":
                last_state = ros
            else:
                urdf = ros.data
    want = {k: v for k, v in stop["messages"].items() if v > 0}
    if counts != want:
        fail(f"message counts {counts} differ from the daemon's {want}")
    print(f"counts: {sum(counts.values())} messages on {len(counts)} channels, as the daemon wrote")
    print(f"log times: inside [{first}, {last}], in order on every channel")
    d = stop["last_joint_state"]
    if last_state is None:
        fail("no /joint_states message")
    got = (list(last_state.position), list(last_state.velocity))
    if got != (d["position"], d["velocity"]):
        fail(f"last joint state {got} differs from the daemon's {d}")
    names = list(last_state.name)
    print(f"last joint state: {names} equal to the daemon's, bit for bit")
    if not urdf or "<robot" not in urdf:
        fail("no URDF on /robot_description")
    print(f"robot description: {len(urdf)} bytes of URDF")


if __name__ == "__main__":
    main()
