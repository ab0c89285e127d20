"""Native vector env: ``n`` joints in one batch on the compiled physics.

``gym.make_vec("HarmonicDriveJoint-v0", num_envs=n,
vectorization_mode="vector_entry_point")`` returns a
:class:`HarmonicDriveVectorEnv`. Every env carries its own parameter row
(randomized per episode when ``randomize`` is given). The physics runs in
SIMD lanes (:mod:`hdgym.physics.lanes`); batches of
``lanes.PARALLEL_THRESHOLD`` envs and more spread over all cores. The
results are the same either way. A step is one compiled call
(:mod:`hdgym.envs.fused`) that writes fresh output arrays; the single env
steps through the composed :meth:`JointBatch.advance`, with the same
numbers.

Seeding: ``reset(seed=s)`` seeds env ``i`` with ``s + i`` (or ``seed`` may
be a list of per-env seeds), so env ``i`` follows exactly the trajectory of
a single env reset with ``seed=s + i`` and given the same actions.
Autoreset is ``NEXT_STEP`` by default (Gymnasium's default): the step after
an env ends returns the first observation of its next episode, reward 0, and
ignores that env's action. ``autoreset_mode="same_step"`` resets it within
the step that ended it instead (the old observation goes to ``info``).

Actions ``(n, 1)`` (or ``(n,)``) in [-1, 1]; values beyond saturate like
the amplifier, NaN or inf raise ``ValueError``. Observations, rewards and
episode ends are those of the single env (see
:class:`~hdgym.envs.joint.HarmonicDriveJointEnv` and
:class:`~hdgym.envs.resonance.HarmonicDriveResonanceEnv`); ``info`` holds
the same keys as arrays of ``n`` with ``_key`` masks.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from hdgym.envs.common import (
    INFO_STATES,
    JointBatch,
    action_space,
    observation_space,
)
from hdgym.envs.fused import N_INFO_FIXED, TASK_IDS, first_bad_action, vector_step
from hdgym.envs.tasks import ResonanceTask, TrackingTask
from hdgym.physics import layout as L


class HarmonicDriveVectorEnv(VectorEnv):
    """``num_envs`` harmonic-drive joints with one task, stepped as one batch.

    Args:
        task: a :class:`~hdgym.envs.tasks.TrackingTask` or
            :class:`~hdgym.envs.tasks.ResonanceTask`.
        num_envs: batch size.
        max_episode_steps: truncation (the registration's by default: 2000
            periods, 3000 for the resonance task).
        render_mode: ``"rgb_array"`` renders env 0.
        parallel: force the threaded (True) or serial (False) kernel;
            None picks by batch size.
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (default, or
            ``"next_step"``) or ``AutoresetMode.SAME_STEP`` (``"same_step"``:
            an env that ends is reset within the same step, its last
            observation and info go to ``info["final_obs"]`` and
            ``info["final_info"]``, masked by ``info["_final_obs"]``; what
            Stable-Baselines3 expects, see ``agents.vec_env``).
        **kwargs: the single env's physics/hardware arguments (``preset``,
            ``without``, ``ctrl_dt``, ``n_substeps``, ``sensors``,
            ``randomize``, ``horizon``, ``torque_limit``, ``speed_limit``,
            ``safety_penalty``, ``load_torque``).
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 50,
                                "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, task: Any, num_envs: int = 1, max_episode_steps: int | None = 2000,
                 render_mode: str | None = None, parallel: bool | None = None,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
                 **kwargs: Any) -> None:
        if int(num_envs) != num_envs or num_envs < 1:
            raise ValueError(f"num_envs must be a whole number >= 1, got {num_envs!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or "
                             f"None, got {render_mode!r}")
        mode = autoreset_mode
        if isinstance(mode, str):
            mode = {"next_step": AutoresetMode.NEXT_STEP,
                    "same_step": AutoresetMode.SAME_STEP}.get(mode.lower(), mode)
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ValueError(f"autoreset_mode must be 'next_step' or 'same_step' (or the "
                             f"AutoresetMode), got {autoreset_mode!r}")
        self.metadata = {**self.metadata, "autoreset_mode": mode}
        self.autoreset_mode = mode
        self.num_envs = int(num_envs)
        self.batch = JointBatch(task, self.num_envs, **kwargs)
        if parallel is not None:
            self.batch.use_threads(bool(parallel))
        self.task = task
        self.params = self.batch.params
        self.max_episode_steps = max_episode_steps
        self.render_mode = render_mode
        self.single_observation_space = observation_space(task)
        self.single_action_space = action_space()
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.prev_done = np.zeros(self.num_envs, dtype=np.bool_)
        self._seeded = False
        self._mask = np.ones(self.num_envs, dtype=np.bool_)
        self._mask.flags.writeable = False
        # the fused step (hdgym.envs.fused): its buffers and the info layout
        b, n = self.batch, self.num_envs
        self._task_id = TASK_IDS[task.name]
        self._imax = b.rows[:, L.I_MAX]
        self._meas = np.zeros((6, n))
        self._z = np.zeros((n, 2))
        self._n_done = 0  # envs in prev_done
        self._info_names = (*INFO_STATES, "time", *task.aux_names)
        assert len(INFO_STATES) + 1 == N_INFO_FIXED
        self._masks = {"_" + k: self._mask for k in (*self._info_names, "diverged")}

    def _info(self) -> dict[str, Any]:
        b = self.batch
        s = b.true_states().T  # a fresh copy; its rows are handed out
        info: dict[str, Any] = {}
        for k, name in enumerate(INFO_STATES):
            info[name] = s[k]
        info["time"] = b.steps * b.ctrl_dt
        for k, name in enumerate(self.task.aux_names):
            info[name] = b.aux[:, k].copy()
        info["diverged"] = b.bad.copy()
        for name in list(info):
            info["_" + name] = self._mask
        return info

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every env. ``seed`` int: env ``i`` gets ``seed + i``; or a list of seeds."""
        n = self.num_envs
        if isinstance(seed, (list, tuple)):
            if len(seed) != n:
                raise ValueError(f"seed list must have {n} entries, got {len(seed)}")
            seeds = list(seed)
        elif seed is not None:
            seeds = [int(seed) + i for i in range(n)]
            super().reset(seed=int(seed))
        else:
            seeds = None
        if seeds is not None:
            self.batch.set_rngs([seeding.np_random(s)[0] for s in seeds], reseeded=True)
            self._seeded = True
        elif not self._seeded:
            self.batch.set_rngs([seeding.np_random(None)[0] for _ in range(n)], reseeded=True)
            self._seeded = True
        self.batch.reset_all()
        self.prev_done = np.zeros(n, dtype=np.bool_)
        self._n_done = 0
        return self.batch.obs.copy(), self._info()

    def _fused(self, phase: int, a: np.ndarray, fresh: np.ndarray,
               out: tuple[np.ndarray, ...]) -> tuple[int, int]:
        b = self.batch
        bank = b.bank
        obs, rew, term, trunc, done, inf = out
        limit = math.inf if self.max_episode_steps is None else self.max_episode_steps
        if phase != 1:
            b.noise_left -= 1  # each env takes one noise sample
        return vector_step(b.lanes.parallel, phase, self._task_id, a, self._imax, b.lanes.W,
                           b.n_substeps, b.xs, b.bad, b.i_cmd, b.t_ext, b.act, bank._steps,
                           bank._prev, bank._held, bank.torque_sensor, bank.delay, self._meas,
                           b.noise_buf, b.noise_ptr, b.noise, self._z, b.tp, b.ts, b.steps,
                           fresh, b.ctrl_dt, b.consts, obs, rew, term, b.aux, inf, trunc, done,
                           limit)

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, Any]]:
        b = self.batch
        n = self.num_envs
        a = np.asarray(actions)
        if a.size != n or a.dtype.kind not in "fiu":
            raise ValueError(f"actions must be numbers of shape ({n}, 1), got "
                             f"{a.dtype} {a.shape}")
        a = a.reshape(n)
        k = first_bad_action(a)
        if k >= 0:
            raise ValueError(f"action must be finite, got {a[k]!r} for env {k}")
        # fresh outputs, written by the compiled step: nothing handed out is reused
        obs = np.empty(b.obs.shape, dtype=np.float32)
        rew = np.empty(n)
        term = np.empty(n, dtype=np.bool_)
        trunc = np.empty(n, dtype=np.bool_)
        done = np.empty(n, dtype=np.bool_)
        inf = np.empty((len(self._info_names), n))
        out = (obs, rew, term, trunc, done, inf)
        if self._n_done:  # NEXT_STEP: envs that ended last step start over instead
            fresh = self.prev_done
            self._fused(1, a, fresh, out)
            b.reset_envs(np.flatnonzero(fresh))
            b.refill_noise()
            n_bad, n_end = self._fused(2, a, fresh, out)
        else:
            b.refill_noise()
            n_bad, n_end = self._fused(0, a, b.no_fresh, out)
        b.obs, b.rew, b.term = obs, rew, term
        if n_bad:  # as JointBatch.true_states: no NaN in info
            np.nan_to_num(inf[:len(INFO_STATES)], copy=False, nan=0.0, posinf=0.0, neginf=0.0)
        info = dict(zip(self._info_names, inf, strict=True))
        info["diverged"] = b.bad.copy()
        info.update(self._masks)
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self.prev_done = done
            self._n_done = n_end
        elif n_end:  # SAME_STEP: the ended envs start over within this step
            final_obs = obs.copy()
            b.restart(done)
            final_info = info
            info = self._info()
            info["final_obs"], info["_final_obs"] = final_obs, done
            info["final_info"], info["_final_info"] = final_info, done
        return obs, rew, term, trunc, info

    def render(self) -> np.ndarray | None:
        """A frame of env 0 (``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array":
            return None
        from hdgym.envs.render import render_frame

        b = self.batch
        return render_frame(b.true_states()[0], b.aux[0], self.task.name,
                            float(b.steps[0] * b.ctrl_dt), b.torque_scale, b.current_limit,
                            b.speed_scale)


_JOINT_TASK = ("reference", "reference_scale", "error_scale", "current_weight")
_RES_TASK = ("target_speed", "oscillation_weight", "torque_time_constant", "deadline")


def _split(kwargs: dict[str, Any], names: tuple[str, ...]) -> dict[str, Any]:
    return {k: kwargs.pop(k) for k in names if k in kwargs}


def make_joint_vector(num_envs: int = 1, **kwargs: Any) -> HarmonicDriveVectorEnv:
    """Vector entry point of ``HarmonicDriveJoint-v0``."""
    task = TrackingTask(**_split(kwargs, _JOINT_TASK))
    return HarmonicDriveVectorEnv(task, num_envs, **kwargs)


def make_resonance_vector(num_envs: int = 1, **kwargs: Any) -> HarmonicDriveVectorEnv:
    """Vector entry point of ``HarmonicDriveResonance-v0`` (and its variants)."""
    from hdgym.envs.resonance import (
        DEADLINE,
        DEFAULT_CURRENT_LIMIT,
        HORIZON,
        gear_rating,
        resonance_params,
    )

    kwargs.setdefault("deadline", DEADLINE)
    kwargs.setdefault("horizon", HORIZON)
    task = ResonanceTask(**_split(kwargs, _RES_TASK))
    if kwargs.get("torque_limit") is None:
        kwargs["torque_limit"] = gear_rating(kwargs.get("preset"))
    kwargs["preset"] = resonance_params(kwargs.get("preset"),
                                        kwargs.pop("current_limit", DEFAULT_CURRENT_LIMIT))
    return HarmonicDriveVectorEnv(task, num_envs, **kwargs)
