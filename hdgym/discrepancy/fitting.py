"""Fit a joint model to a record: bounded ``scipy.optimize.least_squares`` over dotted paths.

The record and the comparison are a :class:`.problem.Problem`; :func:`fit` adjusts the
parameters at the given dotted paths (:mod:`.paths`) to lower its cost, the sum over
channels of NMSE/100.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from hdgym.params import JointParams

from .effect import FitParam
from .paths import get_value, setter
from .problem import BAD, Problem


@dataclass
class FitResult:
    """Outcome of :func:`fit`: the fitted joint, fitted values and NMSE per channel."""

    params: JointParams
    values: dict[str, float]
    nmse: dict[str, float]
    nfev: int
    cost: float



def rescored(problem: Problem, r: FitResult) -> FitResult:
    """``r`` with its NMSE and cost taken again on ``problem`` as it compares now (another
    prediction horizon, or the spring curve)."""
    nm = problem.nmse(r.params)
    return FitResult(r.params, r.values, nm, r.nfev, nm["mean"] / 100)

FD_THREADS = 2
"""Threads that evaluate the columns of a finite-difference Jacobian (the machine this is
built for has two cores). The compiled simulation releases the GIL, so two columns run at
once; each column is its own evaluation and their order is kept, so a fit's result does not
depend on the number (tested). The bench's 60 s record: 48.6 -> 37.4 s, the same 5,081
predictions."""
BLAS_THREADS = 1
"""BLAS threads a fit may use (for its duration, :func:`threadpoolctl.threadpool_limits`).
Least squares factors a tall, narrow Jacobian (some 10^4 residuals by 10-40 parameters) each
iteration, which a second thread does not speed up, and OpenBLAS's idle threads spin after
each call on the cores the finite-difference columns (:data:`FD_THREADS`) run on. The bench's
60 s record (tuttle-joint3 / kinematic_error / step:0.30), alone on the 2-core machine:
64.1 s with OpenBLAS's default two threads (9.5 s of it in the Jacobian's SVD), 29.9 s with
one (1.0 s). One thread also keeps a fit's sums in one order whatever the machine's cores."""
DIFF_STEP = 1e-3
"""Forward finite-difference step, as a share of each parameter's range: the short fits
(the base fit before the search, each step's control refit, the base refit on another
comparison in :func:`.spring_search.search_view`) use it."""
CENTRAL_STEP = 3e-3
"""Central finite-difference step, as a share of each parameter's range: every fit that is
compared or judged once it has converged (``fit(..., central=True)``, :func:`.settle.converge`:
an effect's trial refit, its polish and their control, the settled base model, the named
model refitted at the end).

Seen from a few per cent away the cost is a staircase on the scale of :data:`DIFF_STEP`
(the simulated angles are floored to whole encoder counts like the measured ones, each
breakaway and slip happens at a whole substep): forward differences of a thousandth of a
range measure the stairs, not the slope, the trust region collapses and least squares
stops short of the optimum on ``xtol`` after a few Jacobians, whatever the budget. A wider
forward step sees the slope but with a first-order error that stops it short as well; a
central difference's error is second order. Measured once, before it was used anywhere
(development case hduc20 / stiction / sine:3.34:2 of seed 146, the base fit of 25
parameters from the given model; the joint that made the record reaches 0.00028 % NMSE):
forward 1e-3, 1e-2 and 3e-2 of the range stopped at 4.9, 4.7 and 5.2 %; central 1e-3, 3e-3
and 1e-2 reached 2.2, 0.044 and 0.42 %. It replaces a second, coarse forward run (1e-2)
that converged fits kept when cheaper: the same evaluations per Jacobian."""


MEAN_FTOL = 1e-3
"""``ftol`` of a central fit's first pass, on the encoders' mean reading: that cost is
smooth, so least squares would creep on by small gains to ``ftol`` 1e-6, which the pass on
the floored reading after it does not need (the bench's 60 s tuttle-joint3 record: 71 s
to diagnose with 1e-6, 53 s with 1e-3, the same final cost within 1 %)."""


def _flooring(problem) -> list:
    """The comparisons in ``problem`` (a :class:`.problem.Problem` or one made of several,
    ``parts``) whose model angles are floored to encoder counts
    (:attr:`.problem.Problem.floors_readings`; not the inverse comparison)."""
    return [q for q in getattr(problem, "parts", (problem,))
            if getattr(q, "floors_readings", False)]


@contextmanager
def readings(problem, quantized: bool):
    """``problem`` with its model's encoder readings floored to whole counts or not
    (:attr:`.problem.Problem.quantized`) for the duration, where it floors them at all
    (:func:`_flooring`)."""
    parts = _flooring(problem)
    before = [q.quantized for q in parts]
    for q in parts:
        q.quantized = quantized
    try:
        yield problem
    finally:
        for q, b in zip(parts, before, strict=True):
            q.quantized = b


def fit(problem: Problem, p: JointParams, fps: list[FitParam], max_nfev: int = 40,
        decimate: int | None = None, diff_step: float | None = None,
        search: bool = False, central: bool = False, late: bool = False) -> FitResult:
    """Bounded least squares of ``fps`` (starting at their guesses or current values; those
    :attr:`.effect.FitParam.late` only with ``late``, else they stay as they are).

    Variables are scaled to their bounds (``z = 1 + (x - lo)/(hi - lo)``) so
    a relative finite-difference step (:data:`DIFF_STEP`) is that share of each range.
    With ``search`` on a stick-slip record (:attr:`Problem.stick_slip`), a
    coordinate search (:func:`_pattern_search`) continues from the least-squares
    result. With ``central``, the Jacobian takes central differences of :data:`CENTRAL_STEP`
    (twice the evaluations of a forward one, :data:`DIFF_STEP`), and the fit runs twice:
    first with the model's angles at the encoders' mean reading (:func:`readings`, ``ftol``
    :data:`MEAN_FTOL`), then from there on the floored reading the record is judged on.

    Why twice: the floored angles make the cost a staircase that stops least squares short
    of the optimum even with central differences, and the residual is narrow in the
    parameters that set a resonance (seyfferth-rh32 / none / sine:1.56:2, development seed
    182: from the given model, each parameter 2-5 % off, the cost rises 16-fold within 0.6 %
    of the load inertia's range of its minimum). Development cases with nothing hidden,
    the base model converged from the given one (:func:`.settle.converge`, horizon 0.1 s;
    NMSE %, floored only, then both passes, the joint that made the record): rh32 (182)
    0.198 -> 0.042 (0.0051); tuttle-joint3 (14) 0.843 -> 0.732 (0.778); hduc20 (158) 0.0188
    -> 0.0136 (0.00026); tuttle-joint1 (206) 0.0087 -> 0.0040 (0.0040); hdf40 (86) 0.044 ->
    0.026 (0.032); tuttle-joint2 (134) 0.318 -> 0.201 (0.151). The mean reading alone is
    not the judged cost: on tuttle-joint3, 0.60 % on it read 0.90 % floored, which the
    second pass took to 0.73 %.
    """
    if decimate is None:
        first = problem.measured.get(problem.names[0])  # (line channels: coefficients)
        decimate = 1 if first is None else max(1, first.size // 8000)
    fps = [fp for fp in fps if fp.upper > fp.lower and (late or not fp.late)]
    if not fps:
        nm = problem.nmse(p)
        return FitResult(p, {}, nm, 0, nm["mean"] / 100)
    lo = np.array([fp.lower for fp in fps])
    hi = np.array([fp.upper for fp in fps])
    x0 = np.array([fp.guess if fp.guess is not None else get_value(p, fp.path) for fp in fps])
    x0 = np.clip(x0, lo, hi)
    span = hi - lo

    put = setter(p)

    def build(z: np.ndarray) -> JointParams:
        x = lo + (np.clip(z, 1.0, 2.0) - 1.0) * span
        return put({fp.path: float(v) for fp, v in zip(fps, x, strict=True)})

    def fun(z: np.ndarray) -> np.ndarray:
        try:
            q = build(z)
        except ValueError:
            n = problem.vector(p, decimate).size
            return np.full(n, BAD)
        return problem.vector(q, decimate)

    z = 1.0 + (x0 - lo) / span
    bounds = (np.ones_like(z), 2 * np.ones_like(z))
    nfev = 0
    # central: first on the encoders' mean reading (a cost without the quantization
    # staircase), then on the floored reading the record is judged on
    # (a comparison that never floors the model's angles, the inverse one, has one cost)
    for quantized in ((False, True) if central and _flooring(problem) else (True,)):
        with (readings(problem, quantized), ThreadPoolExecutor(FD_THREADS) as pool,
              threadpool_limits(limits=BLAS_THREADS, user_api="blas")):
            sol = least_squares(fun, z, jac="3-point" if central else "2-point",
                                bounds=bounds, method="trf",
                                diff_step=diff_step or (CENTRAL_STEP if central else DIFF_STEP),
                                max_nfev=max_nfev, ftol=1e-6 if quantized else MEAN_FTOL,
                                xtol=1e-6, gtol=1e-8,
                                workers=pool.map)
        z, nfev = np.clip(sol.x, 1.0, 2.0), nfev + int(sol.nfev)
    if search and problem.stick_slip:
        z, n = _pattern_search(lambda v: float(np.sum(fun(v) ** 2)), np.clip(z, 1.0, 2.0),
                               SEARCH_BUDGET * len(fps))
        nfev += n
    best = build(z)
    values = {fp.path: float(get_value(best, fp.path)) for fp in fps}
    nm = problem.nmse(best)
    return FitResult(best, values, nm, nfev, nm["mean"] / 100)


SEARCH_STEPS = (0.04, 0.02, 0.01, 0.005)
"""Coordinate-search steps, as shares of each parameter's range (:func:`_pattern_search`)."""
SEARCH_BUDGET = 30
"""Cost evaluations per parameter a coordinate search may spend."""


def _pattern_search(cost, z: np.ndarray, budget: int) -> tuple[np.ndarray, int]:
    """Bounded coordinate search on ``z`` in ``[1, 2]`` (steps :data:`SEARCH_STEPS`).

    Stick-slip makes the cost piecewise constant on a fine scale (each breakaway
    and slip happens at a whole substep, the simulated angles are quantized like
    the encoders), so a finite-difference Jacobian sees steps rather than a slope
    and least squares stops early; comparing costs a few per cent of each range
    apart follows the trend. Returns the best point and the evaluations spent.
    """
    best = cost(z)
    n = 1
    for step in SEARCH_STEPS:
        improved = True
        while improved and n < budget:
            improved = False
            for i in range(z.size):
                for sgn in (1.0, -1.0):
                    y = z.copy()
                    y[i] = min(max(z[i] + sgn * step, 1.0), 2.0)
                    if y[i] == z[i]:
                        continue
                    c = cost(y)
                    n += 1
                    if c < best:
                        best, z, improved = c, y, True
                        break
                if n >= budget:
                    break
    return z, n
