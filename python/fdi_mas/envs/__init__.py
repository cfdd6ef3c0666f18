"""Environments over the fdi-mas engine: Gymnasium's :class:`AttackerEnv`,
:class:`DetectorEnv` and :class:`DefenderEnv`, the vectors :class:`VectorAttackerEnv` and
:class:`VectorDefenderEnv`, and PettingZoo's :mod:`attack_defend_v0`."""

from fdi_mas.envs import attack_defend_v0
from fdi_mas.envs.attacker import AttackerEnv
from fdi_mas.envs.defender import DefenderEnv
from fdi_mas.envs.detector import DetectorEnv
from fdi_mas.envs.vector import VectorAttackerEnv, VectorDefenderEnv

__all__ = [
    "AttackerEnv",
    "DefenderEnv",
    "DetectorEnv",
    "VectorAttackerEnv",
    "VectorDefenderEnv",
    "attack_defend_v0",
]
