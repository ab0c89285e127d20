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
