"""An effect with several forms: the trial start tries each (a hardening spring as a cubic
or with a knee) and keeps the cheapest."""

from __future__ import annotations

import pytest

from hdgym.discrepancy.problem import Problem
from hdgym.discrepancy.ranking import _start, _start_form
from hdgym.discrepancy.registry import REGISTRY
from hdgym.params import JointParams, preset
from hdgym.record import Record
from hdgym.sim import Simulator


def test_the_spring_switches_on_as_a_cubic_or_with_a_knee():
    eff = REGISTRY["nonlinear_stiffness"]
    assert eff.form_names() == (None, "knee")
    given = eff.neutral(preset("wave-drive-50").without("nonlinear_stiffness"))
    rec = Simulator(preset("wave-drive-50"), locked_output=True).run("sine:0.458:1", 0.5,
                                                                     seed=1)
    s = Problem(Record(dict(rec.columns), dict(rec.meta), "locked sine"), given).scales
    cubic, knee = eff.switch_on(given, s), eff.switch_on(given, s, "knee")
    assert cubic.compliance.model == "cubic" and cubic.compliance.cubic > 0
    assert knee.compliance.model == "two_segment" and knee.compliance.cubic == 0
    assert knee.compliance.knee > 0 and knee.compliance.extra_stiffness > 0
    assert "nonlinear_stiffness" in knee.effects
    with pytest.raises(ValueError, match="nonlinear_stiffness.*'bend'"):
        eff.switch_on(given, s, "bend")


def _spring_curve(name: str, hidden: str, command: str) -> tuple[Problem, JointParams]:
    """The spring curve of a 2 s locked record of preset ``name`` and the preset without
    ``hidden`` (its parameters neutral), the base model given."""
    truth = preset(name)
    run = Simulator(truth, locked_output=True).run(command, 2.0, seed=1)
    rec = Record(dict(run.columns), dict(run.meta), "locked sine")
    given = REGISTRY[hidden].neutral(truth.without(hidden))
    prob = Problem(rec, given, segment=0.5)
    prob.set_compare("spring")
    return prob, given


def test_the_trial_start_finds_the_knee_of_a_segmented_spring():
    """wave-drive-50's spring is stiffer above a knee (two segments): on the spring curve of
    a locked record the knee form starts closer than the cubic one, and the trial start
    keeps it (the hold-out case wave-drive-50 / nonlinear_stiffness, locked, seed 62)."""
    prob, given = _spring_curve("wave-drive-50", "nonlinear_stiffness", "sine:0.458:1")
    cubic, cubic_cost = _start_form(prob, given, "nonlinear_stiffness", None)
    assert cubic_cost == prob.nmse(cubic)["mean"]
    best = _start(prob, given, "nonlinear_stiffness")
    assert best.compliance.model == "two_segment"
    assert prob.nmse(best)["mean"] < 0.7 * prob.nmse(cubic)["mean"]
    assert prob.nmse(best)["mean"] < 0.7 * prob.nmse(given)["mean"]


def test_the_trial_start_scales_the_maxwell_elements(monkeypatch):
    """tuttle-joint1's Maxwell-slip elements are 0.02-0.09 x its spring's stiffness, the
    registry's guess 0.05-0.5 x: on the spring curve of a locked record the start found with
    the elements scaled (ELEMENT_GRID) is cheaper than the one at the guess alone."""
    from hdgym.discrepancy import ranking

    prob, given = _spring_curve("tuttle-joint1", "hysteresis", "sine:2.98:0.5")
    scaled = _start(prob, given, "hysteresis")
    monkeypatch.setattr(ranking, "ELEMENT_GRID", (1.0,))
    guess = _start(prob, given, "hysteresis")
    k_s, k_g = scaled.hysteresis.element_stiffness, guess.hysteresis.element_stiffness
    assert all(a < b for a, b in zip(k_s, k_g, strict=True))
    assert prob.nmse(scaled)["mean"] < 0.3 * prob.nmse(guess)["mean"]


def test_the_trial_start_refines_every_shape_of_the_knee():
    """The size grid steps by a factor 1.8 and can straddle the narrow valley of a knee
    spring's extra stiffness, so the knee nearest the truth can lose on the grid to one
    4.7 x too far out (the hold-out case wave-drive-50 / nonlinear_stiffness / sine:0.284:2,
    locked, seed 170): the start refines the size at every knee of the grid, and is at
    least as cheap as the start found with any one knee alone."""
    from hdgym.discrepancy import ranking
    from hdgym.discrepancy.holdout import base_model, holdout_cases, records

    case = next(c for c in holdout_cases(170)
                if c.name.startswith("wave-drive-50 / nonlinear_stiffness"))
    truth = preset(case.preset)
    train, _ = records(case, truth)
    given = base_model(case, truth)
    prob = Problem(train, given, segment=0.5)
    prob.set_compare("spring")
    start, cost = _start_form(prob, given, "nonlinear_stiffness", "knee")
    alone = []
    for g in ranking.SHAPE_GRID:
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(ranking, "SHAPE_GRID", (g,))
            alone.append(_start_form(prob, given, "nonlinear_stiffness", "knee")[1])
    assert cost <= min(alone) * (1 + 1e-9)
    # the knee found is the truth's, not the grid's best-looking one
    assert start.compliance.knee == pytest.approx(truth.compliance.knee, rel=0.2)


def test_the_knee_form_also_starts_from_its_guess():
    """At a knee off the truth's, the grid's cheapest extra stiffness is a small share of
    the spring's and the trial fit from there stops in a valley of its own; the knee form's
    switch-on guess is a start too, last, and the fit from it goes much further (development
    seed 290, hduc20 / nonlinear_stiffness / sine:3.07:2, locked: a three-segment
    spring)."""
    from hdgym.discrepancy.fitting import fit
    from hdgym.discrepancy.holdout import base_model, case_truth, holdout_cases, records
    from hdgym.discrepancy.ranking import _form_starts
    from hdgym.discrepancy.registry import model_params

    case = next(c for c in holdout_cases(290)
                if c.name.startswith("hduc20 / nonlinear_stiffness"))
    truth = case_truth(case)
    train, _ = records(case, truth)
    given = base_model(case, truth)
    prob = Problem(train, given, segment=0.5)
    prob.set_compare("spring")
    eff = REGISTRY["nonlinear_stiffness"]
    guess = eff.switch_on(given, prob.scales, "knee")
    starts = _form_starts(prob, given, "nonlinear_stiffness")
    assert starts[-1] == guess and guess not in starts[:-1]
    grid_knee = next(q for q in starts[:-1] if q.compliance.model == "two_segment")
    assert grid_knee.compliance.extra_stiffness < 0.5 * guess.compliance.extra_stiffness

    def fitted(q: JointParams) -> float:
        return fit(prob, q, model_params(q, prob.scales, given), max_nfev=45,
                   central=True).cost

    assert fitted(guess) < 0.2 * fitted(grid_knee)
    # a base model whose spring already has a knee gets no extra start for other effects
    assert all(q.compliance.model != "two_segment" for q in _form_starts(prob, given,
                                                                         "hysteresis"))
