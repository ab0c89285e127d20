"""Gymnasium environments: registration, conformance, determinism, vector env."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import hdgym  # noqa: F401  (registers the ids)
from hdgym.envs.vector import HarmonicDriveVectorEnv
from hdgym.params import preset

IDS = ("HarmonicDriveJoint-v0", "HarmonicDriveResonance-v0")
JOINT = preset("tuttle-joint1")
NOISY = {"torque_noise": 0.5, "current_noise": 0.02, "delay": 1}
RAND = {"compliance.stiffness": 0.2, "friction.output.coulomb": 0.3,
        "kinematic_error.amplitude": 0.2, "load.inertia": 0.2}


def make(env_id: str, **kw):
    return gym.make(env_id, preset=JOINT, **kw)


def rollout(env, actions, seed):
    obs, info = env.reset(seed=seed)
    out = [obs]
    rews = []
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        out.append(obs)
        rews.append(r)
        if term or trunc:
            obs, info = env.reset()
            out.append(obs)
    return np.array(out), np.array(rews)


# ------------------------------------------------------------------ registration
def test_registered_after_import():
    for env_id in IDS:
        assert env_id in gym.registry
        spec = gym.spec(env_id)
        assert spec.max_episode_steps == (3000 if "Resonance" in env_id else 2000)
        assert spec.vector_entry_point is not None
    hdgym.envs.register_envs()  # idempotent
    env = make(IDS[0])
    assert env.unwrapped.params is JOINT


def test_default_preset_is_tuttle_joint1():
    for env_id in IDS:
        env = gym.make(env_id)
        assert env.unwrapped.params.name == "tuttle-joint1"
        env.reset(seed=0)
        env.step(env.action_space.sample())


def test_module_colon_id_form_without_import():
    code = textwrap.dedent("""
        import sys
        import gymnasium as gym
        try:
            gym.make("HarmonicDriveJoint-v0")
        except gym.error.Error:
            pass
        else:
            raise SystemExit("registered without importing hdgym")
        assert "hdgym" not in sys.modules
        for env_id in ("HarmonicDriveJoint-v0", "HarmonicDriveResonance-v0"):
            try:
                env = gym.make("hdgym:" + env_id)
                env.reset(seed=0)
            except ValueError as exc:  # registered, but the default preset is not bundled yet
                assert "tuttle-joint1" in str(exc), exc
            assert env_id in gym.registry
        print("ok")
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip().endswith("ok")


# ------------------------------------------------------------------ conformance
@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_check_env(env_id):
    from gymnasium.utils.env_checker import check_env

    env = make(env_id, sensors=NOISY, randomize=RAND)
    check_env(env.unwrapped)


@pytest.mark.parametrize("env_id", IDS)
def test_sb3_check_env(env_id):
    from stable_baselines3.common.env_checker import check_env

    check_env(make(env_id).unwrapped, warn=True)


@pytest.mark.parametrize("env_id", IDS)
def test_same_seed_same_trajectory(env_id):
    acts = np.random.default_rng(1).uniform(-1.5, 1.5, (300, 1)).astype(np.float32)
    kw = {"sensors": NOISY, "randomize": RAND, "max_episode_steps": 120}
    o1, r1 = rollout(make(env_id, **kw), acts, seed=3)
    o2, r2 = rollout(make(env_id, **kw), acts, seed=3)
    np.testing.assert_array_equal(o1, o2)
    np.testing.assert_array_equal(r1, r2)


def test_different_seeds_differ_with_randomization():
    acts = np.zeros((50, 1), dtype=np.float32)
    env = make(IDS[0], randomize=RAND, reference="sine")
    env.reset(seed=1)
    row1 = env.unwrapped.param_row.copy()
    o1, _ = rollout(env, acts, seed=1)
    env.reset(seed=2)
    row2 = env.unwrapped.param_row.copy()
    o2, _ = rollout(env, acts, seed=2)
    assert not np.array_equal(row1, row2)
    assert not np.array_equal(o1, o2)
    # without randomization the drive is the preset's every episode
    plain = make(IDS[0]).unwrapped
    plain.reset(seed=1)
    a = plain.param_row.copy()
    plain.reset(seed=2)
    np.testing.assert_array_equal(a, plain.param_row)


@pytest.mark.parametrize("env_id", IDS)
def test_nan_action_raises(env_id):
    env = make(env_id)
    env.reset(seed=0)
    for bad in (np.nan, np.inf, -np.inf):
        with pytest.raises(ValueError):
            env.step(np.array([bad], dtype=np.float32))
    venv = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point",
                        preset=JOINT)
    venv.reset(seed=0)
    with pytest.raises(ValueError):
        venv.step(np.array([[0.1], [np.nan]], dtype=np.float32))


@pytest.mark.parametrize("env_id", IDS)
def test_out_of_range_action_saturates(env_id):
    e1, e2 = make(env_id).unwrapped, make(env_id).unwrapped
    o1, _ = e1.reset(seed=5)
    o2, _ = e2.reset(seed=5)
    for big, clipped in ((5.0, 1.0), (1e6, 1.0), (-1e6, -1.0), (-1.0001, -1.0)):
        s1 = e1.step(np.array([big], dtype=np.float32))
        s2 = e2.step(np.array([clipped], dtype=np.float32))
        np.testing.assert_array_equal(s1[0], s2[0])
        assert s1[1] == s2[1]


@pytest.mark.parametrize("env_id", IDS)
def test_observations_stay_in_box(env_id):
    rng = np.random.default_rng(0)
    env = make(env_id, sensors=NOISY, randomize=RAND, max_episode_steps=400)
    obs, info = env.reset(seed=0)
    space = env.observation_space
    assert space.contains(obs)
    choices = np.array([-1e6, -1.0, 0.0, 1.0, 1e6], dtype=np.float32)
    for k in range(1200):
        a = rng.choice(choices) if k % 3 else rng.uniform(-3, 3)
        obs, r, term, trunc, info = env.step(np.array([a], dtype=np.float32))
        assert space.contains(obs), obs
        assert np.isfinite(r)
        assert all(np.isfinite(v) for v in info.values())
        if term or trunc:
            obs, info = env.reset()
            assert space.contains(obs)


def test_diverging_simulation_terminates_finite():
    # a far too coarse integration step makes the stiff joint blow up
    env = make(IDS[0], ctrl_dt=0.05, n_substeps=1)
    obs, _ = env.reset(seed=0)
    for _ in range(200):
        obs, r, term, trunc, info = env.step(np.array([1.0], dtype=np.float32))
        assert env.observation_space.contains(obs)
        assert np.isfinite(r) and all(np.isfinite(v) for v in info.values())
        if term:
            break
    assert term and r <= -99.0


# ------------------------------------------------------------------ vector env
@pytest.mark.parametrize("env_id,kw", [
    (IDS[0], {"sensors": NOISY, "randomize": RAND}),
    (IDS[1], {"sensors": NOISY, "randomize": RAND, "torque_limit": 40.0}),
])
@pytest.mark.parametrize("parallel", [False, True])
def test_vector_equals_single_envs(env_id, kw, parallel):
    n, seed, horizon, steps = 3, 11, 40, 100
    venv = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point",
                        max_episode_steps=horizon, parallel=parallel, preset=JOINT, **kw)
    assert isinstance(venv.unwrapped, HarmonicDriveVectorEnv)
    assert venv.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
    singles = [make(env_id, max_episode_steps=horizon, **kw) for _ in range(n)]
    acts = np.random.default_rng(2).uniform(-1.2, 1.2, (steps, n, 1)).astype(np.float32)
    vobs, vinfo = venv.reset(seed=seed)
    done = [False] * n
    for i, env in enumerate(singles):
        obs, info = env.reset(seed=seed + i)
        np.testing.assert_array_equal(vobs[i], obs)
        assert vinfo["motor_angle"][i] == info["motor_angle"]
    resets = 0
    for k in range(steps):
        vobs, vrew, vterm, vtrunc, vinfo = venv.step(acts[k])
        for i, env in enumerate(singles):
            if done[i]:  # NEXT_STEP autoreset: this step starts env i's next episode
                obs, info = env.reset()
                r, term, trunc = 0.0, False, False
                resets += 1
            else:
                obs, r, term, trunc, info = env.step(acts[k, i])
            np.testing.assert_array_equal(vobs[i], obs, err_msg=f"step {k} env {i}")
            assert vrew[i] == r and vterm[i] == term and vtrunc[i] == trunc, (k, i)
            assert vinfo["output_torque"][i] == info["output_torque"]
            done[i] = term or trunc
    assert resets >= n * 2


@pytest.mark.parametrize("env_id,kw", [
    (IDS[0], {"sensors": NOISY, "randomize": RAND}),
    (IDS[1], {"sensors": NOISY, "randomize": RAND, "torque_limit": 40.0}),
])
def test_vector_same_step_autoreset_equals_single_envs(env_id, kw):
    """SAME_STEP: an env that ends is reset within the step; its last observation goes
    to info["final_obs"]. Env i still follows a single env (reset as soon as it ends)."""
    n, seed, horizon, steps = 3, 5, 30, 100
    venv = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point",
                        max_episode_steps=horizon, autoreset_mode="same_step", preset=JOINT,
                        **kw)
    assert venv.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    singles = [make(env_id, max_episode_steps=horizon, **kw) for _ in range(n)]
    acts = np.random.default_rng(3).uniform(-1.2, 1.2, (steps, n, 1)).astype(np.float32)
    vobs, _ = venv.reset(seed=seed)
    for i, env in enumerate(singles):
        np.testing.assert_array_equal(vobs[i], env.reset(seed=seed + i)[0])
    ends = 0
    for k in range(steps):
        vobs, vrew, vterm, vtrunc, vinfo = venv.step(acts[k])
        for i, env in enumerate(singles):
            obs, r, term, trunc, info = env.step(acts[k, i])
            assert vrew[i] == r and vterm[i] == term and vtrunc[i] == trunc, (k, i)
            if term or trunc:
                ends += 1
                assert vinfo["_final_obs"][i]
                np.testing.assert_array_equal(vinfo["final_obs"][i], obs)
                assert vinfo["final_info"]["output_torque"][i] == info["output_torque"]
                obs, info = env.reset()
            else:
                assert "final_obs" not in vinfo or not vinfo["_final_obs"][i]
            np.testing.assert_array_equal(vobs[i], obs, err_msg=f"step {k} env {i}")
            assert vinfo["motor_angle"][i] == info["motor_angle"]
    assert ends >= n * 3
    with pytest.raises(ValueError, match="autoreset_mode"):
        gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point",
                     autoreset_mode="sometimes")


def test_vector_spaces_and_reset_seed_list():
    venv = gym.make_vec(IDS[0], num_envs=4, vectorization_mode="vector_entry_point",
                        preset=JOINT)
    assert venv.observation_space.shape == (4, 12)
    assert venv.action_space.shape == (4, 1)
    o1, _ = venv.reset(seed=[5, 6, 7, 8])
    o2, _ = venv.reset(seed=5)
    np.testing.assert_array_equal(o1, o2)
    obs, rew, term, trunc, info = venv.step(venv.action_space.sample())
    assert venv.observation_space.contains(obs)
    assert rew.shape == (4,) and term.dtype == np.bool_ and info["_motor_angle"].all()


# ------------------------------------------------------------------ render, effects
@pytest.mark.parametrize("env_id", IDS)
def test_render_rgb_array(env_id):
    env = make(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(np.array([0.7], dtype=np.float32))
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    assert frame.shape[0] >= 200 and frame.shape[1] >= 200
    assert frame.std() > 5  # not blank
    venv = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point",
                        preset=JOINT, render_mode="rgb_array")
    venv.reset(seed=0)
    assert venv.render().shape == frame.shape


def test_without_kinematic_error_changes_dynamics():
    acts = np.full((150, 1), 0.8, dtype=np.float32)
    o1, _ = rollout(make(IDS[0], reference="sine"), acts, seed=4)
    env = make(IDS[0], reference="sine", without=["kinematic_error"])
    assert "kinematic_error" not in env.unwrapped.batch.effects
    o2, _ = rollout(env, acts, seed=4)
    assert not np.array_equal(o1, o2)


def test_unknown_names_raise():
    with pytest.raises(ValueError, match="kinematic_errr"):
        make(IDS[0], without=["kinematic_errr"])
    with pytest.raises(ValueError, match="compliance.stiffnes"):
        make(IDS[0], randomize={"compliance.stiffnes": 0.1})
    with pytest.raises(ValueError, match="reference"):
        make(IDS[0], reference="zigzag")
    with pytest.raises(ValueError, match="spread"):
        make(IDS[0], randomize={"compliance.stiffness": 1.5})
    with pytest.raises(ValueError, match="cannot be randomized"):
        make(IDS[0], randomize={"kinematic_error.order": 0.1})
    with pytest.raises(ValueError, match="motor_countz"):
        make(IDS[0], sensors={"motor_countz": 10})


def test_resonance_current_limit_overrides_the_amplifier():
    from hdgym.envs.resonance import DEFAULT_CURRENT_LIMIT, TRAP_ONLY_CURRENT_LIMIT
    from hdgym.physics import layout as L

    # the default keeps the preset's 6 A amplifier; the trap-only variant's 3.7 A sits inside
    # Tuttle's 2.8-4.0 A velocity plateau
    assert DEFAULT_CURRENT_LIMIT is None
    assert 2.8 <= TRAP_ONLY_CURRENT_LIMIT <= 4.0
    u = make(IDS[1]).unwrapped
    assert u.params.amplifier.current_limit == JOINT.amplifier.current_limit == 6.0
    assert u.params.amplifier.voltage_limit == JOINT.amplifier.voltage_limit
    assert make(IDS[1], current_limit=None).unwrapped.params.amplifier.current_limit == 6.0
    vdef = gym.make_vec(IDS[1], num_envs=2, vectorization_mode="vector_entry_point", preset=JOINT)
    assert np.all(vdef.unwrapped.batch.rows[:, L.I_MAX] == 6.0)
    for lim in (TRAP_ONLY_CURRENT_LIMIT, 2.5, 5.0):
        env = make(IDS[1], current_limit=lim).unwrapped
        venv = gym.make_vec(IDS[1], num_envs=3, vectorization_mode="vector_entry_point",
                            preset=JOINT, current_limit=lim)
        assert env.batch.current_limit == lim and env.param_row[L.I_MAX] == lim
        assert np.all(venv.unwrapped.batch.rows[:, L.I_MAX] == lim)
        env.reset(seed=0)
        venv.reset(seed=0)
        acts = np.array([[1e6], [-1.0], [0.5]], dtype=np.float32)
        for _ in range(30):  # 30 ms: the 500 Hz current loop has settled, back-EMF far away
            _, _, _, _, info = env.step(np.array([1e6], dtype=np.float32))
            _, _, _, _, vinfo = venv.step(acts)
        assert info["motor_current"] == pytest.approx(lim, abs=1e-6)
        np.testing.assert_allclose(vinfo["motor_current"], [lim, -lim, 0.5 * lim], atol=1e-6)
    for bad in (0.0, -1.0, float("nan"), float("inf"), "big"):
        with pytest.raises(ValueError, match="current_limit"):
            make(IDS[1], current_limit=bad)
        with pytest.raises(ValueError, match="current_limit"):
            gym.make_vec(IDS[1], num_envs=2, vectorization_mode="vector_entry_point",
                         preset=JOINT, current_limit=bad)


def test_randomize_slow_path_and_tuples():
    env = make(IDS[0], randomize={"transmission.n": 0.05,
                                  "hysteresis.element_stiffness": 0.2}).unwrapped
    env.reset(seed=0)
    from hdgym.physics import layout as L

    base = L.pack(JOINT)
    row = env.param_row
    assert row[L.RATIO] != base[L.RATIO]
    assert row[L.SLIP_K] != base[L.SLIP_K]


# ------------------------------------------------------------------ SB3 smoke
def test_ppo_smoke():
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    venv = DummyVecEnv([lambda: make(IDS[0])])
    model = PPO("MlpPolicy", venv, n_steps=128, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=256)


# ------------------------------------------------------------------ the resonance task
def test_resonance_task_rating_deadline_and_success():
    """The registered task: the rating ends an episode, success needs the target by the
    deadline within the rating, and info reports time to target and peak torque."""
    from hdgym.envs.resonance import DEADLINE, GEAR_RATINGS, LONG_DEADLINE, LONG_EPISODE

    env = gym.make("HarmonicDriveResonance-v0")
    u = env.unwrapped
    rating = GEAR_RATINGS["tuttle-joint1"]
    assert u.batch.torque_limit == rating and 100.0 < rating < 100.0 / 0.35
    assert u.task.deadline == DEADLINE and env.spec.max_episode_steps == 3000
    obs, info = env.reset(seed=3)
    assert info["time_to_target"] == -1.0 and info["success"] == 0.0
    peak = 0.0
    for _ in range(3000):  # constant full current: fast, but over the rating
        obs, r, term, trunc, info = env.step(np.array([1.0], dtype=np.float32))
        peak = max(peak, abs(info["output_torque"]))
        assert info["peak_torque"] == pytest.approx(peak)
        if term or trunc:
            break
    assert term and info["peak_torque"] > rating and info["success"] == 0.0
    assert r < -50  # the safety penalty
    # without the rating (a huge limit) the same run reaches the target: success; the Long
    # variant runs LONG_EPISODE with the time observation saturating at the default horizon
    env = gym.make("HarmonicDriveResonanceLong-v0", torque_limit=1e6)
    assert env.unwrapped.task.deadline == LONG_DEADLINE and DEADLINE < LONG_DEADLINE
    assert env.spec.max_episode_steps == round(LONG_EPISODE * 1000) > 3000
    assert env.unwrapped.batch.horizon == 3.0
    env.reset(seed=3)
    for _ in range(env.spec.max_episode_steps):
        _, _, term, trunc, info = env.step(np.array([1.0], dtype=np.float32))
        if term or trunc:
            break
    assert trunc and not term
    assert 0.0 < info["time_to_target"] < LONG_DEADLINE and info["success"] == 1.0
    # a deadline shorter than the run-up: reached, but too late
    env = gym.make("HarmonicDriveResonance-v0", torque_limit=1e6, deadline=0.1,
                   max_episode_steps=3000)
    env.reset(seed=3)
    for _ in range(3000):
        _, _, term, trunc, info = env.step(np.array([1.0], dtype=np.float32))
    assert info["time_to_target"] > 0.1 and info["success"] == 0.0
    with pytest.raises(ValueError, match="deadline"):
        gym.make("HarmonicDriveResonance-v0", deadline=0.0)


def test_resonance_constants_are_the_ones_the_pages_state():
    """README and docs/envs.md state the registered deadline, rating and long deadline (they
    are set by agents.benchmark's rules, so a change must reach the texts too)."""
    from hdgym.envs.resonance import DEADLINE, GEAR_RATINGS

    root = Path(__file__).resolve().parents[1]
    phrase = (f"within a {DEADLINE:g} s deadline and never above the gear's "
              f"{GEAR_RATINGS['tuttle-joint1']:g} N m rating")
    for page in ("README.md", "docs/envs.md"):
        assert phrase in (root / page).read_text(), page
    assert f"(default {DEADLINE:g};" in (root / "docs/envs.md").read_text()
    from hdgym.envs.resonance import LONG_DEADLINE, LONG_EPISODE

    long = (f"`HarmonicDriveResonanceLong-v0` ({LONG_EPISODE:g} s episodes, {LONG_DEADLINE:g} s "
            "deadline")
    for page in ("README.md", "docs/envs.md"):
        assert long in (root / page).read_text(), page
    assert f"`HarmonicDriveResonanceLong-v0`: {LONG_DEADLINE:g}, on {LONG_EPISODE:g} s" in (
        root / "docs/envs.md").read_text()


def test_resonance_without_torque_sensor_and_saturating_time():
    env = gym.make("HarmonicDriveResonanceNoTorqueSensor-v0", max_episode_steps=40,
                   horizon=0.02)
    obs, _ = env.reset(seed=0)
    for _ in range(30):
        obs, *_ = env.step(np.array([1.0], dtype=np.float32))
    assert obs[4] == 0.0 and obs[7] == 0.0  # the torque channels read 0
    assert obs[0] > 0  # the encoders still see the speed
    assert obs[9] == 1.0  # time / horizon saturates at 1 past the horizon


def test_resonance_vector_env_reports_the_task_per_env():
    v = gym.make_vec("HarmonicDriveResonance-v0", num_envs=3,
                     vectorization_mode="vector_entry_point", torque_limit=1e6)
    single = gym.make("HarmonicDriveResonance-v0", torque_limit=1e6)
    v.reset(seed=11)
    single.reset(seed=12)
    for _ in range(1500):
        _, _, _, _, info = v.step(np.ones((3, 1), dtype=np.float32))
        _, _, _, _, si = single.step(np.array([1.0], dtype=np.float32))
    for key in ("time_to_target", "peak_torque", "success"):
        assert info[key][1] == si[key]


def test_bench_vector_runner_steps_a_chunk_and_cycles():
    """The short timed rounds of the 1,024-env bench walk through the actions in order and
    wrap around, each round reporting the env steps it ran."""
    from hdgym.envs.bench import _vector_runner

    seen = []

    class Env:
        def step(self, a):
            seen.append(int(a[0, 0]))

    actions = np.arange(5).reshape(5, 1, 1) * np.ones((1, 4, 1))
    run = _vector_runner(Env(), actions, chunk=3)
    assert run() == 12 and run() == 12
    assert seen == [0, 1, 2, 3, 4, 0]
    whole = _vector_runner(Env(), actions)
    assert whole() == 20 and seen[6:] == [0, 1, 2, 3, 4]
