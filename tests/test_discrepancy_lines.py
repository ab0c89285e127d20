"""The order-domain comparison: line channels at orders of each run's own WG angle."""

from __future__ import annotations

import numpy as np
import pytest

from hdgym.discrepancy.orders import coherence
from hdgym.discrepancy.problem import Problem
from hdgym.discrepancy.restarts import drift
from hdgym.discrepancy.spring_search import views
from hdgym.params import preset
from hdgym.sim import Simulator


def _ke_record(seconds: float = 3.0):
    """A free-output step record of the hduc20 drive (its WG turns faster than the filter
    passes the kinematic error's lines); the model without kinematic error."""
    truth = preset("hduc20")
    rec = Simulator(truth).run("step:2.5", seconds, seed=1)
    return truth, truth.without("kinematic_error"), rec


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
    are never put onto the filtered measured state, so no restart error rings into them;
    restarted from it every window the exact model was tens of per cent off), and the model
    without kinematic error is far off."""
    truth, base, train = _ke_record()
    prob = Problem(train, truth)
    assert prob.line_channels() is not None
    prob.set_compare("lines")
    assert set(prob.names) <= {"te_lines", "speed_lines"} and prob.names
    exact = prob.nmse(truth)
    assert exact["mean"] < 3 * prob.noise["mean"]  # the encoders' quantization
    assert prob.nmse(truth.without("kinematic_error"))["mean"] > 30 * exact["mean"]
    prob.set_compare("time")
    assert "motor_speed" in prob.names


def test_the_line_channels_are_searched_only_where_a_line_effect_is_missing():
    """A free-output record with lines offers the line channels while kinematic error or
    position-dependent friction is missing from the model, not once both are in it; a
    locked output offers the spring curve."""
    truth, base, train = _ke_record(2.0)
    prob = Problem(train, base)
    assert views(prob, base) == ("lines",)
    both = truth.set("effects", tuple(dict.fromkeys(
        (*truth.effects, "kinematic_error", "position_dependent_friction"))))
    assert views(prob, both) == ()


def test_a_transmission_error_shown_on_its_lines_makes_the_kinematic_error_testable():
    """The hdf40 drive's output encoder is too coarse for its transmission error to be a
    time channel, so the kinematic error is untestable there; the TE line channel, averaged
    over windows, shows it (development seed 374, hdf40 / kinematic_error / step:3.79: the
    effect changes the line channels by 100 % NMSE, noise 0.4-1.4 %), so the line channels
    are searched for it and the effect is testable while they are compared, and not after."""
    from hdgym.discrepancy.registry import REGISTRY

    truth = preset("hdf40")
    base = truth.without("kinematic_error")
    prob = Problem(Simulator(truth).run("step:3.8", 2.0, seed=1), base)
    ke = REGISTRY["kinematic_error"]
    assert "transmission_error" not in prob.names and not ke.testable(prob.scales)
    assert "te_lines" in prob.line_channels().names
    assert ke.testable(prob.view_scales("lines")) and not ke.testable(prob.view_scales("time"))
    assert views(prob, base) == ("lines",)
    prob.set_compare("lines")
    assert ke.testable(prob.scales)
    prob.set_compare("time")
    assert not ke.testable(prob.scales) and "motor_speed" in prob.names


def test_lines_repeat_from_window_to_window_and_other_content_does_not():
    """A line keeps its coefficients from one window to the next (a split line turns them
    slowly); coefficients that do not repeat are not lines."""
    rng = np.random.default_rng(0)
    line = np.tile([1.0, 0.5, 0.2, 0.0, 0.1, 0.0], (40, 1))
    turning = np.array([[np.cos(0.05 * k), np.sin(0.05 * k), 0, 0, 0, 0] for k in range(40)])
    assert coherence((line + 0.1 * rng.standard_normal(line.shape)).ravel()) > 5
    assert coherence(turning.ravel()) > 5
    assert abs(coherence(rng.standard_normal((40, 6)).ravel())) < 3
