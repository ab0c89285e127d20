"""A candidate judged on both records fitted together (:mod:`.pooled`)."""

from __future__ import annotations

import numpy as np

from hdgym.discrepancy import pooled as P
from hdgym.discrepancy.effect import FitParam
from hdgym.discrepancy.fitting import fit
from hdgym.discrepancy.paths import get_value, set_values
from hdgym.params import preset

BASE = ("motor.inertia", "compliance.stiffness")
EFFECT = "friction.output.viscous"


def _truth():
    return set_values(preset("tuttle-joint3"), {EFFECT: 1.0})


class _Record:
    """A stand-in problem on two channels: its residual is linear, through ``A`` (a column
    per parameter), in the relative errors of the two base parameters and of the effect's
    one parameter (-1 where the model lacks the effect)."""

    names = ("x", "y")
    stick_slip = False
    inverse = False
    scales = None
    compare = "time"

    def __init__(self, truth, A):
        self.truth, self.A = truth, np.asarray(A, dtype=float)
        self.measured = {"x": np.zeros(2), "y": np.zeros(2)}
        self.noise = {"x": 1e-4, "y": 1e-4, "mean": 1e-4}

    def vector(self, p, decimate=1):
        e = np.array([get_value(p, k) / get_value(self.truth, k) - 1
                      for k in (*BASE, EFFECT)])
        return self.A @ e

    def nmse(self, p):
        r = self.vector(p)
        out = {"x": 100.0 * float(r[0] ** 2) + 1e-6, "y": 100.0 * float(r[1] ** 2) + 1e-6}
        out["mean"] = 0.5 * (out["x"] + out["y"])
        return out


def _base_fps(truth):
    return [FitParam(k, 0.5 * get_value(truth, k), 2.0 * get_value(truth, k)) for k in BASE]


def _patch(monkeypatch, truth):
    def fps(p, scales, given):
        out = _base_fps(truth)
        if get_value(p, EFFECT) > 0:  # the effect switched on
            out.append(FitParam(EFFECT, 0.0, 2.0))
        return out

    monkeypatch.setattr(P, "model_params", fps)
    monkeypatch.setattr(P, "_start", lambda problem, p, name: set_values(p, {EFFECT: 0.5}))


def _base_fit(train, truth):
    """The base model (no effect) fitted to the training record alone: in its valley."""
    p0 = set_values(truth, {EFFECT: 0.0, BASE[0]: 1.1 * get_value(truth, BASE[0]),
                            BASE[1]: 0.95 * get_value(truth, BASE[1])})
    return fit(train, p0, _base_fps(truth), max_nfev=200, central=True)


def test_an_effect_the_training_record_lets_the_base_model_mimic_is_named_on_both(
        monkeypatch):
    """The training record sees only the sum of the base errors and the effect's (the base
    fit mimics the effect there exactly); the validation record sees each apart. Refitted
    on both records, the base model cannot mimic it and the effect removes the residual."""
    truth = _truth()
    train = _Record(truth, [[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]])
    val = _Record(truth, [[1.0, 0.0, 1.0], [0.0, 1.0, 2.0]])
    base = _base_fit(train, truth)
    assert base.nmse["mean"] < 1e-4 < val.nmse(base.params)["mean"]  # mimicked on training
    _patch(monkeypatch, truth)
    cands = [{"name": "viscous_friction", "relative_improvement": 0.97}]
    out = P.pooled_candidate(train, val, base, truth, list(BASE), cands, 0.4, 0.005, 0.1, 40)
    assert out is not None
    cand, named, before, rel, why = out
    assert cand["name"] == "viscous_friction" and rel > 0.9 and "together" in why
    assert val.nmse(named.params)["mean"] < 0.01 * val.nmse(before.params)["mean"]
    assert abs(get_value(named.params, EFFECT) - 1.0) < 0.05


def test_an_effect_neither_record_needs_is_not_named(monkeypatch):
    """Where the base model refitted on both records fits both (what the validation record
    showed was the training fit's valley, not an effect), nothing is named; nor is a
    candidate whose trial refit fell short of the training bar refitted at all."""
    truth = _truth()
    train = _Record(truth, [[1.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    val = _Record(truth, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    _patch(monkeypatch, truth)
    base = _base_fit(train, truth)
    cands = [{"name": "viscous_friction", "relative_improvement": 0.97}]
    assert P.pooled_candidate(train, val, base, truth, list(BASE), cands, 0.4, 0.005, 0.1,
                              40) is None
    assert cands[0]["pooled_cut"] < 0.4 and "threshold 40 %" in cands[0]["pooled"]
    assert P.eligible([{"name": "a", "relative_improvement": 0.1}, {"name": "b"}], 0.4) == []



def test_what_a_pooled_refit_that_names_nothing_did_is_said():
    cands = [{"name": "stiction", "pooled": "stiction refitted ... cuts their cost by 4.9 %"},
             {"name": "viscous_friction"}]
    assert P.pooled_words(cands) == ("; not named on both records: stiction refitted ... cuts "
                                     "their cost by 4.9 %")
    assert P.pooled_words([{"name": "viscous_friction"}]) == ""
