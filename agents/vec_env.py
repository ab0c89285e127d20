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
for an env whose episode ended (SB3's conventions), and nothing else: true
states for every env stay available as arrays through :attr:`last_info`.
Seeds follow SB3: ``seed(s)`` then ``reset()`` seeds env ``i`` with ``s + i``,
so env ``i`` follows a single env reset with ``seed=s + i``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env import VecEnv

import hdgym.envs


class HarmonicDriveVecEnv(VecEnv):
    """``num_envs`` hdgym joints as one SB3 ``VecEnv``.

    Args:
        env_id: a registered hdgym id (``"HarmonicDriveJoint-v0"`` or
            ``"HarmonicDriveResonance-v0"``).
        num_envs: batch size.
        **kwargs: passed to ``gym.make_vec`` (``preset``, ``randomize``,
            ``max_episode_steps``, ``parallel``, ...); the autoreset mode is
            fixed to same-step.
    """

    def __init__(self, env_id: str = "HarmonicDriveJoint-v0", num_envs: int = 1,
                 **kwargs: Any) -> None:
        if "autoreset_mode" in kwargs:
            raise ValueError("HarmonicDriveVecEnv always resets on the same step (SB3's "
                             "convention); do not pass autoreset_mode")
        hdgym.envs.register_envs()
        self.venv = gym.make_vec(env_id, num_envs=num_envs,
                                 vectorization_mode="vector_entry_point",
                                 autoreset_mode=AutoresetMode.SAME_STEP, **kwargs)
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
        obs, rew, term, trunc, info = self.venv.step(self._actions)
        self._actions = None
        self.last_info = info
        dones = term | trunc
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if dones.any():
            final = info["final_obs"]
            for i in np.flatnonzero(dones):
                infos[i]["terminal_observation"] = final[i]
                infos[i]["TimeLimit.truncated"] = bool(trunc[i] and not term[i])
        return obs, rew.astype(np.float32), dones, infos

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
