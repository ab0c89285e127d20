"""Stable-Baselines3 ``VecEnv`` over hdgym's native vector env.

SB3 steps a ``VecEnv``; wrapping a Gymnasium vector env in SB3's
``DummyVecEnv`` would step ``n`` Python envs one by one. :class:`HarmonicDriveVecEnv`
hands SB3 the native batch instead (compiled physics, SIMD lanes, threads
from :data:`hdgym.physics.lanes.PARALLEL_THRESHOLD` envs), with the
same-step autoreset SB3 expects::

    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor
    from agents.vec_env import HarmonicDriveVecEnv

    venv = VecMonitor(HarmonicDriveVecEnv("HarmonicDriveJoint-v0", num_envs=64))
    PPO("MlpPolicy", venv, n_steps=256).learn(100_000)

``infos[i]`` carries ``terminal_observation`` and ``TimeLimit.truncated``
for an env whose episode ended (SB3's conventions; ``is_success`` too when
the task reports ``success``), and nothing else: true states for every env
stay available as arrays through :attr:`last_info`.

Training extras run inside the batch, without a Python env per joint:

* ``action_repeat``: each agent action is held for that many control
  periods, per env: an env whose episode ends within the hold stops
  there (its reward is the mean over the periods it lived, its terminal
  observation the one it ended with) and starts its next episode at the
  next agent step, while the others finish their hold;
* ``torque_penalty = (weight, threshold)``: each control period costs
  ``weight * max(0, |T_fs| / threshold - 1)^2`` (true flexspline torque, N m),
  agent-side reward shaping on the peak torque.
Seeds follow SB3: ``seed(s)`` then ``reset()`` seeds env ``i`` with ``s + i``,
so env ``i`` follows a single env reset with ``seed=s + i``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env import VecEnv

import hdgym.envs
from hdgym.hardware import scale_actions
from hdgym.physics import layout as L


class HarmonicDriveVecEnv(VecEnv):
    """``num_envs`` hdgym joints as one SB3 ``VecEnv``.

    Args:
        env_id: a registered hdgym id (``"HarmonicDriveJoint-v0"`` or
            ``"HarmonicDriveResonance-v0"``).
        num_envs: batch size.
        action_repeat: control periods per agent action (held per env).
        torque_penalty: ``(weight, threshold in N m)`` of the reward shaping,
            or None.
        **kwargs: passed to ``gym.make_vec`` (``preset``, ``randomize``,
            ``max_episode_steps``, ``parallel``, ...); the autoreset mode is
            fixed to same-step.
    """

    def __init__(self, env_id: str = "HarmonicDriveJoint-v0", num_envs: int = 1,
                 action_repeat: int = 1, torque_penalty: tuple[float, float] | None = None,
                 **kwargs: Any) -> None:
        if "autoreset_mode" in kwargs:
            raise ValueError("HarmonicDriveVecEnv always resets on the same step (SB3's "
                             "convention); do not pass autoreset_mode")
        if int(action_repeat) != action_repeat or action_repeat < 1:
            raise ValueError(f"action_repeat must be a whole number >= 1, got {action_repeat!r}")
        if torque_penalty is not None:
            w, thr = (float(v) for v in torque_penalty)
            if not (w >= 0 and thr > 0 and math.isfinite(w) and math.isfinite(thr)):
                raise ValueError(f"torque_penalty needs weight >= 0 and threshold > 0 N m, "
                                 f"got {torque_penalty!r}")
            torque_penalty = (w, thr)
        self.action_repeat = int(action_repeat)
        self.torque_penalty = torque_penalty
        hdgym.envs.register_envs()
        self.venv = gym.make_vec(env_id, num_envs=num_envs,
                                 vectorization_mode="vector_entry_point",
                                 autoreset_mode=AutoresetMode.SAME_STEP, **kwargs)
        self._u = self.venv.unwrapped
        self.env_id = env_id
        self.render_mode = self.venv.render_mode
        self.last_info: dict[str, Any] = {}
        self._actions: np.ndarray | None = None
        super().__init__(num_envs, self.venv.single_observation_space,
                         self.venv.single_action_space)

    def reset(self) -> np.ndarray:
        seeds = self._seeds
        seed = None if all(s is None for s in seeds) else list(seeds)
        obs, self.last_info = self.venv.reset(seed=seed)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.float32).reshape(self.num_envs, -1)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async()")
        if self.action_repeat == 1 and self.torque_penalty is None:
            return self._step_once()
        return self._step_held()

    def _step_once(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        obs, rew, term, trunc, info = self.venv.step(self._actions)
        self._actions = None
        self.last_info = info
        dones = term | trunc
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if dones.any():
            final = info["final_obs"]
            success = info["final_info"].get("success")
            for i in np.flatnonzero(dones):
                infos[i]["terminal_observation"] = final[i]
                infos[i]["TimeLimit.truncated"] = bool(trunc[i] and not term[i])
                if success is not None:
                    infos[i]["is_success"] = bool(success[i])
        return obs, rew.astype(np.float32), dones, infos

    def _step_held(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        """``action_repeat`` control periods on the batch, holding each env's action."""
        u, n = self._u, self.num_envs
        b = u.batch
        scale_actions(self._actions.reshape(n), b.rows[:, L.I_MAX], b.act, b.i_cmd)
        self._actions = None
        total = np.zeros(n)
        count = np.zeros(n)
        alive = np.ones(n, dtype=bool)
        term_out = np.zeros(n, dtype=bool)
        trunc_out = np.zeros(n, dtype=bool)
        final_obs = np.zeros_like(b.obs)
        success = np.zeros(n)
        has_success = "success" in u.task.aux_names
        k_success = u.task.aux_names.index("success") if has_success else -1
        limit = u.max_episode_steps
        for _ in range(self.action_repeat):
            b.advance()
            rew = b.rew
            if self.torque_penalty is not None:
                w, thr = self.torque_penalty
                tk = np.nan_to_num(np.abs(b.xs[:, L.TK]), nan=0.0, posinf=0.0)
                excess = np.maximum(0.0, tk / thr - 1.0)
                rew = rew - w * excess * excess
            total[alive] += rew[alive]
            count[alive] += 1
            trunc = b.steps >= limit if limit is not None else np.zeros(n, dtype=bool)
            ended = alive & (b.term | trunc)
            if ended.any():
                final_obs[ended] = b.obs[ended]
                term_out[ended] = b.term[ended]
                trunc_out[ended] = trunc[ended] & ~b.term[ended]
                if has_success:
                    success[ended] = b.aux[ended, k_success]
                alive &= ~ended
                if not alive.any():
                    break
        dones = term_out | trunc_out
        infos: list[dict[str, Any]] = [{} for _ in range(n)]
        if dones.any():
            b.restart(dones)
            for i in np.flatnonzero(dones):
                infos[i]["terminal_observation"] = final_obs[i]
                infos[i]["TimeLimit.truncated"] = bool(trunc_out[i])
                if has_success:
                    infos[i]["is_success"] = bool(success[i])
        self.last_info = u._info()
        return b.obs.copy(), (total / count).astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def render(self, mode: str | None = None) -> np.ndarray | None:
        return self.venv.render()

    # SB3 asks these of the sub-envs; here every env is one batch
    def _indices(self, indices: None | int | Sequence[int]) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        return [indices] if isinstance(indices, int) else list(indices)

    def get_attr(self, attr_name: str, indices: None | int | Sequence[int] = None) -> list[Any]:
        value = getattr(self.venv.unwrapped, attr_name)
        return [value for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any,
                 indices: None | int | Sequence[int] = None) -> None:
        raise AttributeError(f"{self.env_id} vector env: attributes are shared by the batch "
                             f"and cannot be set per env ({attr_name!r})")

    def env_method(self, method_name: str, *method_args: Any,
                   indices: None | int | Sequence[int] = None, **method_kwargs: Any) -> list[Any]:
        result = getattr(self.venv.unwrapped, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class: type,
                       indices: None | int | Sequence[int] = None) -> list[bool]:
        return [False for _ in self._indices(indices)]
