"""agents/: the committed policy crosses the resonance trap; training and evaluation run."""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from agents.baselines import ConstantCurrent, PISpeedController, design_pi  # noqa: E402
from agents.common import load_config, load_policy, make_env, policy_config  # noqa: E402
from agents.evaluate import episode_metrics, evaluate  # noqa: E402
from agents.evaluate import main as evaluate_main  # noqa: E402
from agents.report import trap_only_config  # noqa: E402
from agents.train import main as train_main  # noqa: E402
from agents.vec_env import HarmonicDriveVecEnv  # noqa: E402
from hdgym.envs.resonance import DEFAULT_CURRENT_LIMIT, TRAP_ONLY_CURRENT_LIMIT  # noqa: E402
from hdgym.params import preset  # noqa: E402

POLICY = Path(__file__).resolve().parents[1] / "agents" / "policies" / "resonance_ppo.zip"


def test_committed_policy_is_small_and_carries_its_config():
    assert POLICY.is_file()
    assert POLICY.stat().st_size < 1_000_000
    cfg = policy_config(POLICY)
    assert cfg["env"]["id"] == "HarmonicDriveResonance-v0"
    # the default task: the preset's amplifier (current_limit unset / None)
    assert cfg["env"]["kwargs"].get("current_limit", DEFAULT_CURRENT_LIMIT) is None
    assert set(cfg["env"]["kwargs"]["randomize"]) >= {
        "compliance.stiffness", "friction.output.coulomb", "kinematic_error.amplitude"}


def test_committed_policy_crosses_the_trap_with_lower_peak_torque():
    """The default task (the preset's 6 A), 4 randomized episodes.

    The committed policy reaches the target in every episode, with a peak
    flexspline torque well below constant full current's in each of them.
    """
    model = load_policy(POLICY)
    cfg = policy_config(POLICY)
    stats, traces = evaluate(cfg, ["policy", "full"], 4, 4242, model)
    pol, full = stats
    assert pol.reached == 1.0 and pol.trapped == 0.0
    assert full.reached == 1.0
    mp = episode_metrics(traces["policy"])
    mf = episode_metrics(traces["full"])
    assert np.all(mp["peak_torque"] < 0.75 * mf["peak_torque"])
    assert np.max(traces["full"]["current"]) <= 6.0 + 1e-9


def test_trap_only_variant_traps_full_current_and_pi():
    """``current_limit=3.7``: full current and the saturated PI stay trapped (4 episodes).

    The same episodes cross with the preset's amplifier (previous test).
    """
    cfg = trap_only_config(policy_config(POLICY))
    assert cfg["env"]["kwargs"]["current_limit"] == TRAP_ONLY_CURRENT_LIMIT
    stats, traces = evaluate(cfg, ["full", "pi"], 4, 4242)
    for s in stats:
        assert s.trapped == 1.0 and s.reached == 0.0, s.controller
    # the amplifier saturates at the variant's limit: nobody draws more
    for tr in traces.values():
        assert np.max(tr["current"]) <= TRAP_ONLY_CURRENT_LIMIT + 1e-9


def test_pi_design_meets_its_specification():
    d = design_pi(preset("tuttle-joint1"), crossover_hz=5.0, phase_margin_deg=60.0)
    assert d.kp > 0 and d.ki > 0
    assert math.isclose(d.achieved_pm_deg, 60.0, abs_tol=0.5)
    assert math.isclose(d.achieved_crossover_hz, 5.0, rel_tol=0.02)
    with pytest.raises(ValueError, match="phase margin"):
        design_pi(preset("tuttle-joint1"), crossover_hz=5.0, phase_margin_deg=120.0)


def test_pi_anti_windup_respects_the_limits():
    p = preset("tuttle-joint1")
    pi = PISpeedController(p, target_scale=800.0, dt=1e-3, current_limit=4.0)
    obs = np.zeros((3, 10), dtype=np.float32)
    obs[:, 6] = 0.25  # target 200 rad/s
    obs[:, 0] = [0.0, 0.5, 1.5]  # speed / target
    for _ in range(2000):
        a, _ = pi.predict(obs)
    amps = a[:, 0] * p.amplifier.current_limit
    assert amps[0] == pytest.approx(4.0) and amps[1] == pytest.approx(4.0)
    assert amps[2] < 0
    # the integrator did not wind up: one step with zero error leaves only the clipped value
    assert np.all(np.abs(pi.integral) < 10.0)
    c, _ = ConstantCurrent(0.5).predict(obs)
    assert c.shape == (3, 1) and np.all(c == 0.5)


def test_smoke_training_ppo(tmp_path):
    out = tmp_path / "ppo"
    rc = train_main(["--algo", "ppo", "--total-timesteps", "2000", "--n-envs", "2",
                     "--seed", "3", "--out", str(out), "--no-progress"])
    assert rc == 0
    assert (out / "final.zip").is_file() and (out / "train.json").is_file()
    assert list((out / "monitor").glob("*.monitor.csv"))
    assert list((out / "tb").iterdir())
    model = load_policy(out / "final.zip")
    cfg = policy_config(out / "final.zip")
    assert cfg["train"]["seed"] == 3
    env = make_env(cfg)
    obs, _ = env.reset(seed=0)
    a, _ = model.predict(obs, deterministic=True)
    assert a.shape == (1,)


def test_smoke_training_sac(tmp_path):
    cfg = load_config("resonance_sac")
    assert cfg["train"]["algo"] == "sac"
    out = tmp_path / "sac"
    rc = train_main(["--algo", "sac", "--total-timesteps", "300", "--n-envs", "1",
                     "--out", str(out), "--no-progress"])
    assert rc == 0 and (out / "final.zip").is_file()
    assert policy_config(out / "final.zip")["train"]["algo"] == "sac"


def test_cli_errors_exit_2(tmp_path, capsys):
    assert evaluate_main(["--policy", str(tmp_path / "missing.zip")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert train_main(["--config", str(tmp_path / "nope.toml"), "--no-progress"]) == 2
    assert train_main(["--config", "resonance_sac", "--algo", "ppo", "--no-progress"]) == 2


def test_sb3_vec_env_trains_and_reports_episode_ends():
    """The SB3 VecEnv hands SB3 the native batch: terminal observations, truncation flags
    and seeds follow SB3's conventions, and PPO runs on it."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor

    venv = HarmonicDriveVecEnv("HarmonicDriveJoint-v0", num_envs=4, max_episode_steps=20,
                               preset="tuttle-joint1")
    venv.seed(7)
    first = venv.reset()
    venv.seed(7)
    np.testing.assert_array_equal(venv.reset(), first)
    single = gym.make("HarmonicDriveJoint-v0", preset="tuttle-joint1", max_episode_steps=20)
    np.testing.assert_array_equal(first[2], single.reset(seed=9)[0])
    acts = np.zeros((4, 1), dtype=np.float32)
    for _ in range(20):
        obs, rew, dones, infos = venv.step(acts)
        assert rew.shape == (4,) and dones.dtype == np.bool_ and len(infos) == 4
    assert dones.all()  # every episode truncated at 20 steps
    assert all(info["TimeLimit.truncated"] for info in infos)
    assert all(venv.observation_space.contains(info["terminal_observation"]) for info in infos)
    assert not np.array_equal(infos[0]["terminal_observation"], obs[0])  # obs is the new one
    assert venv.get_attr("num_envs") == [4] * 4 and venv.env_is_wrapped(VecMonitor) == [False] * 4
    model = PPO("MlpPolicy", VecMonitor(venv), n_steps=32, batch_size=64, n_epochs=1, seed=0)
    model.learn(256)
    assert model.num_timesteps >= 256
    venv.close()



def test_sb3_vec_env_rejects_its_fixed_autoreset():
    with pytest.raises(ValueError, match="autoreset_mode"):
        HarmonicDriveVecEnv("HarmonicDriveJoint-v0", num_envs=2, autoreset_mode="next_step")
