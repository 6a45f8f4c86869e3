#!/usr/bin/env python3
"""Plot a chaosd recording's period residual and tracking error over time.

    pip install mcap matplotlib
    python3 plot_residual.py out/demo/run.mcap residual.png

Reads the `/chaosd/residual` channel (JSON, one message per answered state) with the `mcap`
reader and marks every event of `/chaosd/events` (an operator's change, a mode change, the chaos
monitor's verdict) as a vertical line: switch the delayed feedback on during a recording and the
residual falls right after its line.
"""

import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from mcap.reader import make_reader  # noqa: E402


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: plot_residual.py RECORDING.mcap OUT.png")
    t, residual, tracking, events = [], [], [], []
    with open(sys.argv[1], "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(
            topics=["/chaosd/residual", "/chaosd/events"]
        ):
            v = json.loads(message.data)
            if channel.topic == "/chaosd/events":
                events.append((message.log_time, v["message"]))
                continue
            t.append(message.log_time)
            residual.append(v["period_residual"])  # null (NaN) before one delay has passed
            tracking.append(v["tracking_error"])
    if not t:
        sys.exit(f"{sys.argv[1]}: no /chaosd/residual messages")
    t0 = t[0]
    seconds = [(x - t0) * 1e-9 for x in t]
    fig, (a, b) = plt.subplots(2, 1, sharex=True, figsize=(9, 5))
    a.semilogy(seconds, [r if r is not None else float("nan") for r in residual], lw=0.7)
    a.set_ylabel("period residual (rad/s)")
    b.semilogy(seconds, [e if e is not None else float("nan") for e in tracking], lw=0.7)
    b.set_ylabel("tracking error (m)")
    b.set_xlabel("time since the recording started (s)")
    for when, text in events:
        for ax in (a, b):
            ax.axvline((when - t0) * 1e-9, color="grey", lw=0.5)
        a.annotate(text, ((when - t0) * 1e-9, 1), xycoords=("data", "axes fraction"),
                   rotation=90, va="top", fontsize=6)
    fig.tight_layout()
    fig.savefig(sys.argv[2], dpi=120)
    print(f"{len(t)} samples, {len(events)} events → {sys.argv[2]}")


if __name__ == "__main__":
    main()
