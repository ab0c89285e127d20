"""The compiled joint step laid out for SIMD: many envs, one vector lane each.

:mod:`hdgym.physics.kernel` steps one env at a time; each substep there is
one long chain of dependent operations, so a core mostly waits on
latencies. Here envs are grouped in blocks of :data:`BLOCK`, and every
substep is a handful of passes over a block, each pass a branch-free loop
over its envs that the compiler turns into vector instructions (8 envs per
instruction with AVX-512, 4 with AVX2). The physics is the kernel's
semi-implicit step, operation for operation; the tests hold both to the
numpy reference (:mod:`hdgym.physics.reference`). The one-env kernel stays
for single trajectories, where a block would run 63 spare lanes.

A block is one flat float64 buffer of :data:`N_FIELDS` fields per env: the
state (layout of :mod:`hdgym.physics.layout`), constants derived once from
the parameter row, the effect flags and the substep (reciprocals, limits;
effects that are off become zero amplitudes or infinite limits, so every
lane runs the same instructions), sin and cos of the kinematic-error,
friction-ripple and gravity phases, and the substep's temporaries. The
phases are rotated by each substep's angle increment (a Taylor series; exact
sin/cos for increments of 0.3 rad and more) and recomputed exactly every
:data:`RESYNC` substeps.

The module is split by job: :mod:`hdgym.physics.lane_fields` (the block's
fields, filling a lane), :mod:`hdgym.physics.lane_step` (the substep,
:func:`run_block`) and this batch API.

:class:`LaneBatch` owns the buffers and mirrors the state into the caller's
``(n, N_STATE)`` rows after every step; after writing rows (a reset), call
:meth:`LaneBatch.load`.
"""


from __future__ import annotations

import math

import numba as nb
import numpy as np

from hdgym.physics import layout as L
from hdgym.physics.lane_fields import (
    BAD,
    BLOCK,
    COS,
    COUNT,
    ICMD,
    N_FIELDS,
    P_KE,
    RESYNC,
    SIN,
    TEXT,
    jit_lane,
    prepare_lane,
    sync_lane,
)
from hdgym.physics.lane_fields import get as _g
from hdgym.physics.lane_fields import put as _s
from hdgym.physics.lane_step import run_block

__all__ = ["BLOCK", "COS", "COUNT", "N_FIELDS", "P_KE", "PARALLEL_THRESHOLD", "RESYNC", "SIN",
           "LaneBatch", "run_block"]

# ------------------------------------------------------------------ batch
@jit_lane
def _load(W: np.ndarray, xs: np.ndarray, ps: np.ndarray, flags: np.ndarray, dt: float,
          idx: np.ndarray) -> None:
    for e in idx:
        w = W[e // BLOCK]
        j = e % BLOCK
        for f in range(L.N_STATE):
            _s(w, f, j, xs[e, f])
        prepare_lane(ps[e], flags[e], dt, w, j)
        sync_lane(w, j)


@jit_lane
def _step_block(W: np.ndarray, b: int, i_cmd: np.ndarray, t_ext: np.ndarray, n_sub: int,
                xs: np.ndarray, bad: np.ndarray) -> None:
    """Block ``b``: take its inputs, run it, and copy its state out to ``xs`` rows."""
    w = W[b]
    lo = b * BLOCK
    hi = min(xs.shape[0], lo + BLOCK)
    for e in range(lo, hi):
        _s(w, ICMD, e - lo, i_cmd[e])
        _s(w, TEXT, e - lo, t_ext[e])
    run_block(w, hi - lo, n_sub)
    for e in range(lo, hi):
        j = e - lo
        for f in range(L.N_STATE):
            xs[e, f] = _g(w, f, j)
        bad[e] = _g(w, BAD, j) != 0.0


@jit_lane
def _step_serial(W: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray, n_sub: int,
                 xs: np.ndarray, bad: np.ndarray) -> None:
    for b in range(W.shape[0]):
        _step_block(W, b, i_cmd, t_ext, n_sub, xs, bad)


@nb.njit(cache=True, parallel=True, nogil=True)
def _step_parallel(W: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray, n_sub: int,
                   xs: np.ndarray, bad: np.ndarray) -> None:
    for b in nb.prange(W.shape[0]):
        _step_block(W, b, i_cmd, t_ext, n_sub, xs, bad)


def _check(a: np.ndarray, shape: tuple[int, ...], name: str) -> None:
    # the compiled loops do not check bounds: a wrong shape would read past the end
    if not isinstance(a, np.ndarray) or a.shape != shape:
        raise ValueError(f"{name} must be an array of shape {shape}, got "
                         f"{getattr(a, 'shape', type(a).__name__)}")


#: batch size from which :class:`LaneBatch` spreads its blocks over the cores
#: (below it, starting the threads costs more than they save)
PARALLEL_THRESHOLD = 256


class LaneBatch:
    """``n`` joints in SIMD blocks; the state is mirrored into ``xs`` after every step.

    Args:
        xs: ``(n, N_STATE)`` state rows (read now, written after every step).
        ps: ``(n, N_PARAMS)`` parameter rows.
        flags: ``(n,)`` effect flags.
        dt: substep, s.
        parallel: spread blocks over the cores.
    """

    def __init__(self, xs: np.ndarray, ps: np.ndarray, flags: np.ndarray, dt: float,
                 parallel: bool = False) -> None:
        self.n = xs.shape[0]
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be > 0 s, got {dt!r}")
        self.dt = float(dt)
        n_blocks = (self.n + BLOCK - 1) // BLOCK
        # the last block's spare lanes are never computed
        self.W = np.zeros((n_blocks, N_FIELDS * BLOCK))
        self.parallel = parallel
        self.load(xs, ps, flags, np.arange(self.n))

    def load(self, xs: np.ndarray, ps: np.ndarray, flags: np.ndarray, idx: np.ndarray) -> None:
        """Take state, parameters and flags of envs ``idx`` (after a reset or a change)."""
        n = self.n
        _check(xs, (n, L.N_STATE), "xs")
        _check(ps, (n, L.N_PARAMS), "ps")
        _check(flags, (n,), "flags")
        idx = np.asarray(idx, dtype=np.int64)
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise ValueError(f"idx: env indices must be in [0, {n}), got {idx!r}")
        _load(self.W, xs, ps, flags.astype(np.int64, copy=False), self.dt, idx)

    def step(self, i_cmd: np.ndarray, t_ext: np.ndarray, n_sub: int, xs: np.ndarray,
             bad: np.ndarray) -> None:
        """One control period: ``n_sub`` substeps at currents ``i_cmd`` (A), external
        loads ``t_ext`` (N m); the new state goes to ``xs`` rows, divergence to ``bad``."""
        n = self.n
        _check(i_cmd, (n,), "i_cmd")
        _check(t_ext, (n,), "t_ext")
        _check(xs, (n, L.N_STATE), "xs")
        _check(bad, (n,), "bad")
        if int(n_sub) != n_sub or n_sub < 1:
            raise ValueError(f"n_sub must be a whole number >= 1, got {n_sub!r}")
        fn = _step_parallel if self.parallel else _step_serial
        fn(self.W, i_cmd, t_ext, n_sub, xs, bad)

