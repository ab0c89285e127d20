"""The workflow's search on the spring curve of a locked-output record (:mod:`.spring`).

The base fit's linear stiffness absorbs a hardening spring to below the time channels'
noise; over bins of the measured torque (and its direction) the noise goes and the bend
stays. :func:`search_spring` refits the base model on the curve, then ranks and tries the
effects the curve reveals (:attr:`.effect.Effect.compare`) with the workflow's own search
(:func:`.workflow._search`, passed in).
"""

from __future__ import annotations

from collections.abc import Callable

from hdgym.params import JointParams

from .fitting import FitResult, fit, rescored
from .floor import curve_unexplained
from .outcome import NOISE_FACTOR
from .problem import Problem
from .registry import model_params


def search_spring(problem: Problem, vprob: Problem | None, current: FitResult,
                  given: JointParams, nfev: int, min_score: float,
                  search: Callable[[FitResult], tuple[tuple | None, str, list[dict]]]
                  ) -> tuple[tuple | None, list[dict], FitResult, dict[str, str]]:
    """Search the spring curve when the time channels of a locked record show nothing.

    Args:
        problem, vprob: the training and validation comparisons (switched to the curve,
            :meth:`.problem.Problem.set_compare`, and back when nothing is found).
        current: the base fit; given: the base model as given (anchors the refit).
        nfev: least-squares evaluations of the base refit on the curve.
        min_score: least share of the curve's residual a missing effect must explain for
            an unnamed curve above its noise to be unexplained (:func:`.floor.curve_unexplained`).
        search: one round of the workflow's search from a fit (``_search`` with the
            escalated validation cut: an effect found on the curve must cut its mean
            validation NMSE by 80 % and by :data:`.outcome.NOISE_FACTOR` x its noise).

    Returns ``(accepted, candidates, base refit on the curve, unexplained)``: ``accepted``
    as the search's (None: nothing found, the comparisons are back on the time channels;
    else the diagnosis stays on the curve) and ``unexplained`` from
    :func:`.floor.curve_unexplained` when nothing was found.
    """
    probs = [problem] + ([vprob] if vprob is not None else [])
    for pr in probs:
        pr.set_compare("spring")
    cur = rescored(problem, current)
    refit = fit(problem, cur.params, model_params(cur.params, problem.scales, given),
                max_nfev=nfev)
    if refit.cost < cur.cost:
        cur = FitResult(refit.params, {**cur.values, **refit.values}, refit.nmse, refit.nfev,
                        refit.cost)
    accepted, _, candidates = search(cur)
    if accepted is not None:
        return accepted, candidates, cur, {}
    stuck = curve_unexplained(vprob or problem, cur.params, candidates, min_score,
                              NOISE_FACTOR)
    for pr in probs:
        pr.set_compare("time")
    return None, candidates, cur, stuck
