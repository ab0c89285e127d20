"""Friction trial starts per side, and friction event features (friction_events, friction_fit)."""

from __future__ import annotations

import numpy as np
import pytest

from hdgym.discrepancy import friction_events as FE
from hdgym.discrepancy import friction_fit as FF
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


def test_friction_features_read_the_friction_curve_and_ignore_phase():
    """The record's friction curve rises with speed (viscous friction); the truth run
    freely reproduces every feature although nothing restarts it, a model without the
    viscous friction misses the curve, and a model whose inertia is 3 % off (a phase slip
    in the time domain) keeps the features."""
    truth, rec, base = _wave_drive()
    prob = Problem(rec, base)
    rf = FE.record_features(prob)
    fwd = rf.level[0]
    assert np.all(np.diff(fwd[np.isfinite(fwd)]) > 0)
    assert rf.counts["reversal"] >= 2
    assert FE.mismatch(prob, truth, rf)["total"] < 0.02
    assert FE.mismatch(prob, base, rf)["level"] > 0.3
    slow = truth.set("motor.inertia", 1.03 * truth.motor.inertia)
    assert FE.mismatch(prob, slow, rf)["total"] < 0.05
    # locked-output records have no free run to read
    lk = Simulator(truth, locked_output=True).run("sine:0.5:1", 0.5, seed=1)
    assert FE.record_features(Problem(Record(dict(lk.columns), dict(lk.meta), "lk"),
                                      truth)) is None


def test_features_judge_and_report_a_friction_effect():
    """Where the time-domain NMSE drifts, a friction effect is judged on its features: the
    base model misses them, the model with the effect cuts the mismatch; a model that
    already agrees, or a non-friction effect, is not accepted on them; the report's section
    lists the record's friction curve beside before and after."""
    from hdgym.discrepancy.report import to_markdown

    truth, rec, base = _wave_drive()
    prob = Problem(rec, base)
    assert FF.accepts(prob, base, truth, {"name": "viscous_friction"}) == ""
    assert "agree already" in FF.accepts(prob, truth, truth, {"name": "viscous_friction"})
    assert "not a friction" in FF.accepts(prob, base, truth, {"name": "hysteresis"})
    cand = {"name": "coulomb_friction"}
    assert "only by" in FF.accepts(prob, base, base.set("friction.input.coulomb", 0.0011), cand)
    assert cand["feature_judgement"]["cut"] < 0.8
    js = FE.summary(prob, base, truth)
    assert js["mismatch_after"]["total"] < 0.1 * js["mismatch_before"]["total"]
    md = "\n".join(FE.markdown(js))
    assert "## Friction features" in md and md.count("| friction forward") == FE.BANDS
    page = to_markdown({"record": "r", "validation_record": None, "mode": "simulate",
                        "channels": ["motor_speed"], "base_effects": [], "outcome": "named",
                        "missing_effects": ["viscous_friction"], "nmse_before": 1.0,
                        "nmse_after": 0.1, "nmse_on": "training", "conclusion": "found",
                        "steps": [], "where": {}, "where_after": {},
                        "remaining_candidates": [], "untestable_effects": [], "notes": [],
                        "figures": {}, "friction_features": js})
    assert "## Friction features" in page


def test_coulomb_friction_is_seen_on_a_joint_that_mostly_stands_still():
    """A record in which friction holds the joint most of the time (tuttle-joint3 on
    random:0.104:1 moves in 11 % of it, with a standstill it breaks away from) shows the
    Coulomb level; without a standstill, 11 % of motion does not."""
    from hdgym.discrepancy.effect import Scales

    eff = REGISTRY["coulomb_friction"]
    s = Scales(torque=1.0, speed=1.0, torsion=1e-3, current=1.0, moving=0.11)
    assert eff.testable(Scales(**{**s.__dict__, "standstills": 1}))
    assert not eff.testable(Scales(**{**s.__dict__, "standstills": 0}))


def test_drifting_comparison_ranks_friction_by_its_features():
    """Where the time-domain comparison drifts, a friction candidate whose features the
    base model misses is ranked by the share it explains and tried from its feature fit;
    one whose features agree already keeps its time-domain score."""
    q = object()
    cands = [{"name": "kinematic_error", "score": 0.2},
             {"name": "stiction", "score": 0.01, "feature_explained": 0.02,
              "features": {"before": 0.01}, "_feature_start": q},
             {"name": "viscous_friction", "score": 0.05, "feature_explained": 0.6,
              "features": {"before": 0.3}, "_feature_start": q}]
    FF.rank_by_features(cands)
    assert [c["name"] for c in cands] == ["viscous_friction", "kinematic_error", "stiction"]
    assert cands[0]["score"] == 0.6 and cands[0]["_feature_trial"] is q
    assert cands[2]["score"] == 0.01
