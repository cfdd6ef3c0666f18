"""Vectors of :class:`~fdi_mas.envs.AttackerEnv` and :class:`~fdi_mas.envs.DefenderEnv`
stepped inside Rust, on every core."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from fdi_mas import _core
from fdi_mas.envs import _common
from fdi_mas.envs.defender import DEFAULT_ATTACKS


class VectorAttackerEnv(VectorEnv):
    """``num_envs`` :class:`~fdi_mas.envs.AttackerEnv` of one configuration, stepped together
    in Rust on ``threads`` threads (every core by default) with the interpreter released:
    numpy arrays in and out, no Python loop per environment.

    Spaces, reward and episodes are :class:`~fdi_mas.envs.AttackerEnv`'s (same arguments),
    batched. Autoreset is Gymnasium's next-step mode: the step after an environment's episode
    ended resets it (its action is ignored, its reward is 0). ``digests()`` gives each
    environment's last ended episode's trace digest.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int,
        scenario: _core.Scenario | None = None,
        *,
        attack: str | None = "none",
        robots: Sequence[int] | int | None = None,
        channels: Sequence[str] | str = ("position",),
        budget: float | Mapping[str, float] | None = None,
        detectors: Sequence[str] | str = _common.DEFAULT_DETECTORS,
        damage_weight: float = 1.0,
        stealth_weight: float = 1.0,
        damage_scale: float | None = None,
        decision_period: int = 1,
        threads: int | None = None,
        render_mode: str | None = None,
    ) -> None:
        _common.no_render(render_mode)
        if int(num_envs) < 1:
            raise ValueError(f"num_envs: at least 1, got {num_envs}")
        self.num_envs = int(num_envs)
        self.scenario = _common.scenario_of(scenario, attack)
        self.robots = _common.robots_of(robots, self.scenario)
        self.channels = _common.names_of(channels, _common.CHANNELS, "channels")
        self.detectors = _common.names_of(detectors, _core.detectors(), "detectors")
        self.budget = _common.budget_of(budget)
        self.damage_weight = float(damage_weight)
        self.stealth_weight = float(stealth_weight)
        self.damage_scale = _common.damage_scale_of(damage_scale, self.scenario, self.robots)
        decision_period = _common.period_of(decision_period)
        self._batch = _core.Batch(
            self.scenario,
            self.num_envs,
            self.robots,
            self.channels,
            self.budget,
            self.detectors,
            int(decision_period),
            self.damage_weight,
            self.stealth_weight,
            self.damage_scale,
            threads,
        )
        leading = (len(self.robots), len(self.channels))
        agents, self.joints, self.links, self.action_mask = _common.team_of(self._batch, leading)
        self._open(
            _common.observation_names(agents, self.joints, _common.ATTACKER_PARTS),
            self.action_mask.shape,
        )

    def _open(self, observation_names: list[str], action_shape: tuple[int, ...]) -> None:
        """The spaces of a batch whose observations are named ``observation_names`` and whose
        actions have ``action_shape``, at its start."""
        self.observation_names = observation_names
        self.single_observation_space = spaces.Box(
            -np.inf, np.inf, shape=(len(self.observation_names),), dtype=np.float64
        )
        self._action_shape = action_shape
        self.single_action_space = spaces.Box(-1.0, 1.0, shape=self._action_shape, dtype=np.float64)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._started = False
        self._closed = False

    def reset(
        self, *, seed: int | Sequence[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Every environment back to its start (the engine draws nothing: ``seed`` seeds the
        spaces only)."""
        self._check_open()
        if seed is not None:
            first = seed if isinstance(seed, int) else seed[0]
            self.action_space.seed(first)
            self.observation_space.seed(first)
        obs = np.frombuffer(self._batch.reset(), dtype=np.float64).reshape(self.num_envs, -1)
        self._started = True
        return obs.copy(), {}

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        self._check_open()
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = np.asarray(actions, dtype=np.float64)
        want = (self.num_envs, *self._action_shape)
        if a.shape != want:
            raise ValueError(f"actions: expected shape {want}, got {a.shape}")
        # Rewards, ends and the next step's autoreset are the batch's (in Rust); the arrays are
        # numpy views of fresh, writable buffers.
        obs, rewards, term, trunc = self._batch.step(a.tobytes())
        return (
            np.frombuffer(obs, dtype=np.float64).reshape(self.num_envs, -1),
            np.frombuffer(rewards, dtype=np.float64),
            np.frombuffer(term, dtype=np.bool_),
            np.frombuffer(trunc, dtype=np.bool_),
            {},
        )

    def digests(self) -> list[str | None]:
        """Each environment's last ended episode's trace digest (``None`` while none ended)."""
        self._check_open()
        return self._batch.digests()

    @property
    def threads(self) -> int:
        return self._batch.threads

    def _check_open(self) -> None:
        if self._closed:
            raise _common.ClosedEnvironmentError("the environment is closed: make a new one")

    def close_extras(self, **kwargs: Any) -> None:
        if not self._closed:
            self._batch.close()
            self._closed = True


class VectorDefenderEnv(VectorAttackerEnv):
    """``num_envs`` :class:`~fdi_mas.envs.DefenderEnv` of one configuration, stepped together in
    Rust on ``threads`` threads (every core by default), as :class:`VectorAttackerEnv` steps
    attackers.

    Spaces and reward are :class:`~fdi_mas.envs.DefenderEnv`'s (same arguments), batched. Each
    environment draws its episodes' attacks (from ``attacks``) and, with ``vary_seed``, their
    seeds with a generator of its own, seeded from ``seed`` and its index, in Rust: the same
    ``seed`` gives the same episodes. Autoreset is Gymnasium's next-step mode, on a new draw.
    ``digests()`` gives each environment's last ended episode's trace digest.
    """

    def __init__(  # noqa: PLR0913 (the single environment's arguments)
        self,
        num_envs: int,
        scenario: _core.Scenario | None = None,
        *,
        attacks: Sequence[str] = DEFAULT_ATTACKS,
        vary_seed: bool = True,
        correction_budget: float = 1.0,
        effort_weight: float = 0.1,
        error_scale: float | None = None,
        decision_period: int = 10,
        seed: int = 0,
        threads: int | None = None,
        render_mode: str | None = None,
    ) -> None:
        _common.no_render(render_mode)
        if int(num_envs) < 1:
            raise ValueError(f"num_envs: at least 1, got {num_envs}")
        self.num_envs = int(num_envs)
        self.scenario = _common.scenario_of(scenario, None)
        self.attacks = _common.names_of(list(attacks), _core.presets(), "attacks")
        if not self.attacks:
            raise ValueError("attacks: at least one attack profile")
        robots = list(self.scenario.agents)
        self.error_scale = _common.damage_scale_of(error_scale, self.scenario, robots)
        self._batch = _core.Batch.defender(
            [self.scenario.replace(attack=a) for a in self.attacks],
            self.num_envs,
            float(correction_budget),
            int(_common.period_of(decision_period)),
            self.error_scale,
            float(effort_weight),
            int(seed),
            bool(vary_seed),
            threads,
        )
        agents, self.joints, self.links, self.action_mask = _common.team_of(self._batch, (len(robots),))
        self._open(
            _common.observation_names(agents, self.joints, _common.CENTER_PARTS),
            self.action_mask.shape,
        )
