"""Whole runs: :func:`run` on the in-process engine, :func:`open_run` of a command-line run."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from fdi_mas import _core


class RmseTable(Mapping[int, float]):
    """RMSE per robot (rad), by robot id. Printed, it is the metrics table ``fdi-launch run``
    prints (RMSE, maximum error, detection, misses, coverage)."""

    def __init__(self, summary: dict[str, Any], table: str) -> None:
        self._rmse = {int(k): float(v) for k, v in summary["rmse_rad"].items()}
        self._table = table

    def __getitem__(self, robot: int) -> float:
        return self._rmse[robot]

    def __iter__(self) -> Iterator[int]:
        return iter(self._rmse)

    def __len__(self) -> int:
        return len(self._rmse)

    def __str__(self) -> str:
        return self._table.rstrip("\n")

    def __repr__(self) -> str:
        return f"RmseTable({self._rmse!r})"


class Run:
    """A run: its summary (the fields of ``summary.json``), its trace digest, and every tick.

    ``ticks`` maps each column (named as the CSV export names them: ``k``, ``agent``,
    ``t_s``, ``q1_rad``, ``s1_hat_rad_s``, ``alarm``, ``attacked``, …) to a numpy array, one
    entry per robot and tick in the digest's order (tick, then robot); ``None`` when the
    ticks were not kept. :meth:`frame` gives them as a pandas DataFrame.
    """

    def __init__(self, core: _core.RunResult) -> None:
        self.summary: dict[str, Any] = json.loads(core.summary_json)
        self.digest: str = core.digest
        self.rmse = RmseTable(self.summary, core.table)
        self.run_dir: str | None = None if core.run_dir is None else os.fspath(core.run_dir)
        self.warnings: list[str] = list(core.warnings)
        self.ticks: dict[str, np.ndarray] | None = None
        if core.columns is not None:
            self.ticks = {
                name: np.frombuffer(data, dtype=np.dtype(dtype)) for name, dtype, data in core.columns
            }

    def frame(self) -> Any:
        """Every tick as a pandas DataFrame (pandas must be installed)."""
        if self.ticks is None:
            raise ValueError("this run kept no ticks (ticks=False)")
        try:
            import pandas
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("Run.frame() needs pandas: pip install pandas") from e
        return pandas.DataFrame(self.ticks)

    def __repr__(self) -> str:
        s = self.summary
        return (
            f"Run(scenario={s['scenario']!r}, attack={s['attack']!r}, ticks={s['ticks']}, "
            f"digest={self.digest[:12]}…)"
        )


def run(scenario: _core.Scenario | None = None, *, ticks: bool = True) -> Run:
    """Runs ``scenario`` (the paper's by default) to its end on the in-process engine, as
    ``fdi-launch run --engine inproc`` does, without writing a run directory."""
    if scenario is None:
        scenario = _core.Scenario.paper()
    return Run(_core.run(scenario, ticks))


def open_run(run_dir: str | os.PathLike[str], *, ticks: bool = True) -> Run:
    """Reads a run directory ``fdi-launch run`` wrote: its summary and every tick, joined from
    its processes' traces (which must keep every tick, ``--traces full``)."""
    return Run(_core.open_run(os.fspath(run_dir), ticks))
