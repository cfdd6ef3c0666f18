"""``fdi_mas/Attacker-v0``: the learning agent is the man in the middle."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from fdi_mas import _core
from fdi_mas.envs import _common


class AttackerEnv(gym.Env):
    """The man in the middle between the robots and the control center, as a Gymnasium
    environment.

    **Observation** (``Box``, float64): what the attacker sees on the wire after the last tick:
    ``[t, then per robot (scenario order): y, y_dot, u (each of its joints)]`` — each
    robot's clean measured positions (rad) and velocities (rad/s), and the control center's
    torque command (N·m) on the robots whose torque path the attacker sits on (zeros
    elsewhere). ``observation_names`` names every entry. Zeros at reset (nothing seen yet).

    **Action** (``Box`` in [-1, 1], shape ``(robots, channels, links)``, ``links`` the team's
    largest joint count): the injection on each chosen robot's chosen channels and joints (in a
    team that mixes robots, a robot's entries beyond its joints are ignored: ``action_mask`` is
    False there; ``joints`` has each robot's count), as a fraction of the channel's budget (``budget``: rad,
    rad/s, N·m; default 0.05, 0.5, 5). It is added to what the scenario's attack profile
    (``attack``, ``none`` by default) delivers and holds for the ``decision_period`` ticks of
    the step. An action with a non-finite entry, an entry outside [-1, 1] or another shape
    raises ``ValueError`` (wrap the environment in ``gymnasium.wrappers.ClipAction`` to clip).

    **Reward** per step (docs/python.md, "Rewards"), both terms per tick and of order one:
    ``damage_weight × (e / damage_scale − 1) − stealth_weight × alarmed``, where ``e`` is the
    step's mean over its ticks of ``‖q_d − q‖`` (rad, the true tracking error) averaged over
    the chosen robots, ``damage_scale`` the same mean over the whole attack-free run (measured
    once at construction, unless given in rad), and ``alarmed`` the share of the step's ticks
    at whose end any chosen detector of any robot was alarming (0 to 1). So +1 for a step at
    twice the attack-free run's mean error, −1 for a step alarmed throughout. The scale is the
    run's mean, not the attack-free error at the step's time: an attack-free step scores above
    0 in the start-up transient and below it later; a whole attack-free episode of equal steps
    returns 0 (up to false alarms). ``info`` has the
    raw terms: ``damage`` (Σ over the step's ticks of the mean error, rad), ``alarm_ticks``,
    ``ticks``, ``attacked_ticks`` (per robot), and ``damage_scale_rad``. ``detectors``: any of
    :func:`fdi_mas.detectors` (default ``s_hat_norm``, ``chi2``, ``cusum``).

    **Episode**: the scenario's horizon; it terminates when a robot diverges (its state leaves
    the bound of ``fdi_common::metrics::DIVERGENCE_BOUND_RAD`` or becomes non-finite) and
    truncates at the horizon. The last step's ``info`` holds ``summary`` (the fields of
    ``summary.json``) and ``digest`` (the trace digest).

    Bit for bit: with ``attack=None`` (the scenario's own profile) and actions of zeros, an
    episode's digest is ``fdi-launch run --engine inproc``'s on the same scenario.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
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
        render_mode: str | None = None,
    ) -> None:
        _common.no_render(render_mode)
        self.scenario = _common.scenario_of(scenario, attack)
        self.robots = _common.robots_of(robots, self.scenario)
        self.channels = _common.names_of(channels, _common.CHANNELS, "channels")
        self.detectors = _common.names_of(detectors, _core.detectors(), "detectors")
        self.budget = _common.budget_of(budget)
        self.damage_weight = float(damage_weight)
        self.stealth_weight = float(stealth_weight)
        self.damage_scale = _common.damage_scale_of(damage_scale, self.scenario, self.robots)
        # The weights are checked now, not at the first step.
        _core.attacker_reward(0, 0.0, 0, self.damage_weight, self.stealth_weight, self.damage_scale)
        self.decision_period = _common.period_of(decision_period)
        self._episode = _core.Episode(
            self.scenario,
            self.robots,
            self.channels,
            self.budget,
            self.detectors,
            self.decision_period,
        )
        agents, self.joints, self.links, self.action_mask = _common.team_of(
            self._episode, (len(self.robots), len(self.channels))
        )
        self._action_shape = self.action_mask.shape
        self.observation_names = _common.observation_names(agents, self.joints, _common.ATTACKER_PARTS)
        self.observation_space = spaces.Box(
            -np.inf, np.inf, shape=(len(self.observation_names),), dtype=np.float64
        )
        self.action_space = spaces.Box(-1.0, 1.0, shape=self._action_shape, dtype=np.float64)
        self._ended = True

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Back to the scenario's start. ``options={"scenario": Scenario}`` runs another
        scenario with the same robots (e.g. another seed); the damage scale stays the
        constructor's scenario's."""
        super().reset(seed=seed)
        _common.check_open(self._episode)
        scenario = (options or {}).get("scenario")
        if scenario is not None:
            scenario = _common.scenario_of(scenario, None)
        self._episode.reset(scenario)
        self._ended = False
        obs = np.zeros(self.observation_space.shape, dtype=np.float64)
        return obs, {"t_s": 0.0}

    def step(
        self, action: Any
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        _common.check_open(self._episode)
        if self._ended:
            raise gym.error.ResetNeeded("the episode ended (or never began): call reset()")
        out = self._episode.step(_common.checked_action(action, self._action_shape))
        ticks, damage, alarm_ticks, attacked, terminated, truncated = out[:6]
        obs, _ = _common.views(out)
        reward = _core.attacker_reward(
            ticks, damage, alarm_ticks, self.damage_weight, self.stealth_weight, self.damage_scale
        )
        info: dict[str, Any] = {
            "t_s": float(obs[0]),
            "ticks": ticks,
            "damage": damage,
            "alarm_ticks": alarm_ticks,
            "attacked_ticks": attacked,
            "damage_scale_rad": self.damage_scale,
        }
        if terminated or truncated:
            self._ended = True
            _common.add_summary(self._episode, info)
        return obs, float(reward), bool(terminated), bool(truncated), info

    def close(self) -> None:
        self._episode.close()
        self._ended = True
        super().close()
