"""The package's speed, measured (docs/python.md reports it): ``python -m fdi_mas.bench``.

One env-step is one control tick of every robot of one environment (``decision_period=1``).
Three rates on the paper's scenario, in one process, one build:

* the in-process engine alone (``fdi_mas.run``, no ticks kept), on one core;
* one :class:`~fdi_mas.envs.AttackerEnv` stepped from Python (an action of zeros made once);
* the :class:`~fdi_mas.envs.VectorAttackerEnv` of ``--envs`` environments, on every core.

Each round measures the engine before and after the two environments and compares them with
the mean of the two: the ratios are the median of the rounds' ratios.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

import fdi_mas
from fdi_mas.envs import AttackerEnv, VectorAttackerEnv


def engine_rate(scenario: fdi_mas.Scenario) -> float:
    """Ticks per second of the engine (its own wall time)."""
    r = fdi_mas.run(scenario, ticks=False)
    return r.summary["ticks"] / r.summary["wall_s"]


def env_rate(scenario: fdi_mas.Scenario) -> float:
    """Steps per second of one environment stepped from Python over one episode."""
    env = AttackerEnv(scenario)
    zero = np.zeros(env.action_space.shape)
    env.reset(seed=0)
    steps = 0
    start = time.perf_counter()
    while True:
        _, _, terminated, truncated, _ = env.step(zero)
        steps += 1
        if terminated or truncated:
            break
    return steps / (time.perf_counter() - start)


def vector_rate(scenario: fdi_mas.Scenario, envs: int, steps: int) -> float:
    """Env-steps per second of the vector environment (``envs`` × its steps per second)."""
    vec = VectorAttackerEnv(envs, scenario)
    zero = np.zeros(vec.action_space.shape)
    vec.reset(seed=0)
    start = time.perf_counter()
    for _ in range(steps):
        vec.step(zero)
    elapsed = time.perf_counter() - start
    vec.close()
    return envs * steps / elapsed


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--duration-s", type=float, default=20.0, help="episode length (default 20 s)")
    p.add_argument("--envs", type=int, default=64, help="environments of the vector one (default 64)")
    p.add_argument(
        "--repeat", type=int, default=5, help="rounds, each measuring the three in turn (default 5)"
    )
    a = p.parse_args()
    scenario = fdi_mas.Scenario.paper(duration_s=a.duration_s, residual="psi2")
    rates: dict[str, list[float]] = {"engine": [], "single": [], "vector": []}
    ratios: dict[str, list[float]] = {"engine": [], "single": [], "vector": []}
    for _ in range(a.repeat):
        # The engine before and after the others: a machine whose speed drifts (a shared host)
        # is compared with itself, round by round.
        before = engine_rate(scenario)
        single = env_rate(scenario)
        vector = vector_rate(scenario, a.envs, min(scenario.ticks, 2000))
        after = engine_rate(scenario)
        engine = (before + after) / 2
        for key, rate in (("engine", engine), ("single", single), ("vector", vector)):
            rates[key].append(rate)
            ratios[key].append(rate / engine)
    print(
        f"paper scenario (psi2 residual), {a.duration_s:g} s episodes, {a.repeat} rounds "
        f"(median, min-max), {os.cpu_count()} cores"
    )
    print("| what | env-steps/s | vs the engine on one core, round by round |")
    print("|---|---|---|")
    for key, label in (
        ("engine", "in-process engine (`fdi_mas.run`), one core"),
        ("single", "one `AttackerEnv` stepped from Python"),
        ("vector", f"`VectorAttackerEnv`, {a.envs} envs, every core"),
    ):
        r, q = rates[key], ratios[key]
        print(
            f"| {label} | {statistics.median(r):,.0f} ({min(r):,.0f}-{max(r):,.0f}) "
            f"| {statistics.median(q):.2f} ({min(q):.2f}-{max(q):.2f}) |"
        )

if __name__ == "__main__":
    main()
