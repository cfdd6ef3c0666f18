"""``attack_defend_v0``: the attacker and a detector at once, as a PettingZoo
``ParallelEnv``; ``parallel_env(...)`` makes it, ``env(...)`` its AEC form, as PettingZoo's
own environments do.

Agents: ``attacker`` (observation, action and reward of :class:`~fdi_mas.envs.AttackerEnv`)
and ``detector`` (those of :class:`~fdi_mas.envs.DetectorEnv`, scored against the ground
truth, which includes the attacker's injection). Each step, both act; the attacker's injection
holds for the step's ``decision_period`` ticks and the detector's alarms are scored over them.
The attack profile under the attacker's injection is drawn at each reset from ``attacks``
(``none`` only by default: the attacker is the learner).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec

from fdi_mas import _core
from fdi_mas.envs import _common
from fdi_mas.envs.detector import detection_reward

ATTACKER = "attacker"
DETECTOR = "detector"


def parallel_env(**kwargs: Any) -> "AttackDefendEnv":
    """The parallel environment (keywords: :class:`AttackDefendEnv`'s)."""
    return AttackDefendEnv(**kwargs)


def env(**kwargs: Any) -> Any:
    """The AEC form of :func:`parallel_env`."""
    return parallel_to_aec(parallel_env(**kwargs))


class AttackDefendEnv(ParallelEnv):
    """The attacker against a detector (see the module's docs)."""

    metadata = {"name": "attack_defend_v0", "render_modes": [], "is_parallelizable": True}

    def __init__(
        self,
        scenario: _core.Scenario | None = None,
        *,
        attacks: Sequence[str] = ("none",),
        vary_seed: bool = False,
        robots: Sequence[int] | int | None = None,
        channels: Sequence[str] | str = ("position",),
        budget: float | Mapping[str, float] | None = None,
        detectors: Sequence[str] | str = _common.DEFAULT_DETECTORS,
        damage_weight: float = 1.0,
        stealth_weight: float = 1.0,
        damage_scale: float | None = None,
        detect_reward: float = 1.0,
        false_alarm_penalty: float = 1.0,
        miss_penalty: float = 1.0,
        decision_period: int = 1,
        render_mode: str | None = None,
    ) -> None:
        _common.no_render(render_mode)
        base = _common.scenario_of(scenario, None)
        self.attacks = _common.names_of(list(attacks), _core.presets(), "attacks")
        if not self.attacks:
            raise ValueError("attacks: at least one attack profile")
        self._scenarios = {a: base.replace(attack=a) for a in self.attacks}
        self.vary_seed = bool(vary_seed)
        first = self._scenarios[self.attacks[0]]
        self.robots = _common.robots_of(robots, first)
        self.channels = _common.names_of(channels, _common.CHANNELS, "channels")
        self.detectors = _common.names_of(detectors, _core.detectors(), "detectors")
        decision_period = _common.period_of(decision_period)
        budget_values = _common.budget_of(budget)
        # The damage scale measured (the attack-free error of the base scenario, its attack
        # replaced) and the weights checked before the episode is made, as AttackerEnv does:
        # nothing left open on error.
        scale = _common.damage_scale_of(damage_scale, first, self.robots)
        self.attack_weights = (float(damage_weight), float(stealth_weight), scale)
        _core.attacker_reward(0, 0.0, 0, *self.attack_weights)
        self._episode = _core.Episode(
            first,
            self.robots,
            self.channels,
            budget_values,
            self.detectors,
            int(decision_period),
        )
        self.detect_weights = (float(detect_reward), float(false_alarm_penalty), float(miss_penalty))
        robot_ids, self.joints, self.links, self.action_mask = _common.team_of(
            self._episode, (len(self.robots), len(self.channels))
        )
        self._action_shape = self.action_mask.shape
        self.robot_ids = robot_ids
        self.possible_agents = [ATTACKER, DETECTOR]
        self.agents: list[str] = []
        self._spaces = {
            ATTACKER: (
                spaces.Box(
                    -np.inf,
                    np.inf,
                    shape=(len(_common.observation_names(robot_ids, self.joints, _common.ATTACKER_PARTS)),),
                    dtype=np.float64,
                ),
                spaces.Box(-1.0, 1.0, shape=self._action_shape, dtype=np.float64),
            ),
            DETECTOR: (
                spaces.Box(
                    -np.inf,
                    np.inf,
                    shape=(len(_common.observation_names(robot_ids, self.joints, _common.CENTER_PARTS)),),
                    dtype=np.float64,
                ),
                spaces.MultiBinary(len(robot_ids)),
            ),
        }
        self.attack: str | None = None
        self._rng = np.random.default_rng()

    @functools.lru_cache(maxsize=None)
    def observation_space(self, agent: str) -> spaces.Space:
        return self._spaces[agent][0]

    @functools.lru_cache(maxsize=None)
    def action_space(self, agent: str) -> spaces.Space:
        return self._spaces[agent][1]

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        _common.check_open(self._episode)
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        attack, scenario = _common.draw_episode(self._rng, self.attacks, self._scenarios, self.vary_seed)
        self._episode.reset(scenario)
        self.attack = attack
        self.agents = list(self.possible_agents)
        obs = {a: np.zeros(self.observation_space(a).shape, dtype=np.float64) for a in self.agents}
        infos = {a: {"t_s": 0.0, "attack": attack} for a in self.agents}
        return obs, infos

    def step(self, actions: dict[str, Any]) -> tuple[
        dict[str, np.ndarray],
        dict[str, float],
        dict[str, bool],
        dict[str, bool],
        dict[str, dict[str, Any]],
    ]:
        _common.check_open(self._episode)
        if not self.agents:
            raise RuntimeError("the episode ended (or never began): call reset()")
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"actions: no action of {missing}")
        alarm = np.asarray(actions[DETECTOR])
        n = len(self.robot_ids)
        if alarm.shape != (n,) or not np.isin(alarm, (0, 1)).all():
            raise ValueError(f"actions['detector']: {n} alarms of 0 or 1 expected, got {alarm!r}")
        out = self._episode.step(_common.checked_action(actions[ATTACKER], self._action_shape))
        ticks, damage, alarm_ticks, attacked, terminated, truncated = out[:6]
        a_obs, c_obs = _common.views(out)
        rewards = {
            ATTACKER: _core.attacker_reward(ticks, damage, alarm_ticks, *self.attack_weights),
            DETECTOR: detection_reward(alarm, np.asarray(attacked), ticks, *self.detect_weights),
        }
        obs = {ATTACKER: a_obs, DETECTOR: c_obs}
        info: dict[str, Any] = {"t_s": float(a_obs[0]), "attack": self.attack, "attacked_ticks": attacked}
        if terminated or truncated:
            _common.add_summary(self._episode, info)
        infos = {a: dict(info) for a in self.agents}
        terms = {a: bool(terminated) for a in self.agents}
        truncs = {a: bool(truncated) for a in self.agents}
        if terminated or truncated:
            self.agents = []
        return obs, rewards, terms, truncs, infos

    def close(self) -> None:
        self._episode.close()
        self.agents = []
