"""Parsimony between nested effects: the simpler one wins when it does nearly as well."""

from __future__ import annotations

import cmath
import dataclasses
import math

from hdgym.params import GROUNDED, JointParams

from .fitting import FitResult, rescored
from .problem import Problem
from .registry import model_params
from .settle import TwoRecords, converge

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


def nested_on_both(problem: Problem, vprob: Problem, base: FitResult, winner: tuple,
                   simpler: tuple, given: JointParams, nfev: int) -> tuple | None:
    """The simpler of two nested effects, decided on both records refitted together, where
    the search is about to name the general one (``winner``, ``(cost, entry, fit)`` as
    :func:`.search.trial` returns, its fit polished) and the simpler one's trial refit
    (``simpler``) reached :data:`PARSIMONY` of its cut of the training cost: the base model
    (``base``), the winner and the simpler effect are each refitted on the training and
    validation records together until they converge (:class:`.settle.TwoRecords`, the
    coordinate search on a stick-slip record), and the simpler one is preferred when it
    achieves :data:`PARSIMONY` of the winner's cut of that joint cost. Returns the simpler
    effect as ``(cost, entry, fit)``, its fit rescored on ``problem``, or None. (The fit
    named then has seen the validation record, as :func:`.settle.settle_named`'s refit of
    a named model that is not at its floor has; ``entry["both_records_cut"]`` and the
    winner's say what each cut of the joint cost was.)

    Why not on the validation record alone (:func:`simpler_does_nearly_as_well`): a record
    on which the joint hardly sticks cannot tell stiction from Stribeck friction, and a
    stiction fit to the other record, its levels within 2 % of the true ones, can still
    stick where the joint slipped there. Development seed 386, tuttle-joint2 / stiction /
    random:0.962:4 with the records' roles swapped (stiction changes the checked record by
    0.39 % NMSE against its 0.94 % noise): stiction's trial cut the training cost by 91.5 %,
    Stribeck friction's by 91.2 %; polished, stiction took the checked record's NMSE from
    0.084 to 0.41 % and failed the hold-out check, Stribeck friction (a 1.4 % hump) took it
    to 0.037 % and was named."""
    two = TwoRecords(problem, vprob)

    def refit(q: JointParams) -> FitResult:
        return converge(two, q, model_params(q, problem.scales, given), nfev, search=True)

    b, w, s = refit(base.params), refit(winner[2].params), refit(simpler[2].params)
    gain_w, gain_s = b.cost - w.cost, b.cost - s.cost
    share = 1.0 / b.cost if b.cost > 0 else 0.0  # a gain as a share of the base refit's cost
    entry = {**simpler[1], "both_records_cut": round(gain_s * share, 4)}
    winner[1]["both_records_cut"] = round(gain_w * share, 4)
    if not (gain_w > 0 and gain_s >= PARSIMONY * gain_w):
        return None
    fit = rescored(problem, s)
    return fit.cost, entry, fit


def better_on_validation(vprob: Problem, winner: tuple, forms: list[tuple]) -> tuple | None:
    """The simpler form of the same effect (``(cost, entry, fit)`` as ``winner``) with the
    lowest validation NMSE, where that is below the winner's; else None (no allowance: the
    forms of one effect are not nested the way :data:`NESTED` effects are, and an allowance
    of :data:`PARSIMONY` of the gain let one line per order stand for the tuned
    tuttle-joint1 case's two at order 2: validation NMSE 0.155 -> 3.7 %). Each NMSE is
    computed once and kept in its entry (``validation_nmse``)."""
    def nmse(t: tuple) -> float:
        v = vprob.nmse(t[2].params)["mean"]
        t[1]["validation_nmse"] = v
        return v if math.isfinite(v) else math.inf

    vw = nmse(winner)
    best = min(forms, key=nmse, default=None)
    if best is None or not math.isfinite(best[1]["validation_nmse"]):
        return None
    return best if best[1]["validation_nmse"] < vw else None


def one_port_lines(p: JointParams, port: str) -> JointParams | None:
    """``p`` with each order's kinematic-error lines folded into one line at ``port`` (their
    sum at the record's start; None when every line is at that port already): a simpler
    form of a kinematic error fitted with both splines' lines at an order
    (:func:`.gear_effects.ke_lines`: the grounded spline's at the order, the other's at
    ``order x (1 -+ 1/ratio)``).

    The two lines of an order beat over about ratio / order WG turns; over a few beats a fit
    can split one line's amplitude between them to take up other misfit, and the split does
    not carry over to a run at another speed (development seed 254, seyfferth-rh25 /
    kinematic_error / step:1.75, 280 WG turns: the order-2 line split 1.05e-4 / 1.28e-4 rad
    between the splines, validation NMSE 16.4 %; folded into the grounded spline's line and
    refitted, 5.9 %, the true line alone there). Which spline's teeth make a drive's lines
    is not known beforehand (Tuttle's joints have them on the circular spline, the one not
    grounded), so the search folds them into either (:func:`.search.search_round`) and keeps
    the folded form where it carries over better (:func:`better_on_validation`)."""
    ke = p.kinematic_error
    if all(h.port == port for h in ke.harmonics):
        return None
    lines: dict[float, complex] = {}
    for h in ke.harmonics:
        lines[h.order] = lines.get(h.order, 0j) + cmath.rect(h.amplitude, h.phase)
    kept = tuple(dataclasses.replace(ke.harmonics[0], order=o, amplitude=abs(z),
                                     phase=cmath.phase(z), port=port)
                 for o, z in lines.items())
    return dataclasses.replace(p, kinematic_error=dataclasses.replace(ke, harmonics=kept))


def one_port_forms(p: JointParams) -> list[tuple[str, JointParams]]:
    """A fitted kinematic error's simpler forms: its lines folded into one an order at each
    spline in turn (:func:`one_port_lines`), as ``(label, model)``."""
    return [(f"lines at the {port}", q) for port in GROUNDED
            if (q := one_port_lines(p, port)) is not None]


SIMPLER_FORMS = {"kinematic_error": one_port_forms}
"""Effect -> its simpler forms of a model fitted with it (``forms(model)`` -> ``[(label,
model)]``): refitted after the effect's trial and kept where one carries over better
(:func:`better_on_validation`; :func:`.search.search_round`)."""
