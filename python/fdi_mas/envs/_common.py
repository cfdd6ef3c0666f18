"""What the environments share: their arguments checked, the episode built, actions checked."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from fdi_mas import _core

CHANNELS = ("position", "velocity", "torque")
UNITS = {"position": "rad", "velocity": "rad/s", "torque": "N·m"}
#: The injection an action of 1 gives, per channel, unless the constructor says otherwise:
#: 0.05 rad, 0.5 rad/s, 5 N·m.
DEFAULT_BUDGET = {"position": 0.05, "velocity": 0.5, "torque": 5.0}
#: The detectors whose alarms cost the attacker, unless the constructor says otherwise.
DEFAULT_DETECTORS = ("s_hat_norm", "chi2", "cusum")


def default_scenario() -> _core.Scenario:
    """The environments' scenario unless given one: the paper's, its detectors on the ``psi2``
    residual. On the default ``innovation`` residual the χ² and CUSUM detectors alarm on most
    ticks of the paper's run without any attack (docs/python.md), which would make every
    stealth penalty noise."""
    return _core.Scenario.paper(residual="psi2")


def scenario_of(scenario: _core.Scenario | None, attack: str | None) -> _core.Scenario:
    """The scenario (:func:`default_scenario` when ``None``) with ``attack`` as its attack
    profile (``None`` keeps its own)."""
    s = scenario if scenario is not None else default_scenario()
    if not isinstance(s, _core.Scenario):
        raise TypeError(f"scenario: expected fdi_mas.Scenario, got {type(s).__name__}")
    return s if attack is None else s.replace(attack=attack)


def budget_of(budget: float | Mapping[str, float] | None) -> list[float]:
    """Per channel of :data:`CHANNELS`, the largest injection."""
    out = dict(DEFAULT_BUDGET)
    if budget is None:
        pass
    elif isinstance(budget, Mapping):
        unknown = sorted(set(budget) - set(CHANNELS))
        if unknown:
            raise ValueError(f"budget: no channel {unknown[0]!r}; the channels are {CHANNELS}")
        out.update({k: float(v) for k, v in budget.items()})
    else:
        out = {c: float(budget) for c in CHANNELS}
    for c, v in out.items():
        if not np.isfinite(v) or v < 0:
            raise ValueError(f"budget: {c} must be finite and >= 0 ({UNITS[c]}), got {v}")
    return [out[c] for c in CHANNELS]


def names_of(values: Sequence[str] | str, known: Sequence[str], what: str) -> list[str]:
    """``values`` as a list, each one of ``known``."""
    if isinstance(values, str):
        values = [values]
    out = list(values)
    for v in out:
        if v not in known:
            raise ValueError(f"{what}: no {what[:-1]} {v!r}; the {what} are {tuple(known)}")
    return out


def robots_of(robots: Sequence[int] | int | None, scenario: _core.Scenario) -> list[int]:
    """The robots (ids) an action injects into: every robot of the scenario by default."""
    if robots is None:
        return list(scenario.agents)
    if isinstance(robots, (int, np.integer)):
        robots = [int(robots)]
    out = [int(r) for r in robots]
    for r in out:
        if r not in scenario.agents:
            raise ValueError(f"robots: {r} is not a robot of the scenario (its robots are {scenario.agents})")
    if len(set(out)) != len(out):
        raise ValueError(f"robots: {out} names a robot twice")
    return out


def checked_action(action: Any, shape: tuple[int, ...]) -> bytes:
    """The action as bytes of float64, after its shape is checked (values are checked by the
    engine: finite, inside [-1, 1])."""
    a = np.asarray(action, dtype=np.float64)
    if a.shape != shape:
        raise ValueError(f"action: expected shape {shape}, got {a.shape}")
    return a.tobytes()


def views(core_out: tuple[Any, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The attacker's and the center's views of a step's outcome."""
    return (
        np.frombuffer(core_out[6], dtype=np.float64).copy(),
        np.frombuffer(core_out[7], dtype=np.float64).copy(),
    )


def observation_names(agents: Sequence[int], joints: Sequence[int], parts: Sequence[str]) -> list[str]:
    """Names of a view's entries: ``t_s``, then per robot and part, per joint of that robot
    (``joints``: each robot's, in the order of ``agents``; a team may mix robots)."""
    names = ["t_s"]
    for a, n in zip(agents, joints, strict=True):
        for p in parts:
            names.extend(f"robot{a}.{p}{i}" for i in range(1, n + 1))
    return names


def team_of(core: Any, leading: tuple[int, ...] | None) -> tuple[list[int], list[int], int, np.ndarray | None]:
    """A core episode's (or batch's) robots (scenario order), their joints, ``links`` (an
    action's entries per robot and channel: the team's largest joint count) and, for an action
    of shape ``(*leading, links)``, its mask: True where the entry acts, False where its link is
    beyond its robot's joints (the entry is ignored). ``leading`` None: no action, no mask."""
    agents, links, _ = core.shape()
    joints, mask = core.joints()
    shaped = None if leading is None else np.asarray(mask, dtype=bool).reshape(*leading, links)
    return list(agents), list(joints), int(links), shaped


ATTACKER_PARTS = ("y", "y_dot", "u")
CENTER_PARTS = ("y", "y_dot", "s_hat", "r", "r_dot")


class ClosedEnvironmentError(RuntimeError):
    """An environment was used after ``close()``."""


def check_open(episode: Any) -> None:
    """Raises :class:`ClosedEnvironmentError` for a closed episode."""
    if episode.closed:
        raise ClosedEnvironmentError("the environment is closed: make a new one")


def no_render(render_mode: str | None) -> None:
    """The environments do not render: any mode but ``None`` is refused."""
    if render_mode is not None:
        raise ValueError(f"render_mode: this environment does not render, got {render_mode!r}")


def period_of(decision_period: int) -> int:
    """Ticks per step, at least 1."""
    if int(decision_period) < 1:
        raise ValueError(f"decision_period: at least 1 tick, got {decision_period}")
    return int(decision_period)


#: Attack-free errors already measured, per (scenario TOML, robots).
_ATTACK_FREE: dict[tuple[str, tuple[int, ...]], float] = {}


def attack_free_error(scenario: _core.Scenario, robots: Sequence[int]) -> float:
    """The attacker's damage scale: over the attack-free run of ``scenario`` (its attack
    replaced by ``none``, nothing injected), the mean over the ticks of ``‖q_d − q‖`` averaged
    over ``robots`` (rad). Measured once per scenario and robots (one run of the engine: about
    0.3 s for the paper's 40 s)."""
    free = scenario.replace(attack="none")
    key = (free.to_toml(), tuple(robots))
    if key not in _ATTACK_FREE:
        episode = _core.Episode(free, list(robots), [], [0.0, 0.0, 0.0], [], max(1, free.ticks))
        ticks, damage = 0, 0.0
        try:
            # One step runs the whole horizon; the bound only guards against an engine that
            # would never end its episode.
            for _ in range(free.ticks + 1):
                out = episode.step(b"")
                ticks, damage = ticks + out[0], damage + out[1]
                if out[4] or out[5]:
                    break
            else:
                raise RuntimeError(f"the attack-free run of {scenario.name!r} did not end")
        finally:
            episode.close()
        if ticks == 0 or not np.isfinite(damage) or damage <= 0.0:
            raise ValueError(
                f"damage_scale: the attack-free run of {scenario.name!r} gave no finite error to "
                f"scale the damage by ({damage} rad over {ticks} ticks): give damage_scale"
            )
        _ATTACK_FREE[key] = damage / ticks
    return _ATTACK_FREE[key]


def damage_scale_of(
    damage_scale: float | None, scenario: _core.Scenario, robots: Sequence[int]
) -> float:
    """``damage_scale`` (rad) when given, else :func:`attack_free_error`; finite and above 0."""
    if damage_scale is None:
        return attack_free_error(scenario, robots)
    scale = float(damage_scale)
    if not np.isfinite(scale) or scale <= 0.0:
        raise ValueError(f"damage_scale: a finite error above 0 rad, got {damage_scale}")
    return scale


def draw_episode(
    rng: np.random.Generator,
    attacks: Sequence[str],
    scenarios: Mapping[str, _core.Scenario],
    vary_seed: bool,
    attack: str | None = None,
) -> tuple[str, _core.Scenario]:
    """The next episode's attack (``attack``, or one of ``attacks`` drawn with ``rng``) and its
    scenario (of ``scenarios``, one per attack), with a seed drawn with ``rng`` when
    ``vary_seed``."""
    if attack is None:
        attack = attacks[int(rng.integers(len(attacks)))]
    elif attack not in scenarios:
        raise ValueError(f"options['attack']: {attack!r} is not one of {tuple(attacks)}")
    scenario = scenarios[attack]
    if vary_seed:
        scenario = scenario.replace(seed=int(rng.integers(0, 2**63)))
    return attack, scenario


def add_summary(episode: Any, info: dict[str, Any]) -> None:
    """Once the episode ended: its ``summary`` (the fields of ``summary.json``) and ``digest``
    into ``info``."""
    summary = episode.summary_json()
    if summary is not None:
        info["summary"] = json.loads(summary)
        info["digest"] = info["summary"]["trace_digest"]


class DrawnEpisodeEnv(gym.Env):
    """An environment whose episode draws its attack from ``self.attacks`` (and, with
    ``self.vary_seed``, its seed) at each reset: the detector's and the defender's. Subclasses
    set ``self._episode``, ``self.attacks``, ``self._scenarios``, ``self.vary_seed`` and
    ``self.observation_space``, and call ``self._check_step()`` first in ``step``."""

    attack: str | None = None
    _ended: bool = True

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Draws the episode's attack (``options={"attack": name}`` chooses it) and, with
        ``vary_seed``, its seed, and goes back to the start."""
        super().reset(seed=seed)
        check_open(self._episode)
        attack, scenario = draw_episode(
            self.np_random, self.attacks, self._scenarios, self.vary_seed, (options or {}).get("attack")
        )
        self._episode.reset(scenario)
        self.attack = attack
        self._ended = False
        obs = np.zeros(self.observation_space.shape, dtype=np.float64)
        return obs, {"t_s": 0.0, "attack": attack, "seed": scenario.seed}

    def _check_step(self) -> None:
        """An episode that is open and has not ended, or an error saying why."""
        check_open(self._episode)
        if self._ended:
            raise gym.error.ResetNeeded("the episode ended (or never began): call reset()")

    def close(self) -> None:
        self._episode.close()
        self._ended = True
        super().close()
