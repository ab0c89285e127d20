"""Parsimony between nested effects: the simpler one wins when it does nearly as well."""

from __future__ import annotations

import math

from .fitting import FitResult
from .problem import Problem

NESTED = {"stribeck_friction": "stiction"}
"""Effect -> simpler effect that is its limit case (preferred when it does nearly as well)."""
PARSIMONY = 0.75
"""The simpler effect is preferred if it achieves this share of the winner's improvement (on
the validation record when there is one, see :func:`simpler_does_nearly_as_well`)."""


def simpler_does_nearly_as_well(vprob: Problem | None, current: FitResult, winner: tuple,
                                 simpler: tuple) -> bool:
    """Parsimony between nested effects (stiction inside Stribeck friction).

    The simpler effect is preferred if it achieves :data:`PARSIMONY` of the
    winner's improvement. With a validation record the improvement is judged
    there (the extra parameter, the Stribeck velocity, must earn its keep on
    held-out data: a speed-dependent drop that is really a breakaway threshold
    does not carry over); without one, on the training cost. Both numbers are
    kept in the candidates' entries (``validation_nmse``).
    """
    if vprob is not None:
        v0 = vprob.nmse(current.params)["mean"]
        vw = vprob.nmse(winner[2].params)["mean"]
        vs = vprob.nmse(simpler[2].params)["mean"]
        winner[1]["validation_nmse"], simpler[1]["validation_nmse"] = vw, vs
        if math.isfinite(v0) and math.isfinite(vw) and v0 > vw:
            return math.isfinite(vs) and v0 - vs >= PARSIMONY * (v0 - vw)
    return (simpler[1]["relative_improvement"]
            >= PARSIMONY * winner[1]["relative_improvement"])
