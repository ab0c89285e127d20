"""Friction candidates fitted, ranked and judged on their phase-free features.

The features themselves and their comparison are :mod:`.friction_events`. Here:
:func:`fit_features` fits parameters to them, :func:`candidate_entry` is what they say of
one candidate in the ranking (:func:`.ranking.rank_candidates`), :func:`rank_by_features`
ranks friction candidates by them where the time-domain comparison drifts, and
:func:`short_of` / :func:`accepts` judge an effect found there on them
(:func:`.search.search_round`).
"""

from __future__ import annotations

import math

import numpy as np

from hdgym.params import JointParams

from .friction_events import (
    FRICTION_EFFECTS,
    FrictionFeatures,
    _r,
    mismatch,
    model_features,
    record_features,
    vector,
)

FEATURE_STEPS = 3
"""Gauss-Newton steps of a feature fit (:func:`fit_features`; each costs one free run per
parameter and one to check)."""


def fit_features(problem, q: JointParams, fps, record: FrictionFeatures,
                 steps: int = FEATURE_STEPS) -> tuple[JointParams, float]:
    """Fit the parameters ``fps`` (a candidate's own) of ``q`` to the record's features.

    A free run, read as features, has no phase to slip, so this sizes a friction effect
    where the time-domain comparison drifts. Gauss-Newton steps on :func:`vector` with
    finite differences of 5 % of each range (the features are band and event averages of
    quantized runs: smooth on that scale, rough on a finer one), each step a linear least
    squares within the bounds, kept only when it lowers the mismatch. Returns the fitted
    joint and the squared feature mismatch left.
    """
    from scipy.optimize import lsq_linear

    from .paths import get_value, set_values

    fps = [fp for fp in fps if fp.upper > fp.lower]
    lo = np.array([fp.lower for fp in fps])
    hi = np.array([fp.upper for fp in fps])

    def run(x: np.ndarray) -> np.ndarray:
        try:
            p = set_values(q, {fp.path: float(v) for fp, v in zip(fps, x, strict=True)})
        except ValueError:
            return np.full(record.level.size + 4, 10.0)
        return vector(model_features(problem, p, record), record)

    x = np.array([get_value(q, fp.path) for fp in fps])
    v = run(x)
    cost = float(v @ v)
    for _ in range(steps if fps else 0):
        h = 0.05 * (hi - lo)
        h = np.where(x + h <= hi, h, -h)
        J = np.column_stack([(run(x + np.where(np.arange(x.size) == i, h, 0.0)) - v) / h[i]
                             for i in range(x.size)])
        span = hi - lo  # the step in shares of each range, within the bounds
        dz = lsq_linear(J * span, -v, bounds=((lo - x) / span, (hi - x) / span)).x
        x1 = np.clip(x + dz * span, lo, hi)
        v1 = run(x1)
        if not float(v1 @ v1) < cost:
            break
        x, v, cost = x1, v1, float(v1 @ v1)
    best = set_values(q, {fp.path: float(val) for fp, val in zip(fps, x, strict=True)}) \
        if fps else q
    return best, cost


FEATURE_GAIN = 0.8
"""Share by which a friction effect must cut the validation record's feature mismatch
(:func:`compare`, ``total``) to be accepted on the features where the time-domain NMSE
drifts (:func:`.search.escalate`)."""


LEVELS = ("coulomb", "viscous", "breakaway_excess", "stribeck_velocity")
"""Friction-level parameters (of either side) a feature fit refits with a candidate's own:
a base fit shifts them to mimic the missing effect (its Coulomb level towards a Stribeck
friction's mean), and the features cannot tell one friction side from the other."""


def _feature_params(problem, q: JointParams, own) -> list:
    """The candidate's own parameters plus the friction levels of ``q`` (:data:`LEVELS`)."""
    from .registry import model_params

    paths = {fp.path for fp in own}
    out = list(own)
    for fp in model_params(q, problem.scales, problem.params):
        parts = fp.path.split(".")
        if (fp.path not in paths and parts[0] == "friction"
                and (parts[-1] in LEVELS or parts[-1] == "tooth_mu")):
            out.append(fp)
            paths.add(fp.path)
    return out


def candidate_entry(problem, current: JointParams, q: JointParams, fps, name: str) -> dict:
    """What the features say of one candidate (an entry of the ranking).

    The candidate's own parameters ``fps`` and the friction levels are fitted to the
    record's features (:func:`fit_features`) from the best of three starts by feature
    mismatch: ``q`` (its time-domain start), the candidate at zero size on ``current``, and
    at the size the record suggests. ``feature_explained``: the share of the squared
    feature mismatch of ``current`` that fit removes beyond what refitting the friction
    levels alone removes (a base fit some per cent off is not credited to the candidate);
    ``_feature_start``: the fit, a trial
    start sized without regard to phase; ``features``: the mismatch totals (current, start,
    fit). Empty for candidates other than friction effects, or records without features.
    """
    from .paths import set_values
    from .registry import REGISTRY

    if name not in FRICTION_EFFECTS:
        return {}
    rf = record_features(problem)
    if rf is None:
        return {}

    def sq(p: JointParams) -> float:
        v = vector(model_features(problem, p, rf), rf)
        return float(v @ v)

    n = rf.level.size + 4
    c0 = sq(current)
    eff = REGISTRY[name]
    starts = [q, eff.switch_on(current, problem.scales)]
    zero = {fp.path: fp.lower for fp in fps if fp.lower == 0.0}
    if zero:
        try:
            starts.append(set_values(starts[1], zero))
        except ValueError:
            pass
    costs = [sq(s) for s in starts]
    k = int(np.argmin(costs))
    qf, left = fit_features(problem, starts[k], _feature_params(problem, starts[k], fps), rf)
    # the control: the friction levels alone refitted (what the candidate adds is the rest)
    _, ctrl = fit_features(problem, current, _feature_params(problem, current, []), rf)
    ctrl = min(ctrl, c0)
    return {"feature_explained": round(max((ctrl - left) / c0, 0.0), 4) if c0 > 0 else 0.0,
            "features": {"before": math.sqrt(c0 / n), "levels_refitted": math.sqrt(ctrl / n),
                         "start": math.sqrt(costs[k] / n), "fitted": math.sqrt(left / n)},
            "_feature_start": qf}


def judge(problem, before: JointParams, after: JointParams) -> dict | None:
    """The feature mismatch (:func:`compare`) of ``before`` and ``after`` on ``problem``'s
    record and the share cut (``cut``); None without features."""
    rf = record_features(problem)
    if rf is None:
        return None
    b, a = mismatch(problem, before, rf), mismatch(problem, after, rf)
    tb, ta = b["total"], a["total"]
    cut = 1.0 - ta / tb if tb > 0 and math.isfinite(tb) and math.isfinite(ta) else 0.0
    return {"before": b, "after": a, "cut": cut}


FEATURE_FLOOR = 0.05
"""Least feature mismatch (:func:`compare` ``total``, in units of the record's friction
level) before an effect for the features to judge it: below it they agree already."""


def rank_by_features(candidates: list[dict]) -> None:
    """Where the time-domain comparison drifts, a friction candidate scores the larger of
    its time-domain score and the share of the feature mismatch it explains
    (``feature_explained``, :func:`candidate_entry`), and its feature fit is also a trial
    start (``_feature_trial``, :func:`.search.trial`); re-sorts ``candidates`` in place.
    (At the chosen horizon the feature start is not tried: on the tuned load-dependent
    friction case it let Stribeck friction, not in the truth, pass as a second effect.)"""
    for c in candidates:
        if c.get("_feature_start") is not None:
            c["_feature_trial"] = c["_feature_start"]
        fe = c.get("feature_explained")
        if fe is not None and c.get("features", {}).get("before", 0.0) >= FEATURE_FLOOR:
            c["score"] = round(max(c["score"], fe), 4)
    candidates.sort(key=lambda c: -c["score"])


def accepts(problem, before: JointParams, after: JointParams, cand: dict) -> str:
    """Why a friction effect found where the time-domain NMSE drifts is *not* accepted on
    its features ('' when it is): on ``problem``'s (validation) record the feature mismatch
    of ``before`` must be at least :data:`FEATURE_FLOOR` and fall by :data:`FEATURE_GAIN`.
    The judgement is kept in ``cand["feature_judgement"]``."""
    if cand["name"] not in FRICTION_EFFECTS:
        return "(not a friction effect: no phase-free features judge it)"
    j = judge(problem, before, after)
    if j is None:
        return "(no friction features on this record)"
    cand["feature_judgement"] = {"before": _r(j["before"]["total"]),
                                 "after": _r(j["after"]["total"]), "cut": _r(j["cut"])}
    tb = j["before"]["total"]
    if not tb >= FEATURE_FLOOR:
        return (f"and the friction features agree already (mismatch {tb:.3g} < "
                f"{FEATURE_FLOOR:g})")
    if not j["cut"] >= FEATURE_GAIN:
        return (f"and the friction-feature mismatch only by {100 * j['cut']:.0f} % (needs "
                f"{100 * FEATURE_GAIN:.0f} %)")
    return ""


def short_of(problem, before: JointParams, after: JointParams, cand: dict, cut: float,
             gain: float) -> str:
    """Why an effect found where the time-domain NMSE drifts falls short ('' when it
    passes): it must cut the mean validation NMSE by ``gain`` (``cut``: what it did; no
    ``gain``: nothing asked), or, a friction effect, pass on its features
    (:func:`accepts`)."""
    if not gain or cut >= gain:
        return ""
    why = accepts(problem, before, after, cand)
    return (f"{cand['name']} cuts the mean validation NMSE by {100 * cut:.0f} % (needs "
            f"{100 * gain:.0f} % here) {why}") if why else ""
