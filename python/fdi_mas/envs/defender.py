"""``fdi_mas/Defender-v0``: the learning agent is a defence at the control center."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from fdi_mas import _core
from fdi_mas.envs import _common

#: The attacks an episode draws from unless the constructor says otherwise: shipped profiles
#: (scenarios/attacks/), ``none`` among them.
DEFAULT_ATTACKS = ("none", "paper", "actuator-bias", "scale", "stealthy-bias")
#: The largest torque correction (N·m) an action of 1 gives, unless the constructor says
#: otherwise.
DEFAULT_CORRECTION_BUDGET = 1.0


class DefenderEnv(_common.DrawnEpisodeEnv):
    """A defence at the control center, as a Gymnasium environment: the policy corrects the
    torque the scenario's controller commands, robot by robot and joint by joint.

    **Observation** (``Box``, float64): what the control center has after the last tick:
    ``[t, then per robot (scenario order): y, y_dot, s_hat, r, r_dot]`` (each of its joints)
    — the measurements it received (tampered or not), the NN estimate ``Ŝ`` of the
    attack, and the observer's residuals ``y − q̂``, ``ẏ − q̂̇``; as for ``Detector-v0``.
    ``observation_names`` names every entry.

    **Action** (``Box`` in [-1, 1], shape ``(robots, links)``, ``links`` the team's largest
    joint count; in a team that mixes robots a robot's entries beyond its joints are ignored,
    ``action_mask`` False there, and count in neither the effort nor the reward): per robot and
    joint a torque correction, as a fraction of ``correction_budget`` (N·m, default 1), added at the control
    center to the torque its controller commands, for the step's ``decision_period`` ticks.
    It is the torque the center sends (and records as its ``u``); an attack on the torque path
    acts on it afterwards. An action with a non-finite entry, an entry outside [-1, 1] or
    another shape raises ``ValueError``.

    **Reward** per step (docs/python.md, "Rewards"): ``− e / error_scale − effort_weight ×
    mean(action²)``, where ``e`` is the step's mean over its ticks of the true tracking error
    ``‖q_d − q‖`` averaged over the robots (rad) and ``error_scale`` that mean over the whole
    attack-free run of the scenario (measured once at construction, unless given in rad). So
    about −1 per step for a policy that does nothing on an attack-free episode, less under an
    attack that hurts tracking; −100 for the step in which a robot diverges. ``info`` has ``tracking_error`` (the step's ``e``),
    ``effort``, ``attack``, ``attacked_ticks``.

    **Episode**: at each reset the attack is drawn from ``attacks`` (shipped profiles, ``none``
    included) with the environment's random generator, and, with ``vary_seed``, the
    scenario's seed (its sensor noise) too; the scenario's horizon, terminated when a robot
    diverges. The last step's ``info`` holds ``summary`` and ``digest``.

    Bit for bit: actions of zeros give the episode ``fdi-launch run --engine inproc`` gives on
    the same scenario and attack.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        scenario: _core.Scenario | None = None,
        *,
        attacks: Sequence[str] = DEFAULT_ATTACKS,
        vary_seed: bool = True,
        correction_budget: float = DEFAULT_CORRECTION_BUDGET,
        effort_weight: float = 0.1,
        error_scale: float | None = None,
        decision_period: int = 10,
        render_mode: str | None = None,
    ) -> None:
        _common.no_render(render_mode)
        self.base = _common.scenario_of(scenario, None)
        self.attacks = _common.names_of(list(attacks), _core.presets(), "attacks")
        if not self.attacks:
            raise ValueError("attacks: at least one attack profile")
        self._scenarios = {a: self.base.replace(attack=a) for a in self.attacks}
        self.vary_seed = bool(vary_seed)
        budget = float(correction_budget)
        if not np.isfinite(budget) or budget <= 0.0:
            raise ValueError(f"correction_budget: finite and above 0 N·m, got {correction_budget}")
        self.correction_budget = budget
        self.effort_weight = float(effort_weight)
        if not np.isfinite(self.effort_weight) or self.effort_weight < 0.0:
            raise ValueError(f"effort_weight: finite and >= 0, got {effort_weight}")
        self.decision_period = _common.period_of(decision_period)
        robots = list(self.base.agents)
        self._episode = _core.Episode(
            self._scenarios[self.attacks[0]], robots, ["correction"], [0.0, 0.0, 0.0], [],
            self.decision_period, correction_budget=budget,
        )
        self.agents, self.joints, self.links, self.action_mask = _common.team_of(
            self._episode, (len(robots),)
        )
        self.error_scale = _common.damage_scale_of(error_scale, self.base, robots)
        self.observation_names = _common.observation_names(self.agents, self.joints, _common.CENTER_PARTS)
        self.observation_space = spaces.Box(
            -np.inf, np.inf, shape=(len(self.observation_names),), dtype=np.float64
        )
        self.action_space = spaces.Box(-1.0, 1.0, shape=self.action_mask.shape, dtype=np.float64)


    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self._check_step()
        a = np.asarray(action, dtype=np.float64)
        out = self._episode.step(_common.checked_action(a, self.action_space.shape))
        ticks, damage, _, attacked, terminated, truncated = out[:6]
        _, obs = _common.views(out)
        error = damage / ticks if ticks else 0.0
        # The one formula, in Rust (the vector environment's too).
        acting = a[self.action_mask]
        reward = _core.defender_reward(ticks, damage, acting.tolist(), self.error_scale, self.effort_weight)
        info: dict[str, Any] = {
            "t_s": float(obs[0]),
            "attack": self.attack,
            "attacked_ticks": attacked,
            "tracking_error": error,
            "effort": float(np.mean(acting * acting)),
        }
        if terminated or truncated:
            self._ended = True
            _common.add_summary(self._episode, info)
        return obs, float(reward), bool(terminated), bool(truncated), info
