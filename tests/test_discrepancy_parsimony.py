"""Parsimony between an effect's forms (:mod:`hdgym.discrepancy.parsimony`)."""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import pytest

from hdgym.discrepancy.parsimony import (
    SIMPLER_FORMS,
    better_on_validation,
    one_port_forms,
    one_port_lines,
    simpler_does_nearly_as_well,
)
from hdgym.params import Harmonic, KinematicError, preset


def test_one_port_lines_fold_each_orders_lines_into_one():
    """Each order's lines summed at the record's start (sines of one angle add as phasors)."""
    rh25 = preset("seyfferth-rh25")  # circular spline grounded, both lines on it
    assert one_port_lines(rh25, "circular_spline") is None
    tj1 = preset("tuttle-joint1")  # Tuttle's split order-2 lines on both splines
    for port in ("circular_spline", "flexspline"):
        q = one_port_lines(tj1, port)
        assert q is not None and q.friction == tj1.friction
        lines = {h.order: h for h in q.kinematic_error.harmonics}
        assert sorted(lines) == [2.0, 4.0]
        assert all(h.port == port for h in lines.values())
        assert lines[2.0].amplitude == pytest.approx(0.000242 + 0.000109)  # both at phase 0
        assert lines[4.0].amplitude == pytest.approx(8.46e-05)
    two = dataclasses.replace(tj1, kinematic_error=KinematicError(harmonics=(
        Harmonic(2.0, 1e-4, 0.0, "circular_spline"), Harmonic(2.0, 1e-4, math.pi / 2,
                                                              "flexspline"))))
    # the forms the search refits after a kinematic-error trial: one an order at each spline
    assert SIMPLER_FORMS["kinematic_error"] is one_port_forms
    assert [label for label, _ in one_port_forms(tj1)] == [
        "lines at the flexspline", "lines at the circular_spline"]
    assert [label for label, _ in one_port_forms(rh25)] == ["lines at the flexspline"]
    h = one_port_lines(two, "flexspline").kinematic_error.harmonics
    assert len(h) == 1 and h[0].amplitude == pytest.approx(math.sqrt(2) * 1e-4)
    assert h[0].phase == pytest.approx(math.pi / 4)


class _Val:
    """A validation problem whose NMSE is looked up by the model."""

    def __init__(self, table):
        self.table = table
        self.calls: dict = {}

    def nmse(self, p):
        self.calls[p] = self.calls.get(p, 0) + 1
        return {"mean": self.table[p]}


def test_a_simpler_form_wins_only_where_it_carries_over_better():
    """Judged on the validation record: the split lines cut the training cost more (they
    take up other misfit), the lines at one spline carry over better. No allowance: with
    the nested effects' one (a share of the gain), one line an order stood for the tuned
    tuttle-joint1 case's two."""
    now, split, one = "now", "split", "one"
    fits = {k: SimpleNamespace(params=k) for k in (now, split, one)}
    winner = (0.1, {"relative_improvement": 0.99}, fits[split])
    simpler = (0.2, {"relative_improvement": 0.98}, fits[one])
    assert better_on_validation(_Val({now: 45.9, split: 16.4, one: 5.9}), winner,
                                [simpler]) is simpler
    assert simpler[1]["validation_nmse"] == 5.9 and winner[1]["validation_nmse"] == 16.4
    tj1 = _Val({now: 52.7, split: 0.155, one: 3.7})
    assert better_on_validation(tj1, winner, [simpler]) is None
    assert simpler_does_nearly_as_well(tj1, fits[now], winner, simpler)  # (what it replaces)
    assert better_on_validation(_Val({now: 1.0, split: 0.5, one: math.nan}), winner,
                                [simpler]) is None
    # of two forms, the one that carries over best; each NMSE computed once
    other = (0.3, {"relative_improvement": 0.9}, SimpleNamespace(params="other"))
    val = _Val({now: 45.9, split: 16.4, one: 5.9, "other": 2.0})
    assert better_on_validation(val, winner, [simpler, other]) is other
    assert val.calls == {"split": 1, "one": 1, "other": 1}
    assert better_on_validation(val, winner, []) is None


def _fits_by_start(monkeypatch, costs: dict):
    """``parsimony``'s refits on both records replaced: a fit from the model ``k`` ends at
    cost ``costs[k]`` (its model named ``k + "*"``); rescoring keeps the cost."""
    import hdgym.discrepancy.parsimony as P
    from hdgym.discrepancy.fitting import FitResult

    started = []

    def converge(two, q, fps, nfev, **kw):
        started.append((q, kw.get("search")))
        assert isinstance(two, P.TwoRecords)
        return FitResult(q + "*", {}, {"mean": 100 * costs[q]}, 1, costs[q])

    monkeypatch.setattr(P, "converge", converge)
    monkeypatch.setattr(P, "model_params", lambda q, scales, given: [])
    monkeypatch.setattr(P, "rescored", lambda problem, r: r)
    return started


def _prob():
    return SimpleNamespace(names=("motor_speed",), measured={}, stick_slip=True, scales=None)


def test_nested_effects_are_decided_on_both_records_refitted_together(monkeypatch):
    """The simpler effect (stiction) is named in place of the general one (Stribeck
    friction) when, with the base model, both are refitted on both records together, it
    achieves PARSIMONY of the general one's cut of their joint cost."""
    from hdgym.discrepancy.parsimony import PARSIMONY, nested_on_both

    started = _fits_by_start(monkeypatch, {"base": 1.0, "strib": 0.1, "stick": 0.12})
    base = SimpleNamespace(params="base")
    winner = (0.2, {"name": "stribeck_friction"}, SimpleNamespace(params="strib"))
    simpler = (0.3, {"name": "stiction"}, SimpleNamespace(params="stick"))
    got = nested_on_both(_prob(), _prob(), base, winner, simpler, None, 30)
    assert got is not None and got[2].params == "stick*" and got[0] == 0.12
    assert got[1]["name"] == "stiction" and got[1]["both_records_cut"] == 0.88
    assert winner[1]["both_records_cut"] == 0.9
    assert "both_records_cut" not in simpler[1]  # (a copy is named, the trial is kept)
    # each from its own fit, with the coordinate search (stick-slip)
    assert started == [("base", True), ("strib", True), ("stick", True)]
    # short of PARSIMONY of the general one's cut: the general one stays
    gain = 0.9
    _fits_by_start(monkeypatch, {"base": 1.0, "strib": 0.1,
                                 "stick": 1.0 - PARSIMONY * gain + 0.01})
    assert nested_on_both(_prob(), _prob(), base, winner, simpler, None, 30) is None
    # the general one not better than the base model refitted alike: nothing to prefer
    _fits_by_start(monkeypatch, {"base": 0.1, "strib": 0.1, "stick": 0.1})
    assert nested_on_both(_prob(), _prob(), base, winner, simpler, None, 30) is None


def test_the_search_weighs_the_nested_effect_only_where_its_trial_nearly_matched(monkeypatch):
    """:func:`.search._nested_instead`: only with a validation record, a trial of the
    nested effect, and that trial within PARSIMONY of the winner's training cut."""
    import hdgym.discrepancy.search as S
    from hdgym.discrepancy.parsimony import PARSIMONY

    calls = []
    monkeypatch.setattr(S, "nested_on_both", lambda *a: calls.append(a) or ("picked",))
    best = {"name": "stribeck_friction", "relative_improvement": 0.9}
    near = (0.2, {"name": "stiction", "relative_improvement": PARSIMONY * 0.9}, None)
    far = (0.2, {"name": "stiction", "relative_improvement": PARSIMONY * 0.9 - 0.01}, None)
    cur = SimpleNamespace(cost=1.0)
    ctrl = SimpleNamespace(cost=0.5)
    pol = SimpleNamespace(cost=0.1)
    args = (cur, [(0.1, best, pol), near], best, pol, None, 30)
    assert S._nested_instead(_prob(), None, ctrl, *args) is None  # no validation record
    assert S._nested_instead(_prob(), _prob(), ctrl, cur, [(0.1, best, pol), far], best, pol,
                             None, 30) is None
    other = {"name": "viscous_friction", "relative_improvement": 0.9}
    assert S._nested_instead(_prob(), _prob(), ctrl, cur, [(0.1, other, pol), near], other,
                             pol, None, 30) is None  # nothing nested in it
    assert not calls
    assert S._nested_instead(_prob(), _prob(), ctrl, *args) == ("picked",)
    assert calls[0][2] is ctrl  # against the converged control, the better base fit
    S._nested_instead(_prob(), _prob(), SimpleNamespace(cost=2.0), *args)
    assert calls[1][2] is cur
