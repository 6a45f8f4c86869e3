#!/usr/bin/env python3
"""Golden fixtures for chaosd's URDF robot model, computed with pinocchio.

Why: chaosd loads a serial chain (base link -> tip link) from a URDF and implements its own
kinematics, Jacobian, J̇q̇, RNEA, CRBA and ABA (SCIENCE.md §8). Those are easy to get subtly wrong
(frame conventions, off-chain loads, continuous joints, rpy on origins), so the Rust tests compare
them with an independent, widely used implementation: pinocchio. This script writes the reference
values once; the Rust tests read them without needing Python.

The definition (chaosd implements the same, so keep the two in step):
  * full model = pin.buildModelFromUrdf(urdf) (fixed base, no root joint);
  * chain = the movable joints on the URDF path from the base link down to the tip link;
  * every other movable joint is locked at pin.neutral (angle/offset 0): its bodies become a rigid
    load of the link they hang from (pin.buildReducedModel); fixed joints merge bodies anyway;
  * oMb = the base link's placement (constant: the joints above the base must be fixed); gravity is
    9.81 m/s² along the base frame's -z, i.e. model.gravity = oMb.R (0, 0, -9.81);
  * all outputs are expressed in the base frame: tip_pose = oMb⁻¹ oMtip (the tip link's BODY frame),
    the Jacobian of the tip origin with rows (v, ω) in base axes, J̇q̇ = the tip origin's classical
    acceleration at q̈ = 0 in base axes;
  * mass_matrix = crba (symmetrised), rnea(q, q̇, q̈), gravity = computeGeneralizedGravity(q),
    aba(q, q̇, τ);
  * JSON stores joint angles; pinocchio's continuous joints take (cos θ, sin θ).

States: numpy default_rng(2026 + i) for the i-th robot of ROBOTS; case 0 is all zeros (even where
q = 0 is outside the limits); then q ~ U[lower, upper] (continuous joints: [-π, π]), q̇ ~ U[-2, 2],
q̈ ~ U[-5, 5], τ ~ U[-0.5, 0.5]·effort (no or zero effort: U[-10, 10]).

Self-checks (the script fails loudly): aba(rnea(q̈)) = q̈ to 1e-9; M symmetric positive definite
and equal to RNEA's columns; the Jacobian and J̇q̇ against central finite differences; the chain
is 1 to 12 revolute/continuous/prismatic joints; robots/panda.urdf's flange equals Franka's
modified-DH product to 1e-12.

Deterministic and idempotent: rerunning rewrites identical files. Usage (repo root or anywhere):
    /path/to/venv/bin/python scripts/golden/pinocchio_fixtures.py
See scripts/golden/README.md.
"""

import importlib.metadata
import json
import math
import shutil
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin

REPO = Path(__file__).resolve().parents[2]
FIXTURES = REPO / "control" / "tests" / "fixtures"
JSON_DIR = FIXTURES / "pinocchio"
URDF_DIR = FIXTURES / "urdf"

ERD_VERSION = "6.0.0"
G = 9.81
CASES = 12
SEED = 2026

# name, source, base link, tip link. "erd:<path>" is a file of example-robot-data, copied unmodified
# to control/tests/fixtures/urdf/<name>.urdf and read from there.
ROBOTS = [
    ("panda", "robots/panda.urdf", "panda_link0", "panda_link8"),
    ("planar3", "robots/planar3.urdf", "base", "tip"),
    ("erd_panda", "erd:panda_description/urdf/panda.urdf", "panda_link0", "panda_hand"),
    ("ur5", "erd:ur_description/urdf/ur5_robot.urdf", "base_link", "tool0"),
    ("ur3_gripper", "erd:ur_description/urdf/ur3_gripper.urdf", "base_link", "tool0"),
    ("xarm7", "erd:xarm_description/urdf/xarm7.urdf", "link_base", "link_eef"),
    ("kinova", "erd:kinova_description/robots/kinova.urdf", "j2s6s200_link_base",
     "j2s6s200_end_effector"),
    ("z1", "erd:z1_description/urdf/z1.urdf", "link00", "gripperStator"),
    # Ours: prismatic joints, axes off x/y/z, a tilted base, a load on an off-chain joint.
    ("quirks", "control/tests/fixtures/urdf/quirks.urdf", "base", "tcp"),
    # Longer than an arm: a torso joint and a 7-joint arm (8), two torso joints (9), and ours at
    # chaosd's capacity (12).
    ("tiago_no_hand", "erd:tiago_description/robots/tiago_no_hand.urdf", "base_link", "arm_7_link"),
    ("talos_reduced", "erd:talos_data/robots/talos_reduced.urdf", "base_link", "arm_left_7_link"),
    ("snake12", "control/tests/fixtures/urdf/snake12.urdf", "base", "tip"),
]

MOVABLE = ("revolute", "continuous", "prismatic")


def erd_robots_dir():
    """The robots/ folder of the installed example-robot-data wheel (cmeel layout)."""
    version = importlib.metadata.version("example-robot-data")
    if version != ERD_VERSION:
        sys.exit(f"example-robot-data {version} installed; the fixtures are from {ERD_VERSION}")
    dist = importlib.metadata.distribution("example-robot-data")
    path = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))
    if not path.is_dir():
        sys.exit(f"example-robot-data's robots not found at {path}")
    return path


def resolve_source(name, source):
    """The URDF to read, relative to the repo root; copies an ERD file into the fixtures first."""
    if not source.startswith("erd:"):
        return source
    URDF_DIR.mkdir(parents=True, exist_ok=True)
    dst = URDF_DIR / f"{name}.urdf"
    shutil.copyfile(erd_robots_dir() / source[4:], dst)
    return str(dst.relative_to(REPO))


# ---------------------------------------------------------------------------------------------
# The chain, from the URDF's own tree (not pinocchio's), so it is defined the way chaosd reads it.


def urdf_chain(path, base, tip):
    """Movable joints from base down to tip: [(name, type, lower, upper, effort)], in order."""
    root = ET.parse(path).getroot()
    links = {link.get("name") for link in root.findall("link")}
    for link in (base, tip):
        if link not in links:
            sys.exit(f"{path}: no link {link}")
    parent_joint = {j.find("child").get("link"): j for j in root.findall("joint")}

    def path_up(link, stop):
        joints = []
        while link != stop and link in parent_joint:
            j = parent_joint[link]
            joints.append(j)
            link = j.find("parent").get("link")
        return joints, link

    down, reached = path_up(tip, base)
    if reached != base:
        sys.exit(f"{path}: {base} is not an ancestor of {tip}")
    above, _ = path_up(base, None)
    if any(j.get("type") != "fixed" for j in above):
        sys.exit(f"{path}: a movable joint above {base}: the base would not be fixed")
    chain = []
    for j in reversed(down):
        kind = j.get("type")
        if kind == "fixed":
            continue
        if kind not in MOVABLE:
            sys.exit(f"{path}: joint {j.get('name')} is {kind}: not a serial-arm joint")
        lim = j.find("limit")
        attr = (lambda k: float(lim.get(k, "0"))) if lim is not None else (lambda k: 0.0)
        if kind == "continuous":
            lower, upper = -math.pi, math.pi
        else:
            lower, upper = attr("lower"), attr("upper")
        chain.append((j.get("name"), kind, lower, upper, attr("effort")))
    if not 1 <= len(chain) <= 12:
        sys.exit(f"{path}: {len(chain)} joints from {base} to {tip}; chaosd takes 1 to 12")
    return chain


# ---------------------------------------------------------------------------------------------
# The reduced pinocchio model and the quantities.


class Chain:
    """A pinocchio model reduced to the chain, with gravity along the base frame's -z."""

    def __init__(self, urdf, base, tip, chain):
        full = pin.buildModelFromUrdf(urdf)
        names = [c[0] for c in chain]
        lock = [i for i in range(1, full.njoints) if full.names[i] not in names]
        self.model = pin.buildReducedModel(full, lock, pin.neutral(full))
        m = self.model
        if list(m.names)[1:] != names:
            sys.exit(f"{urdf}: reduced model's joints {list(m.names)[1:]} are not the chain {names}")
        self.continuous = [c[1] == "continuous" for c in chain]
        for i, cont in enumerate(self.continuous):
            if m.joints[i + 1].nq != (2 if cont else 1) or m.joints[i + 1].nv != 1:
                sys.exit(f"{urdf}: joint {names[i]} has nq {m.joints[i + 1].nq}")
        self.data = m.createData()
        self.base_id = m.getFrameId(base, pin.BODY)
        self.tip_id = m.getFrameId(tip, pin.BODY)
        if self.base_id >= len(m.frames) or self.tip_id >= len(m.frames):
            sys.exit(f"{urdf}: base or tip frame missing in the reduced model")
        pin.framesForwardKinematics(m, self.data, pin.neutral(m))
        self.oMb = self.data.oMf[self.base_id].copy()
        if m.frames[self.base_id].parentJoint != 0:
            sys.exit(f"{urdf}: {base} moves")
        m.gravity.linear = self.oMb.rotation @ np.array([0.0, 0.0, -G])
        self.n = m.nv

    def config(self, q):
        """pinocchio's q from joint angles/offsets: (cos, sin) for continuous joints."""
        out = []
        for qi, cont in zip(q, self.continuous):
            out.extend([math.cos(qi), math.sin(qi)] if cont else [qi])
        return np.array(out)

    def tip_pose(self, qp):
        pin.framesForwardKinematics(self.model, self.data, qp)
        return (self.oMb.inverse() * self.data.oMf[self.tip_id]).homogeneous

    def link_poses(self, qp):
        """Each chain joint's child link frame (pinocchio's joint frame), base frame, n × 4×4."""
        pin.forwardKinematics(self.model, self.data, qp)
        return np.array([(self.oMb.inverse() * self.data.oMi[i]).homogeneous
                         for i in range(1, self.n + 1)])

    def jacobian(self, qp):
        pin.computeJointJacobians(self.model, self.data, qp)
        pin.updateFramePlacements(self.model, self.data)
        j = pin.getFrameJacobian(self.model, self.data, self.tip_id, pin.LOCAL_WORLD_ALIGNED)
        r = self.oMb.rotation.T
        return np.vstack([r @ j[:3], r @ j[3:]])

    def jdot_qd(self, qp, qd):
        pin.forwardKinematics(self.model, self.data, qp, qd, np.zeros(self.n))
        a = pin.getFrameClassicalAcceleration(
            self.model, self.data, self.tip_id, pin.LOCAL_WORLD_ALIGNED
        )
        r = self.oMb.rotation.T
        return np.concatenate([r @ a.linear, r @ a.angular])

    def mass_matrix(self, qp):
        m = pin.crba(self.model, self.data, qp).copy()
        return np.triu(m) + np.triu(m, 1).T

    def rnea(self, qp, qd, qdd):
        return pin.rnea(self.model, self.data, qp, qd, qdd).copy()

    def gravity(self, qp):
        return pin.computeGeneralizedGravity(self.model, self.data, qp).copy()

    def aba(self, qp, qd, tau):
        return pin.aba(self.model, self.data, qp, qd, tau).copy()

    def chain_mass(self):
        """Mass carried by the chain's joints (links and rigid loads; not the fixed base)."""
        return sum(self.model.inertias[i].mass for i in range(1, self.model.njoints))


# ---------------------------------------------------------------------------------------------
# Checks.


def check(ok, what):
    if not ok:
        sys.exit(f"self-check failed: {what}")


def check_case(name, arm, q, qd, qdd, out):
    """Internal consistency of one case (out: the case's lists, as written)."""
    qp = arm.config(q)
    jac = np.array(out["jacobian"]).reshape(6, arm.n)
    back = arm.aba(qp, qd, arm.rnea(qp, qd, qdd))
    check(np.max(np.abs(back - qdd)) < 1e-9, f"{name}: aba(rnea(qdd)) != qdd")
    m = np.array(out["mass_matrix"]).reshape(arm.n, arm.n)
    check(np.array_equal(m, m.T), f"{name}: M not symmetric")
    check(np.all(np.linalg.eigvalsh(m) > 0), f"{name}: M not positive definite")
    # CRBA against RNEA: column i of M = rnea(q, 0, e_i) - g(q).
    g = arm.gravity(qp)
    cols = [arm.rnea(qp, np.zeros(arm.n), e) - g for e in np.eye(arm.n)]
    check(np.max(np.abs(np.array(cols).T - m)) < 1e-9, f"{name}: crba != rnea columns")
    # Jacobian and J̇q̇ against central differences along q(t) = q + t q̇.
    h = 1e-6

    def step(t):
        return arm.config([a + t * b for a, b in zip(q, qd)])

    p = lambda t: arm.tip_pose(step(t))[:3, 3]
    v_fd = (p(h) - p(-h)) / (2 * h)
    check(np.max(np.abs(v_fd - jac[:3] @ qd)) < 1e-7, f"{name}: J v vs differences")
    jq = lambda t: arm.jacobian(step(t)) @ qd
    a_fd = (jq(h) - jq(-h)) / (2 * h)
    check(np.max(np.abs(a_fd - np.array(out["jdot_qd"]))) < 1e-5, f"{name}: J̇q̇ vs differences")


def dh_flange(q):
    """Franka's modified-DH product (SCIENCE.md §8) times the 0.107 m flange offset."""
    a = [0, 0, 0, 0.0825, -0.0825, 0, 0.088]
    d = [0.333, 0, 0.316, 0, 0.384, 0, 0]
    alpha = [0, -math.pi / 2, math.pi / 2, math.pi / 2, -math.pi / 2, math.pi / 2, math.pi / 2]
    t = np.eye(4)
    for i in range(7):
        ca, sa, ct, st = math.cos(alpha[i]), math.sin(alpha[i]), math.cos(q[i]), math.sin(q[i])
        t = t @ np.array(
            [
                [ct, -st, 0, a[i]],
                [st * ca, ct * ca, -sa, -d[i] * sa],
                [st * sa, ct * sa, ca, d[i] * ca],
                [0, 0, 0, 1],
            ]
        )
    flange = np.eye(4)
    flange[2, 3] = 0.107
    return t @ flange


def check_panda_dh(arm, rng):
    for _ in range(20):
        q = rng.uniform(-math.pi, math.pi, 7)
        err = np.max(np.abs(arm.tip_pose(arm.config(q)) - dh_flange(q)))
        check(err < 1e-12, f"panda: flange differs from the DH table by {err:.1e}")


# ---------------------------------------------------------------------------------------------
# States, cases, files.


def states(chain, rng):
    """CASES states (q, q̇, q̈, τ); the first is all zeros."""
    n = len(chain)
    # Infinite limits become ±π (continuous joints already have [-π, π]).
    lower = np.array([c[2] if math.isfinite(c[2]) else -math.pi for c in chain])
    upper = np.array([c[3] if math.isfinite(c[3]) else math.pi for c in chain])
    # τ ~ U[-0.5, 0.5]·effort; no effort: U[-0.5, 0.5]·20 = U[-10, 10].
    effort = np.array([c[4] if c[4] > 0 else 20.0 for c in chain])
    out = [(np.zeros(n),) * 4]
    for _ in range(CASES - 1):
        q = rng.uniform(lower, upper)
        qd = rng.uniform(-2.0, 2.0, n)
        qdd = rng.uniform(-5.0, 5.0, n)
        tau = rng.uniform(-0.5, 0.5, n) * effort
        out.append((q, qd, qdd, tau))
    return out


def floats(a):
    return [float(x) for x in np.asarray(a).ravel()]


def case(arm, q, qd, qdd, tau):
    qp = arm.config(q)
    return {
        "q": floats(q),
        "qd": floats(qd),
        "qdd": floats(qdd),
        "tau": floats(tau),
        "tip_pose": floats(arm.tip_pose(qp)),
        "link_poses": floats(arm.link_poses(qp)),
        "jacobian": floats(arm.jacobian(qp)),
        "jdot_qd": floats(arm.jdot_qd(qp, qd)),
        "mass_matrix": floats(arm.mass_matrix(qp)),
        "rnea": floats(arm.rnea(qp, qd, qdd)),
        "gravity": floats(arm.gravity(qp)),
        "aba": floats(arm.aba(qp, qd, tau)),
    }


def write_json(path, header, cases):
    """json.dump's floats (shortest round-trip repr), one case per line for readable diffs."""
    head = ", ".join(f"{json.dumps(k)}: {json.dumps(v)}" for k, v in header.items())
    body = ",\n".join(json.dumps(c) for c in cases)
    text = "{" + head + ', "cases": [\n' + body + "\n]}\n"
    json.loads(text)  # valid JSON
    path.write_text(text)


def build(index, name, source, base, tip):
    urdf = resolve_source(name, source)
    chain = urdf_chain(REPO / urdf, base, tip)
    arm = Chain(str(REPO / urdf), base, tip, chain)
    rng = np.random.default_rng(SEED + index)
    cases = []
    for q, qd, qdd, tau in states(chain, rng):
        out = case(arm, q, qd, qdd, tau)
        check_case(name, arm, q, qd, qdd, out)
        cases.append(out)
    if name == "panda":
        check_panda_dh(arm, np.random.default_rng(SEED - 1))
    header = {
        "robot": name,
        "source": urdf,
        "base": base,
        "tip": tip,
        "n": arm.n,
        "joints": [c[0] for c in chain],
        "gravity": [0.0, 0.0, -G],
        "pinocchio": pin.__version__,
    }
    JSON_DIR.mkdir(parents=True, exist_ok=True)
    write_json(JSON_DIR / f"{name}.json", header, cases)
    kinds = ", ".join(f"{c[0]} ({c[1]})" for c in chain)
    print(f"{name}: n = {arm.n}, chain mass {arm.chain_mass():.6f} kg, {base} -> {tip}: {kinds}")


def main():
    for index, (name, source, base, tip) in enumerate(ROBOTS):
        build(index, name, source, base, tip)


if __name__ == "__main__":
    main()
