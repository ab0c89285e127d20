"""The native vector env's one-call step (hdgym.envs.fused) against single envs.

A single env steps through the composed path (:meth:`JointBatch.advance`:
physics, :class:`SensorBank`, noise, the task's post function, each a separate
call); the vector env runs the same pieces fused per block of 64 envs. Over
several blocks, threaded and not, with frequent safety terminations and
truncations (NEXT_STEP autoresets mid-block) and past a sensor-noise block
(256 samples per env), every observation, reward, episode end and ``info``
value must be equal bit for bit.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import hdgym  # noqa: F401  (registers the ids)
from hdgym.envs.common import NOISE_BLOCK
from hdgym.hardware import scale_actions
from hdgym.params import preset
from hdgym.physics import layout as L

IDS = ("HarmonicDriveJoint-v0", "HarmonicDriveResonance-v0")
JOINT = preset("tuttle-joint1")


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("parallel,sensors", [
    (False, {"torque_noise": 0.5, "current_noise": 0.02, "delay": 1}),
    (True, {"torque_noise": 0.3, "current_noise": 0.01, "delay": 0}),
])
def test_fused_vector_step_equals_single_envs(env_id, parallel, sensors):
    n, seed, steps = 70, 4, NOISE_BLOCK + 40  # two blocks, one noise refill
    kw = {"preset": JOINT, "sensors": sensors, "torque_limit": 8.0, "speed_limit": 150.0,
          "max_episode_steps": 45, "randomize": {"compliance.stiffness": 0.2}}
    venv = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point",
                        parallel=parallel, **kw)
    singles = [gym.make(env_id, **kw) for _ in range(n)]
    acts = np.random.default_rng(5).uniform(-1.3, 1.3, (steps, n, 1)).astype(np.float32)
    vobs, _ = venv.reset(seed=seed)
    for i, env in enumerate(singles):
        np.testing.assert_array_equal(vobs[i], env.reset(seed=seed + i)[0])
    done = np.zeros(n, dtype=bool)
    n_term = n_trunc = 0
    for k in range(steps):
        vobs, vrew, vterm, vtrunc, vinfo = venv.step(acts[k])
        for i, env in enumerate(singles):
            if done[i]:
                obs, info = env.reset()
                r, term, trunc = 0.0, False, False
            else:
                obs, r, term, trunc, info = env.step(acts[k, i])
            np.testing.assert_array_equal(vobs[i], obs, err_msg=f"step {k} env {i}")
            assert (vrew[i], vterm[i], vtrunc[i]) == (r, term, trunc), (k, i)
            for key, v in info.items():
                assert vinfo[key][i] == v, (k, i, key)
            done[i] = term or trunc
            n_term += term
            n_trunc += trunc
    assert n_term >= n and n_trunc >= n  # autoresets everywhere, mid-block


def test_fused_step_mixed_with_composed_advance_keeps_the_noise_stream():
    """Steps through ``JointBatch.advance`` (as agents.vec_env holds actions) between
    fused steps, past a noise-block refill: the fused step must see the samples the
    composed path took (a stale count would read past the block)."""
    n, seed, steps = 5, 8, NOISE_BLOCK + 60
    kw = {"preset": JOINT, "sensors": {"torque_noise": 0.4, "current_noise": 0.02},
          "max_episode_steps": 10_000}
    venv = gym.make_vec(IDS[0], num_envs=n, vectorization_mode="vector_entry_point", **kw)
    u = venv.unwrapped
    singles = [gym.make(IDS[0], **kw) for _ in range(n)]
    acts = np.random.default_rng(9).uniform(-0.3, 0.3, (steps, n, 1)).astype(np.float32)
    venv.reset(seed=seed)
    for i, env in enumerate(singles):
        env.reset(seed=seed + i)
    for k in range(steps):
        if k % 3 == 1:  # the composed path, as agents.vec_env._step_held
            scale_actions(acts[k].reshape(n), u.batch.rows[:, L.I_MAX], u.batch.act,
                          u.batch.i_cmd)
            u.batch.advance()
            vobs = u.batch.obs
        else:
            vobs = venv.step(acts[k])[0]
        for i, env in enumerate(singles):
            obs, _, term, trunc, _ = env.step(acts[k, i])
            assert not (term or trunc)
            np.testing.assert_array_equal(vobs[i], obs, err_msg=f"step {k} env {i}")
