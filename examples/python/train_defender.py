"""Trains a defence on ``fdi_mas/Defender-v0`` with the cross-entropy method, numpy only.

The defence corrects the torque the control center's controller commands, joint by joint, from
what the center has of that joint: ``c_ij = tanh(w · [Ŝ_ij, r_ij, ṙ_ij, 1])`` (the NN's attack
estimate, the observer's residuals, a constant; one ``w`` for every robot and joint), times the
environment's correction budget. A candidate ``w`` is scored by its mean return over the same
episodes, one per attack of ATTACKS (the reward of docs/python.md, "Rewards": per step, minus
the tracking error over the attack-free run's, minus the effort). It prints one line per
iteration: the population's mean return, its best, and the mean's own return, which starts at
the defence that corrects nothing (``w = 0``) and climbs when the search finds better.

    python examples/python/train_defender.py                 # 8 iterations × 12
    python examples/python/train_defender.py --iterations 2  # a short form
"""

from __future__ import annotations

import argparse

import numpy as np

import fdi_mas
from fdi_mas.envs import DefenderEnv

#: The attacks of the training episodes: no attack, and shipped profiles.
ATTACKS = ("none", "paper", "actuator-bias", "scale")


def features(obs: np.ndarray, names: list[str], robots: list[int], links: int) -> np.ndarray:
    """Per robot and joint (rows): its ``Ŝ``, ``r``, ``ṙ`` and a constant 1;
    shape (robots, links, 4)."""
    out = np.empty((len(robots), links, 4))
    for i, r in enumerate(robots):
        at = names.index(f"robot{r}.s_hat1")
        parts = obs[at : at + 3 * links].reshape(3, links)
        out[i, :, :3] = parts.T
        out[i, :, 3] = 1.0
    return out


def episode(env: DefenderEnv, w: np.ndarray, attack: str) -> tuple[float, float]:
    """One episode's return under ``w`` with ``attack`` under it, and its mean tracking error."""
    obs, _ = env.reset(options={"attack": attack})
    total, errors = 0.0, []
    while True:
        action = np.tanh(features(obs, env.observation_names, env.agents, env.links) @ w)
        obs, reward, terminated, truncated, info = env.step(action)
        total += reward
        errors.append(info["tracking_error"])
        if terminated or truncated:
            return total, float(np.mean(errors))


def score(env: DefenderEnv, w: np.ndarray) -> float:
    """Mean return over one episode per attack of ATTACKS."""
    return float(np.mean([episode(env, w, a)[0] for a in ATTACKS]))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--iterations", type=int, default=8)
    p.add_argument("--population", type=int, default=12)
    p.add_argument("--elite", type=int, default=3)
    p.add_argument("--duration-s", type=float, default=20.0)
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args()
    if not 1 <= args.elite <= args.population:
        p.error("--elite: between 1 and --population")

    scenario = fdi_mas.Scenario.paper(duration_s=args.duration_s, residual="psi2")
    env = DefenderEnv(scenario, attacks=ATTACKS, vary_seed=False, decision_period=50)
    rng = np.random.default_rng(args.seed)
    mean = np.zeros(4)  # the start: no correction
    std = np.full(4, 0.5)
    print(f"error scale (attack-free mean tracking error): {env.error_scale:.5f} rad")
    print("iteration  population mean  best     defence (the mean)")
    curve = [score(env, mean)]
    print(f"{0:9d}  {'':15s}  {'':7s}  {curve[0]:8.2f}")
    for it in range(1, args.iterations + 1):
        pop = mean + std * rng.standard_normal((args.population, mean.size))
        scores = np.array([score(env, w) for w in pop])
        elite = pop[np.argsort(scores)[-args.elite :]]
        # The mean moves to the elite's only when that scores better than where it is.
        candidate = elite.mean(axis=0)
        if score(env, candidate) > curve[-1]:
            mean = candidate
        std = elite.std(axis=0) + 0.02
        curve.append(score(env, mean))
        print(f"{it:9d}  {scores.mean():15.2f}  {scores.max():7.2f}  {curve[-1]:8.2f}")
    per_attack = {a: episode(env, mean, a)[1] / env.error_scale for a in ATTACKS}
    before = {a: episode(env, np.zeros(4), a)[1] / env.error_scale for a in ATTACKS}
    print(
        f"the defence's mean return: {curve[0]:.2f} at the start (no correction), "
        f"{curve[-1]:.2f} at the end; w = {np.array2string(mean, precision=3)}"
    )
    for a in ATTACKS:
        print(f"  {a}: tracking error {before[a]:.2f} -> {per_attack[a]:.2f} × the attack-free run's")
    env.close()


if __name__ == "__main__":
    main()
