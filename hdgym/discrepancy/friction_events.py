"""Friction event features: what a run says of its friction, whatever its phase.

A model that runs freely against a record slips in phase, and the time-domain NMSE of a
friction error then grows with the slip rather than with the error. These features are read
from one run (the record, or the model run freely on the record's command) without aligning
it in time to the other, so a phase slip does not change them:

``level``
    the friction curve: the apparent friction torque (output-referred N m: motor torque
    through the gear, ``K_t N i``, minus the load and the inertia's share ``J alpha``),
    times the direction of motion, averaged over each band of |output speed| and each
    direction while the joint moves (away from starts and reversals);
``start``
    the drive torque (``K_t N i`` minus the load, times the new direction) at which the
    joint starts moving after a standstill (no encoder count for
    :data:`.restarts.REST_PAUSE`): its breakaway level, median over the starts;
``stop``
    the same at the sample a moving joint comes to a standstill;
``reversal``
    the same where the speed changes sign without a standstill;
``stuck``
    the share of the run the joint stands still, and the median standstill, s.

:func:`record_features` reads them from a record (:class:`.problem.Problem`),
:func:`model_features` from a free run of a model on the record's command, and
:func:`compare` gives their mismatch, each item in units of the record's friction level.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hdgym.params import JointParams
from hdgym.physics import layout as L
from hdgym.sim import SimulationError, Simulator

from . import residuals as R
from .restarts import REST_PAUSE, pauses

BANDS = 5
"""Bands of |output speed| (quantiles of the record's moving speed) of the friction curve."""
SETTLE = 0.03
"""Seconds after a start or reversal left out of the friction curve (the spring rings)."""
MOVING = 0.1
"""A joint moves where its speed exceeds this share of the record's 90th-percentile speed."""
FRICTION_EFFECTS = ("coulomb_friction", "viscous_friction", "stribeck_friction", "stiction",
                    "load_dependent_friction")
"""The candidates whose evidence these features are (:mod:`.friction_effects`)."""


@dataclass(frozen=True)
class FrictionFeatures:
    """The friction features of one run (see the module text).

    Attributes:
        edges: band edges of |output speed|, rad/s (the record's; ``BANDS + 1`` values).
        level: apparent friction per direction (row 0 forwards, 1 backwards) and band,
            output N m (nan where the run has no sample).
        start, stop, reversal: median drive torque at those events, output N m
            (nan without events); ``counts`` the number of each.
        stuck: share of the run standing still; ``stuck_median``: median standstill, s.
    """

    edges: np.ndarray
    level: np.ndarray
    start: float
    stop: float
    reversal: float
    stuck: float
    stuck_median: float
    counts: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict:
        """Plain numbers (for report.json)."""
        return {"speed_bands": [round(float(e), 6) for e in self.edges],
                "level_forward": [_r(x) for x in self.level[0]],
                "level_backward": [_r(x) for x in self.level[1]],
                "start": _r(self.start), "stop": _r(self.stop), "reversal": _r(self.reversal),
                "stuck_share": _r(self.stuck), "stuck_median_s": _r(self.stuck_median),
                "counts": dict(self.counts)}


def _r(x: float) -> float | None:
    return float(f"{x:.4g}") if math.isfinite(x) else None


@dataclass(frozen=True)
class _Ref:
    """What both runs share: the record's drive, sizes and bands."""

    dt: float
    cutoff: float
    ratio: float
    kt_n: float
    j_out: float
    load: np.ndarray
    typical: float
    edges: np.ndarray
    counts: float


def _ref(problem, edges: np.ndarray | None = None) -> _Ref:
    p: JointParams = problem.params
    r = problem.ratio
    th = R.lowpass(np.asarray(problem.raw.motor_angle, dtype=float), problem.dt, problem.cutoff)
    w = np.gradient(th, problem.dt) / r
    typical = float(np.quantile(np.abs(w), 0.9))
    if edges is None:
        moving = np.abs(w) > MOVING * typical
        aw = np.abs(w[moving]) if moving.any() else np.abs(w)
        edges = np.quantile(aw, np.linspace(0.0, 1.0, BANDS + 1))
    load = p.load.torque + np.asarray(problem.t_ext, dtype=float)
    return _Ref(problem.dt, problem.cutoff, r, p.motor.torque_constant * r,
                p.motor.inertia * r * r + p.load.inertia, load, typical, np.asarray(edges),
                problem.counts[0])


def _features(angle: np.ndarray, current: np.ndarray, ref: _Ref) -> FrictionFeatures:
    """Features of one run from its (encoder-quantized) motor angle and its current."""
    dt = ref.dt
    th = R.lowpass(angle, dt, ref.cutoff)
    w = np.gradient(th, dt) / ref.ratio
    alpha = np.gradient(w, dt)
    drive = ref.kt_n * R.lowpass(current, dt, ref.cutoff) - ref.load
    friction = drive - ref.j_out * alpha
    m = max(int(round(REST_PAUSE / dt)), 1)
    stuck = pauses(angle, m)
    moving = (np.abs(w) > MOVING * ref.typical) & ~stuck
    sgn = np.sign(w)
    # events: starts and stops of standstills, and reversals while moving
    edge = np.diff(stuck.astype(np.int8))
    starts = np.flatnonzero(edge == -1) + 1
    stops = np.flatnonzero(edge == 1) + 1
    settle = max(int(round(SETTLE / dt)), 1)
    n = w.size

    def direction(k: int, after: bool) -> float:
        seg = th[k:min(k + settle, n)] if after else th[max(k - settle, 0):k + 1]
        return float(np.sign(seg[-1] - seg[0])) if seg.size > 1 else 0.0

    start_lv = [drive[k] * d for k in starts if (d := direction(k, True))]
    stop_lv = [drive[k] * d for k in stops if (d := direction(k, False))]
    fast = np.abs(w) > MOVING * ref.typical
    idx = np.flatnonzero(fast)
    rev_lv, rev_at = [], []
    if idx.size > 1:  # consecutive fast samples of opposite sign with no standstill between
        a, b = idx[:-1], idx[1:]
        flip = (sgn[a] != sgn[b])
        for i, j in zip(a[flip], b[flip], strict=True):
            if stuck[i:j + 1].any():
                continue
            k = i + int(np.argmin(np.abs(w[i:j + 1])))
            rev_lv.append(drive[k] * sgn[j])
            rev_at.append(k)
    quiet = moving.copy()
    for k in list(starts) + rev_at:
        quiet[k:k + settle] = False
    aw = np.abs(w)
    level = np.full((2, ref.edges.size - 1), np.nan)
    for row, d in enumerate((1.0, -1.0)):
        for b in range(ref.edges.size - 1):
            lo, hi = ref.edges[b], ref.edges[b + 1]
            sel = quiet & (sgn == d) & (aw >= lo) & (aw <= hi)
            if int(sel.sum()) >= 5:
                level[row, b] = float(np.mean(friction[sel] * d))
    runs = _run_lengths(stuck) * dt
    return FrictionFeatures(
        edges=ref.edges, level=level,
        start=float(np.median(start_lv)) if start_lv else math.nan,
        stop=float(np.median(stop_lv)) if stop_lv else math.nan,
        reversal=float(np.median(rev_lv)) if rev_lv else math.nan,
        stuck=float(np.mean(stuck)), stuck_median=float(np.median(runs)) if runs.size else 0.0,
        counts={"start": len(start_lv), "stop": len(stop_lv), "reversal": len(rev_lv)})


def _run_lengths(mask: np.ndarray) -> np.ndarray:
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return (np.flatnonzero(d == -1) - np.flatnonzero(d == 1)).astype(float)


def record_features(problem) -> FrictionFeatures | None:
    """The features of a free-output record (:class:`.problem.Problem`); None for locked
    output records and the inverse comparison (no free run to read them from)."""
    if problem.locked or problem.inverse:
        return None
    raw = problem.raw
    current = raw.motor_current if raw.motor_current is not None else problem.u
    return _features(np.asarray(raw.motor_angle, dtype=float),
                     np.asarray(current, dtype=float), _ref(problem))


def model_features(problem, p: JointParams, record: FrictionFeatures) -> FrictionFeatures | None:
    """The features of model ``p`` run freely (one run, no restarts) on the record's
    command and load, read like the record's (its bands, inertia and encoder); None when
    the run fails."""
    from .problem import with_sample_time

    if record is None:
        return None
    try:
        sim = Simulator(with_sample_time(p, problem.dt), locked_output=False, sensors=False)
        x0 = sim.initial_state(float(problem.raw.motor_angle[0]))
        _, _, _, st = sim.trajectory(problem.u, load_torque=problem.t_ext, state=x0)
    except (SimulationError, ValueError, FloatingPointError):
        return None
    if not np.all(np.isfinite(st[:, L.TH_M])):
        return None
    ref = _ref(problem, record.edges)
    angle = R.quantize(st[:, L.TH_M], ref.counts)
    current = st[:, L.CUR] if problem.raw.motor_current is not None else problem.u
    return _features(angle, np.asarray(current, dtype=float), ref)


ITEMS = ("level", "start", "stop", "reversal", "stuck")
"""The compared items (:func:`compare`)."""


def scale_of(record: FrictionFeatures) -> float:
    """The record's friction level, output N m: the median of its friction curve (a floor at
    a thousandth of the largest, so a record without friction still has a scale)."""
    lv = np.abs(record.level[np.isfinite(record.level)])
    vals = [x for x in (record.start, record.stop, record.reversal) if math.isfinite(x)]
    allv = np.concatenate([lv, np.abs(vals)]) if vals else lv
    if not allv.size:
        return 1.0
    return max(float(np.median(allv)), 1e-3 * float(np.max(allv)), 1e-12)


def compare(model: FrictionFeatures | None, record: FrictionFeatures) -> dict[str, float]:
    """Mismatch of each item (:data:`ITEMS`) and ``total`` (root mean square of the items the
    record has), each in units of the record's friction level (:func:`scale_of`); the stuck
    share is compared as a share. An event the record has and the run lacks counts 1; a
    failed run counts inf."""
    if model is None:
        return {**{k: math.inf for k in ITEMS}, "total": math.inf}
    s = scale_of(record)
    out: dict[str, float] = {}
    both = np.isfinite(record.level) & np.isfinite(model.level)
    only = np.isfinite(record.level) & ~np.isfinite(model.level)
    errs = np.concatenate([((model.level - record.level)[both] / s), np.ones(int(only.sum()))])
    out["level"] = float(np.sqrt(np.mean(errs**2))) if errs.size else math.nan
    for k in ("start", "stop", "reversal"):
        a, b = getattr(model, k), getattr(record, k)
        if not math.isfinite(b):
            out[k] = math.nan
        else:
            out[k] = abs(a - b) / s if math.isfinite(a) else 1.0
    out["stuck"] = abs(model.stuck - record.stuck)
    items = [v for v in out.values() if math.isfinite(v)]
    out["total"] = float(math.sqrt(np.mean(np.square(items)))) if items else math.nan
    return out


def mismatch(problem, p: JointParams, record: FrictionFeatures | None) -> dict[str, float] | None:
    """:func:`compare` of model ``p`` on ``problem``'s record (None without features)."""
    if record is None:
        return None
    return compare(model_features(problem, p, record), record)


def vector(model: FrictionFeatures | None, record: FrictionFeatures) -> np.ndarray:
    """The items of :func:`compare` as one residual vector (model minus record, in units of
    the record's friction level; an event or band the run lacks counts 1, a failed run 10
    per item): what :func:`fit_features` lowers."""
    n = record.level.size + 4
    if model is None:
        return np.full(n, 10.0)
    s = scale_of(record)
    lv = np.where(np.isfinite(record.level),
                  np.where(np.isfinite(model.level), (model.level - record.level) / s, 1.0),
                  0.0).ravel()
    ev = []
    for k in ("start", "stop", "reversal"):
        a, b = getattr(model, k), getattr(record, k)
        ev.append(0.0 if not math.isfinite(b) else (a - b) / s if math.isfinite(a) else 1.0)
    return np.concatenate([lv, ev, [model.stuck - record.stuck]])


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
drifts (:func:`.workflow._escalate`)."""


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


def summary(problem, before: JointParams, after: JointParams) -> dict | None:
    """Record, before and after features and their mismatch on ``problem``'s record (for
    the report); None without features."""
    rf = record_features(problem)
    if rf is None:
        return None
    fb, fa = model_features(problem, before, rf), model_features(problem, after, rf)
    return {"record": rf.as_dict(),
            "before": None if fb is None else fb.as_dict(),
            "after": None if fa is None else fa.as_dict(),
            "mismatch_before": {k: _r(v) for k, v in compare(fb, rf).items()},
            "mismatch_after": {k: _r(v) for k, v in compare(fa, rf).items()}}


def markdown(js: dict | None) -> list[str]:
    """The report's friction-feature section from :func:`summary`'s dict (empty without)."""
    if not js:
        return []

    def cell(d: dict | None, key: str, i: int | None = None) -> str:
        if d is None:
            return "-"
        v = d[key] if i is None else d[key][i]
        return "-" if v is None else f"{v:.4g}"

    rec, bef, aft = js["record"], js["before"], js["after"]
    e = rec["speed_bands"]
    lines = ["## Friction features", "",
             "Read from one free run each (record; base model fitted; after), not aligned in "
             "time, so a phase slip does not change them "
             "(`hdgym.discrepancy.friction_events`): apparent friction (K_t N i - load - "
             "J alpha, output N m) per band of |output speed| and direction while moving, "
             "and the drive torque at starts, stops and reversals.", "",
             "| item | record | before | after |", "|---|---|---|---|"]
    for d, key in (("forward", "level_forward"), ("backward", "level_backward")):
        for i in range(len(e) - 1):
            lines.append(f"| friction {d}, {e[i]:.3g}-{e[i + 1]:.3g} rad/s | "
                         f"{cell(rec, key, i)} | {cell(bef, key, i)} | {cell(aft, key, i)} |")
    for key in ("start", "stop", "reversal", "stuck_share"):
        lines.append(f"| {key.replace('_', ' ')} | {cell(rec, key)} | {cell(bef, key)} | "
                     f"{cell(aft, key)} |")
    mb, ma = js["mismatch_before"], js["mismatch_after"]
    lines += ["", f"Mismatch (root mean square, in units of the record's friction level): "
              f"{mb['total']} before, {ma['total']} after.", ""]
    return lines


FEATURE_FLOOR = 0.05
"""Least feature mismatch (:func:`compare` ``total``, in units of the record's friction
level) before an effect for the features to judge it: below it they agree already."""


def rank_by_features(candidates: list[dict]) -> None:
    """Where the time-domain comparison drifts, a friction candidate scores the larger of
    its time-domain score and the share of the feature mismatch it explains
    (``feature_explained``, :func:`candidate_entry`), and its feature fit is also a trial
    start (``_feature_trial``, :func:`.workflow._trial`); re-sorts ``candidates`` in place.
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
