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
