"""fdi-mas from Python: the engine of fdi-mas and environments for learned attackers and
detectors.

The numbers come from the same Rust code the command line (``fdi-launch``) runs: a run here
and ``fdi-launch run --engine inproc`` on the same scenario give the same trace digest.

>>> import fdi_mas
>>> result = fdi_mas.run(fdi_mas.Scenario.paper(duration_s=1.0))
>>> sorted(result.rmse)
[1, 2, 3, 4]

Environments (Gymnasium 1.x, registered on import): ``fdi_mas/Attacker-v0``
(:class:`fdi_mas.envs.AttackerEnv`), ``fdi_mas/Detector-v0``
(:class:`fdi_mas.envs.DetectorEnv`), ``fdi_mas/Defender-v0``
(:class:`fdi_mas.envs.DefenderEnv`); the PettingZoo parallel environment
``fdi_mas.envs.attack_defend_v0``; the vector environment
:class:`fdi_mas.envs.VectorAttackerEnv`. docs/python.md has the details.
"""

from __future__ import annotations

from fdi_mas._core import (
    EngineError,
    Scenario,
    ScenarioError,
    detectors,
    presets,
)
from fdi_mas._run import Run, RmseTable, open_run, run

__all__ = [
    "EngineError",
    "RmseTable",
    "Run",
    "Scenario",
    "ScenarioError",
    "detectors",
    "open_run",
    "presets",
    "run",
]


def _register() -> None:
    import gymnasium

    for env_id, entry, vector in (
        ("fdi_mas/Attacker-v0", "fdi_mas.envs:AttackerEnv", "fdi_mas.envs:VectorAttackerEnv"),
        ("fdi_mas/Detector-v0", "fdi_mas.envs:DetectorEnv", None),
        ("fdi_mas/Defender-v0", "fdi_mas.envs:DefenderEnv", "fdi_mas.envs:VectorDefenderEnv"),
    ):
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=entry, vector_entry_point=vector)


_register()
