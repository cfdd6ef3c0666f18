"""Trains a detector on ``fdi_mas/Detector-v0`` with the cross-entropy method, numpy only.

The detector alarms on robot i when a linear score of what the control center has of robot i
crosses 0: ``alarm_i = w · [log10 ‖Ŝ_i‖, log10 ‖r_i‖, log10 ‖ṙ_i‖, 1] > 0`` (the NN's attack
estimate and the observer's residuals; one ``w`` for every robot). A candidate ``w`` is scored
by its mean return over the same episodes, one per attack of ATTACKS (the reward of
docs/python.md, "Rewards": per robot-tick, +1 for an alarm on an attacked tick, −1 for one on a
clean tick or for silence on an attacked one). It prints one line per iteration: the
population's mean return, its best, and the mean's own return, which starts at a detector
that never alarms and climbs.

    python examples/python/train_detector.py                 # 10 iterations × 16, 62 s on one core
    python examples/python/train_detector.py --iterations 2  # a short form
"""

from __future__ import annotations

import argparse

import numpy as np

import fdi_mas
from fdi_mas.envs import DetectorEnv

#: The attacks of the training episodes: no attack, and shipped profiles acting early.
ATTACKS = ("none", "paper", "stealthy-bias", "sign-flip")


def features(obs: np.ndarray, names: list[str], robots: list[int], links: int) -> np.ndarray:
    """Per robot (rows): log10 of ‖Ŝ‖, ‖r‖, ‖ṙ‖ (floored at 1e-9), and a constant 1."""
    rows = []
    for r in robots:
        at = names.index(f"robot{r}.s_hat1")
        parts = obs[at : at + 3 * links].reshape(3, links)
        norms = np.log10(np.maximum(np.linalg.norm(parts, axis=1), 1e-9))
        rows.append(np.concatenate([norms, [1.0]]))
    return np.array(rows)


def episode(env: DetectorEnv, w: np.ndarray, attack: str) -> float:
    """One episode's return under ``w`` with ``attack`` under it."""
    obs, _ = env.reset(options={"attack": attack})
    total = 0.0
    while True:
        f = features(obs, env.observation_names, env.agents, env.links)
        alarm = (f @ w > 0).astype(np.int8)
        obs, reward, terminated, truncated, _ = env.step(alarm)
        total += reward
        if terminated or truncated:
            return total


def score(env: DetectorEnv, w: np.ndarray) -> float:
    """Mean return over one episode per attack of ATTACKS."""
    return float(np.mean([episode(env, w, a) for a in ATTACKS]))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--iterations", type=int, default=10)
    p.add_argument("--population", type=int, default=16)
    p.add_argument("--elite", type=int, default=3)
    p.add_argument("--duration-s", type=float, default=10.0)
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args()
    if not 1 <= args.elite <= args.population:
        p.error("--elite: between 1 and --population")

    scenario = fdi_mas.Scenario.paper(duration_s=args.duration_s, residual="psi2")
    env = DetectorEnv(scenario, attacks=ATTACKS, vary_seed=False, decision_period=50)
    rng = np.random.default_rng(args.seed)
    # The start: a detector that never alarms (a large negative constant).
    mean = np.array([0.0, 0.0, 0.0, -1.0])
    std = np.array([1.0, 1.0, 1.0, 1.0])
    print("iteration  population mean  best     detector (the mean)")
    curve = [score(env, mean)]
    print(f"{0:9d}  {'':15s}  {'':7s}  {curve[0]:8.2f}")
    for it in range(1, args.iterations + 1):
        pop = mean + std * rng.standard_normal((args.population, mean.size))
        scores = np.array([score(env, w) for w in pop])
        elite = pop[np.argsort(scores)[-args.elite :]]
        mean = elite.mean(axis=0)
        std = elite.std(axis=0) + 0.05
        curve.append(score(env, mean))
        print(f"{it:9d}  {scores.mean():15.2f}  {scores.max():7.2f}  {curve[-1]:8.2f}")
    print(
        f"the detector's mean return: {curve[0]:.2f} at the start (never alarming), "
        f"{curve[-1]:.2f} at the end; w = {np.array2string(mean, precision=2)}"
    )
    env.close()


if __name__ == "__main__":
    main()
