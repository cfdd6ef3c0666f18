"""Searches for a stealthy attack with the cross-entropy method, numpy only.

The attack: robot ROBOT's measured position, each link biased by a ramp from START_S that
holds once it reaches its cap (two numbers per link: the cap in rad, the time to reach it).
The score of an attack is the tracking RMSE of that robot from START_S on (rad; the whole
run's RMSE is mostly the start's transient), minus the share of its attacked ticks on which a
detector (the paper's ‖Ŝ‖ alarm, χ², CUSUM, on the ψ2 residual)
was alarming: any alarm loses to every silent attack. Each candidate is an attack profile
run by the engine (``fdi_mas.run``), so the best one, written as a profile, replays through
the command line bit for bit:

    python examples/python/cem_attack.py --out found.toml
    fdi-launch run --residual psi2 --attack found.toml

(docs/python.md shows what it finds.) ``--iterations 2 --population 6`` is a short form.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import tempfile
from concurrent.futures import ThreadPoolExecutor

import numpy as np

import fdi_mas

ROBOT = 2
START_S = 5.0
DETECTORS = ("s_hat_norm", "chi2", "cusum")
#: Search box of each link's parameters: cap (rad), log10 of the time to reach it (s).
LOW = np.array([-0.2, 0.0])
HIGH = np.array([0.2, 1.5])


def profile(theta: np.ndarray, name: str) -> str:
    """The attack profile (TOML) of the parameters ``theta`` = per link [cap, log10 rise]."""
    lines = [
        f'name = "{name}"',
        'description = "Found by examples/python/cem_attack.py: a ramp on each link of robot '
        f'{ROBOT}\'s position from {START_S} s, held at its cap."',
    ]
    for link, (cap, log_rise) in enumerate(theta.reshape(-1, 2), start=1):
        rise = 10.0 ** float(log_rise)
        slope = float(cap) / rise
        lines += [
            "",
            "[[channels]]",
            f"agent = {ROBOT}",
            'signal = "position"',
            f"links = [{link}]",
            'units = "rad"',
            "segments = [",
            f'  {{ from_s = {START_S!r}, waveform = {{ kind = "ramp", slope_per_s = {slope!r}, start = 0.0 }} }},',
            f'  {{ from_s = {START_S + rise!r}, waveform = {{ kind = "constant", value = {float(cap)!r} }} }},',
            "]",
        ]
    return "\n".join(lines) + "\n"


def window_rmse(run: fdi_mas.Run) -> float:
    """The robot's tracking RMSE from START_S on, rad (every link)."""
    assert run.ticks is not None
    t = run.ticks
    mine = (t["agent"] == ROBOT) & (t["t_s"] >= START_S)
    links = sum(1 for name in t if name.endswith("_des_rad"))
    err = np.concatenate([t[f"q{i}_des_rad"][mine] - t[f"q{i}_rad"][mine] for i in range(1, links + 1)])
    return float(np.sqrt(np.mean(err**2)))


def score(run: fdi_mas.Run) -> tuple[float, float, float]:
    """(score, RMSE of the robot from START_S on in rad, summed alarm coverage of the
    detectors)."""
    m = run.summary["metrics"][str(ROBOT)]
    coverage = sum((m["detectors"][d]["coverage"] or 0.0) for d in DETECTORS)
    rmse = window_rmse(run)
    return rmse - coverage, rmse, coverage


def evaluate(base: fdi_mas.Scenario, path: pathlib.Path) -> fdi_mas.Run:
    """The run of the base scenario under the profile at ``path``."""
    return fdi_mas.run(base.replace(attack=str(path)))


def search(base: fdi_mas.Scenario, iterations: int, population: int, seed: int, work: pathlib.Path):
    """The cross-entropy method: the best parameters seen, their profile and summary."""
    rng = np.random.default_rng(seed)
    links = base.links
    low, high = np.tile(LOW, links), np.tile(HIGH, links)
    mean, std = (low + high) / 2, (high - low) / 4
    elite = max(2, population // 4)
    best: tuple[float, np.ndarray, dict] | None = None
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        for it in range(iterations):
            thetas = np.clip(rng.normal(mean, std, size=(population, mean.size)), low, high)
            paths = []
            for i, theta in enumerate(thetas):
                p = work / f"candidate-{it}-{i}.toml"
                p.write_text(profile(theta, "cem-candidate"))
                paths.append(p)
            summaries = list(pool.map(lambda p: evaluate(base, p), paths))
            scores = np.array([score(s)[0] for s in summaries])
            order = np.argsort(-scores)
            if best is None or scores[order[0]] > best[0]:
                best = (float(scores[order[0]]), thetas[order[0]], summaries[order[0]])
            top = thetas[order[:elite]]
            mean = 0.3 * mean + 0.7 * top.mean(axis=0)
            std = 0.3 * std + 0.7 * top.std(axis=0) + 1e-3 * (high - low)
            _, rmse, cov = score(summaries[order[0]])
            print(f"iteration {it + 1}/{iterations}: best of the population RMSE {rmse:.4f} rad, "
                  f"detector coverage {cov:.3f}; best so far {best[0]:.4f}", flush=True)
    assert best is not None
    return best


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--iterations", type=int, default=12)
    p.add_argument("--population", type=int, default=24)
    p.add_argument("--duration-s", type=float, default=20.0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--controller", default="proposed", help="proposed (default) or traditional")
    p.add_argument("--out", type=pathlib.Path, default=pathlib.Path("cem-attack.toml"))
    a = p.parse_args()
    base = fdi_mas.Scenario.paper(
        duration_s=a.duration_s, residual="psi2", attack="none", controller=a.controller
    )
    with tempfile.TemporaryDirectory() as work:
        best_score, theta, _ = search(base, a.iterations, a.population, a.seed, pathlib.Path(work))
    a.out.write_text(profile(theta, a.out.stem))
    found = fdi_mas.run(base.replace(attack=str(a.out)))
    paper = fdi_mas.run(base.replace(attack="paper"))
    _, rmse, cov = score(found)
    print(f"wrote {a.out}: robot {ROBOT} RMSE from {START_S} s {rmse:.5f} rad, detector coverage {cov:.3f}")
    print(
        f"| attack | robot {ROBOT}: RMSE from {START_S:g} s (rad) | RMSE of the run (rad) | "
        + " | ".join(f"{d}: alarmed share of attacked ticks" for d in DETECTORS)
        + " |"
    )
    print("|---|---|---|" + "---|" * len(DETECTORS))
    for label, r in (("found", found), ("none", fdi_mas.run(base)), ("paper", paper)):
        m = r.summary["metrics"][str(ROBOT)]
        cells = [
            "-" if m["detectors"][d]["coverage"] is None else f"{m['detectors'][d]['coverage']:.3f}" for d in DETECTORS
        ]
        print(f"| {label} | {window_rmse(r):.5f} | {m['rmse_rad']:.5f} | " + " | ".join(cells) + " |")
    result = {"profile": str(a.out), "duration_s": a.duration_s, "residual": "psi2",
              "controller": a.controller, "digest": found.digest,
              "rmse_rad": found.summary["rmse_rad"][str(ROBOT)], "window_rmse_rad": rmse, "coverage": cov}
    a.out.with_suffix(".json").write_text(json.dumps(result, indent=2) + "\n")
    print(f"digest {found.digest}")


if __name__ == "__main__":
    main()
