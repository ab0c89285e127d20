"""What a generated case's own model leaves on its record: the floor no diagnosis can go below.

A hold-out or blind case (:mod:`.holdout`) knows the joint its records were made with. That
joint, compared with its validation record exactly as the diagnosis compares (the same
:class:`.problem.Problem`: channels, prediction horizon, restarts, time channels or spring
curve), shows the *truth floor* (:func:`truth_nmse`): sensor noise, encoder quantization and
what the restarts cost (a locked output restarts on the filtered measured state; a moving
joint only has its slow drift removed, which leaves the exact model near the noise). A
diagnosis closes at most ``before - truth`` of its NMSE (the *closable gap*, :func:`gap_cut`).

Known only for generated cases; the workflow's own outcome estimates that floor without the
truth (:func:`.floor.floor_nmse`, kept as :attr:`.diagnosis.Diagnosis.floor`).
:func:`true_noise_nmse` measures the record's sensor noise alone (the measured channels
against the same run's true states), the number :func:`.noise.noise_nmse` estimates from
the record.
"""

from __future__ import annotations

import math

import numpy as np

from hdgym.params import JointParams
from hdgym.record import Record

from . import residuals as R
from .diagnosis import Diagnosis
from .problem import Problem


def _judged(diag: Diagnosis) -> Problem | None:
    """The comparison a diagnosis reports its before and after on (validation, else training)."""
    return diag.validation or diag.problem


def truth_nmse(diag: Diagnosis, truth: JointParams) -> float:
    """Mean NMSE, percent, of the joint ``truth`` on the comparison the diagnosis reports
    ``nmse_before`` and ``nmse_after`` on (nan without one, inf if the run diverges)."""
    judged = _judged(diag)
    if judged is None:
        return math.nan
    return float(judged.nmse(truth)["mean"])


def gap_cut(before: float, after: float, truth: float) -> float:
    """Share of the closable gap ``before - truth`` a diagnosis closed: ``(before - after) /
    (before - truth)`` (nan when there is no gap: ``before <= truth``)."""
    gap = before - truth
    if not gap > 0 or not math.isfinite(gap):
        return math.nan
    return (before - after) / gap


def true_noise_nmse(problem: Problem, clean: Record) -> dict[str, float]:
    """The record's sensor noise as an NMSE, percent per channel and ``"mean"``.

    ``problem`` compares the measured record (time channels); ``clean`` is the same run
    without sensors (:class:`hdgym.sim.Simulator` with ``sensors=False``: true angles,
    torque and current). Each filtered channel of ``clean`` is subtracted from the measured
    one; the variance of the difference is divided by the measured channel's variance, as
    :func:`.noise.noise_nmse` scales its estimate. Encoder quantization counts as noise, its
    mean (half a count, which a model that floors its angles the same way shows too) not.
    """
    raw = R.Raw(np.asarray(clean.motor_angle, dtype=float),
                None if problem.locked else np.asarray(clean.output_angle, dtype=float),
                clean.output_torque, clean.motor_current)
    true = R.channels(raw, problem.names, problem.ratio, problem.dt, problem.cutoff)
    out = {k: 100.0 * float(np.var(problem.measured[k] - true[k])) / problem.sigma2[k]
           for k in problem.names}
    out["mean"] = float(np.mean([out[k] for k in problem.names])) if problem.names else 0.0
    return out


def view_size(problem: Problem, truth: JointParams, without: JointParams,
              views: tuple[str, ...]) -> tuple[float, float] | None:
    """How much an effect changes ``problem``'s record on the comparisons that reveal it,
    beside the noise of each: ``(size, noise)``, NMSE percent, of the view where the change
    stands highest above its noise (None: no view of ``views`` applies to the record).

    ``problem``: a comparison of the record on its time channels (switched to each view
    and back: its noise estimate is made once); ``truth``: the joint the record was made
    with; ``without``: the same joint lacking the effect. ``views``: the effect's declared
    comparisons (:attr:`.effect.Effect.compare`), of which ``"time"`` is skipped:
    ``"spring"`` on a locked output (the binned spring curve, where a hardening spring
    stands out although a linear stiffness absorbs it on the time channels), ``"lines"`` on
    a free one (the line channels of the WG angle's orders).
    Both joints are compared exactly as the diagnosis compares on that view
    (:meth:`.problem.Problem.residuals`, which subtract the same measurement).
    """
    best = None
    try:
        for view in views:
            if view == "time" or view == "spring" and not problem.locked:
                continue
            try:
                problem.set_compare(view)
                a, b = problem.residuals(truth), problem.residuals(without)
            except ValueError:  # no line channels in this record
                continue
            size = float(np.mean([100.0 * np.mean((a[k] - b[k]) ** 2) / problem.sigma2[k]
                                  for k in problem.names]))
            noise = float(problem.noise["mean"])
            if best is None or size * best[1] > best[0] * noise:
                best = (size, noise)
    finally:
        problem.set_compare("time")
    return best
