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
