#!/usr/bin/env python3
"""Golden forward-dynamics trajectories of the Panda, computed with pinocchio.

Why: pinocchio_fixtures.py checks chaosd's ABA at single states; this checks the Rust rigid-body
plant end to end: starting from (q0, q̇0) under a constant joint torque, the integrated state must
follow the true trajectory. The reference is q̈ = pin.aba(q, q̇, τ) integrated with classical RK4 on
(q, q̇) (all Panda joints are revolute, so q integrates as a plain vector) at h = 1e-5 s for 1 s, far
below the Rust integrator's step, so its error is negligible (roundoff level) against any practical
integrator. Kinetic energy = ½ q̇ᵀ M(q) q̇ with M from pin.crba (upper triangle symmetrised).

The model is exactly pinocchio_fixtures.py's "panda" (robots/panda.urdf, panda_link0 -> panda_link8,
same reduced model, gravity along the base frame's -z; its Chain class is reused). Per case the
gravity is set to oMb.R · g_base (oMb = identity for the Panda); "gravity" in the JSON is the value.

Cases (q0 = the ready pose plus an offset so nothing is symmetric):
  free_swing       g = (0, 0, -9.81), τ = 0, q̇0 = 0;
  constant_torque  g = (0, 0, -9.81), τ = g(q0) + [2, -3, 1.5, 2, 0.5, -0.4, 0.3], q̇0 ≠ 0;
  no_gravity       g = 0, τ = 0, q̇0 ≠ 0 (kinetic energy is conserved).
Samples every 0.1 s, t = 0.1 … 1.0.

Self-checks (fails loudly): no_gravity's kinetic energy and free_swing's total energy (kinetic +
pin.computePotentialEnergy) are conserved to 1e-9 relative. It also prints, for information, the
max |Δq| at t = 1 s of each case integrated with RK4 at h = 2.5e-4 (4 substeps at 1 kHz) against
the h = 1e-5 reference.

Deterministic; takes about 10 s. Usage (repo root or anywhere):
    /path/to/venv/bin/python scripts/golden/dynamics_trajectories.py
See scripts/golden/README.md (same venv as pinocchio_fixtures.py).
"""

import json
import sys

import numpy as np
import pinocchio as pin

from pinocchio_fixtures import JSON_DIR, REPO, Chain, check, floats, urdf_chain

SOURCE, BASE, TIP = "robots/panda.urdf", "panda_link0", "panda_link8"
H = 1e-5
T_END = 1.0
SAMPLE_EVERY = 0.1
H_COARSE = 2.5e-4  # 4 substeps at 1 kHz

READY = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
Q0 = READY + np.array([0.1, -0.2, 0.15, 0.1, -0.1, 0.2, -0.3])
G = np.array([0.0, 0.0, -9.81])
NO_G = np.zeros(3)
ZERO = np.zeros(7)

# name, gravity (base frame), q̇0, τ (None: g(q0) + TAU_EXTRA).
TAU_EXTRA = np.array([2.0, -3.0, 1.5, 2.0, 0.5, -0.4, 0.3])
CASES = [
    ("free_swing", G, ZERO, ZERO),
    ("constant_torque", G, np.array([0.3, -0.2, 0.4, 0.1, -0.5, 0.6, -0.7]), None),
    ("no_gravity", NO_G, np.array([0.8, -0.6, 0.9, 0.7, -1.0, 1.2, -1.5]), ZERO),
]


def set_gravity(arm, g):
    arm.model.gravity.linear = arm.oMb.rotation @ g
    return floats(arm.model.gravity.linear)


def kinetic_energy(arm, q, qd):
    return float(0.5 * qd @ arm.mass_matrix(q) @ qd)


def potential_energy(arm, q):
    return float(pin.computePotentialEnergy(arm.model, arm.data, q))


def rk4(arm, q0, qd0, tau, h, t_end, every):
    """RK4 on (q, q̇); returns [(t, q, q̇)] every `every` s up to t_end (step counts, no drift)."""
    f = lambda q, qd: arm.aba(q, qd, tau)
    per_sample = round(every / h)
    samples = round(t_end / every)
    if abs(per_sample * h - every) > 1e-12 or abs(samples * every - t_end) > 1e-12:
        sys.exit("h must divide the sample interval, and the interval t_end")
    q, qd = q0.copy(), qd0.copy()
    out = []
    for k in range(1, samples + 1):
        for _ in range(per_sample):
            a1 = f(q, qd)
            v2 = qd + 0.5 * h * a1
            a2 = f(q + 0.5 * h * qd, v2)
            v3 = qd + 0.5 * h * a2
            a3 = f(q + 0.5 * h * v2, v3)
            v4 = qd + h * a3
            a4 = f(q + h * v3, v4)
            q = q + (h / 6.0) * (qd + 2.0 * v2 + 2.0 * v3 + v4)
            qd = qd + (h / 6.0) * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        out.append((round(k * every, 12), q, qd))
    return out


def relative_spread(values):
    values = np.array(values)
    return float((values.max() - values.min()) / abs(values[0]))


def write(path, header, cases):
    """Header on one line, each case's inputs on one line, one sample per line."""
    head = ", ".join(f"{json.dumps(k)}: {json.dumps(v)}" for k, v in header.items())
    parts = []
    for c in cases:
        inputs = ", ".join(f"{json.dumps(k)}: {json.dumps(v)}" for k, v in c.items() if k != "samples")
        samples = ",\n  ".join(json.dumps(s) for s in c["samples"])
        parts.append("{" + inputs + ', "samples": [\n  ' + samples + "\n]}")
    text = "{" + head + ', "cases": [\n' + ",\n".join(parts) + "\n]}\n"
    json.loads(text)  # valid JSON
    path.write_text(text)


def main():
    chain = urdf_chain(REPO / SOURCE, BASE, TIP)
    arm = Chain(str(REPO / SOURCE), BASE, TIP, chain)
    check(arm.n == 7 and not any(arm.continuous), "panda: expected 7 revolute joints")
    cases = []
    for name, g, qd0, tau in CASES:
        gravity = set_gravity(arm, g)
        if tau is None:
            tau = arm.gravity(Q0) + TAU_EXTRA
        traj = rk4(arm, Q0, qd0, tau, H, T_END, SAMPLE_EVERY)
        samples = [
            {"t": t, "q": floats(q), "qd": floats(qd), "kinetic_energy": kinetic_energy(arm, q, qd)}
            for t, q, qd in traj
        ]
        ke = [kinetic_energy(arm, Q0, qd0)] + [s["kinetic_energy"] for s in samples]
        if name == "no_gravity":
            spread = relative_spread(ke)
            check(spread < 1e-9, f"{name}: kinetic energy drifts by {spread:.2e} relative")
            print(f"{name}: kinetic energy {ke[0]:.12f} J, relative spread {spread:.2e}")
        if name == "free_swing":
            total = [k + potential_energy(arm, q) for k, (_, q, _) in zip(ke, [(0, Q0, 0)] + traj)]
            spread = float((max(total) - min(total)) / abs(total[0]))
            check(spread < 1e-9, f"{name}: total energy drifts by {spread:.2e} relative")
            print(f"{name}: total energy {total[0]:.12f} J, relative spread {spread:.2e}")
        coarse = rk4(arm, Q0, qd0, tau, H_COARSE, T_END, T_END)[-1]
        dq = float(np.max(np.abs(coarse[1] - traj[-1][1])))
        dqd = float(np.max(np.abs(coarse[2] - traj[-1][2])))
        print(f"{name}: RK4 h = {H_COARSE} vs h = {H} at t = {T_END} s: "
              f"max |dq| {dq:.3e} rad, max |dqd| {dqd:.3e} rad/s")
        cases.append({"name": name, "gravity": gravity, "q0": floats(Q0), "qd0": floats(qd0),
                      "tau": floats(tau), "samples": samples})
    header = {
        "source": SOURCE,
        "base": BASE,
        "tip": TIP,
        "generator": f"pinocchio {pin.__version__}, RK4, h = {H}",
        "h": H,
    }
    path = JSON_DIR / "panda_trajectories.json"
    write(path, header, cases)
    print(f"wrote {path.relative_to(REPO)}")


if __name__ == "__main__":
    main()
