"""The native vector env's step as one compiled call over the batch.

:meth:`hdgym.envs.common.JointBatch.advance` composes a step from separate
calls (the physics of :mod:`hdgym.physics.lanes`, the sensors of
:class:`hdgym.hardware.SensorBank`, the sensor noise, the task's compiled
observation/reward function) with numpy glue between them: at 1,024 envs the
glue, the extra fork/join of the threads and the copies cost about a third
of the physics. :func:`vector_step` runs the same pieces block by block
(:data:`BLOCK` envs, the physics' SIMD block) in one loop: the action scaling
of :func:`hdgym.hardware.scale_actions`, the physics block step of
:mod:`hdgym.physics.lanes`, the encoder read of :mod:`hdgym.hardware`, the
env's noise sample, the task's per-env function, the truncation and the
``info`` rows, so a step is one call and, on threads, one fork/join.

The numbers are those of the composed step, bit for bit (the same compiled
functions in the same order per env; ``tests/test_envs.py`` holds the vector
env to single envs, which step through the composed path). Random numbers
are not drawn here: the caller refills the per-env noise blocks from the
envs' own generators before the call (:meth:`JointBatch.refill_noise`, in the
order :meth:`JointBatch.advance` draws: a new episode's draws first).

Phases (``phase``): 0 the whole step; 1 only actions, physics, sensors and
the step count (the envs that start a new episode are then reset from
Python, their draws need the generators); 2 the rest, with ``fresh`` the
envs just reset (their encoders restart from the new state, like
:meth:`SensorBank.reset`).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from hdgym.envs.tasks import _resonance_envs, _track_envs
from hdgym.hardware import _read
from hdgym.physics import layout as L
from hdgym.physics.lane_fields import BLOCK
from hdgym.physics.lanes import _step_block

#: task ids of :func:`vector_step`
TASK_IDS = {"tracking": 0, "resonance": 1}
#: ``info`` rows written by the step before the task's aux rows: the six true states, time
N_INFO_FIXED = 7


@nb.njit(cache=True)
def first_bad_action(a: np.ndarray) -> int:
    """Index of the first NaN or infinite action, -1 if all are finite."""
    for i in range(a.shape[0]):
        if not math.isfinite(float(a[i])):
            return i
    return -1


@nb.njit(cache=True, nogil=True)
def _block(b: int, phase: int, task: int, a: np.ndarray, imax: np.ndarray, W: np.ndarray,
           n_sub: int, xs: np.ndarray, bad: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray,
           act: np.ndarray, enc: np.ndarray, prev: np.ndarray, held: np.ndarray,
           tsens: bool, delay: int, meas: np.ndarray, nbuf: np.ndarray, nptr: np.ndarray,
           noisy: bool, z: np.ndarray, tp: np.ndarray, ts: np.ndarray, steps: np.ndarray,
           fresh: np.ndarray, cdt: float, c: np.ndarray, obs: np.ndarray, rew: np.ndarray,
           term: np.ndarray, aux: np.ndarray, inf: np.ndarray, trunc: np.ndarray,
           done: np.ndarray, max_steps: float) -> tuple[int, int]:
    """Block ``b`` of one step (see the module docstring); returns (diverged, ended) counts."""
    n = xs.shape[0]
    lo = b * BLOCK
    hi = min(n, lo + BLOCK)
    if phase != 2:
        for e in range(lo, hi):  # hardware.scale_actions (validated before)
            v = float(a[e])
            v = 1.0 if v > 1.0 else (-1.0 if v < -1.0 else v)
            act[e] = v
            i_cmd[e] = v * imax[e]
        _step_block(W, b, i_cmd, t_ext, n_sub, xs, bad)
        # SensorBank.measure: with a delay the reading is the one held from the last step
        if delay == 0:
            _read(xs[lo:hi], enc[:, lo:hi], prev[:, lo:hi], cdt, tsens, meas[:, lo:hi])
        else:
            for e in range(lo, hi):
                for k in range(meas.shape[0]):
                    meas[k, e] = held[k, e]
            _read(xs[lo:hi], enc[:, lo:hi], prev[:, lo:hi], cdt, tsens, held[:, lo:hi])
        for e in range(lo, hi):
            steps[e] += 1
        if phase == 1:
            return 0, 0
    n_bad = 0
    n_end = 0
    for e in range(lo, hi):
        if fresh[e]:  # SensorBank.reset: counting restarts at the new state
            for k in range(2):
                s = enc[k, e]
                r = math.floor(xs[e, L.TH_M if k == 0 else L.TH_O] / s) * s
                meas[k, e] = r
                meas[2 + k, e] = 0.0
                prev[k, e] = r
            meas[4, e] = xs[e, L.TK] if tsens else 0.0
            meas[5, e] = xs[e, L.CUR]
            for k in range(meas.shape[0]):
                held[k, e] = meas[k, e]
        if noisy:  # the env's next noise sample (JointBatch._noise)
            p = nptr[e]
            z[e, 0] = nbuf[e, p, 0]
            z[e, 1] = nbuf[e, p, 1]
            nptr[e] = p + 1
    if task == 0:
        _track_envs(lo, hi, xs, bad, meas, z, act, tp, steps, fresh, cdt, c, obs, rew, term,
                    aux)
    else:
        _resonance_envs(lo, hi, xs, bad, meas, z, act, tp, ts, steps, fresh, cdt, c, obs, rew,
                        term, aux)
    for e in range(lo, hi):
        for k in range(N_INFO_FIXED - 1):
            inf[k, e] = xs[e, k]
        inf[N_INFO_FIXED - 1, e] = steps[e] * cdt
        for k in range(aux.shape[1]):
            inf[N_INFO_FIXED + k, e] = aux[e, k]
        trunc[e] = steps[e] >= max_steps
        done[e] = term[e] or trunc[e]
        n_end += done[e]
        n_bad += bad[e]
    return n_bad, n_end


@nb.njit(cache=True)
def _serial(phase: int, task: int, a: np.ndarray, imax: np.ndarray, W: np.ndarray, n_sub: int,
            xs: np.ndarray, bad: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray,
            act: np.ndarray, enc: np.ndarray, prev: np.ndarray, held: np.ndarray, tsens: bool,
            delay: int, meas: np.ndarray, nbuf: np.ndarray, nptr: np.ndarray, noisy: bool,
            z: np.ndarray, tp: np.ndarray, ts: np.ndarray, steps: np.ndarray,
            fresh: np.ndarray, cdt: float, c: np.ndarray, obs: np.ndarray, rew: np.ndarray,
            term: np.ndarray, aux: np.ndarray, inf: np.ndarray, trunc: np.ndarray,
            done: np.ndarray, max_steps: float) -> tuple[int, int]:
    n_bad = 0
    n_end = 0
    for b in range(W.shape[0]):
        nb_, ne_ = _block(b, phase, task, a, imax, W, n_sub, xs, bad, i_cmd, t_ext, act, enc,
                          prev, held, tsens, delay, meas, nbuf, nptr, noisy, z, tp, ts, steps,
                          fresh, cdt, c, obs, rew, term, aux, inf, trunc, done, max_steps)
        n_bad += nb_
        n_end += ne_
    return n_bad, n_end


@nb.njit(cache=True, parallel=True, nogil=True)
def _parallel(phase: int, task: int, a: np.ndarray, imax: np.ndarray, W: np.ndarray, n_sub: int,
              xs: np.ndarray, bad: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray,
              act: np.ndarray, enc: np.ndarray, prev: np.ndarray, held: np.ndarray,
              tsens: bool, delay: int, meas: np.ndarray, nbuf: np.ndarray, nptr: np.ndarray,
              noisy: bool, z: np.ndarray, tp: np.ndarray, ts: np.ndarray, steps: np.ndarray,
              fresh: np.ndarray, cdt: float, c: np.ndarray, obs: np.ndarray, rew: np.ndarray,
              term: np.ndarray, aux: np.ndarray, inf: np.ndarray, trunc: np.ndarray,
              done: np.ndarray, max_steps: float) -> tuple[int, int]:
    n_bad = 0
    n_end = 0
    for b in nb.prange(W.shape[0]):
        nb_, ne_ = _block(b, phase, task, a, imax, W, n_sub, xs, bad, i_cmd, t_ext, act, enc,
                          prev, held, tsens, delay, meas, nbuf, nptr, noisy, z, tp, ts, steps,
                          fresh, cdt, c, obs, rew, term, aux, inf, trunc, done, max_steps)
        n_bad += nb_
        n_end += ne_
    return n_bad, n_end


def vector_step(parallel: bool, phase: int, task: int, a: np.ndarray, imax: np.ndarray,
                W: np.ndarray, n_sub: int, xs: np.ndarray, bad: np.ndarray, i_cmd: np.ndarray,
                t_ext: np.ndarray, act: np.ndarray, enc: np.ndarray, prev: np.ndarray,
                held: np.ndarray, tsens: bool, delay: int, meas: np.ndarray, nbuf: np.ndarray,
                nptr: np.ndarray, noisy: bool, z: np.ndarray, tp: np.ndarray, ts: np.ndarray,
                steps: np.ndarray, fresh: np.ndarray, cdt: float, c: np.ndarray,
                obs: np.ndarray, rew: np.ndarray, term: np.ndarray, aux: np.ndarray,
                inf: np.ndarray, trunc: np.ndarray, done: np.ndarray,
                max_steps: float) -> tuple[int, int]:
    """One step of ``n`` envs (see the module docstring); every array is written in place.

    Shapes: ``a, imax, xs (n, N_STATE), bad, i_cmd, t_ext, act, steps, fresh, rew, term,
    trunc, done`` per env; ``enc, prev (2, n)``, ``held, meas (6, n)``, ``nbuf (n,
    NOISE_BLOCK, 2)``, ``nptr (n,)``, ``z (n, 2)``, ``obs (n, n_obs)``, ``aux (n, n_aux)``,
    ``inf (N_INFO_FIXED + n_aux, n)``. ``W`` is the :class:`LaneBatch`'s block buffer.
    Returns the numbers of diverged and of ended (terminated or truncated) envs; phase 1
    returns (0, 0).
    """
    fn = _parallel if parallel else _serial
    return fn(phase, task, a, imax, W, n_sub, xs, bad, i_cmd, t_ext, act, enc, prev, held,
              tsens, delay, meas, nbuf, nptr, noisy, z, tp, ts, steps, fresh, cdt, c, obs, rew,
              term, aux, inf, trunc, done, max_steps)
