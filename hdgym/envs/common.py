"""Plumbing shared by the single and the vector environments.

:class:`JointBatch` holds ``n`` joints as flat arrays (state rows, parameter
rows, effect flags), steps them with the compiled kernel, reads them through
:class:`hdgym.hardware.SensorBank` and hands the readings to a task's
compiled observation/reward function. A single env is a batch of one, so the
single env and env ``i`` of the vector env run the same code.

Random numbers: env ``i`` owns one ``numpy.random.Generator``. Each episode
draws, in this order, the randomized parameters (in the order of the
``randomize`` mapping), the initial WG angle and the task's reference or
target. Sensor noise (when on) is drawn from the same generator in blocks
of :data:`NOISE_BLOCK` samples per env, one sample per observation. The
vector env seeds env ``i`` with ``seed + i``; a single env reset with
``seed + i`` then gives the same trajectory step for step.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from hdgym.effects import check_effects, flags_of
from hdgym.envs.tasks import N_COMMON, OBS_BOUND
from hdgym.hardware import CHANNELS, SensorBank
from hdgym.params import JointParams, preset
from hdgym.physics import layout as L
from hdgym.physics.lanes import PARALLEL_THRESHOLD, LaneBatch

DEFAULT_PRESET = "tuttle-joint1"
#: sensor-noise samples drawn per env at a time
NOISE_BLOCK = 256

#: true-state names reported in ``info`` (state columns 0..5 of the layout)
INFO_STATES = ("motor_angle", "motor_velocity", "output_angle", "output_velocity",
               "motor_current", "output_torque")
_INFO_COLS = slice(L.TH_M, L.TK + 1)
assert [L.TH_M, L.W_M, L.TH_O, L.W_O, L.CUR, L.TK] == list(range(6))  # a slice, not a gather

# parameter-row columns that are switches, counts or orders, not physical values
_NOT_RANDOMIZABLE = re.compile(
    r"(compliance\.model|hysteresis\.model|hysteresis\.n_elements|kinematic_error\.n_harmonics"
    r"|kinematic_error\.order|friction\.(input|output)\.(n_ripple|ripple\[\d+\]\.(order|frame)))"
    r"(\[\d+\])?$")


def resolve_params(p: str | JointParams | None) -> JointParams:
    """A preset name (or None for the default) or a JointParams -> JointParams."""
    if p is None:
        p = DEFAULT_PRESET
    if isinstance(p, str):
        return preset(p)
    if isinstance(p, JointParams):
        return p
    raise ValueError(f"preset must be a preset name or a JointParams, got {type(p).__name__}")


class Randomizer:
    """Per-episode domain randomization: ``value * (1 + spread * U(-1, 1))``.

    Paths that are columns of the packed parameter row
    (:data:`hdgym.physics.layout.PARAM_INDEX`; a tuple field such as
    ``hysteresis.element_stiffness`` scales each element independently)
    are drawn directly on the row. Any other numeric JointParams path (e.g.
    ``transmission.n``, ``friction.tooth_angle``) goes through
    :meth:`JointParams.perturb` and :func:`layout.pack` (slower, validated);
    those are drawn first, then the row paths, each in the mapping's order.
    Sensor and integration settings cannot be randomized per episode.

    Row draws do not re-check cross-field constraints (e.g. breakaway >=
    coulomb friction); spreads must be in [0, 1) so signs never flip.
    """

    def __init__(self, params: JointParams, spec: Mapping[str, float] | None) -> None:
        self.params = params
        self.base = L.pack(params)
        self.row_items: list[tuple[np.ndarray, float]] = []
        self.slow: dict[str, float] = {}
        for path, spread in (spec or {}).items():
            if not isinstance(path, str):
                raise ValueError(f"randomize: keys must be dotted parameter paths, got {path!r}")
            try:
                spread = float(spread)
            except (TypeError, ValueError):
                raise ValueError(f"randomize[{path!r}]: spread must be a number, "
                                 f"got {spread!r}") from None
            if not (0.0 <= spread < 1.0):
                raise ValueError(f"randomize[{path!r}]: spread must be in [0, 1), got {spread!r}")
            head = path.split(".")[0]
            if head in ("sensors", "integration") or _NOT_RANDOMIZABLE.match(path):
                raise ValueError(f"randomize: {path!r} cannot be randomized per episode")
            col = path if path != "friction.tooth_mu" else "friction.load_coefficient"
            if col in L.PARAM_INDEX:
                self.row_items.append((np.array([L.PARAM_INDEX[col]]), spread))
            elif f"{col}[0]" in L.PARAM_INDEX:
                k0 = L.PARAM_INDEX[f"{col}[0]"]
                k = 0
                while f"{col}[{k}]" in L.PARAM_INDEX:
                    k += 1
                self.row_items.append((np.arange(k0, k0 + k), spread))
            else:
                try:
                    value = params.get(path)
                except ValueError:
                    raise ValueError(f"randomize: unknown parameter {path!r}") from None
                if isinstance(value, bool) or not isinstance(value, (int, float, tuple)):
                    raise ValueError(f"randomize: {path!r} is not numeric")
                self.slow[path] = spread

    @property
    def active(self) -> bool:
        return bool(self.row_items or self.slow)

    def draw(self, rng: np.random.Generator) -> np.ndarray:
        """A fresh parameter row for one episode."""
        row = L.pack(self.params.perturb(rng, self.slow)) if self.slow else self.base.copy()
        for cols, spread in self.row_items:
            row[cols] = row[cols] * (1.0 + spread * rng.uniform(-1.0, 1.0, cols.size))
        return row


class JointBatch:
    """``n`` joints on the compiled physics behind the hardware layer, with a task.

    See the env docstrings for the keyword arguments; this class does the
    work for both :class:`HarmonicDriveEnv` (``n = 1``) and
    :class:`~hdgym.envs.vector.HarmonicDriveVectorEnv`.
    """

    def __init__(self, task: Any, n: int, preset: str | JointParams | None = None,
                 without: Iterable[str] = (), ctrl_dt: float | None = None,
                 n_substeps: int | None = None, sensors: Mapping[str, Any] | None = None,
                 randomize: Mapping[str, float] | None = None, horizon: float = 2.0,
                 torque_limit: float | None = None, speed_limit: float | None = None,
                 safety_penalty: float = 100.0, load_torque: float = 0.0) -> None:
        if isinstance(without, str):
            without = (without,)
        without = check_effects(without, "without")
        params = resolve_params(preset)
        integ = params.integration
        ctrl_dt = integ.ctrl_dt if ctrl_dt is None else float(ctrl_dt)
        n_substeps = integ.n_substeps if n_substeps is None else n_substeps
        if not (ctrl_dt > 0 and math.isfinite(ctrl_dt)):
            raise ValueError(f"ctrl_dt must be > 0 s, got {ctrl_dt!r}")
        if int(n_substeps) != n_substeps or n_substeps < 1:
            raise ValueError(f"n_substeps must be a whole number >= 1, got {n_substeps!r}")
        if sensors:
            try:
                sens = replace(params.sensors, **dict(sensors))
            except TypeError as exc:
                raise ValueError(f"sensors: {exc}") from None
        else:
            sens = params.sensors
        if not (horizon > 0 and math.isfinite(horizon)):
            raise ValueError(f"horizon must be > 0 s, got {horizon!r}")
        if not (safety_penalty >= 0 and math.isfinite(safety_penalty)):
            raise ValueError(f"safety_penalty must be >= 0, got {safety_penalty!r}")
        if not math.isfinite(load_torque):
            raise ValueError(f"load_torque must be finite, got {load_torque!r}")
        self.params = params
        self.task = task
        self.n = n
        self.without = without
        self.effects = tuple(e for e in params.effects if e not in without)
        self.flag = flags_of(self.effects)
        self.ctrl_dt = ctrl_dt
        self.n_substeps = int(n_substeps)
        self.dt = ctrl_dt / self.n_substeps
        self.sensor_params = sens
        self.horizon = float(horizon)
        self.randomizer = Randomizer(params, randomize)

        # nominal scales (from the unrandomized drive, so normalization is fixed)
        m, a = params.motor, params.amplifier
        self.ratio = params.ratio
        self.current_limit = a.current_limit
        self.torque_scale = m.torque_constant * a.current_limit * self.ratio
        self.speed_scale = a.voltage_limit / m.back_emf_constant if m.back_emf_constant > 0 \
            else 1000.0
        self.torque_limit = 8.0 * self.torque_scale if torque_limit is None else float(torque_limit)
        self.speed_limit = 1.5 * self.speed_scale if speed_limit is None else float(speed_limit)
        if not (self.torque_limit > 0 and self.speed_limit > 0):
            raise ValueError("torque_limit and speed_limit must be > 0")
        c = np.zeros(N_COMMON)
        c[:] = [self.ratio, self.current_limit, self.torque_scale, self.speed_scale,
                self.torque_limit, self.speed_limit, safety_penalty,
                sens.torque_noise if sens.torque_sensor else 0.0, sens.current_noise, self.horizon]
        self.consts = np.concatenate([c, np.asarray(task.constants(), dtype=float)])
        self.noise = (sens.torque_noise > 0 and sens.torque_sensor) or sens.current_noise > 0

        # batch arrays, allocated once
        self.rows = np.tile(self.randomizer.base, (n, 1))
        self.flags = np.full(n, self.flag, dtype=np.int64)
        self.xs = L.initial_state(self.rows, self.flags)
        self.i_cmd = np.zeros(n)
        self.t_ext = np.full(n, float(load_torque))
        self.bad = np.zeros(n, dtype=np.bool_)
        self.act = np.zeros(n)
        self.steps = np.zeros(n, dtype=np.int64)
        self.tp = np.zeros((n, task.n_params))
        self.ts = np.zeros((n, task.n_state))
        self.obs = np.zeros((n, len(task.obs_names)), dtype=np.float32)
        self.rew = np.zeros(n)
        self.term = np.zeros(n, dtype=np.bool_)
        self.aux = np.zeros((n, len(task.aux_names)))
        self.no_fresh = np.zeros(n, dtype=np.bool_)
        self.all_fresh = np.ones(n, dtype=np.bool_)
        self.zeros2 = np.zeros((n, 2))
        self.noise_buf = np.zeros((n, NOISE_BLOCK, 2))
        self.noise_ptr = np.full(n, NOISE_BLOCK)  # per env: envs can restart mid-step
        #: samples every env still has in its block (0: unknown, look before using one)
        self.noise_left = 0
        self._all = np.arange(n)
        self.rngs: list[np.random.Generator] = [np.random.default_rng() for _ in range(n)]
        # noise is drawn per env by this class (see module docstring), not by the bank
        quiet = replace(sens, torque_noise=0.0, current_noise=0.0)
        self.bank = SensorBank.from_params(n, quiet, ctrl_dt, np.random.default_rng(0))
        # the physics runs in SIMD lanes (hdgym.physics.lanes); ``xs`` mirrors its state
        self.lanes = LaneBatch(self.xs, self.rows, self.flags, self.dt)
        self.use_threads(n >= PARALLEL_THRESHOLD)

    def use_threads(self, on: bool) -> None:
        """Step the physics and the task on all cores (or on one); the numbers are the same."""
        self.lanes.parallel = on
        self.post = self.task.post_parallel if on else self.task.post

    # ------------------------------------------------------------ episodes
    def set_rngs(self, rngs: Sequence[np.random.Generator], reseeded: bool = True) -> None:
        """Use these generators (one per env); a reseed restarts the noise blocks."""
        self.rngs = list(rngs)
        if reseeded:
            self.noise_ptr[:] = NOISE_BLOCK
            self.noise_left = 0

    def _draw_episode(self, i: int) -> float:
        rng = self.rngs[i]
        self.rows[i] = self.randomizer.draw(rng)
        return float(rng.uniform(0.0, 2.0 * math.pi))

    def reset_envs(self, idx: np.ndarray) -> None:
        """Start new episodes for envs ``idx`` (draws, state at rest, sensors)."""
        th = np.array([self._draw_episode(int(i)) for i in idx])
        x0 = L.initial_state(self.rows[idx], self.flags[idx], motor_angle=th)
        self.xs[idx] = x0
        self.lanes.load(self.xs, self.rows, self.flags, idx)
        self.bad[idx] = False
        self.steps[idx] = 0
        self.act[idx] = 0.0
        self.ts[idx] = 0.0
        for j, i in enumerate(idx):
            self.tp[i] = self.task.draw(self.rngs[int(i)], float(x0[j, L.TH_O]), self.horizon)

    def refill_noise(self) -> None:
        """Make sure every env has a noise sample left: a new block for the envs whose
        block is used up, from their own generators. Callers that take samples without
        :meth:`_noise` (the vector env's compiled step) lower :attr:`noise_left` by one
        per sample each env takes."""
        if not self.noise or self.noise_left > 0:
            return
        ptr = self.noise_ptr
        for i in np.flatnonzero(ptr >= NOISE_BLOCK):
            self.rngs[i].standard_normal((NOISE_BLOCK, 2), out=self.noise_buf[i])
            ptr[i] = 0
        self.noise_left = NOISE_BLOCK - int(ptr.max())

    def _noise(self, idx: np.ndarray | None = None) -> np.ndarray:
        """The next noise sample ``(len(idx), 2)`` of envs ``idx`` (all by default)."""
        if not self.noise:
            return self.zeros2 if idx is None else np.zeros((len(idx), 2))
        self.noise_left = 0  # the pointers move here: refill_noise looks again
        ptr = self.noise_ptr
        if idx is None and ptr[0] < NOISE_BLOCK and (ptr == ptr[0]).all():
            # the usual step: every env at the same sample, so a view does
            z = self.noise_buf[:, ptr[0], :]
            ptr += 1
            return z
        sel = self._all if idx is None else idx
        for i in sel[ptr[sel] >= NOISE_BLOCK]:
            self.rngs[i].standard_normal((NOISE_BLOCK, 2), out=self.noise_buf[i])
            self.noise_ptr[i] = 0
        z = self.noise_buf[sel, self.noise_ptr[sel]]
        self.noise_ptr[sel] += 1
        return z

    def reset_all(self) -> None:
        """New episodes for every env; fills ``obs`` (rewards 0, nothing terminated)."""
        self.reset_envs(np.arange(self.n))
        meas = self.bank.reset(self.xs)
        self.post(self.xs, self.bad, meas, self._noise(), self.act, self.tp, self.ts,
                  self.steps, self.all_fresh, self.ctrl_dt, self.consts, self.obs, self.rew,
                  self.term, self.aux)

    def advance(self, reset_mask: np.ndarray | None = None) -> None:
        """One control period for all envs with ``i_cmd``/``act`` already set.

        Envs in ``reset_mask`` start a new episode instead (autoreset): their
        observation is the first of the new episode, reward 0, not terminated.
        """
        self.lanes.step(self.i_cmd, self.t_ext, self.n_substeps, self.xs, self.bad)
        meas = self.bank.measure(self.xs)
        self.steps += 1
        fresh = self.no_fresh
        if reset_mask is not None and reset_mask.any():
            idx = np.flatnonzero(reset_mask)
            self.reset_envs(idx)
            reading = self.bank.reset(self.xs, reset_mask)
            meas = meas.copy()
            meas[:, idx] = reading[:, idx]
            fresh = reset_mask
        self.post(self.xs, self.bad, meas, self._noise(), self.act, self.tp, self.ts,
                  self.steps, fresh, self.ctrl_dt, self.consts, self.obs, self.rew, self.term,
                  self.aux)

    def restart(self, mask: np.ndarray) -> None:
        """Start new episodes now for the envs in ``mask`` (same-step autoreset).

        Their observation becomes the first of the new episode; the rewards and
        episode ends of the step that finished them are left in place.
        """
        idx = np.flatnonzero(mask)
        if idx.size == 0:
            return
        self.reset_envs(idx)
        reading = self.bank.reset(self.xs, mask)[:, idx]
        obs, ts, aux = self.obs[idx], self.ts[idx], self.aux[idx]
        self.task.post(self.xs[idx], self.bad[idx], np.ascontiguousarray(reading),
                       self._noise(idx), self.act[idx], self.tp[idx], ts, self.steps[idx],
                       self.all_fresh[idx], self.ctrl_dt, self.consts, obs,
                       np.zeros(idx.size), np.zeros(idx.size, dtype=np.bool_), aux)
        self.obs[idx], self.ts[idx], self.aux[idx] = obs, ts, aux

    def true_states(self) -> np.ndarray:
        """A fresh ``(n, 6)`` array of the true states in :data:`INFO_STATES` order, NaN -> 0."""
        s = self.xs[:, _INFO_COLS]
        return np.nan_to_num(s, nan=0.0, posinf=0.0, neginf=0.0) if self.bad.any() else s.copy()


def observation_space(task: Any) -> spaces.Box:
    """The flat normalized observation box of a task."""
    dim = len(task.obs_names)
    return spaces.Box(-OBS_BOUND, OBS_BOUND, (dim,), dtype=np.float32)


def action_space() -> spaces.Box:
    """Normalized current command; 1 asks for the amplifier's full current."""
    return spaces.Box(-1.0, 1.0, (1,), dtype=np.float32)


def scalar_action(action: Any) -> float:
    """The single env's action as a float clipped to [-1, 1].

    Same numbers as :func:`hdgym.hardware.scale_actions` (which the
    vector env calls): NaN/inf raise ``ValueError``, values beyond +-1
    saturate like the amplifier.
    """
    if type(action) is np.ndarray and action.shape == (1,) and action.dtype.kind in "iuf":
        a = float(action[0])
    else:  # what Box((1,)) can hold: one real number in an array (or list) of shape (1,)
        arr = np.asarray(action) if isinstance(action, (np.ndarray, list, tuple)) else None
        if arr is None or arr.dtype.kind not in "iuf" or arr.shape != (1,):
            what = (f"shape {arr.shape}, dtype {arr.dtype}" if arr is not None
                    else type(action).__name__)
            raise ValueError(f"action must be an array of shape (1,) holding one real number "
                             f"(the action space is Box(-1, 1, (1,))), got {action!r} ({what})")
        a = float(arr[0])
    if not math.isfinite(a):
        raise ValueError(f"action must be finite, got {action!r}")
    return 1.0 if a > 1.0 else (-1.0 if a < -1.0 else a)


class HarmonicDriveEnv(gym.Env):
    """Base of the single-joint environments (a :class:`JointBatch` of one).

    Subclasses pick the task; see :class:`~hdgym.envs.joint.HarmonicDriveJointEnv`
    and :class:`~hdgym.envs.resonance.HarmonicDriveResonanceEnv` for the
    spaces, rewards and arguments.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 50}

    def __init__(self, task: Any, render_mode: str | None = None, **kwargs: Any) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or "
                             f"None, got {render_mode!r}")
        self.batch = JointBatch(task, 1, **kwargs)
        self.task = task
        self.render_mode = render_mode
        self.observation_space = observation_space(task)
        self.action_space = action_space()
        self.params = self.batch.params
        self._aux_names = task.aux_names
        self._imax = L.I_MAX

    @property
    def state(self) -> np.ndarray:
        """The true physics state row (see :data:`hdgym.physics.layout.STATE_NAMES`), read-only."""
        row = self.batch.xs[0].view()
        row.flags.writeable = False
        return row

    @property
    def param_row(self) -> np.ndarray:
        """This episode's (randomized) parameter row (:data:`layout.PARAM_NAMES`)."""
        return self.batch.rows[0]

    def _info(self) -> dict[str, Any]:
        b = self.batch
        if b.bad[0]:
            s = b.true_states()[0].tolist()
        else:
            s = b.xs[0, :6].tolist()
        info = dict(zip(INFO_STATES, s, strict=True))
        info["time"] = float(b.steps[0]) * b.ctrl_dt
        for name, v in zip(self._aux_names, b.aux[0].tolist(), strict=True):
            info[name] = v
        info["diverged"] = bool(b.bad[0])
        return info

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.batch.set_rngs([self.np_random], reseeded=seed is not None)
        self.batch.reset_all()
        return self.batch.obs[0].copy(), self._info()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        a = scalar_action(action)
        b = self.batch
        b.act[0] = a
        b.i_cmd[0] = a * b.rows[0, self._imax]
        b.advance()
        return b.obs[0].copy(), float(b.rew[0]), bool(b.term[0]), False, self._info()

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        from hdgym.envs.render import render_frame

        b = self.batch
        return render_frame(b.true_states()[0], b.aux[0], self.task.name,
                            b.steps[0] * b.ctrl_dt, b.torque_scale, b.current_limit,
                            b.speed_scale)


__all__ = ["CHANNELS", "DEFAULT_PRESET", "INFO_STATES", "HarmonicDriveEnv", "JointBatch",
           "NOISE_BLOCK", "Randomizer", "action_space", "observation_space", "resolve_params",
           "scalar_action"]
