"""The search of examples/python/cem_attack.py, in its short form: it writes a profile whose
run through the command line has the digest the search measured."""

from __future__ import annotations

import json
import subprocess
import sys

from conftest import REPO, cli_run


def test_the_found_attack_replays_through_the_command_line(fdi_launch, tmp_path):
    found = tmp_path / "found.toml"
    done = subprocess.run(
        [
            sys.executable,
            str(REPO / "examples" / "python" / "cem_attack.py"),
            "--iterations", "2",
            "--population", "4",
            "--duration-s", "6",
            "--out", str(found),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "iteration 2/2" in done.stdout
    result = json.loads(found.with_suffix(".json").read_text())
    runs = tmp_path / "runs"
    runs.mkdir()
    summary, _ = cli_run(
        fdi_launch, runs, "--duration-s", "6", "--residual", "psi2", "--attack", str(found)
    )
    assert summary["trace_digest"] == result["digest"]
    assert summary["rmse_rad"]["2"] == result["rmse_rad"]
