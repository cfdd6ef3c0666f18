"""The training examples (examples/python/train_attacker.py, train_detector.py,
train_defender.py), in their short forms: each runs, prints one line of its curve per
iteration, and the attacker's policy and the defence end above the zero policy they start from
(seeded: the same numbers every run)."""

from __future__ import annotations

import re
import subprocess
import sys

from conftest import REPO


def example(name: str, *args: str) -> str:
    done = subprocess.run(
        [sys.executable, str(REPO / "examples" / "python" / name), *args],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def curve(out: str) -> list[float]:
    """The last column of the iteration lines: the policy's (or detector's) own return."""
    return [float(m.group(1)) for m in re.finditer(r"^\s+\d+\s.*?(-?\d+\.\d+)$", out, re.M)]


def test_the_attacker_learns_a_policy_better_than_doing_nothing():
    out = example("train_attacker.py", "--iterations", "3", "--population", "8", "--elite", "3", "--duration-s", "2")
    c = curve(out)
    assert len(c) == 4, out
    assert c[0] == 0.0 and c[-1] > c[0], out
    assert "× the attack-free run's" in out and "alarmed on" in out


def test_the_detector_example_prints_its_curve():
    out = example("train_detector.py", "--iterations", "1", "--population", "3", "--elite", "1", "--duration-s", "2")
    c = curve(out)
    assert len(c) == 2, out
    assert "at the start (never alarming)" in out


def test_the_defence_learns_to_track_better_than_correcting_nothing():
    out = example("train_defender.py", "--iterations", "2", "--population", "6", "--elite", "2", "--duration-s", "4")
    c = curve(out)
    assert len(c) == 3, out
    assert c[-1] > c[0], out
    assert "at the start (no correction)" in out and "× the attack-free run's" in out
