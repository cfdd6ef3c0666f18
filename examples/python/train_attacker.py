"""Trains an attacker on ``fdi_mas/Attacker-v0`` with the cross-entropy method, numpy only.

The policy is linear in what the attacker sees of robot 2 (its measured positions and
velocities, scaled) and in sines of the time, squashed into the action's box:
``a = tanh(W · [y, ẏ / 10, sin 2πft, cos 2πft, 1])`` on
robot 2's position and velocity channels. Each iteration draws a population of ``W`` around a
mean, scores each by one episode's return (the reward of docs/python.md, "Rewards": the
tracking error in units of the attack-free run's, minus the share of alarmed ticks), and moves
the mean to the best. It prints one line per iteration: the population's mean return, its
best, and the mean's own return, which starts at the zero policy's (0: no damage, no alarm)
and climbs.

    python examples/python/train_attacker.py                 # 15 iterations × 24, 13 s on one core
    python examples/python/train_attacker.py --iterations 3  # a short form
"""

from __future__ import annotations

import argparse

import numpy as np

import fdi_mas
from fdi_mas.envs import AttackerEnv

ROBOT = 2


#: Frequencies (Hz) of the time features: the policy can shape an oscillating injection.
FREQS_HZ = (0.5, 2.0, 8.0)


def features(obs: np.ndarray, names: list[str], links: int) -> np.ndarray:
    """Robot ROBOT's measured ``y`` (rad) and ``ẏ`` / 10 (rad/s), the sine and cosine of the
    time at each of FREQS_HZ, and a constant 1."""
    at = names.index(f"robot{ROBOT}.y1")
    y = obs[at : at + links]
    y_dot = obs[at + links : at + 2 * links]
    phase = 2.0 * np.pi * np.array(FREQS_HZ) * obs[0]
    return np.concatenate([y, y_dot / 10.0, np.sin(phase), np.cos(phase), [1.0]])


def episode(env: AttackerEnv, w: np.ndarray, terms: dict[str, float] | None = None) -> float:
    """One episode's return under the policy ``w`` (action entries × features); ``terms``
    receives its raw terms (``info["damage"]``, ``info["alarm_ticks"]``, ``info["ticks"]``)."""
    obs, _ = env.reset()
    total = 0.0
    sums = {"damage": 0.0, "alarm_ticks": 0, "ticks": 0}
    while True:
        f = features(obs, env.observation_names, env.links)
        action = np.tanh(w @ f).reshape(env.action_space.shape)
        obs, reward, terminated, truncated, info = env.step(action)
        total += reward
        for k in sums:
            sums[k] += info[k]
        if terminated or truncated:
            if terms is not None:
                terms.update(sums)
            return total


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--iterations", type=int, default=15)
    p.add_argument("--population", type=int, default=24)
    p.add_argument("--elite", type=int, default=6)
    p.add_argument("--duration-s", type=float, default=5.0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--stealth-weight", type=float, default=1.0, help="the reward's price of an alarmed step")
    args = p.parse_args()
    if not 1 <= args.elite <= args.population:
        p.error("--elite: between 1 and --population")

    scenario = fdi_mas.Scenario.paper(duration_s=args.duration_s, residual="psi2")
    env = AttackerEnv(
        scenario,
        robots=[ROBOT],
        channels=("position", "velocity"),
        stealth_weight=args.stealth_weight,
        decision_period=50,
    )
    rng = np.random.default_rng(args.seed)
    n_out = int(np.prod(env.action_space.shape))
    n_in = 2 * env.links + 2 * len(FREQS_HZ) + 1
    mean = np.zeros((n_out, n_in))
    std = np.full((n_out, n_in), 0.3)
    print(f"damage scale (attack-free mean error of robot {ROBOT}): {env.damage_scale:.5f} rad")
    print("iteration  population mean  best     policy (the mean)")
    curve = [episode(env, mean)]
    print(f"{0:9d}  {'':15s}  {'':7s}  {curve[0]:8.2f}")
    for it in range(1, args.iterations + 1):
        pop = mean + std * rng.standard_normal((args.population, n_out, n_in))
        scores = np.array([episode(env, w) for w in pop])
        elite = pop[np.argsort(scores)[-args.elite :]]
        mean = elite.mean(axis=0)
        std = elite.std(axis=0) + 0.05
        curve.append(episode(env, mean))
        print(f"{it:9d}  {scores.mean():15.2f}  {scores.max():7.2f}  {curve[-1]:8.2f}")
    terms: dict[str, float] = {}
    episode(env, mean, terms)
    error = terms["damage"] / terms["ticks"]
    print(
        f"the policy's return: {curve[0]:.2f} at the start, {curve[-1]:.2f} at the end; its "
        f"tracking error {error:.5f} rad ({error / env.damage_scale:.1f}× the attack-free run's), "
        f"alarmed on {terms['alarm_ticks'] / terms['ticks']:.0%} of the ticks"
    )
    env.close()


if __name__ == "__main__":
    main()
