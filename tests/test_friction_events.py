"""Friction trial starts per side, and friction event features (friction_events)."""

from __future__ import annotations

import pytest

from hdgym.discrepancy.paths import get_value
from hdgym.discrepancy.problem import Problem
from hdgym.discrepancy.registry import REGISTRY
from hdgym.params import preset
from hdgym.record import Record
from hdgym.sim import Simulator


def _wave_drive(seconds: float = 2.0) -> tuple:
    """wave-drive-50 with every effect on (its viscous friction on the motor side only), a
    record of sine:0.5:1, and the base model without viscous friction."""
    truth = preset("wave-drive-50")
    rec = Simulator(truth).run("sine:0.5:1", seconds, seed=1)
    rec = Record(dict(rec.columns), dict(rec.meta), "wave-drive-50 sine")
    base = REGISTRY["viscous_friction"].neutral(truth.without("viscous_friction"))
    return truth, rec, base


def test_trial_start_puts_friction_on_the_side_that_has_it():
    """The size grid moves both friction sides together; on wave-drive-50 the viscous
    friction sits on the motor side, where output-side viscous friction loads the spring
    instead: the start must try each side alone (before, it started at a fifth of the
    motor-side value with output-side friction the record does not have)."""
    from hdgym.discrepancy.ranking import _start

    truth, rec, base = _wave_drive()
    prob = Problem(rec, base, segment=0.05)
    q = _start(prob, base, "viscous_friction")
    b_in = truth.friction.input.viscous
    assert get_value(q, "friction.input.viscous") == pytest.approx(b_in, rel=0.5)
    # output-referred, the output side holds less than a tenth of the motor side's share
    assert get_value(q, "friction.output.viscous") < 0.1 * b_in * truth.ratio**2
    assert prob.nmse(q)["mean"] < 0.5 * prob.nmse(base)["mean"]
