"""The engine from Python: the same numbers as the command line, and clear errors."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest

import fdi_mas
from conftest import cli_run


def test_a_run_is_the_command_line_s_in_process_run(fdi_launch, tmp_path):
    summary, _ = cli_run(fdi_launch, tmp_path, "--duration-s", "2")
    result = fdi_mas.run(fdi_mas.Scenario.paper(duration_s=2.0))
    assert result.digest == summary["trace_digest"]
    assert result.summary["rmse_rad"] == summary["rmse_rad"]
    assert result.summary["metrics"] == summary["metrics"]
    assert dict(result.rmse) == {int(k): v for k, v in summary["rmse_rad"].items()}
    # Printed, the RMSE table is the command line's metrics table.
    assert str(result.rmse).startswith("| robot | RMSE (rad) |")
    assert len(str(result.rmse).splitlines()) == 2 + len(summary["rmse_rad"])


def test_overrides_are_the_command_line_s(fdi_launch, tmp_path):
    summary, _ = cli_run(
        fdi_launch, tmp_path, "--duration-s", "1", "--attack", "stealthy-bias", "--seed", "7"
    )
    s = fdi_mas.Scenario.paper(duration_s=1.0, attack="stealthy-bias", seed=7)
    assert (s.attack, s.seed, s.ticks) == ("stealthy-bias", 7, 1000)
    assert fdi_mas.run(s, ticks=False).digest == summary["trace_digest"]


def test_a_team_of_urdf_arms_runs_as_on_the_command_line(fdi_launch, tmp_path):
    scenario = pathlib.Path(__file__).parents[2] / "scenarios" / "panda-team.toml"
    summary, _ = cli_run(fdi_launch, tmp_path, str(scenario), "--duration-s", "0.5")
    s = fdi_mas.Scenario.load(str(scenario), duration_s=0.5)
    assert (s.links, len(s.agents)) == (7, 4)
    r = fdi_mas.run(s)
    assert r.digest == summary["trace_digest"]
    assert r.ticks is not None and len(r.ticks["q7_rad"]) == 4 * 500


def test_a_team_of_different_joint_counts_runs_as_on_the_command_line(fdi_launch, tmp_path):
    scenario = pathlib.Path(__file__).parents[2] / "scenarios" / "mixed-team.toml"
    summary, run_dir = cli_run(fdi_launch, tmp_path, str(scenario), "--duration-s", "0.5")
    s = fdi_mas.Scenario.load(str(scenario), duration_s=0.5)
    assert (s.links, s.joint_counts) == (7, {1: 7, 2: 7, 3: 2, 4: 2})
    r = fdi_mas.run(s)
    assert r.digest == summary["trace_digest"]
    assert r.ticks is not None
    agent = np.asarray(r.ticks["agent"])
    # A column per joint of the largest arm; a two-link arm's other joints are NaN.
    for name in ("q1_rad", "q2_rad"):
        assert np.isfinite(np.asarray(r.ticks[name])).all(), name
    q7 = np.asarray(r.ticks["q7_rad"])
    assert np.isfinite(q7[agent <= 2]).all() and np.isnan(q7[agent >= 3]).all()
    # The command line's run read back gives the same table.
    opened = fdi_mas.open_run(run_dir)
    assert opened.ticks is not None and list(opened.ticks) == list(r.ticks)
    np.testing.assert_array_equal(np.asarray(opened.ticks["q7_rad"]), q7)


def test_open_run_reads_a_command_line_run_as_run_gives_it(fdi_launch, tmp_path):
    summary, run_dir = cli_run(fdi_launch, tmp_path, "--duration-s", "0.5")
    opened = fdi_mas.open_run(run_dir)
    assert opened.digest == summary["trace_digest"]
    assert opened.warnings == []
    assert opened.run_dir == str(run_dir)
    here = fdi_mas.run(fdi_mas.Scenario.paper(duration_s=0.5))
    assert opened.ticks is not None and here.ticks is not None
    assert list(opened.ticks) == list(here.ticks)
    for name, column in here.ticks.items():
        np.testing.assert_array_equal(opened.ticks[name], column, err_msg=name)


def test_every_tick_is_a_column_of_one_row_per_robot_and_tick():
    r = fdi_mas.run(fdi_mas.Scenario.paper(duration_s=0.25))
    assert r.ticks is not None
    rows = 250 * 4
    assert all(len(c) == rows for c in r.ticks.values())
    assert r.ticks["k"][:8].tolist() == [0, 0, 0, 0, 1, 1, 1, 1]
    assert r.ticks["agent"][:4].tolist() == [1, 2, 3, 4]
    assert r.ticks["alarm"].dtype == np.bool_
    # The RMSE of the summary is the one of the columns.
    mine = r.ticks["agent"] == 2
    err = np.concatenate(
        [r.ticks[f"q{i}_des_rad"][mine] - r.ticks[f"q{i}_rad"][mine] for i in (1, 2)]
    )
    assert np.sqrt(np.mean(err**2)) == pytest.approx(r.rmse[2], rel=1e-12)
    frame = r.frame()
    assert frame.shape == (rows, len(r.ticks))


def test_scenario_errors_name_every_field():
    with pytest.raises(fdi_mas.ScenarioError) as e:
        fdi_mas.Scenario.paper(duraton_s=1.0, controller="nope", seed=-1)
    paths = sorted(p for p, _ in e.value.problems)
    assert paths == ["controller", "duraton_s", "seed"], e.value.problems
    with pytest.raises(fdi_mas.ScenarioError) as e:
        fdi_mas.Scenario.paper(duration_s=-1.0)
    assert "duration_s" in [p for p, _ in e.value.problems]
    with pytest.raises(fdi_mas.ScenarioError, match="realtime"):
        fdi_mas.Scenario.paper(clock="realtime")
    with pytest.raises(fdi_mas.ScenarioError, match="no-such-attack"):
        fdi_mas.Scenario.paper(attack="no-such-attack")
    with pytest.raises(fdi_mas.ScenarioError, match="expected a number"):
        fdi_mas.Scenario.paper(duration_s="long")


def test_python_errors_speak_of_keywords_and_suggest_the_name_meant():
    """Regression (issue 55): `Scenario.paper(attack='frezee')` spoke of `--attack`, a bad
    keyword was reported under "command-line overrides", and an unknown preset got no "did
    you mean" where a scenario key does."""
    with pytest.raises(fdi_mas.ScenarioError) as e:
        fdi_mas.Scenario.paper(attack="frezee")
    said = str(e.value)
    assert said.startswith("keyword arguments: 1 problem(s)"), said
    assert "--" not in said and "command-line" not in said, said
    [(path, message)] = e.value.problems
    assert path == "attack" and '"frezee"' in message, e.value.problems
    assert message.endswith("did you mean `freeze`?"), message
    with pytest.raises(fdi_mas.ScenarioError) as e:
        fdi_mas.Scenario.paper(duration_s=-1.0, sed=3)
    said = str(e.value)
    assert said.startswith("keyword arguments: ") and "command-line" not in said, said
    assert ("sed", next(m for p, m in e.value.problems if p == "sed")) in e.value.problems
    assert "did you mean `seed`?" in dict(e.value.problems)["sed"]
    with pytest.raises(fdi_mas.ScenarioError) as e:
        fdi_mas.Scenario.paper().replace(duration_s=0.0)
    assert str(e.value).startswith("keyword arguments: "), str(e.value)


def test_a_scenario_file_s_errors_give_line_and_column(tmp_path: pathlib.Path):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\nduration_s = 1.0\nduraton_s = 2.0\n')
    with pytest.raises(fdi_mas.ScenarioError) as e:
        fdi_mas.Scenario.load(bad)
    assert "duraton_s" in str(e.value) and "line 3" in str(e.value), str(e.value)
    with pytest.raises(fdi_mas.ScenarioError):
        fdi_mas.Scenario.load(tmp_path / "missing.toml")


def test_a_rust_panic_is_an_exception_not_an_abort():
    with pytest.raises(BaseException, match="on purpose"):
        fdi_mas._core.panic_for_test()
    # The interpreter goes on.
    assert fdi_mas.run(fdi_mas.Scenario.paper(duration_s=0.01), ticks=False).summary["ticks"] == 10


def test_ctrl_c_reaches_a_long_run_between_ticks():
    """Regression (issue 51): `fdi_mas.run` ran its whole simulation after Ctrl-C (the engine
    never looked). KeyboardInterrupt now reaches it between ticks."""
    import signal
    import subprocess
    import sys

    # Python leaves SIGINT ignored in a child whose parent ignored it (a job started in the
    # background by a shell): the child asks for Ctrl-C's usual meaning itself.
    script = (
        "import signal\n"
        "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
        "import fdi_mas\n"
        "s = fdi_mas.Scenario.paper(duration_s=100000)\n"
        "print('start', flush=True)\n"
        "try:\n"
        "    fdi_mas.run(s, ticks=False)\n"
        "    print('ran to the end')\n"
        "except KeyboardInterrupt:\n"
        "    print('interrupted')\n"
    )
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "start"
    p.send_signal(signal.SIGINT)
    out, _ = p.communicate(timeout=300)
    assert out.strip() == "interrupted", out
