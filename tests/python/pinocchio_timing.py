"""Pinocchio's time for the terms `cargo bench -p fdi-common --bench urdf` measures of ours, on
the same arms at the same state, for docs/performance.md: M (crba), the Coriolis matrix
(computeCoriolisMatrix), G (computeGeneralizedGravity), V q̇ + G (rnea at q̈ = 0), M⁻¹
(computeMinverse) and q̈ (aba). Each time is the best of several rounds of many calls, per
call, in µs; it includes Python's cost of a call into Pinocchio (measured here as the time of
a call to a Pinocchio function that does almost nothing, and printed beside).

    python tests/python/pinocchio_timing.py

Needs `pin` (Pinocchio); reads the arms of common/testdata/urdf/arms.json.
"""

import json
import pathlib
import timeit

import numpy as np
import pinocchio as pin

from pinocchio_reference import DATA, ROOT, reduced_model, set_angle

ARMS = ["paper-two-link", "panda"]
ROUNDS, CALLS = 7, 20000


def best_us(fn):
    return min(timeit.repeat(fn, number=CALLS, repeat=ROUNDS)) / CALLS * 1e6


def main():
    arms = {a["name"]: a for a in json.loads((DATA / "arms.json").read_text())}
    print(f"Pinocchio {pin.__version__}, best of {ROUNDS} rounds of {CALLS} calls, µs per call")
    for name in ARMS:
        arm = arms[name]
        model = reduced_model(ROOT / arm["path"], arm)
        data = model.createData()
        n = model.nv
        q = pin.neutral(model)
        for i in range(n):
            set_angle(model, q, i + 1, 0.1 + 0.2 * i)
        qd = np.array([0.5 - 0.15 * i for i in range(n)])
        tau = np.ones(n)
        zero = np.zeros(n)
        terms = {
            "M (crba)": lambda: pin.crba(model, data, q),
            "V (computeCoriolisMatrix)": lambda: pin.computeCoriolisMatrix(model, data, q, qd),
            "G (computeGeneralizedGravity)": lambda: pin.computeGeneralizedGravity(model, data, q),
            "V q̇ + G (rnea, q̈ = 0)": lambda: pin.rnea(model, data, q, qd, zero),
            "M⁻¹ (computeMinverse)": lambda: pin.computeMinverse(model, data, q),
            "q̈ (aba)": lambda: pin.aba(model, data, q, qd, tau),
        }
        print(f"{name} ({n} joints)")
        total = 0.0
        for label, fn in terms.items():
            t = best_us(fn)
            if label.startswith(("M (", "V (", "G (", "M⁻¹")):
                total += t
            print(f"  {label:32s} {t:8.3f}")
        print(f"  {'M + V + G + M⁻¹':32s} {total:8.3f}")
        print(f"  {'a call (pin.neutral)':32s} {best_us(lambda: pin.neutral(model)):8.3f}")


if __name__ == "__main__":
    main()
