"""The environments: Gymnasium's and PettingZoo's own checks, bit-exactness with the command
line, and clear errors for bad input."""

from __future__ import annotations

import pathlib

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test

import fdi_mas
from conftest import cli_run
from fdi_mas.envs import (
    AttackerEnv,
    DefenderEnv,
    DetectorEnv,
    VectorAttackerEnv,
    VectorDefenderEnv,
    attack_defend_v0,
)
from fdi_mas.envs._common import ClosedEnvironmentError

SHORT = fdi_mas.Scenario.paper(duration_s=0.3)


def run_episode(env, action):
    env.reset(seed=0)
    total, steps = 0.0, 0
    while True:
        _, reward, terminated, truncated, info = env.step(action)
        total += reward
        steps += 1
        if terminated or truncated:
            return total, steps, info


def test_gymnasium_s_checker_passes_on_every_environment():
    check_env(AttackerEnv(SHORT), skip_render_check=True)
    check_env(DetectorEnv(SHORT), skip_render_check=True)
    check_env(DefenderEnv(SHORT, decision_period=1), skip_render_check=True)
    check_env(AttackerEnv(SHORT, channels=("position", "velocity", "torque"), decision_period=10))


def test_pettingzoo_s_parallel_api_test_passes():
    parallel_api_test(attack_defend_v0.parallel_env(scenario=SHORT), num_cycles=400)
    parallel_api_test(
        attack_defend_v0.parallel_env(scenario=SHORT, attacks=("none", "paper"), decision_period=25),
        num_cycles=100,
    )


def test_the_registered_ids_make_the_environments():
    env = gym.make("fdi_mas/Attacker-v0", scenario=SHORT)
    assert isinstance(env.unwrapped, AttackerEnv)
    env = gym.make("fdi_mas/Detector-v0", scenario=SHORT)
    assert isinstance(env.unwrapped, DetectorEnv)
    env = gym.make("fdi_mas/Defender-v0", scenario=SHORT)
    assert isinstance(env.unwrapped, DefenderEnv)
    vec = gym.make_vec("fdi_mas/Attacker-v0", num_envs=3, vectorization_mode="vector_entry_point", scenario=SHORT)
    assert vec.num_envs == 3


@pytest.mark.parametrize("period", [1, 7])
def test_zero_actions_on_the_scenario_s_attack_give_the_command_line_s_digest(fdi_launch, tmp_path, period):
    summary, _ = cli_run(fdi_launch, tmp_path, "--duration-s", "2")
    env = AttackerEnv(fdi_mas.Scenario.paper(duration_s=2.0), attack=None, decision_period=period)
    _, steps, info = run_episode(env, np.zeros(env.action_space.shape))
    assert steps == -(-2000 // period)
    assert info["digest"] == summary["trace_digest"]
    assert info["summary"]["rmse_rad"] == summary["rmse_rad"]


def test_the_vector_environment_gives_each_episode_the_single_one_s_digest():
    scenario = fdi_mas.Scenario.paper(duration_s=0.2)
    single = AttackerEnv(scenario, attack="paper")
    _, steps, info = run_episode(single, np.zeros(single.action_space.shape))
    vec = VectorAttackerEnv(5, scenario, attack="paper", threads=2)
    obs, _ = vec.reset(seed=0)
    assert obs.shape == (5, single.observation_space.shape[0])
    for i in range(steps):
        obs, rewards, term, trunc, _ = vec.step(np.zeros(vec.action_space.shape))
        assert rewards.shape == (5,)
        assert trunc.all() == (i == steps - 1)
    assert vec.digests() == [info["digest"]] * 5
    # Next-step autoreset: the step after the end starts new episodes.
    obs, rewards, term, trunc, _ = vec.step(np.zeros(vec.action_space.shape))
    assert not trunc.any() and (rewards == 0).all() and (obs == 0).all()
    vec.close()
    with pytest.raises(ClosedEnvironmentError):
        vec.step(np.zeros(vec.action_space.shape))


def test_an_injection_does_damage_and_detectors_see_a_large_one():
    scenario = fdi_mas.Scenario.paper(duration_s=3.0, residual="psi2")
    env = AttackerEnv(scenario, robots=[2], budget={"position": 0.2}, stealth_weight=0.0)
    clean, _, info_clean = run_episode(env, np.zeros(env.action_space.shape))
    full, _, info_full = run_episode(env, np.ones(env.action_space.shape))
    assert info_full["summary"]["rmse_rad"]["2"] > 2 * info_clean["summary"]["rmse_rad"]["2"]
    assert info_full["summary"]["rmse_rad"]["1"] == info_clean["summary"]["rmse_rad"]["1"]
    assert info_full["summary"]["metrics"]["2"]["attacked_ticks"] == 3000
    assert info_clean["summary"]["metrics"]["2"]["attacked_ticks"] == 0
    # Weights: all damage, then all stealth.
    assert full > clean
    # Stealth only: the detectors (ψ2 residual) stay silent without an injection, and alarm
    # on the large one.
    loud = AttackerEnv(scenario, robots=[2], budget={"position": 0.2}, damage_weight=0.0)
    assert run_episode(loud, np.zeros(loud.action_space.shape))[0] == 0
    assert run_episode(loud, np.ones(loud.action_space.shape))[0] < 0


@pytest.mark.parametrize(
    "action, message",
    [
        (np.full((4, 1, 2), np.nan), "finite"),
        (np.zeros((4, 2)), "shape"),
        (np.full((4, 1, 2), 1.5), r"outside \[-1, 1\]"),
        ([[0.0]], "shape"),
    ],
)
def test_bad_actions_raise_value_error_and_change_nothing(action, message):
    env = AttackerEnv(SHORT)
    env.reset()
    with pytest.raises(ValueError, match=message):
        env.step(action)
    # The episode goes on.
    _, _, _, _, info = env.step(np.zeros(env.action_space.shape))
    assert info["ticks"] == 1


def test_bad_arguments_and_misuse_raise_clear_errors():
    with pytest.raises(ValueError, match="not a robot"):
        AttackerEnv(SHORT, robots=[9])
    with pytest.raises(ValueError, match="no detector"):
        AttackerEnv(SHORT, detectors=("chi3",))
    with pytest.raises(ValueError, match="no channel"):
        AttackerEnv(SHORT, channels=("voltage",))
    with pytest.raises(ValueError, match="budget"):
        AttackerEnv(SHORT, budget={"position": -1.0})
    with pytest.raises(fdi_mas.ScenarioError):
        AttackerEnv(SHORT, attack="nope")
    with pytest.raises(ValueError, match="attacks"):
        DetectorEnv(SHORT, attacks=("nope",))
    env = AttackerEnv(SHORT)
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(env.action_space.shape))
    env.reset()
    env.close()
    with pytest.raises(ClosedEnvironmentError):
        env.step(np.zeros(env.action_space.shape))
    with pytest.raises(ClosedEnvironmentError):
        env.reset()
    det = DetectorEnv(SHORT)
    det.reset(seed=1)
    with pytest.raises(ValueError, match="0 or 1"):
        det.step(np.array([0, 1, 2, 0]))
    with pytest.raises(ValueError, match="shape"):
        det.step(np.array([0, 1]))


def test_the_detector_environment_draws_its_attack_from_its_seed_and_scores_alarms():
    env = DetectorEnv(fdi_mas.Scenario.paper(duration_s=0.2), attacks=("none", "paper"), decision_period=20)
    drawn = [env.reset(seed=s)[1]["attack"] for s in range(12)]
    assert set(drawn) == {"none", "paper"}
    assert drawn == [env.reset(seed=s)[1]["attack"] for s in range(12)]
    env.reset(options={"attack": "none"})
    # No attack: an alarm costs a false alarm per tick, silence costs nothing.
    _, r_on, *_ = env.step(np.ones(4, dtype=np.int8))
    _, r_off, *_ = env.step(np.zeros(4, dtype=np.int8))
    # Per robot-tick: -1 for every robot alarming on every clean tick.
    assert r_on == -1.0 and r_off == 0
    env.reset(options={"attack": "paper"})
    _, r_on, _, _, info = env.step(np.ones(4, dtype=np.int8))
    attacked = sum(info["attacked_ticks"])
    assert attacked > 0 and r_on == (attacked - (4 * 20 - attacked)) / (4 * 20)


def test_the_attacker_s_reward_is_on_the_attack_free_error_s_scale():
    """Regression (issue 55): the stealth penalty (1 per alarmed tick) was about 1000 times
    the damage term (about 1e-3 rad per tick): every perturbation of a policy scored far below
    the zero policy. Both terms are now per tick and of order one."""
    scenario = fdi_mas.Scenario.paper(duration_s=2.0, residual="psi2")
    env = AttackerEnv(scenario, robots=[2], budget={"position": 0.2}, decision_period=50)
    scale = env.damage_scale
    assert 1e-5 < scale < 0.1
    clean, steps, info = run_episode(env, np.zeros(env.action_space.shape))
    assert info["damage_scale_rad"] == scale
    # The attack-free episode: error on its own scale, no alarm: a return of 0.
    assert abs(clean) < 1e-9 * steps
    # Each step's reward from its info: the documented formula.
    env.reset()
    _, r, _, _, i = env.step(np.ones(env.action_space.shape))
    e = i["damage"] / i["ticks"]
    assert r == pytest.approx((e / scale - 1.0) - i["alarm_ticks"] / i["ticks"], rel=1e-12)
    with pytest.raises(ValueError, match="damage_scale"):
        AttackerEnv(scenario, damage_scale=0.0)
    given = AttackerEnv(scenario, damage_scale=0.01)
    assert given.damage_scale == 0.01


def test_the_vector_environment_names_the_environment_of_a_bad_action():
    vec = VectorAttackerEnv(3, SHORT, threads=2)
    vec.reset()
    actions = np.zeros(vec.action_space.shape)
    actions[1, 0, 0] = np.nan
    with pytest.raises(ValueError, match="environment 1: .*finite"):
        vec.step(actions)
    with pytest.raises(ValueError, match="shape"):
        vec.step(np.zeros((2, 4, 1, 2)))
    # Nothing ran: the next good step is every environment's first tick.
    obs, *_ = vec.step(np.zeros(vec.action_space.shape))
    assert (obs[:, 0] == 0.0).all()


def test_a_vector_environment_too_large_for_the_memory_left_raises_memory_error():
    """Regression (issue 51): `VectorAttackerEnv(100000)` (about 83 KB an environment) under a
    memory limit aborted the interpreter ("memory allocation … failed"). The size is checked
    first: MemoryError, saying what it would need, and the interpreter goes on."""
    import subprocess
    import sys
    import textwrap

    script = textwrap.dedent(
        """
        import resource
        import fdi_mas
        from fdi_mas.envs import VectorAttackerEnv
        scenario = fdi_mas.Scenario.paper(duration_s=0.3)
        VectorAttackerEnv(2, scenario, threads=1)  # the module's own memory, first
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))
        try:
            VectorAttackerEnv(100000, scenario, threads=1)
        except MemoryError as e:
            print("MemoryError:", e)
        print("still here")
        """
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert "MemoryError: 100000 environments need about" in out.stdout, out.stdout + out.stderr
    assert "still here" in out.stdout


def test_the_defender_s_zero_corrections_give_the_command_line_s_digest(fdi_launch, tmp_path):
    summary, _ = cli_run(fdi_launch, tmp_path, "--duration-s", "2", "--attack", "actuator-bias")
    env = DefenderEnv(fdi_mas.Scenario.paper(duration_s=2.0), attacks=("actuator-bias",), vary_seed=False, decision_period=7)
    _, steps, info = run_episode(env, np.zeros(env.action_space.shape))
    assert steps == -(-2000 // 7)
    assert info["digest"] == summary["trace_digest"]


def test_the_defender_s_correction_reaches_the_torque_and_its_reward_counts_error_and_effort():
    scenario = fdi_mas.Scenario.paper(duration_s=0.5)
    env = DefenderEnv(scenario, attacks=("none",), vary_seed=False, decision_period=500, effort_weight=0.5)
    zero, corrected = np.zeros(env.action_space.shape), np.full(env.action_space.shape, 0.5)
    env.reset()
    _, r0, _, _, i0 = env.step(zero)
    env.reset()
    _, r1, _, _, i1 = env.step(corrected)
    # Without a correction: the attack-free run's own error, so its reward is -e/scale alone.
    assert i0["effort"] == 0.0 and r0 == pytest.approx(-i0["tracking_error"] / env.error_scale)
    assert i1["effort"] == 0.25 and r1 == pytest.approx(-i1["tracking_error"] / env.error_scale - 0.5 * 0.25)
    assert i1["tracking_error"] != i0["tracking_error"], "the correction moved the robots"
    # The torque the center records is the controller's plus the correction (N·m).
    assert i1["digest"] != i0["digest"]
    with pytest.raises(ValueError, match="outside"):
        env.reset()
        env.step(np.full(env.action_space.shape, 2.0))
    with pytest.raises(ValueError, match="correction_budget"):
        DefenderEnv(scenario, correction_budget=0.0)


def test_the_vector_defender_gives_each_episode_the_single_one_s_digest_and_rewards():
    scenario = fdi_mas.Scenario.paper(duration_s=0.2)
    single = DefenderEnv(scenario, attacks=("actuator-bias",), vary_seed=False, decision_period=20)
    single.reset()
    action = np.full(single.action_space.shape, 0.25)
    want = []
    while True:
        _, r, te, tr, info = single.step(action)
        want.append(r)
        if te or tr:
            break
    vec = VectorDefenderEnv(3, scenario, attacks=("actuator-bias",), vary_seed=False, decision_period=20, threads=2)
    obs, _ = vec.reset(seed=0)
    assert obs.shape == (3, single.observation_space.shape[0])
    got = []
    for _ in want:
        _, rewards, term, trunc, _ = vec.step(np.broadcast_to(action, (3, *action.shape)))
        got.append(rewards.copy())
    assert np.array_equal(np.array(got), np.repeat(np.array(want)[:, None], 3, axis=1))
    assert trunc.all() and not term.any()
    assert vec.digests() == [info["digest"]] * 3
    # Its draws: the same seed, the same episodes; several attacks are all drawn.
    mixed = [VectorDefenderEnv(8, scenario, attacks=("none", "paper"), decision_period=200, seed=5) for _ in range(2)]
    for v in mixed:
        v.reset()
        v.step(np.zeros((8, *action.shape)))
    assert mixed[0].digests() == mixed[1].digests() and len(set(mixed[0].digests())) > 1
    vec = gym.make_vec("fdi_mas/Defender-v0", num_envs=2, vectorization_mode="vector_entry_point", scenario=scenario)
    assert vec.num_envs == 2


MIXED = pathlib.Path(__file__).parents[2] / "scenarios" / "mixed-team.toml"


def test_a_team_of_different_robots_has_each_robot_s_joints_and_ignores_the_rest_of_an_action(fdi_launch, tmp_path):
    summary, _ = cli_run(fdi_launch, tmp_path, str(MIXED), "--duration-s", "0.2")
    s = fdi_mas.Scenario.load(str(MIXED), duration_s=0.2)
    env = AttackerEnv(s, attack=None, channels=("position", "velocity"))
    assert (env.joints, env.links) == ([7, 7, 2, 2], 7)
    assert env.observation_space.shape == (1 + 3 * 18,)
    names = env.observation_names
    assert "robot3.y2" in names and "robot3.y3" not in names and names[-1] == "robot4.u2"
    assert env.action_space.shape == env.action_mask.shape == (4, 2, 7)
    assert env.action_mask[:2].all() and env.action_mask[2:, :, :2].all() and not env.action_mask[2:, :, 2:].any()
    # Zeros: the command line's run. Values where the mask is False: ignored, the same run.
    _, _, zeros = run_episode(env, np.zeros(env.action_space.shape))
    assert zeros["digest"] == summary["trace_digest"]
    ignored = np.where(env.action_mask, 0.0, 0.9)
    _, _, info = run_episode(env, ignored)
    assert info["digest"] == zeros["digest"]
    acting = np.zeros(env.action_space.shape)
    acting[2, 0, 1] = 0.5
    _, _, info = run_episode(env, acting)
    assert info["digest"] != zeros["digest"], "an entry of a joint acts"
    # The vector environment: the single one's episode.
    vec = VectorAttackerEnv(2, s, attack=None, channels=("position", "velocity"), threads=1)
    obs, _ = vec.reset(seed=0)
    assert obs.shape == (2, 1 + 3 * 18) and (vec.joints, vec.links) == ([7, 7, 2, 2], 7)
    while not vec.step(np.broadcast_to(ignored, (2, *ignored.shape)))[3].all():
        pass
    assert vec.digests() == [zeros["digest"]] * 2
    vec.close()


def test_a_team_of_different_robots_passes_the_checkers_and_the_defence_counts_the_joints_it_acts_on():
    s = fdi_mas.Scenario.load(str(MIXED), duration_s=0.05)
    check_env(AttackerEnv(s), skip_render_check=True)
    check_env(DetectorEnv(s), skip_render_check=True)
    check_env(DefenderEnv(s, decision_period=5), skip_render_check=True)
    parallel_api_test(attack_defend_v0.parallel_env(scenario=s), num_cycles=60)
    defender = DefenderEnv(s, attacks=("none",), vary_seed=False, decision_period=50)
    assert defender.observation_space.shape == (1 + 5 * 18,) and defender.action_space.shape == (4, 7)
    defender.reset()
    # 0.5 on every joint, 1 beyond a robot's joints (ignored): the effort is 0.25.
    _, _, _, _, info = defender.step(np.where(defender.action_mask, 0.5, 1.0))
    assert info["effort"] == 0.25
    # A correction of a two-joint arm reaches it; one beyond its joints changes nothing.
    small = DefenderEnv(s, attacks=("none",), vary_seed=False, decision_period=50)
    zeros = run_episode(small, np.zeros(small.action_space.shape))[2]["digest"]
    beyond = np.zeros(small.action_space.shape)
    beyond[2, 2:] = 1.0
    assert run_episode(small, beyond)[2]["digest"] == zeros
    on_joint = np.zeros(small.action_space.shape)
    on_joint[2, 1] = 1.0
    assert run_episode(small, on_joint)[2]["digest"] != zeros
    vec = VectorDefenderEnv(2, s, attacks=("none",), vary_seed=False, decision_period=50, threads=1)
    vec.reset(seed=0)
    _, rewards, _, _, _ = vec.step(np.broadcast_to(np.where(defender.action_mask, 0.5, 1.0), (2, 4, 7)))
    assert vec.joints == [7, 7, 2, 2]
    assert rewards[0] == rewards[1] and np.isfinite(rewards).all()
    vec.close()
