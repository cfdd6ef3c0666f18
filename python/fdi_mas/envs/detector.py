"""``fdi_mas/Detector-v0``: the learning agent is a detector at the control center."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from fdi_mas import _core
from fdi_mas.envs import _common

#: The attacks an episode draws from unless the constructor says otherwise: shipped profiles
#: (scenarios/attacks/), ``none`` among them.
DEFAULT_ATTACKS = (
    "none",
    "paper",
    "stealthy-bias",
    "scale",
    "sign-flip",
    "freeze",
    "replay-original",
    "dos-drop",
)


def detection_reward(
    alarm: np.ndarray,
    attacked: np.ndarray,
    ticks: int,
    detect_reward: float,
    false_alarm_penalty: float,
    miss_penalty: float,
) -> float:
    """A step's reward for per-robot ``alarm``s against the ground truth, per robot-tick so that
    it is of order one whatever the step's length and the team's size: per robot, with its
    alarm on, ``detect_reward`` per attacked tick and ``− false_alarm_penalty`` per clean one;
    with its alarm off, ``− miss_penalty`` per attacked tick; summed over robots and divided by
    ``ticks × robots`` (0 for a step of no tick)."""
    attacked = np.asarray(attacked, dtype=np.float64)
    clean = ticks - attacked
    on = np.asarray(alarm, dtype=bool)
    if ticks <= 0 or on.size == 0:
        return 0.0
    r = np.where(on, detect_reward * attacked - false_alarm_penalty * clean, -miss_penalty * attacked)
    return float(r.sum() / (ticks * on.size))


class DetectorEnv(_common.DrawnEpisodeEnv):
    """A detector at the control center, as a Gymnasium environment.

    **Observation** (``Box``, float64): what the control center has after the last tick:
    ``[t, then per robot (scenario order): y, y_dot, s_hat, r, r_dot]`` (each of its joints)
    — the measurements it received (tampered or not), the NN estimate ``Ŝ`` of the
    attack, and the observer's residuals ``y − q̂``, ``ẏ − q̂̇``. ``observation_names`` names
    every entry.

    **Action** (``MultiBinary(robots)``): the alarm per robot, held for the step's
    ``decision_period`` ticks.

    **Reward** per step (docs/python.md, "Rewards"), against the ground truth the attacker
    records (an attack in force on the robot at the tick): per robot, alarm on:
    ``detect_reward`` per attacked tick, ``− false_alarm_penalty`` per clean tick; alarm off:
    ``− miss_penalty`` per attacked tick; divided by the step's robot-ticks, so between
    ``−max(false_alarm_penalty, miss_penalty)`` and ``detect_reward`` per step. A detector that
    never alarms scores ``−miss_penalty ×`` the attacked share.

    **Episode**: at each reset the attack is drawn (from ``attacks``, shipped profiles,
    ``none`` included) with the environment's random generator (``reset(seed=…)``), and,
    with ``vary_seed``, the scenario's seed (its sensor noise) too. ``info["attack"]`` names
    it. The episode ends at the scenario's horizon (or when a robot diverges).
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        scenario: _core.Scenario | None = None,
        *,
        attacks: Sequence[str] = DEFAULT_ATTACKS,
        vary_seed: bool = True,
        detect_reward: float = 1.0,
        false_alarm_penalty: float = 1.0,
        miss_penalty: float = 1.0,
        decision_period: int = 1,
        render_mode: str | None = None,
    ) -> None:
        _common.no_render(render_mode)
        self.base = _common.scenario_of(scenario, None)
        self.attacks = _common.names_of(list(attacks), _core.presets(), "attacks")
        if not self.attacks:
            raise ValueError("attacks: at least one attack profile")
        # Every profile is checked against the scenario now, not at some later reset.
        self._scenarios = {a: self.base.replace(attack=a) for a in self.attacks}
        self.vary_seed = bool(vary_seed)
        self.weights = (float(detect_reward), float(false_alarm_penalty), float(miss_penalty))
        self.decision_period = _common.period_of(decision_period)
        self._episode = _core.Episode(
            self._scenarios[self.attacks[0]], [], [], [0.0, 0.0, 0.0], [], self.decision_period
        )
        # (No action on the wire: the mask of an empty action.)
        self.agents, self.joints, self.links, _ = _common.team_of(self._episode, None)
        self.observation_names = _common.observation_names(self.agents, self.joints, _common.CENTER_PARTS)
        self.observation_space = spaces.Box(
            -np.inf, np.inf, shape=(len(self.observation_names),), dtype=np.float64
        )
        self.action_space = spaces.MultiBinary(len(self.agents))


    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self._check_step()
        alarm = np.asarray(action)
        if alarm.shape != (len(self.agents),):
            raise ValueError(f"action: expected shape ({len(self.agents)},), got {alarm.shape}")
        if not np.isin(alarm, (0, 1)).all():
            raise ValueError(f"action: each robot's alarm is 0 or 1, got {alarm.tolist()}")
        out = self._episode.step(b"")
        ticks, _, _, attacked, terminated, truncated = out[:6]
        _, obs = _common.views(out)
        reward = detection_reward(alarm, np.asarray(attacked), ticks, *self.weights)
        info: dict[str, Any] = {"t_s": float(obs[0]), "attack": self.attack, "attacked_ticks": attacked}
        if terminated or truncated:
            self._ended = True
            _common.add_summary(self._episode, info)
        return obs, reward, bool(terminated), bool(truncated), info
