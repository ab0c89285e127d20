"""The order-domain comparison: line channels at orders of each run's own WG angle."""

from __future__ import annotations

import numpy as np
import pytest

from hdgym.discrepancy import cases
from hdgym.discrepancy.orders import drift
from hdgym.discrepancy.problem import Problem
from hdgym.discrepancy.spring_search import views


def _ke_record(seconds: float = 1.5):
    case = cases.Case("kinematic_error", ("kinematic_error",), "current_steps")
    truth = cases.truth_for(case)
    train, _ = cases.records(case, truth, seconds)
    return truth, cases.base_for(case, truth), train


def test_drift_removes_the_slow_offset_not_the_lines():
    """The straight line fitted to measured - model over whole WG turns gives the offset and
    slope at the last sample; a line at an order of the angle leaves them (nearly) alone."""
    dt = 1e-3
    t = np.arange(200) * dt
    theta = 100.0 * t  # rad: 200 samples, 20 rad, about 3 WG turns
    model = theta + 0.01 * np.sin(2 * theta)
    measured = theta + 0.002 + 0.05 * (t - t[-1])
    offset, slope = drift(measured, model, dt)
    assert offset == pytest.approx(0.002, abs=5e-4)
    assert slope == pytest.approx(0.05, abs=0.02)


def test_the_exact_model_matches_the_line_channels_and_a_model_without_the_lines_does_not():
    """On a free-output record whose WG turns faster than the filter passes the lines, the
    model that made the record leaves its line channels at the quantization level (the runs
    are never put onto the filtered measured state, so no restart error rings into them),
    and the model without kinematic error is far off."""
    truth, base, train = _ke_record()
    prob = Problem(train, truth)
    assert prob.line_channels() is not None
    prob.set_compare("lines")
    assert set(prob.names) <= {"te_lines", "speed_lines"} and prob.names
    exact = prob.nmse(truth)
    assert exact["mean"] < 0.1
    assert prob.nmse(truth.without("kinematic_error"))["mean"] > 100 * max(exact["mean"], 1e-3)
    prob.set_compare("time")
    assert "motor_speed" in prob.names


def test_the_line_channels_are_searched_only_where_a_line_effect_is_missing():
    """A free-output record with lines offers the line channels while kinematic error or
    position-dependent friction is missing from the model, not once both are in it; a
    locked output offers the spring curve."""
    truth, base, train = _ke_record(1.0)
    prob = Problem(train, base)
    assert views(prob, base) == ("lines",)
    both = truth.set("effects", tuple(dict.fromkeys(
        (*truth.effects, "kinematic_error", "position_dependent_friction"))))
    assert views(prob, both) == ()
