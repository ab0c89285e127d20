"""Honest outcomes: a channel that alone shows what the model lacks is not called noise."""

from __future__ import annotations

from hdgym.discrepancy import cases, experiments
from hdgym.discrepancy.floor import floor_nmse, unexplained_channels
from hdgym.discrepancy.outcome import RESOLVED, outcome_of
from hdgym.discrepancy.problem import Problem
from hdgym.discrepancy.registry import REGISTRY, model_params


def _clipped_record():
    """A current-steps record of the case joint whose amplifier clips the current, and the
    model without the clipping."""
    truth = cases.truth_for(next(c for c in cases.all_cases()
                                 if c.name == "amplifier_saturation"))
    rec = experiments.generate("current_steps", truth, duration=1.5, seed=1)
    base = REGISTRY["amplifier_saturation"].neutral(truth.without("amplifier_saturation"))
    return truth, base, Problem(rec, base, segment=0.1)


def test_a_clipped_current_is_not_noise_or_slack():
    truth, base, prob = _clipped_record()
    final = prob.nmse(base)
    assert "motor_current" in prob.names
    # the model the record was made with leaves nothing unexplained on any channel
    assert unexplained_channels(prob, truth, model_params(truth, prob.scales, truth),
                                prob.nmse(truth), 3.0) == {}
    # without the clipping the current channel is above its floor and no fitted
    # parameter of the model can make it
    why = unexplained_channels(prob, base, model_params(base, prob.scales, base), final, 3.0)
    assert "motor_current" in why, why
    floor = floor_nmse(prob, base)
    assert final["motor_current"] > 3.0 * floor["motor_current"]
    # a mean that the old rule called resolved is now unexplained
    out, _ = outcome_of([], 0.5 * RESOLVED, 1.0, [], {}, base, why)
    assert out == "unexplained"
    assert outcome_of([], 0.5 * RESOLVED, 1.0, [], {}, base, {})[0] == "nothing missing"
    assert outcome_of(["x"], 0.5 * RESOLVED, 1.0, [], {}, base, why)[0] == (
        "named; rest unexplained")


def test_a_named_model_is_judged_against_its_own_floor():
    from hdgym.discrepancy.outcome import FLOOR_FACTOR, judge

    truth, base, prob = _clipped_record()
    # the joint the record was made with, named: at its own floor
    out, _, stuck, floor = judge(prob, truth, model_params(truth, prob.scales, truth),
                                 ["amplifier_saturation"], [], {}, truth, {})
    assert out == "named" and not stuck and floor is not None
    assert prob.nmse(truth)["mean"] <= FLOOR_FACTOR * floor
    # a model still without the clipping, had something else been named: the rest is not
    # at its floor (the current channel the clipping shapes)
    out, _, _, floor = judge(prob, base, model_params(base, prob.scales, base),
                             ["viscous_friction"], [], {}, base, {})
    assert out == "named; rest unexplained"
    assert prob.nmse(base)["mean"] > FLOOR_FACTOR * floor


def test_the_spring_curve_shows_the_hardening_the_time_channels_hide():
    from hdgym.discrepancy.fitting import fit
    from hdgym.discrepancy.spring_search import search_view
    from hdgym.discrepancy.workflow import ESCALATED_GAIN, MIN_SCORE, THRESHOLD, _search
    from hdgym.params import preset
    from hdgym.record import Record
    from hdgym.sim import Simulator

    truth = preset("seyfferth-rh32")  # the blind case's drive and command, 2 s
    run = Simulator(truth, locked_output=True).run("sine:2.0:1", 2.0, seed=1)
    rec = Record(dict(run.columns), dict(run.meta), "locked sine")
    given = REGISTRY["nonlinear_stiffness"].neutral(truth.without("nonlinear_stiffness"))
    prob = Problem(rec, given, segment=0.5)
    fps = model_params(given, prob.scales, given)
    base = fit(prob, given, fps, max_nfev=20)
    # on the time channels the refitted linear spring is within the noise
    assert prob.nmse(base.params)["mean"] < 3.0 * prob.noise["mean"]
    assert REGISTRY["nonlinear_stiffness"].compare == ("time", "spring")
    prob.set_compare("spring")
    assert prob.names == ("motor_angle",) and prob.segment == 0.0
    # the bend stays on the curve, well above the noise of its bin means; the joint the
    # record was made with leaves it at that noise
    assert prob.nmse(base.params)["motor_angle"] > 3.0 * prob.noise["motor_angle"]
    assert prob.nmse(truth)["motor_angle"] < prob.noise["motor_angle"]
    prob.set_compare("time")
    assert prob.noise is prob.noise_time and prob.segment == 0.5 and len(prob.names) == 3
    # the workflow's spring search names it there
    paths = [f.path for f in fps]
    accepted, _, _, stuck = search_view(
        prob, None, base, given, 10, MIN_SCORE,
        lambda cur: _search(prob, None, cur, given, paths, THRESHOLD, 10, 20, ESCALATED_GAIN))
    assert accepted is not None and accepted[0]["name"] == "nonlinear_stiffness"
    assert prob.compare == "spring" and not stuck


def test_report_without_a_floor_does_not_print_none():
    """An inverse comparison (a closed-loop real record) has no floor: the report's NMSE
    line leaves the floor out instead of printing "None %"; with a floor it names it."""
    import json
    from pathlib import Path

    from hdgym.discrepancy.report import to_markdown

    js = json.loads((Path(__file__).parents[1] / "results/real-data/report.json").read_text())
    js["floor_nmse"] = None
    text = to_markdown(js)
    assert "None" not in text and "made itself" not in text
    js["floor_nmse"] = 0.0123
    assert "the final model on a record it made itself: 0.0123 %" in to_markdown(js)
