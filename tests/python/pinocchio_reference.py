"""The reference values of the URDF arms' dynamics, made with Pinocchio (an independent
implementation): for every arm of common/testdata/urdf/arms.json, at seeded random states,
M(q) (crba), V(q, q̇) q̇ (rnea(q, q̇, 0) − G), G(q) (computeGeneralizedGravity) and
q̈ = aba(q, q̇, τ) for a random τ, friction left out (Pinocchio's algorithms have none).
The Rust tests (`fdi_common::model::urdf`, `pinocchio_reference`) read them and must agree
within 1e-9 relative; docs/model.md says how.

    python tests/python/pinocchio_reference.py            # writes common/testdata/urdf/*.ref.json
    python tests/python/pinocchio_reference.py --check    # exits 1 when a file differs

Needs `pin` (Pinocchio). The real arms' URDFs beside the data were copied from
`example-robot-data` (common/testdata/urdf/README.md).
"""

import argparse
import json
import pathlib
import sys

import numpy as np
import pinocchio as pin

ROOT = pathlib.Path(__file__).resolve().parents[2]
DATA = ROOT / "common" / "testdata" / "urdf"
STATES = 20


def reduced_model(path, arm):
    model = pin.buildModelFromUrdf(str(path))
    model.gravity.linear[:] = arm.get("gravity", [0.0, 0.0, -9.81])
    locks = arm.get("lock", {})
    if not locks:
        return model
    q_ref = pin.neutral(model)
    ids = []
    for name, value in locks.items():
        jid = model.getJointId(name)
        if jid >= model.njoints:
            sys.exit(f"{arm['name']}: no joint {name}")
        ids.append(jid)
        set_angle(model, q_ref, jid, value)
    return pin.buildReducedModel(model, ids, q_ref)


def set_angle(model, q, jid, value):
    """Joint `jid` at `value` (a continuous joint's q is its cosine and sine)."""
    j = model.joints[jid]
    if j.nq == 2:
        q[j.idx_q], q[j.idx_q + 1] = np.cos(value), np.sin(value)
    else:
        q[j.idx_q] = value


def reference(arm):
    path = ROOT / arm["path"]
    model = reduced_model(path, arm)
    data = model.createData()
    rng = np.random.default_rng(arm.get("seed", 1))
    names = [model.names[j] for j in range(1, model.njoints)]
    states = []
    for _ in range(STATES):
        angles = rng.uniform(-2.0, 2.0, model.nv)
        qd = rng.uniform(-2.0, 2.0, model.nv)
        tau = rng.uniform(-20.0, 20.0, model.nv)
        q = pin.neutral(model)
        for jid in range(1, model.njoints):
            set_angle(model, q, jid, angles[model.joints[jid].idx_v])
        m = pin.crba(model, data, q)
        m = np.triu(m) + np.triu(m, 1).T
        g = pin.computeGeneralizedGravity(model, data, q)
        vqd = pin.rnea(model, data, q, qd, np.zeros(model.nv)) - g
        qdd = pin.aba(model, data, q, qd, tau)
        states.append(
            {
                "q": angles.tolist(),
                "qd": qd.tolist(),
                "tau": tau.tolist(),
                "inertia": m.tolist(),
                "coriolis_qd": vqd.tolist(),
                "gravity": g.tolist(),
                "acceleration": qdd.tolist(),
            }
        )
    return {
        "arm": arm["name"],
        "pinocchio": pin.__version__,
        "joints": names,
        "states": states,
    }


def same(a, b, tol=1e-12):
    """The same values (Pinocchio's version aside), numbers within `tol` of the largest of the
    list they are in: another machine's Pinocchio may round the last bits otherwise."""
    if isinstance(a, dict):
        keys = a.keys() - {"pinocchio"}
        return isinstance(b, dict) and keys == b.keys() - {"pinocchio"} and all(same(a[k], b[k]) for k in keys)
    if isinstance(a, list):
        if not isinstance(b, list) or len(a) != len(b):
            return False
        if a and all(isinstance(x, float) for x in a + b):
            scale = max(1.0, max(abs(x) for x in b))
            return all(abs(x - y) <= tol * scale for x, y in zip(a, b))
        return all(same(x, y) for x, y in zip(a, b))
    return a == b


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--check", action="store_true", help="compare, write nothing")
    args = parser.parse_args()
    arms = json.loads((DATA / "arms.json").read_text())
    differ = []
    for arm in arms:
        text = json.dumps(reference(arm), indent=1) + "\n"
        out = DATA / f"{arm['name']}.ref.json"
        if args.check:
            if not out.is_file() or not same(json.loads(out.read_text()), json.loads(text)):
                differ.append(out)
            else:
                print(f"{out.relative_to(ROOT)}: {arm['name']}, {STATES} states, as Pinocchio {pin.__version__} makes them")
        else:
            out.write_text(text)
            print(f"{out.relative_to(ROOT)}: {arm['name']}, {STATES} states")
    for out in differ:
        print(f"{out.relative_to(ROOT)} is not what Pinocchio {pin.__version__} makes", file=sys.stderr)
    sys.exit(1 if differ else 0)


if __name__ == "__main__":
    main()
