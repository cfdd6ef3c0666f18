"""Shared fixtures: the command line's binary, for the tests that compare with it."""

from __future__ import annotations

import json
import os
import pathlib
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def fdi_launch() -> pathlib.Path:
    """The release build of ``fdi-launch`` (``FDI_LAUNCH`` names another): the tests that
    compare with the command line fail, never skip, without it."""
    path = pathlib.Path(os.environ.get("FDI_LAUNCH", REPO / "target" / "release" / "fdi-launch"))
    if not path.is_file():
        pytest.fail(
            f"{path} is missing: build it first (cargo build --release --bins), "
            "or name it with FDI_LAUNCH"
        )
    return path


def cli_run(fdi_launch: pathlib.Path, out: pathlib.Path, *args: str) -> tuple[dict, pathlib.Path]:
    """``fdi-launch run --engine inproc ARGS --json`` into ``out``: its summary and run
    directory."""
    done = subprocess.run(
        [str(fdi_launch), "run", "--engine", "inproc", "--out", str(out), "--json", *args],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    (run_dir,) = [p for p in out.iterdir() if p.is_dir()]
    return summary, run_dir
